"""report.html draws what report.md's PNGs draw (harness/report/html.py, page_script.py):
Figs. 4-6 the profile (and instance) of their PNG only, the performance profiles and the
convergence traces each solver in its own dash and marker (sparse markers: panels.py
``MARK_EVERY``), and a legend under its plot below the x axis's labels; report.md writes a whole
number (n, a step, iterations) whole."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from contactbench.harness import build_report
from contactbench.harness.report import core as rp
from contactbench.harness.report import html as html_report
from contactbench.harness.report.browser import browser_missing, load_page, open_driver
from contactbench.harness.report.charts import PLOTLY_DASHES
from contactbench.harness.report.core import attempted, natural_sorted, pick_profile
from contactbench.harness.report.panels import MARK_EVERY
from contactbench.harness.report.style import FAMILY_SLOTS
from tests.helpers import META, fabricate_table, trace_json, write_out

#: The paper-sweep solver given a long trace (``LONG_TRACE`` points), so that its markers are sparse.
LONG_SOLVER = "pk"
LONG_TRACE = 400
#: Solvers of the crowded sweep whose names are longer than the page's LEGEND_CHARS and differ
#: only in their middle: elided alike, their legend entries would read the same.
ALIKE = [f"cmr+fast-dual-pccg coarse=subsample h={h} from 16 on the finest grid" for h in ("1.5", "2", "3")]
#: A second instance of the paper sweep: Fig. 4's PNG draws the first only.
SECOND = "rmd-H0.7-N64-s1"


def _table(crowded: bool = False) -> pd.DataFrame:
    """``fabricate_table`` with a second paper-sweep instance and a long trace for ``LONG_SOLVER``;
    ``crowded``: with the qp and peer families' solvers (``FAMILY_SLOTS``) in the sweep too,
    whose legends of many entries leave the plots short."""
    df = fabricate_table()
    sweep = df["scene"] == "paper-sweep"
    df.loc[sweep & (df["solver"] == LONG_SOLVER), "trace"] = [
        trace_json(t, LONG_TRACE) for t in df.loc[sweep & (df["solver"] == LONG_SOLVER), "solve_time_s"]]
    base = df[sweep & (df["solver"] == "fast-pdas")]
    many = [base.assign(solver=s, base_solver=s, family=f, solve_time_s=base["solve_time_s"] * (1 + 0.1 * i))
            for f in ("qp", "peer") if crowded for i, s in enumerate(FAMILY_SLOTS[f])]
    alike = [base.assign(solver=s, base_solver=s, solve_time_s=base["solve_time_s"] * (1.05 + 0.1 * i))
             for i, s in enumerate(ALIKE) if crowded]
    df = pd.concat([df, *many, *alike], ignore_index=True)
    second = df[df["scene"] == "paper-sweep"].assign(instance=SECOND, solve_time_s=lambda d: d["solve_time_s"] * 1.5)
    return pd.concat([df, second], ignore_index=True)


def _data(html: str) -> dict[str, Any]:
    m = re.search(r'<script id="report-data" type="application/json">(.*?)</script>', html, re.S)
    assert m, "the page's data block is missing"
    return json.loads(m.group(1))


@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = write_out(tmp_path_factory.mktemp("page-drawing"), _table())
    build_report(folder)
    return folder


def _expected(scene: str) -> tuple[str, str]:
    """The profile and the first instance a paper figure's PNG draws for ``scene``."""
    rows = attempted(_table()[lambda d: d["scene"] == scene])
    prof = pick_profile(rows)
    return prof, natural_sorted(rows.loc[rows["profile"] == prof, "instance"].unique())[0]


def test_the_paper_figures_page_charts_name_the_profile_and_instance_of_their_png(out: Path) -> None:
    charts = {c["scene"]: c for c in _data((out / "report.html").read_text())["rowcharts"]}
    for scene, with_instance in (("paper-sweep", True), ("greedy-linear-solvers", False), ("gp-k-sweep", True)):
        prof, inst = _expected(scene)
        assert charts[scene]["profile"] == prof, scene
        assert charts[scene]["instance"] == (inst if with_instance else None), scene
    assert _expected("paper-sweep") != ("default", SECOND)  # the table has more than the PNG draws


