"""What a reader sees in the report's figures and page data matches the table: the CMR design
note and panel titles name the bases and warm starts the rows record, a time-ratio axis has a
label beyond its data, the SGM counts only the cells a solver was planned to run, two solvers
of close colour never share a marker, every profile has its own marker size, a log axis is
labelled without overlapping labels, a profile curve hidden on the axis says so, and the page's
trace and load-area charts draw what report.md's figures draw.

Every check reads data (the sections' text and tables, the figures' artists and limits, the
page's data block), never pixels."""

from __future__ import annotations

import json
import math
from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from contactbench.harness.profiles import PROFILES
from contactbench.harness.report import core as rp
from contactbench.harness.report.view import report_view
from contactbench.harness.report import html as html_report
from contactbench.harness.report.core import PROFILE_PREFERENCE, natural_key, tidy_log_ticks
from contactbench.harness.report import panels
from contactbench.harness.report.panels import label_short_log_axes
from contactbench.harness.report.sections import cmr as rc
from contactbench.harness.report.sections import cmr_figures as rcf
from contactbench.harness.report.sections import generic
from contactbench.harness.report.sections.fields import fields_section
from contactbench.harness.report.style import COLOUR_APART, FAMILY_SLOTS, SolverStyles, cielab, delta_e00
from contactbench.harness.table.fields import field_name
from contactbench.harness.table.schema import ALL_COLUMNS

from tests.harness.test_report_cmr import HURSTS, SEEDS, STEPS, fabricate_cmr
from tests.helpers import report_row


def _figures(monkeypatch: pytest.MonkeyPatch) -> dict[str, Figure]:
    """Every figure a section saves from now on, by name, as drawn."""
    figures: dict[str, Figure] = {}
    keep = rp.ReportContext.save_figure

    def record(self: rp.ReportContext, fig: Figure, name: str, on_page: bool = False) -> str:
        figures[name] = fig
        return keep(self, fig, name, on_page)

    monkeypatch.setattr(rp.ReportContext, "save_figure", record)
    return figures


# --- the CMR design note and panel titles read the table ---------------------------------------


def _as_nnls(table: pd.DataFrame) -> pd.DataFrame:
    """The fabricated CMR table with its dense base called ``nnls`` (the claims run's base)."""
    t = table.copy()
    for col in ("solver", "base_solver"):
        t[col] = t[col].str.replace("scipy-nnls", "nnls", regex=False)
    return t


