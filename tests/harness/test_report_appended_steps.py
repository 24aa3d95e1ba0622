"""A run appended to a folder for fewer solvers (``--append``, another instance): the
totals table of Fig. 4 counts a solver's steps over the steps it was run on, not over
steps it was never asked to run, and says so where these are fewer than the sweep's."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import run_cli

RUN = ["run", "paper-sweep", "--seeds", "0", "--reference", "none", "--no-progress"]


def totals_row(report: str, solver: str) -> list[str]:
    line = next(ln for ln in report.splitlines() if ln.startswith(f"| {solver} (warm)") or ln.startswith(f"| {solver} "))
    return [c.strip() for c in line.strip("|").split("|")]


def test_steps_not_run_are_not_counted_as_unsolved(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli([*RUN, "--size", "16", "--steps", "3", "--solvers", "nnls,pk", "--out", "o"], capsys)[0] == 0
    assert run_cli([*RUN, "--size", "32", "--steps", "2", "--solvers", "nnls", "--out", "o", "--append"],
                   capsys)[0] == 0
    assert run_cli(["report", "o"], capsys)[0] == 0
    report = (in_tmp / "o" / "report.md").read_text()
    nnls, pk = totals_row(report, "nnls"), totals_row(report, "pk")
    assert nnls[2] == "5 of 5" and pk[2] == "3 of 3", (nnls, pk)
    assert "over the 3 steps it was run on, of the sweep's 5" in pk[3], pk