def test_the_page_gives_each_solver_its_own_dash_and_marker(out: Path) -> None:
    ctx = rp.ReportContext(out, _table(), dict(META))
    members = [s for f in _data((out / "report.html").read_text())["families"] for s in f["solvers"]]
    assert members
    for s in members:
        assert s["dash"] == PLOTLY_DASHES[ctx.dash(s["name"])], s
        assert s["symbol"] == html_report.SOLVER_SYMBOLS[ctx.marker(s["name"])], s
    assert len({s["dash"] for s in members}) > 1


def test_report_md_writes_whole_numbers_whole(out: Path) -> None:
    """n, N, a step and iterations: "25600", never "2.56e+04" (three significant figures)."""
    md = (out / "report.md").read_text()
    assert "Cholesky was skipped from n = 25600 on" in md
    assert re.search(r"\| n6400 \| 0 \| 6400 \| greedy-cg \|", md)
    assert not re.search(r"\| n\d+ \| \d+ \| \d\.\d*e\+0\d \|", md)


#: What the open page drew: each solver's own dash and symbol (the page's data); Fig. 4's points
#: (profile and instance of each); each solver line of the performance profiles and convergence
#: traces (its dash, symbol and marker sizes; its stand-in's name in the legend); and under each
#: chart whose legend is under its plot, the pixels from the lowest x tick label or axis title
#: down to the legend's top.
DRAWN_JS = """
const plots = [...document.querySelectorAll('.js-plotly-plot')];
const title = d => d.layout.title.text;
const fig4 = plots.find(d => title(d).startsWith('Fig. 4'));
const lines = plots.filter(d => /^(performance profile|convergence traces)/.test(title(d))).map(d => ({
  title: title(d),
  series: d.data.filter(t => t.meta && t.meta.so && t.x.length > 1).map(t => ({so: t.meta.so,
    dash: (t.line || {}).dash, symbol: (t.marker || {}).symbol, sizes: [].concat((t.marker || {}).size || []),
    n: t.x.length, legend: t.showlegend !== false})),
  legend: d.data.filter(t => t.showlegend !== false && t.meta && t.meta.so).map(t => t.meta.so)}));
const gaps = plots.filter(d => d.layout.legend && d.layout.legend.orientation === 'h').map(d => {
  const texts = [...d.querySelectorAll('.xtick text, .g-xtitle text')].map(e => e.getBoundingClientRect())
    .filter(b => b.height > 0);
  const lg = d.querySelector('.legend');
  return [title(d), lg && texts.length ? lg.getBoundingClientRect().top - Math.max(...texts.map(b => b.bottom)) : null];
});
const below = plots.filter(d => d.layout.legend && d.layout.legend.orientation === 'h').map(d => [title(d),
  d._fullLayout._size.h, d.layout.margin.t, d.layout.margin.b]);
const own = {};
JSON.parse(document.getElementById('report-data').textContent).families.forEach(f => f.solvers.forEach(s => {
  own[s.name] = [s.dash, s.symbol]; }));
return {own: own, fig4: fig4.data.filter(t => t.customdata).map(t => t.customdata.map(c => [c[10], c[0]])),
        fig4pts: fig4.data.filter(t => t.customdata).map(t => t.customdata.map((c, i) => [t.name, c[9], c[1], t.y[i]])),
        lines: lines, gaps: gaps, below: below,
        legends: plots.map(d => [title(d), d.data.filter(t => t.showlegend !== false && t.name).map(t => t.name)])};
"""


