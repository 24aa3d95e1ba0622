"""The report's aggregates against tables built to mislead them: a solver appended with a
short time limit that solved nothing, an all-zero time column, skip and planning-failure
rows that name no operator, rows that name no scene, solver, profile or status, a row that
takes another cell's id, and a
per-scene summary whose median time took in unsolved cells."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import run_benchmark
from contactbench.harness.report import core as rp
from contactbench.harness.report.sections import generic
from contactbench.harness.report.view import report_view
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.table import aggregates as agg
from contactbench.harness.table.schema import ALL_COLUMNS, TableError, check_table
from contactbench.harness.table.store import load_table
from contactbench.problems.scenes import SceneConfig
from contactbench.solvers import register
from contactbench.solvers.registry import unregister
from contactbench.solvers.base import ProblemTraits

from tests.helpers import ExactStub, report_row, run_cli


def _table(rows: list[dict]) -> pd.DataFrame:
    return report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))


def _problems(solver: str, times: list[float], status: str = "solved", limit: float = 10.0) -> list[dict]:
    return [report_row(scene="s", instance=f"i{k}", step=0, solver=solver, solve_time_s=t, status=status,
                       time_limit_s=limit, solver_converged=status == "solved",
                       kkt_error=1e-10 if status == "solved" else np.nan) for k, t in enumerate(times)]


# --- an unsolved cell counts at the part's largest limit ---------------------------------------


def test_a_solver_that_solved_nothing_under_a_short_limit_never_tops_the_table() -> None:
    """Rows appended with ``--timeout 0.001`` that all timed out count at the part's
    largest limit (10 s), not their own: SGM 10 s, never under the solvers that solved."""
    t = _table([*_problems("good", [0.5, 1.0, 2.0]), *_problems("cheat", [0.0011] * 3, "timeout", limit=0.001)])
    summ = {s.solver: s for s in agg.summarize(t)}
    assert summ["cheat"].sgm_s == pytest.approx(10.0)
    assert summ["cheat"].sgm_rel > 1 and summ["good"].sgm_rel == 1
    assert agg.penalty_time(t) == 10.0


def test_an_unsolved_cell_never_counts_under_the_largest_solved_time() -> None:
    """Solves recorded without a limit (an older table) took 5 s; a solver that timed out
    under a 0.001 s limit counts at 5 s, not 0.001 s."""
    t = _table([*_problems("good", [5.0, 1.0], limit=np.nan), *_problems("cheat", [0.0011] * 2, "timeout", 0.001)])
    summ = {s.solver: s for s in agg.summarize(t)}
    assert summ["cheat"].sgm_s == pytest.approx(5.0) and summ["cheat"].sgm_rel >= 1
    assert agg.penalty_time(t) == 5.0


# --- an all-zero time column -------------------------------------------------------------------


@pytest.mark.parametrize("shift", [agg.DEFAULT_SHIFT_S, 1e-3])
def test_the_sgm_of_zero_times_is_zero(shift: float) -> None:
    assert agg.shifted_geometric_mean([0.0, 0.0, 0.0], shift) == 0.0
    assert agg.shifted_geometric_mean([0.0, 1e-300], shift) == 0.0
    assert agg.shifted_geometric_mean([0.0, 1e-3], shift) > 0


def test_a_zero_best_sgm_gives_no_ratio() -> None:
    """Every time of ``zero`` reads 0 s: its SGM is 0, and the others' "SGM / best" is
    undefined ("-"), not 1e15."""
    t = _table([*_problems("zero", [0.0, 0.0, 0.0]), *_problems("other", [0.01, 0.02, 0.03])])
    summ = {s.solver: s for s in agg.summarize(t)}
    assert summ["zero"].sgm_s == 0.0
    assert math.isnan(summ["other"].sgm_rel) and math.isnan(summ["zero"].sgm_rel)


# --- skip and planning-failure rows name their operator ----------------------------------------


class DenseSkipper(ExactStub):
    """A dense solver on the FFT scene: it skips itself at 10 < n <= 40 and its skip check
    raises above (a planning failure)."""

    name = "test-dense-skipper"

    def skip(self, traits: ProblemTraits) -> str | None:
        if traits.n > 40:
            raise RuntimeError("skip check broke")
        return "too large for the test" if traits.n > 10 else None


def test_skip_and_planning_failure_rows_name_the_operator_the_solver_is_given(tmp_path: Path) -> None:
    """paper-sweep at 32^2, 6 steps (n = 2, 5, 7, 16, 33, 55), built with the FFT operator:
    the dense solver is given "dense" on every row, the ones it skipped or failed to plan
    too, so the report counts them with its dense solves."""
    out = tmp_path / "run"
    register(DenseSkipper, replace=True)  # (for this test only: the conformance tests read the registry)
    try:
        run_benchmark(["paper-sweep"], SceneConfig(size=32, steps=6, seeds=(0,)), [DenseSkipper.name],
                      RunConfig(timeout=60.0, reference="none", warmup=False, progress=False), out, command=["pytest"])
    finally:
        unregister(DenseSkipper.name)
    rows = pd.read_csv(out / "results.csv")
    by_status = rows.groupby("status")["operator"].agg(lambda s: sorted(set(s.fillna(""))))
    assert set(by_status.index) == {"solved", "skipped", "failed"}, by_status
    assert all(ops == ["dense"] for ops in by_status), by_status


# --- rows that name nothing --------------------------------------------------------------------


@pytest.mark.parametrize("column", ["scene", "instance", "solver", "profile", "status"])
@pytest.mark.parametrize("empty", ["", np.nan, "  "])
def test_a_row_that_names_no_scene_solver_profile_or_status_is_refused(column: str, empty: object) -> None:
    rows = pd.DataFrame([report_row(scene="s", solver="pk"), report_row(scene="s", solver="pk", step=1)],
                        columns=list(ALL_COLUMNS))
    rows[column] = rows[column].astype(object)
    rows.loc[1, column] = empty
    with pytest.raises(TableError, match=f"column {column} of .* row 2"):
        check_table(rows)


def test_the_report_of_a_table_with_an_empty_scene_is_one_line_and_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pd.DataFrame([report_row(scene="s", solver="pk"), report_row(scene="", solver="pk", step=1)],
                 columns=list(ALL_COLUMNS)).to_csv(tmp_path / "results.csv", index=False)
    rc, out, err = run_cli(["report", str(tmp_path)], capsys)
    assert rc == 2 and "Traceback" not in err and err.count("\n") == 1, (rc, out, err)
    assert "column scene" in err and "row 2" in err
    assert not (tmp_path / "report.md").exists()


def test_a_row_that_takes_another_cells_id_is_refused_not_dropped(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Reading keeps the first row of a cell: a row copied with another solver's cell_id would
    vanish unsaid, so the table is refused in one line (exit 2); rows of one cell that agree
    (a resumed run's) are read as one."""
    rows = [report_row(scene="s", solver=so, cell_id="c1", solve_time_s=0.1) for so in ("pk", "nnls", "pk")]
    pd.DataFrame(rows, columns=list(ALL_COLUMNS)).to_csv(tmp_path / "results.csv", index=False)
    rc, out, err = run_cli(["report", str(tmp_path)], capsys)
    assert rc == 2 and "Traceback" not in err and err.count("\n") == 1, (rc, out, err)
    assert "rows 1 and 2" in err and "cell_id c1" in err and "'pk' against 'nnls'" in err
    pd.DataFrame([rows[0], rows[2]], columns=list(ALL_COLUMNS)).to_csv(tmp_path / "results.csv", index=False)
    assert len(load_table(tmp_path)) == 1


