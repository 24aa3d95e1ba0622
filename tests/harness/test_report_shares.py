"""The report's aggregate figures read right on their own: a share names its denominator and
comes with the problem count, a scene nobody solved has no time aggregate, the reference's
own answers are named as the reference (never as exact answers), and report.html collapses
its sidebar on a narrow screen.

The table (scene "paper-sweep", one instance, profile "default", 10 steps):

    solver   steps 0-2          steps 3-9
    pk       solved             solved
    gp       solved             skipped
    greedy   timeout            timeout

The reference solution is pk's own answer (``reference_solver`` "pk@default") on steps 0-1
and nnls's on steps 2-9 (a candidate outside the run).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.report import core as rp
from contactbench.harness.report.view import report_view
from contactbench.harness.report import html as html_report
from contactbench.harness.report.sections import generic
from contactbench.harness.table.aggregates import served_name
from contactbench.harness.table import aggregates as agg
from contactbench.harness.table.schema import ALL_COLUMNS

from tests.helpers import report_row

SCENE = "paper-sweep"
STEPS = 10


def _reference(step: int) -> str:
    return served_name("pk", "default") if step < 2 else "nnls"


def _table() -> pd.DataFrame:
    rows = []
    for k in range(STEPS):
        ref = _reference(k)
        rows.append(report_row(scene=SCENE, step=k, n=100 + k, solver="pk", solve_time_s=0.01 * (k + 1),
                               reference_solver=ref, p_rel_error=0.0 if ref == "pk@default" else 1e-9))
        rows.append(report_row(scene=SCENE, step=k, n=100 + k, solver="gp", solve_time_s=0.02 * (k + 1),
                               status="solved" if k < 3 else "skipped", skip_reason="" if k < 3 else "too slow",
                               reference_solver=ref, p_rel_error=1e-7))
        rows.append(report_row(scene=SCENE, step=k, n=100 + k, solver="greedy", solve_time_s=60.0, status="timeout",
                               solver_converged=False, reference_solver=ref, p_rel_error=np.nan, kkt_error=np.nan))
    return report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))


def _context(tmp_path: Path, table: pd.DataFrame) -> rp.ReportContext:
    return rp.ReportContext(tmp_path, table, {})


def _tables(ctx: rp.ReportContext, word: str) -> list[rp.TableRecord]:
    return [t for t in ctx.tables if word in t.caption]


def _cell(t: rp.TableRecord, solver: str, column: str) -> str:
    (row,) = [r for r in t.rows if r[0] == solver]
    return row[t.headers.index(column)]


# --- solved / problems beside solved / attempted ---------------------------------------------


def test_solved_share_is_over_every_problem_and_success_over_the_attempted() -> None:
    """gp solved 3 of 10 problems, the 7 others skipped: 30 % of the problems, 100 % of
    what it attempted; a solver absent from a problem counts it as not solved too, but its
    time aggregate counts only the cells it was planned to run (pk on steps 0-4: 0.01 to
    0.05 s, shift 0.01 s: (720 * 1e-10)^(1/5) - 0.01 s over 5 cells, the best there; gp,
    planned on all ten, is compared with the solvers planned on all ten that solved one:
    itself alone)."""
    t = _table()
    summ = {s.solver: s for s in agg.summarize(t)}
    gp = summ["gp"]
    assert (gp.problems, gp.attempted, gp.solved) == (10, 3, 3)
    assert gp.solved_share == pytest.approx(0.3) and gp.success_rate == pytest.approx(1.0)
    absent = t[~((t["solver"] == "pk") & (t["step"] >= 5))]
    pk = {s.solver: s for s in agg.summarize(absent)}["pk"]
    assert (pk.problems, pk.solved, pk.solved_share, pk.success_rate) == (10, 5, 0.5, 1.0)
    after = {s.solver: s for s in agg.summarize(absent)}
    assert pk.sgm_s == pytest.approx(720 ** 0.2 * 0.01 - 0.01, rel=1e-12)
    assert (pk.sgm_cells, pk.sgm_rel, after["gp"].sgm_cells, after["gp"].sgm_rel) == (5, 1.0, 10, 1.0)


def test_every_aggregate_table_shows_the_problems_and_both_shares(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    section = generic.aggregates_section(ctx, ctx.table)
    tables = _tables(ctx, "aggregates, scene") + _tables(ctx, "over every scene")
    assert len(tables) == 2
    for t in tables:
        for col in ("problems", "solved / problems", "solved / attempted"):
            assert col in t.headers, (t.caption, t.headers)
        assert "success" not in t.headers  # a share without its denominator
        assert (_cell(t, "gp", "problems"), _cell(t, "gp", "solved / problems"),
                _cell(t, "gp", "solved / attempted")) == ("10", "30 %", "100 %")
    assert "**solved / problems**" in section.body and "**solved / attempted**" in section.body


def test_the_page_s_aggregate_table_shows_the_problems_and_both_shares(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    _, sgm = html_report.profiles_and_sgm(ctx, html_report.scene_summaries(ctx))
    (t,) = sgm[SCENE]
    for col in ("problems", "solved / problems", "solved / attempted"):
        assert col in t["columns"]
    assert [t["columns"][i] for i in t["percent"]] == ["solved / problems", "solved / attempted"]
    assert t["columns"][t["sort"]] == "SGM / best"
    (gp,) = [r for r in t["rows"] if r[0] == "gp"]
    row = dict(zip(t["columns"], gp))
    assert (row["problems"], row["solved"]) == (10, 3)
    assert row["solved / problems"] == pytest.approx(0.3) and row["solved / attempted"] == pytest.approx(1.0)


# --- no solver solved: no SGM -----------------------------------------------------------------


def test_a_scene_nobody_solved_has_no_time_aggregate(tmp_path: Path) -> None:
    """Every cell counts at the limit: a tie that would read as "1 = best" for all."""
    t = _table()
    t = t[t["solver"] == "greedy"].assign(time_limit_s=60.0)
    both = pd.concat([t, t.assign(solver="other", base_solver="other")], ignore_index=True)
    for s in agg.summarize(both):
        assert s.solved == 0 and np.isnan(s.sgm_s) and np.isnan(s.sgm_rel)
    ctx = _context(tmp_path, both)
    generic.aggregates_section(ctx, both)
    (table,) = _tables(ctx, "aggregates, scene")
    for solver in ("greedy", "other"):
        assert _cell(table, solver, "SGM / best") == "-" and _cell(table, solver, "SGM [s]") == "-"
    assert "No solver solved a problem of this scene" in table.caption


def test_a_solver_that_solved_nothing_is_never_the_best() -> None:
    """The best is taken among the solvers with a solve, whatever the others' limits."""
    t = _table()
    t.loc[t["solver"] == "greedy", "time_limit_s"] = 1e-3  # its failures count at a tiny limit
    summ = {s.solver: s for s in agg.summarize(t)}
    assert summ["greedy"].solved == 0
    assert min(summ["pk"].sgm_rel, summ["gp"].sgm_rel) == 1.0