def test_the_cmr_note_names_the_tables_bases_and_counts_their_warm_starts(tmp_path: Path) -> None:
    """The base is ``nnls``, warm started on every step but the first; no word of a
    ``scipy-nnls`` that never ran, nor of a cold start that did not happen."""
    table, _ = fabricate_cmr()
    table = _as_nnls(table)
    warm = (table["base_solver"] == "nnls") & (table["step"] > 0)
    table.loc[warm, "warm_start"] = True
    ctx = rp.ReportContext(tmp_path, table, {})
    body = rcf.cmr_section(ctx, table).body
    direct = len(HURSTS) * len(SEEDS) * STEPS
    assert "scipy-nnls" not in body
    assert (f"`nnls` (incremental NNLS, operator dense), warm started from the previous step's answer on "
            f"{direct * (STEPS - 1) // STEPS} of its {direct} direct solves") in body
    assert f"`fast-dual-pccg` (operator fft), never warm started: each of its {direct} direct solves" in body
    runs = rc.base_runs(rc.cmr_pairs(table))
    assert (runs["nnls"].direct_warm, runs["nnls"].direct) == (direct * (STEPS - 1) // STEPS, direct)
    assert runs["fast-dual-pccg"].direct_warm == 0


def test_the_cmr_panel_titles_say_how_the_direct_solves_ran(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The h sweep's rows are cold: no panel title calls its base warm."""
    figures = _figures(monkeypatch)
    parts = []
    for i, h in enumerate((1.25, 2.0, 3.0)):
        t, _ = fabricate_cmr(seed=i, scene="cmr-h-sweep", params={"h": h, "coarsest": 16})
        parts.append(t if i == 0 else t[t["base_solver"].str.startswith("cmr+")])
    table = _as_nnls(pd.concat(parts, ignore_index=True))
    table = table[table["step"] == STEPS - 1]
    assert not table["warm_start"].any()
    ctx = rp.ReportContext(tmp_path, table, {})
    rcf.cmr_h_section(ctx, table)
    titles = [ax.get_title() for ax in figures["fig9-cmr-h-saupe"].axes if ax.get_title()]
    assert titles and all("cold" in t and "warm" not in t for t in titles), titles
    assert any(t.startswith("nnls base (dense)") for t in titles), titles


@pytest.mark.parametrize("ratios", [[[0.1, 0.4, 0.6], [1.49, 1.5, 1.78]], [[0.1, 0.3, 0.8], [1.5, 1.9, 2.3]]])
def test_a_log_time_ratio_axis_has_a_labelled_tick_beyond_its_data(ratios: list[list[float]]) -> None:
    """FFT ratios of 1.5-1.8 (or to 2.3) under a dense base's 0.1: the axis reaches a labelled
    2 (or 5), and 0.1 is labelled too."""
    fig = Figure(figsize=(7.2, 2.6))
    row = [fig.add_subplot(1, 2, j + 1) for j in range(2)]
    for ax, r in zip(row, ratios):
        ax.plot([1.25, 2.0, 3.0], r, "o-")
    rcf._ratio_axes(row, [v for r in ratios for v in r])
    top = max(max(r) for r in ratios)
    for ax in row:
        lo, hi = ax.get_ylim()
        assert lo <= 0.1 and hi >= top
        shown = [float(t) for t, _, _ in _rendered_labels(fig, ax, "y")
                 if t.replace(".", "", 1).isdigit() and lo <= float(t) <= hi]
        assert any(v > top for v in shown) and any(v <= 0.1 for v in shown), shown
    assert rcf.ratio_limits(0.087, 1.9) == (0.05, 2.0)


# --- the SGM counts the cells a solver was planned to run ---------------------------------------


def _planned_table() -> pd.DataFrame:
    """Scene paper-sweep, 4 steps at a 9000 s limit: ``pk`` planned on all four (1 s each),
    ``nnls-gp`` on steps 2-3 only (2 s each), ``slow`` on all four (4 s), ``gone`` on step 0
    (failed)."""
    rows = []
    for k in range(4):
        rows.append(report_row(scene="paper-sweep", step=k, solver="pk", solve_time_s=1.0, time_limit_s=9000.0))
        rows.append(report_row(scene="paper-sweep", step=k, solver="slow", solve_time_s=4.0, time_limit_s=9000.0))
        if k >= 2:
            rows.append(report_row(scene="paper-sweep", step=k, solver="nnls-gp", solve_time_s=2.0,
                                   time_limit_s=9000.0))
    rows.append(report_row(scene="paper-sweep", step=0, solver="gone", status="failed", solve_time_s=0.5,
                           time_limit_s=9000.0, solver_converged=False))
    return report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))


def test_the_sgm_leaves_out_the_cells_a_solver_was_never_planned_to_run(tmp_path: Path) -> None:
    """nnls-gp's two absent steps would count at 9000 s: an SGM of ~130 s, 130x the best.
    Over its own two steps it took 2 s, twice pk's 1 s on those steps."""
    t = _planned_table()
    ctx = rp.ReportContext(tmp_path, t, {})
    section = generic.aggregates_section(ctx, t)
    (table,) = [x for x in ctx.tables if "aggregates, scene" in x.caption]

    def cell(solver: str, column: str) -> str:
        (row,) = [r for r in table.rows if r[0] == solver]
        return str(row[table.headers.index(column)])

    assert (cell("nnls-gp", "SGM [s]"), cell("nnls-gp", "SGM / best"), cell("nnls-gp", "SGM cells")) == ("2", "2", "2")
    assert (cell("pk", "SGM [s]"), cell("pk", "SGM / best"), cell("pk", "SGM cells")) == ("1", "1", "4")
    assert (cell("slow", "SGM / best"), cell("gone", "SGM cells")) == ("4", "1")
    assert float(cell("gone", "SGM [s]")) == pytest.approx(9000.0, rel=1e-3)  # its one planned cell failed
    assert "never planned to run is not counted" in section.body
    _, sgm = html_report.profiles_and_sgm(ctx, html_report.scene_summaries(ctx))
    (table_p,) = sgm["paper-sweep"]
    page = {r[0]: dict(zip(table_p["columns"], r)) for r in table_p["rows"]}
    assert page["nnls-gp"]["SGM [s]"] == pytest.approx(2.0) and page["nnls-gp"]["SGM / best"] == pytest.approx(2.0)
    assert page["nnls-gp"]["SGM cells"] == 2 and "never planned" in table_p["note"]


