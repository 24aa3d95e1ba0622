"""Refusals of ``contactbench`` that come before anything runs, in one line with exit 2 and
no folder written: a plan whose every cell would be skipped for a capability its solvers
lack (a plan where some cell runs still runs), a ``--reference`` that can serve no step,
several problems at once (joined by "; "), ``report`` given a file; and a Ctrl-C or
SIGTERM that the code it landed in wrapped or swallowed still stops the command."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pandas as pd
import pytest

from contactbench.harness import cli

from tests.helpers import run_cli

TINY = ["--size", "16", "--steps", "2", "--seeds", "0", "--no-progress"]


def refused(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one line of a refused command (exit 2, no traceback)."""
    rc, out, err = run_cli(args, capsys)
    assert rc == 2 and out == "", (rc, out, err)
    assert "Traceback" not in err and err.count("\n") == 1 and err.startswith("contactbench: error:"), err
    return err.strip()


def test_a_plan_whose_every_cell_lacks_a_capability_is_refused(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    line = refused(["run", "paper-sweep", *TINY, "--solvers", "nnls", "--hardness", "1e9", "--out", str(out)], capsys)
    assert "every cell would be skipped" in line and "nnls cannot pose bounded pressures" in line, line
    assert not out.exists()


def test_a_plan_where_some_cell_runs_still_runs_and_records_the_skips(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    rc, _, err = run_cli(["run", "paper-sweep", *TINY, "--solvers", "nnls,pk", "--hardness", "1e9",
                          "--reference", "none", "--out", str(out)], capsys)
    assert rc == 0, err
    t = pd.read_csv(out / "results.csv")
    assert set(t.loc[t.solver == "nnls", "status"]) == {"skipped"}
    assert set(t.loc[t.solver == "pk", "status"]) == {"solved"}


def test_a_scene_that_tells_no_sizes_is_refused_for_a_declared_capability(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The stress scenes tell no trial-set sizes; their recipes' control and bounds still
    refuse a solver that declares it cannot pose them, and a plan where some cell runs
    still runs, recording the skipped cells' reasons."""
    out = tmp_path / "o"
    line = refused(["run", "stress-constrained", "--solvers", "nnls", "--no-progress", "--out", str(out)], capsys)
    assert "every cell would be skipped" in line and "nnls cannot pose load control" in line, line
    assert not out.exists()
    rc, _, err = run_cli(["run", "stress-constrained", "--solvers", "nnls,pk", "--no-progress", "--out", str(out)],
                         capsys)
    assert rc == 0, err
    t = pd.read_csv(out / "results.csv")
    nnls = t[t.solver == "nnls"].set_index("instance")
    assert set(nnls.status) == {"skipped"} and set(t.loc[t.solver == "pk", "status"]) == {"solved"}
    assert nnls.skip_reason.str.contains("cannot pose").all()
    assert nnls.control.to_dict() == {"constrained/load-bcc-N16": "load", "constrained/hardness-bcc-N16": "displacement",
                                      "constrained/load-hardness-bcc-N16": "load"}


def test_a_reference_that_cannot_pose_the_problem_is_refused(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    line = refused(["run", "paper-sweep", *TINY, "--solvers", "pk", "--reference", "nnls", "--hardness", "1e9",
                    "--out", str(out)], capsys)
    assert "--reference nnls would serve no step" in line and "bounded pressures" in line, line
    assert not out.exists()


@pytest.mark.parametrize("name", ["nl\nx", "tab\tx", "cr\rx"])
def test_an_out_folder_named_with_a_control_character_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 name: str) -> None:
    out = tmp_path / name
    line = refused(["run", "paper-sweep", *TINY, "--solvers", "pk", "--reference", "none", "--out", str(out)], capsys)
    assert "control character" in line, line
    assert not out.exists()


@pytest.mark.parametrize("args, words", [
    (["run", "counterexample", "--control", "load", "--loads", "0.001"], ["--control", "--loads"]),
    (["run", "paper-sweep", "--size", "16", "--seeds", "0", "--surface", "X"], ["--size", "--seeds"]),
    (["run", "paper-sweep", "--size", "100000", "--seeds", "0-200000"], ["memory budget", "--max-cells"]),
])
def test_several_problems_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
                                       words: list[str]) -> None:
    out = tmp_path / "o"
    line = refused([*args, "--no-progress", "--out", str(out)], capsys)
    assert all(w in line for w in words) and "; " in line, line
    assert not out.exists()


def test_report_of_a_file_says_it_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = tmp_path / "results.csv"
    table.write_text("scene\n")
    line = refused(["report", str(table)], capsys)
    assert "a file, not a run folder" in line and "no such folder" not in line, line


def test_an_interrupt_wrapped_in_another_exception_is_that_interrupt(monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    def wrapped(what: str, params: bool) -> int:  # as CPython wraps one raised inside __set_name__
        try:
            raise cli.Terminated()
        except KeyboardInterrupt as exc:
            raise RuntimeError("Error calling __set_name__ on 'Field' instance 'x' in 'Row'") from exc

    monkeypatch.setattr(cli, "cmd_list", wrapped)
    rc, _, err = run_cli(["list", "scenes"], capsys)
    assert rc == 143 and err.count("\n") == 1 and err.startswith("terminated: "), err


def test_a_sigterm_the_code_swallowed_still_ends_the_command_as_terminated(monkeypatch: pytest.MonkeyPatch,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    def swallowing(what: str, params: bool) -> int:  # as a weakref callback does ("Exception ignored")
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(10**6):  # (the handler runs at the next bytecode)
                pass
        except KeyboardInterrupt:
            pass
        return 0

    monkeypatch.setattr(cli, "cmd_list", swallowing)
    rc, _, err = run_cli(["list", "scenes"], capsys)
    assert rc == 143 and err.count("\n") == 1 and err.startswith("terminated: "), err
