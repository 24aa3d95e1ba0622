"""A folder may hold one problem solved on two operators (``--append --operator dense``
beside the FFT run): the same instance, step and solver, but two cells
(``schema.CELL_COLUMNS`` holds ``operator``), never one cell's repeats -- a row's repeat
statistics are its own operator's, and the report counts each operator's cells."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from contactbench.harness import cli
from contactbench.harness.report.view import read_table, report_view
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


def test_the_report_shows_each_operator_s_solves_apart(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One solver on two operators at one profile: the report's labels carry the operator
    ("pk [dense]", "pk [fft]"), so its tables count and time each apart; a table of one
    operator keeps its labels."""
    out = tmp_path / "run"
    common = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--solvers", "pk",
              "--reference", "none", "--no-progress", "--out", str(out)]
    assert cli.main(common) == 0
    assert set(read_table(out)["solver"]) == {"pk"}
    assert cli.main([*common, "--append", "--operator", "dense"]) == 0
    assert cli.main(["report", str(out)]) == 0
    capsys.readouterr()
    table = read_table(out)
    assert set(table["solver"]) == {"pk [dense]", "pk [fft]"} and set(table["base_solver"]) == {"pk"}
    text = (out / "report.md").read_text()
    assert "pk [dense]" in text and "pk [fft]" in text


@pytest.mark.parametrize("operators, labels", [
    (["", "dense", "dense"], ["pk", "pk", "pk"]),  # (a skipped row names no operator: one operator ran)
    (["fft", "dense", ""], ["pk [fft]", "pk [dense]", "pk"]),
])
def test_only_rows_of_a_solver_on_two_operators_are_labelled_by_operator(operators: list[str],
                                                                           labels: list[str]) -> None:
    rows = pd.DataFrame({"scene": "s", "solver": "pk", "profile": "default", "operator": operators})
    assert list(report_view(rows)["solver"]) == labels