# --- markers, sizes and tick labels ---------------------------------------------------------------


def test_two_solvers_of_close_colour_never_share_a_marker() -> None:
    """A chart of markers only (run time against error) mixes families: there a shared dash
    does not help, so two solvers within ``COLOUR_APART`` must differ in marker (``nnls`` and
    ``qp-proxqp`` shared a triangle 12.8 apart, ``admm`` and ``cm-pk-ccg`` another at 11.2)."""
    from contactbench.solvers.registry import all_solvers

    every = {s: f for f, names in FAMILY_SLOTS.items() for s in names}
    every |= {n: s.family for n, s in all_solvers().items() if s.family != "test"}
    every |= {f"nnls-gp[K={k}]": "paper" for k in (0, 10, 25, 50, 100, 150, 200)}
    every |= {"ext-a": "external", "ext-b": "external", "mine": "other", "mine2": "other"}
    st = SolverStyles(every, natural_key)
    lab = {s: cielab(st.color(s)) for s in every}
    close = [(a, b, round(float(delta_e00(lab[a], lab[b])), 1)) for a, b in combinations(every, 2)
             if st.marker(a) == st.marker(b) and float(delta_e00(lab[a], lab[b])) < COLOUR_APART]
    assert not close, close


def test_every_profile_has_its_own_marker_size_growing_with_its_accuracy() -> None:
    """low < default < mid < paper < high, on the PNG and on the page alike."""
    sizes = generic._PROFILE_SIZES
    assert set(PROFILES) <= set(sizes)
    order = list(PROFILE_PREFERENCE[::-1])
    assert [sizes[p] for p in order] == sorted({sizes[p] for p in order})
    page = generic.page_marker_sizes()
    assert [page[p] for p in order] == sorted({page[p] for p in order})


def _rendered_labels(fig: Figure, ax: Any, which: str) -> list[tuple[str, float, float]]:
    """(text, start, end) in points along the axis of each visible tick label, as drawn."""
    FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    axis = ax.xaxis if which == "x" else ax.yaxis
    out = []
    for t in axis.get_majorticklabels():
        if t.get_visible() and t.get_text():
            bb = t.get_window_extent(renderer)
            lo, hi = (bb.x0, bb.x1) if which == "x" else (bb.y0, bb.y1)
            out.append((t.get_text(), lo * 72 / fig.dpi, hi * 72 / fig.dpi))
    return sorted(out, key=lambda x: x[1])


def test_no_two_tick_labels_of_a_log_axis_overlap() -> None:
    """A panel 3.2 inches wide over 0.0003-0.044 s, labelled at 1-2-5 steps: "0.0005" and
    "0.001" were drawn into one another; the powers of ten keep their labels."""
    fig = Figure(figsize=(9.6, 3.5))
    ax = fig.add_subplot(1, 2, 1)
    fig.add_subplot(1, 2, 2)
    fig.subplots_adjust(wspace=0.35)
    ax.scatter([0.0004, 0.002, 0.03], [1.0, 2.0, 3.0])
    ax.set_xscale("log")
    ax.set_xlim(3.06e-4, 0.0444)
    tidy_log_ticks(ax, "x", 1.9)
    label_short_log_axes(fig)
    shown = _rendered_labels(fig, ax, "x")
    assert {"0.001", "0.01"} <= {t for t, _, _ in shown}
    assert all(b[1] >= a[2] for a, b in zip(shown, shown[1:])), shown