@pytest.fixture(scope="module")
def drawn(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """What the page of the crowded ``_table`` drew (``DRAWN_JS``), at a width that makes its
    charts narrower than the page's NARROW_CHART_PX: their legends go under the plot."""
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    folder = write_out(tmp_path_factory.mktemp("page-crowded"), _table(crowded=True))
    build_report(folder)
    driver = open_driver(1400, 1000)
    try:
        load_page(driver, folder / "report.html")
        return driver.execute_script(DRAWN_JS)
    finally:
        driver.quit()


@pytest.mark.slow
def test_the_page_fig4_draws_only_the_pngs_profile_and_instance(drawn: dict[str, Any]) -> None:
    points = [p for trace in drawn["fig4"] for p in trace]
    assert points
    assert {tuple(p) for p in points} == {_expected("paper-sweep")}


@pytest.mark.slow
def test_the_page_fig4_draws_one_point_per_cell_at_its_least_time(drawn: dict[str, Any]) -> None:
    """As the PNG (core.py ``per_cell``): a step's repeats are one point, at the least time of them
    (the fabricated sweep repeats nnls-gp's first step at the PNG's profile)."""
    prof, inst = _expected("paper-sweep")
    rows = _table(crowded=True)[lambda d: (d["scene"] == "paper-sweep") & (d["profile"] == prof) & (d["instance"] == inst)]
    least = rows.groupby(["solver", "step"])["solve_time_s"].min()
    points = [p for trace in drawn["fig4pts"] for p in trace]
    keys = [(name, step) for name, _, step, _ in points]
    assert points and len(keys) == len(set(keys))
    assert rows.groupby(["solver", "step"]).size().max() > 1  # the table has repeats to fold
    for _, so, step, y in points:
        assert y == pytest.approx(least[(so, step)]), (so, step)


@pytest.mark.slow
def test_the_page_profiles_and_traces_draw_each_solver_in_its_dash_and_sparse_marker(drawn: dict[str, Any]) -> None:
    own = {s: tuple(v) for s, v in drawn["own"].items()}
    charts = {c["title"].split(" (")[0] + (" time" if c["title"].endswith("time") else ""): c for c in drawn["lines"]}
    assert {"performance profile", "convergence traces", "convergence traces time"} <= set(charts)
    for chart in drawn["lines"]:
        assert chart["series"], chart["title"]
        for s in chart["series"]:
            assert (s["dash"], s["symbol"]) == own[s["so"]], (chart["title"], s["so"])
            marked = sum(1 for v in s["sizes"] if v > 0)
            assert marked >= 1 and not s["legend"], (chart["title"], s["so"])  # its stand-in is in the legend
        assert sorted(chart["legend"]) == sorted(s["so"] for s in chart["series"]), chart["title"]
    for key in ("convergence traces", "convergence traces time"):
        (long,) = [s for s in charts[key]["series"] if s["so"] == LONG_SOLVER]
        marked = sum(1 for v in long["sizes"] if v > 0)
        # a mark every MARK_EVERY of the diagonal: about 1 / MARK_EVERY of them along a line that crosses the plot
        assert long["n"] == LONG_TRACE and 2 <= marked <= 3 / MARK_EVERY, (key, marked)


@pytest.mark.slow
def test_a_legend_under_its_plot_leaves_the_plot_its_normal_height(drawn: dict[str, Any]) -> None:
    """The chart grows by its legend: the plot is as tall as in a chart of the CSS height (420 px)
    with its legend beside it (long legends under a fixed height left the plots slivers)."""
    assert drawn["below"]
    short = [(t, round(h)) for t, h, top, bottom in drawn["below"] if h < 420 - top - bottom - 2]
    assert not short, short


@pytest.mark.slow
def test_a_legend_under_its_plot_starts_below_the_x_axis_labels(drawn: dict[str, Any]) -> None:
    assert drawn["gaps"]
    bad = [(t, g) for t, g in drawn["gaps"] if g is None or g < 0]
    assert not bad, bad


@pytest.mark.slow
def test_no_two_legend_entries_of_a_chart_read_the_same(drawn: dict[str, Any]) -> None:
    """Long names are elided in their middle (``legendName``), unless that makes two read the
    same: those keep their full names (cmr variants that differ in h read alike)."""
    seen = [(t, names) for t, names in drawn["legends"] if any(a in n for n in names for a in ALIKE)]
    assert seen  # the alike names are drawn, whole
    for title, names in drawn["legends"]:
        assert len(set(names)) == len(names), (title, names)