# --- the reference's own answers ------------------------------------------------------------


def test_own_reference_is_the_row_whose_answer_served() -> None:
    t = _table()
    own = agg.own_reference(t)
    assert set(zip(t.loc[own, "solver"], t.loc[own, "step"])) == {("pk", 0.0), ("pk", 1.0)}
    assert agg.reference_steps(t) == {"pk@default": (0, 1), "nnls": tuple(range(2, STEPS))}
    assert generic.step_ranges([0, 1, 2, 3, 5, 7, 8]) == "0-3, 5, 7-8"


def test_scene_tables_show_the_reference_s_own_cells_as_ref_and_name_the_reference(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    generic.scene_tables_section(ctx, ctx.table)
    (t,) = _tables(ctx, f"scene `{SCENE}`")
    col = t.headers.index("p err")
    pk = {r[t.headers.index("step")]: r[col] for r in t.rows if r[t.headers.index("solver")] == "pk"}
    assert pk["0"] == pk["1"] == generic.REF_CELL and pk["2"] == "1.0e-09"
    assert "`pk@default` (steps 0-1)" in t.caption and "`nnls` (steps 2-9)" in t.caption


def test_the_summarised_scene_table_leaves_the_reference_s_own_cells_out_of_its_worst(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(generic, "MAX_TABLE_ROWS", 5)
    ctx = _context(tmp_path, _table())
    generic.scene_tables_section(ctx, ctx.table)
    (t,) = _tables(ctx, "summarised")
    worst = {(r[0], r[1]): r[t.headers.index("worst p err")] for r in t.rows}
    assert worst[("100", "pk")] == generic.REF_CELL and worst[("102", "pk")] == "1.0e-09"


def test_work_precision_leaves_the_reference_s_own_answers_out_of_the_p_panel(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    figures: dict[str, Any] = {}
    monkeypatch.setattr(rp.ReportContext, "save_figure", lambda self, fig, name, on_page=False: (
        figures.__setitem__(name, fig), f"figures/{name}.png")[1])
    ctx = _context(tmp_path, _table())
    section = generic.work_precision_section(ctx, ctx.table)
    fig = figures[f"wp-{SCENE}"]
    (p_ax,) = [a for a in fig.axes if a.get_title().endswith("error against reference")]
    ys = np.concatenate([c.get_offsets()[:, 1] for c in p_ax.collections])
    attempted = ctx.table[ctx.table["status"] != "skipped"]
    measured = attempted["p_rel_error"].notna() & ~agg.own_reference(attempted)
    assert len(ys) == int(measured.sum()) and np.all(ys > rp.LOG_FLOOR)
    assert "`pk@default` (steps 0-1), `nnls` (steps 2-9)" in section.body
    assert "left out of the error-in-p panel" in section.body


def test_page_rows_mark_the_reference_s_own_answers(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    rows = html_report.page_rows(ctx)
    assert {(r["so"], r["st"]) for r in rows if r["ref"]} == {("pk", 0), ("pk", 1)}


# --- the page on a narrow screen --------------------------------------------------------------


def test_the_page_collapses_its_sidebar_on_a_narrow_screen(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    generic.aggregates_section(ctx, ctx.table)
    ctx.tables[:] = [rp.TableRecord(t.number, t.caption, t.headers, t.rows, t.align, True) for t in ctx.tables]
    page = html_report.render_html(ctx)
    head = page.split("</head>")[0]
    assert '<meta name="viewport" content="width=device-width' in head
    media = head.split(f"@media (max-width:{html_report.NARROW_MAX_PX}px)")[1]
    assert "#layout{display:block}" in media and ".grid{grid-template-columns:1fr}" in media
    assert "minmax(min(520px,100%),1fr)" in head  # a grid column never wider than the page
    body = page.split("</head>")[1]
    assert body.count('<div class="tablebox"><table') == len(ctx.tables)  # each table scrolls in its own box


# --- one profile at a time: solvers at two profiles never met ---------------------------------------


def _two_profiles() -> pd.DataFrame:
    """Four steps: fast-a and fast-b at profile "default", nnls-gp at "paper" (a profile is
    an accuracy target: nnls-gp never solved the problems the others did)."""
    rows = []
    for k in range(4):
        for solver, prof, t in (("fast-a", "default", 0.0147), ("fast-b", "default", 0.03), ("nnls-gp", "paper", 0.0071)):
            rows.append(report_row(scene=SCENE, step=k, n=100, solver=solver, profile=prof, solve_time_s=t,
                                   family="fast" if solver.startswith("fast") else "paper"))
    return report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))


def test_a_scene_at_two_profiles_is_aggregated_once_per_profile(tmp_path: Path) -> None:
    """Each (instance, step) is one problem per profile: the aggregates of a scene whose
    solvers ran at two profiles are a table and a performance profile per profile, 4 problems
    each, never one of 8 where every curve stops at 1/2 and both profiles' fastest read "1"."""
    ctx = _context(tmp_path, _two_profiles())
    section = generic.aggregates_section(ctx, ctx.table)
    tables = _tables(ctx, "aggregates, scene")
    assert [t.caption.split(" (")[0] for t in tables] == [f"aggregates, scene `{SCENE}`, profile `default`",
                                                          f"aggregates, scene `{SCENE}`, profile `paper`"]
    assert [_cell(t, t.rows[0][0], "problems") for t in tables] == ["4", "4"]
    assert [r[0] for r in tables[1].rows] == ["nnls-gp"]
    assert any(rel.endswith(f"pp-{SCENE}-default.png") for rel in ctx.figures)
    assert not any(f"pp-{SCENE}-paper" in rel for rel in ctx.figures)  # one solver: nothing to compare
    assert "compared within each profile" in section.body
    pp, sgm = html_report.profiles_and_sgm(ctx, html_report.scene_summaries(ctx))
    assert [(t["profile"], t["problems"]) for t in sgm[SCENE]] == [("default", 4), ("paper", 4)]
    (curves,) = pp[SCENE]
    assert (curves["profile"], curves["n"], set(curves["curves"])) == ("default", 4, {"fast-a", "fast-b"})
    assert curves["curves"]["fast-a"][-1] == pytest.approx(1.0) and curves["curves"]["fast-b"][-1] == pytest.approx(1.0)


def test_a_scene_at_one_profile_keeps_its_one_table_and_profile(tmp_path: Path) -> None:
    ctx = _context(tmp_path, _table())
    generic.aggregates_section(ctx, ctx.table)
    (t,) = _tables(ctx, "aggregates, scene")
    assert "profile `" not in t.caption and any(rel.endswith(f"pp-{SCENE}.png") for rel in ctx.figures)
    pp, _ = html_report.profiles_and_sgm(ctx, html_report.scene_summaries(ctx))
    (curves,) = pp[SCENE]
    assert curves["profile"] is None and curves["n"] == STEPS


def test_the_profile_caption_names_its_denominator_and_the_short_planned(tmp_path: Path) -> None:
    """gp was planned on 3 of the 10 problems: its curve stops at 0.3 because the y axis is a
    share of every problem, and the caption says so."""
    t = _table()
    t = t[~((t["solver"] == "gp") & (t["step"] >= 3))]
    ctx = _context(tmp_path, t)
    section = generic.aggregates_section(ctx, ctx.table)
    assert "a share of all the 10 problems of the scene" in section.body
    assert "gp (3 of 10)" in section.body


def test_the_best_of_a_family_is_ranked_by_solved_share_before_speed(tmp_path: Path) -> None:
    """A solver planned on 2 of 10 problems and fast there is not its family's best over one
    that solved all 10, a little slower."""
    rows = []
    for k in range(10):
        rows.append(report_row(scene=SCENE, step=k, n=100, solver="many", solve_time_s=0.05, family="fast"))
        if k < 2:
            rows.append(report_row(scene=SCENE, step=k, n=100, solver="few", solve_time_s=0.01, family="fast"))
    ctx = _context(tmp_path, report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS))))
    summ = agg.summarize(ctx.table, ctx.shift, ["few", "many"])
    assert generic.best_of_family(ctx, summ) == {"fast": "many"}
    assert html_report.scene_leads(ctx, html_report.scene_summaries(ctx))[SCENE]["order"] == ["many", "few"]
