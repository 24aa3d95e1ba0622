"""A chart with no data says why in text instead of drawing empty axes, in report.md (the
"**No figure.**" paragraph, ``panels.no_figure``, as Fig. 4 writes it) and on report.html
(the note on the chart): the performance profile of a scene where no solver solved a
problem, the convergence traces when every stored trace is a single point, and a
backend-neutral ``Chart`` with no finite point and a note."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from contactbench.harness.report import core as rp
from contactbench.harness.report import html as html_report
from contactbench.harness.report.build import charts_md
from contactbench.harness.report.charts import Chart, Series
from contactbench.harness.report.panels import EMPTY_NOTE, no_figure
from contactbench.harness.report.sections.fields import fields_section
from contactbench.harness.report.sections.generic import aggregates_section
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row



def says(why: str) -> str:
    """report.md's paragraph in place of a figure, for a ``why`` that starts the reason."""
    return no_figure(why).strip()


def unsolved_sweep(trace: str) -> pd.DataFrame:
    """Two solvers on three steps of one instance, every answer failing the KKT check
    (status "inaccurate"), each row with the stored ``trace``."""
    rows = [report_row(scene="paper-sweep", instance="i0", step=k, n=100 * (k + 1), N=64, solver=s, profile="high",
                       status="inaccurate", kkt_error=1e-3, solve_time_s=0.1 * (k + 1), dim_load=1e-4 * (k + 1),
                       solver_converged=False, solver_status="stalled", trace=trace)
            for s in ("a", "b") for k in range(3)]
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def test_a_scene_nobody_solved_has_no_performance_profile_figure_but_says_why(tmp_path: Path) -> None:
    ctx = rp.ReportContext(tmp_path, unsolved_sweep("[]"), dict(META))
    md = aggregates_section(ctx, ctx.table).body
    assert not any("pp-paper-sweep" in rel for rel in ctx.figures)
    assert says("Performance profile, scene `paper-sweep`: no solver solved any") in md
    assert "(inaccurate 6)" in md


def test_the_page_profile_of_a_scene_nobody_solved_has_no_curve_and_says_why(tmp_path: Path) -> None:
    ctx = rp.ReportContext(tmp_path, unsolved_sweep("[]"), dict(META))
    (pp,) = html_report.page_data(ctx)["pp"]["paper-sweep"]
    assert pp["curves"] == {} and "no solver solved any of the scene's 3 problems" in pp["empty"]


def test_single_point_traces_give_no_trace_figure_but_say_why(tmp_path: Path) -> None:
    """Every stored trace is one point (a backend that reports its final residual only):
    report.md says so in place of the figure; the page draws no such trace, and its trace
    charts carry the same words."""
    ctx = rp.ReportContext(tmp_path, unsolved_sweep(json.dumps([[7, 0.05, 1e-3]])), dict(META))
    section = fields_section(ctx, ctx.table)
    assert section is not None
    md = section.body
    assert not any("traces-" in rel for rel in ctx.figures)
    assert says("Convergence traces, scene `paper-sweep`: every stored trace is a single point") in md
    traces = html_report.trace_data(ctx)
    assert traces["solvers"] == {} and "(a, b)" in traces["empty"]


def test_an_empty_chart_with_a_note_is_that_note_in_report_md_not_a_png(tmp_path: Path) -> None:
    ctx = rp.ReportContext(tmp_path, unsolved_sweep("[]"), dict(META))
    empty = Chart("e", "seeds rejected", "n", "%", (Series("a", (1.0,), (float("nan"),)),),
                  notes={EMPTY_NOTE: "no seed was judged"})
    text = charts_md(ctx, "paper-sweep", rp.Section("s", "", charts=(empty,)))
    assert ctx.figures == []
    assert says("seeds rejected: no seed was judged.") in text
    assert [pc.chart for pc in ctx.charts] == [empty]  # the page still gets it, and writes the note on it