# --- the per-scene summary's median time -------------------------------------------------------


def test_the_summarised_scene_table_takes_its_median_time_over_solved_cells(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """pk solves 3 of 5 cells at n = 100 in 0.1-0.3 s and times out on 2 at 60 s: the
    median solved time is 0.2 s (over every cell it would be 0.3 s); a line with no
    solved cell reads "-"."""
    monkeypatch.setattr(generic, "MAX_TABLE_ROWS", 2)
    rows = [report_row(scene="s", instance=f"i{k}", n=100, solver="pk", solve_time_s=t) for k, t in
            enumerate([0.1, 0.2, 0.3])]
    rows += [report_row(scene="s", instance=f"i{k}", n=100, solver=s, solve_time_s=60.0, status="timeout",
                        solver_converged=False, kkt_error=np.nan) for k in (3, 4) for s in ("pk", "slow")]
    ctx = rp.ReportContext(tmp_path, _table(rows), {})
    generic.scene_tables_section(ctx, ctx.table)
    (t,) = [t for t in ctx.tables if "summarised" in t.caption]
    col = t.headers.index("median solved time [s]")
    median = {r[1]: r[col] for r in t.rows}
    assert median == {"pk": "0.2", "slow": "-"}, median
    assert "over the solved cells" in t.caption
