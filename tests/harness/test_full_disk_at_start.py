"""A run whose first writes fail (a full disk: the marker or meta.json) stops in one line
naming the file, exit 1 -- a write that failed, not bad input -- and the same command then
runs; an atomic write's error without a file names the file it was writing."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from contactbench.problems import atomic_files
from contactbench.harness.table.meta import META_FILE
from contactbench.harness.table.store import MARKER_FILE
from tests.helpers import run_cli

RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--solvers", "nnls",
       "--reference", "none", "--no-progress", "--out", "o"]


def test_an_atomic_write_error_names_the_file(tmp_path: Path) -> None:
    def full(tmp: str) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(OSError) as caught:
        atomic_files.replace_atomically(tmp_path / "x.json", full)
    assert caught.value.filename == str(tmp_path / "x.json") and not list(tmp_path.iterdir())


@pytest.mark.parametrize("name", [MARKER_FILE, META_FILE])
def test_a_full_disk_at_the_start_stops_in_one_line_naming_the_file(
        name: str, in_tmp: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    replace = os.replace

    def full_disk(src: str, dst: os.PathLike[str] | str) -> None:
        if Path(dst).name == name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        replace(src, dst)

    monkeypatch.setattr(atomic_files.os, "replace", full_disk)
    rc, _, err = run_cli(RUN, capsys)
    lines = err.strip().splitlines()
    assert rc == 1 and len(lines) == 1, (rc, err)
    assert f"o/{name}: No space left on device; the run stopped before it solved anything" in lines[0], err
    monkeypatch.setattr(atomic_files.os, "replace", replace)
    rc, out, err = run_cli(RUN, capsys)
    assert rc == 0, err
    assert (in_tmp / "o" / "results.csv").exists()