def test_a_log_axis_over_one_power_of_ten_is_labelled_below_it() -> None:
    """A/A0 from 0.0015 to 0.035: evenly placed ticks (0.01, 0.02, 0.03) left nothing below 0.01."""
    fig = Figure(figsize=(6.4, 4.4))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot([1e-3, 3e-3, 1.3e-2], [0.0015, 0.006, 0.035], "o-")
    ax.set_xscale("log")
    ax.set_yscale("log")
    label_short_log_axes(fig)
    lo, hi = ax.get_ylim()
    shown = [v for t, _, _ in _rendered_labels(fig, ax, "y") if lo <= (v := float(t)) <= hi]
    assert any(v < 0.01 for v in shown) and any(v > 0.01 for v in shown), shown


# --- a profile curve drawn on the axis says so ----------------------------------------------------


def test_a_performance_profile_panel_whose_curves_lie_at_zero_says_so(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Eleven solvers (two panels): six wrappers that solved nothing lie on the axis, one
    under the other; their legend, the panel and the caption say so."""
    figures = _figures(monkeypatch)
    rows = []
    wrappers = FAMILY_SLOTS["wrapper"]
    for k in range(3):
        for i, s in enumerate(("pk", "nnls", "gp", "greedy-cg", "nnls-gp")):
            rows.append(report_row(scene="paper-sweep", step=k, solver=s, solve_time_s=0.01 * (i + 1)))
        for s in wrappers:
            rows.append(report_row(scene="paper-sweep", step=k, solver=s, family="wrapper", solve_time_s=0.02,
                                   status="inaccurate", solver_converged=False))
    t = report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    ctx = rp.ReportContext(tmp_path, t, {})
    body = generic.aggregates_section(ctx, t).body
    fig = figures["pp-paper-sweep"]
    (panel,) = [ax for ax in fig.axes if ax.get_title().endswith("family wrapper (3 problems)")]
    labels = [line.get_label() for line in panel.get_lines() if not str(line.get_label()).startswith("_")]
    assert sorted(labels) == sorted(f"{s} ({panels.AT_ZERO})" for s in wrappers)
    assert any("every curve of the panel lies at 0" in x.get_text() for x in panel.texts)
    assert all(f"{s} ({panels.AT_ZERO})" in body for s in wrappers)


# --- the page's trace and load-area charts draw report.md's numbers -------------------------------


def test_the_pages_iteration_axis_keeps_iteration_zero() -> None:
    """Traces from iteration 0 to 999 (three decades): the page draws iteration + 1 on its
    log axis, so no point falls off it, and says so on the axis; an equal trace says so."""
    trace = json.dumps([[i, 1e-4 * (i + 1), 10.0 ** (-i / 100)] for i in (0, 1, 10, 100, 999)])
    rows = [report_row(scene="paper-sweep", solver=s, solve_time_s=0.1, trace=trace) for s in ("pk", "fast-ccg")]
    t = report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    data = html_report.trace_data(rp.ReportContext(Path("unused"), t, {}))
    axis = data["it_axis"]
    assert axis["log"] and axis["shift"] == 1 and "iteration + 1" in axis["title"]
    for d in data["solvers"].values():
        assert d["it"][0] == 0 and all(x > 0 for x in d["x"]) and d["x"] == [i + 1 for i in d["it"]]
    assert data["solvers"]["pk"].get("same") == "fast-ccg" or data["solvers"]["fast-ccg"].get("same") == "pk"


def _write_field(out: Path, scene: str, instance: str, step: int, rms_slope: float) -> None:
    n = 8
    h = np.linspace(0.0, 1.0, n * n).reshape(n, n)
    (out / "arrays").mkdir(parents=True, exist_ok=True)
    np.savez(out / "arrays" / field_name(scene, instance, step), heights=h, pressure=h, gap=h, contact=h > 0.5,
             N=np.int64(n), spacing=np.float64(1.0), E=np.float64(1.0), far_field=np.float64(0.0),
             load=np.float64(1.0), dim_load=np.float64(0.01), contact_fraction=np.float64(0.02),
             rms_slope=np.float64(rms_slope), step=np.int64(step), steps=np.int64(4), solver=np.str_("pk"),
             unit=np.str_("m"), periodic=np.bool_(False))


def test_the_pages_load_area_chart_draws_the_pngs_numbers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The PNG draws A/A0 against P/(E* A0 h'_rms) with Persson's and BGT's lines; the page
    drew P/(E* A0) under the same title.  Now both draw the same points and axes."""
    figures = _figures(monkeypatch)
    hrms = 0.4
    rows = [report_row(scene="paper-sweep", instance="s0", step=k, solver="pk", solve_time_s=0.1, delta=1e-7 * (k + 1),
                       dim_load=1e-4 * 3 ** k, contact_fraction=2e-4 * 3 ** k) for k in range(4)]
    t = report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    _write_field(tmp_path, "paper-sweep", "s0", 3, hrms)
    ctx = rp.ReportContext(tmp_path, t, {})
    fields_section(ctx, t)
    ax = figures["load-area"].axes[0]
    page = html_report.load_area_data(ctx)
    assert (page["title"], page["x_title"], page["y_title"]) == (ax.get_title(), ax.get_xlabel(), ax.get_ylabel())
    png = {str(line.get_label()): list(line.get_xdata()) for line in ax.get_lines()}
    (series,) = page["series"]
    assert series["name"] in png and png[series["name"]] == pytest.approx(series["x"])
    assert series["x"] == pytest.approx([1e-4 * 3 ** k / hrms for k in range(4)])
    assert [ln["name"] for ln in page["lines"]] == [n for n in png if n.startswith(("Persson", "BGT"))]
    for ln in page["lines"]:
        kappa = ln["y"][0] / ln["x"][0]
        assert kappa == pytest.approx(math.sqrt(8 / math.pi) if ln["name"].startswith("Persson") else
                                      math.sqrt(2 * math.pi))


# --- Fig. 5: at most MAX_SERIES solvers a panel -----------------------------------------------------


def test_fig5_of_thirteen_solvers_draws_a_panel_per_family(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Thirteen solvers of two families in greedy-linear-solvers: no panel draws more than
    ``MAX_SERIES`` of them in colour, and every one is drawn in its family's panel."""
    from contactbench.harness.report.sections import paper as rpp
    from contactbench.harness.report.style import MAX_SERIES

    figures = _figures(monkeypatch)
    solvers = {**{f"greedy-v{i}": "greedy" for i in range(6)}, **{f"fast-v{i}": "fast" for i in range(7)}}
    rows = [report_row(scene="greedy-linear-solvers", step=k, n=100 * 4 ** k, solver=s, family=f,
                       solve_time_s=0.01 * (i + 1) * (k + 1))
            for k in range(3) for i, (s, f) in enumerate(solvers.items())]
    t = report_view(pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    ctx = rp.ReportContext(tmp_path, t, {})
    rpp.fig5_section(ctx, t)
    (name,) = [n for n in figures if n.startswith("fig5-greedy-linear-solvers")]
    drawn: set[str] = set()
    for ax in figures[name].axes:
        named = {str(line.get_label()) for line in ax.get_lines()} & set(solvers)
        assert len(named) <= MAX_SERIES, ax.get_title()
        drawn |= named
    assert drawn == set(solvers)


def test_one_family_gets_no_best_of_each_family_panel() -> None:
    """Twelve solvers of one family: its "best of each family" panel would be one solver
    drawn again; the panels are the family's parts only."""
    from contactbench.harness.report.style import family_panels

    names = [f"fast-v{i:02d}" for i in range(12)]
    panels = family_panels(names, lambda s: "fast", {"fast": names[0]})
    assert [p.title for p in panels] == ["family fast (1/2)", "family fast (2/2)"]
