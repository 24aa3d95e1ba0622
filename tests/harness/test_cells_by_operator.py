"""A folder may hold one problem solved on two operators (``--append --operator dense``
beside the FFT run): the same instance, step and solver, but two cells
(``schema.CELL_COLUMNS`` holds ``operator``), never one cell's repeats -- a row's repeat
statistics are its own operator's, and the report counts each operator's cells."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness import cli
from contactbench.harness.table.store import load_table


def test_rows_on_two_operators_are_two_cells(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    common = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--solvers", "pk",
              "--reference", "none", "--repeats", "2", "--no-progress", "--out", str(out)]
    assert cli.main(common) == 0
    assert cli.main([*common, "--append", "--operator", "dense"]) == 0
    capsys.readouterr()
    table = load_table(out)
    assert sorted(table["operator"].unique()) == ["dense", "fft"] and len(table) == 8
    for _, cell in table.groupby(["step", "operator"]):
        assert len(cell) == 2  # the two repeats, of one operator
        assert cell["solve_time_min_s"].iloc[0] == pytest.approx(cell["solve_time_s"].min())
        assert cell["solve_time_median_s"].iloc[0] == pytest.approx(cell["solve_time_s"].median())
