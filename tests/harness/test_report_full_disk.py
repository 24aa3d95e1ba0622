"""A report that cannot be written (a full disk) says so in one line naming the file -- or
the folder, where the system names none -- exit 1: a write that failed, not bad input (no
folder, no table); the results are untouched and the same command then writes it."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
from matplotlib.figure import Figure

from contactbench.problems import atomic_files
from tests.helpers import run_cli

RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--solvers", "nnls",
       "--reference", "none", "--no-progress", "--out", "o"]


def no_space(*args: object, **kwargs: object) -> None:
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_page_that_cannot_be_written_is_named_exit_1(in_tmp: Path, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(RUN, capsys)[0] == 0
    results = (in_tmp / "o" / "results.csv").read_bytes()
    replace = os.replace
    monkeypatch.setattr(atomic_files.os, "replace",
                        lambda src, dst: no_space() if Path(dst).name == "report.md" else replace(src, dst))
    rc, _, err = run_cli(["report", "o"], capsys)
    lines = err.strip().splitlines()
    assert rc == 1 and len(lines) == 1, (rc, err)
    assert "o/report.md: No space left on device; the report was not written" in lines[0], err
    assert (in_tmp / "o" / "results.csv").read_bytes() == results
    monkeypatch.setattr(atomic_files.os, "replace", replace)
    assert run_cli(["report", "o"], capsys)[0] == 0 and (in_tmp / "o" / "report.md").is_file()


def test_a_figure_that_cannot_be_written_names_the_folder(in_tmp: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(RUN, capsys)[0] == 0
    monkeypatch.setattr(Figure, "savefig", no_space)
    rc, _, err = run_cli(["report", "o"], capsys)
    assert rc == 1 and "o: No space left on device; the report was not written" in err, (rc, err)
