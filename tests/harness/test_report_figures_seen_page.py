"""report.html's charts as its script draws them: the page's script (html.py ``PAGE_SCRIPT``)
run by node over the page's data block, with a stand-in for the document and for Plotly that
records every ``Plotly.react`` call -- so that the drawn traces and layouts are read as data,
without a browser.  Skipped where node is not installed.

A chart's legend lists at most ``MAX_SERIES`` series and says how to draw the others; a run
time against error chart of two profiles has one legend entry per solver and one per
profile's marker size; no two drawn series of close colour share a marker; no point of a
log axis is at 0 or below (iteration 0 is drawn at iteration + 1)."""

from __future__ import annotations

import json
import shutil
import subprocess
from itertools import combinations
from typing import Any

import pandas as pd
import pytest
from matplotlib.colors import to_rgb

from contactbench.harness.report import core as rp
from contactbench.harness.report.view import report_view
from contactbench.harness.report import html as html_report
from contactbench.harness.report.page_script import PAGE_SCRIPT
from contactbench.harness.report.style import COLOUR_APART, MAX_SERIES, cielab, delta_e00

from tests.helpers import every_solver_table

NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="node is not installed")

#: A document of stand-in elements and a Plotly that records each chart it is handed.
STUB = r"""
const fs = require('fs');
const data = fs.readFileSync(process.argv[2], 'utf8'), page = fs.readFileSync(process.argv[3], 'utf8');
function El(tag) {
  return {tag, children: [], className: '', dataset: {}, style: {}, classList: {toggle() {}, add() {}},
    _html: '', set innerHTML(v) { this._html = v; }, get innerHTML() { return this._html; },
    appendChild(c) { this.children.push(c); return c; }, addEventListener() {}, querySelectorAll() { return []; },
    querySelector() { return null; }, clientWidth: 1000, textContent: ''};
}
const byId = {'report-data': {textContent: data}, charts: El('main'), picker: El('nav')};
global.document = {getElementById: id => byId[id], createElement: El, createTextNode: t => ({t}),
  querySelectorAll: () => [], body: {dataset: {}}};
global.window = {addEventListener() {}};
global.performance = {now: () => 0};
const calls = [];
global.Plotly = {react: (div, traces, lay) => { calls.push({traces, layout: lay}); return Promise.resolve(); },
  relayout: () => Promise.resolve()};
eval(page);
setTimeout(() => console.log(JSON.stringify(calls)), 50);
"""


def _table() -> pd.DataFrame:
    """The fabricated table, every solver of the project run in the paper sweep (``fast-pdas``'s
    rows under each name and family), and ``pk``'s trace from iteration 0 over three decades."""
    df = every_solver_table()
    pk = (df["scene"] == "paper-sweep") & (df["solver"] == "pk")
    df.loc[pk, "trace"] = json.dumps([[i, 1e-4 * (i + 1), 10.0 ** (-i / 100)] for i in (0, 1, 10, 100, 999)])
    return df


@pytest.fixture(scope="module")
def charts(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, Any]]:
    """Every chart the page draws: (traces, layout) as handed to Plotly."""
    tmp = tmp_path_factory.mktemp("page")
    ctx = rp.ReportContext(tmp, report_view(_table()), {})
    (tmp / "data.json").write_text(json.dumps(html_report.page_data(ctx), allow_nan=False))
    (tmp / "page.js").write_text(PAGE_SCRIPT)
    (tmp / "stub.js").write_text(STUB)
    done = subprocess.run([NODE, str(tmp / "stub.js"), str(tmp / "data.json"), str(tmp / "page.js")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _title(chart: dict[str, Any]) -> str:
    return str(chart["layout"]["title"]["text"])


def _drawn(trace: dict[str, Any]) -> bool:
    return trace.get("visible", True) not in (False, "legendonly") and any(x is not None for x in trace.get("x", []))


def _in_legend(trace: dict[str, Any]) -> bool:
    return trace.get("showlegend", True) is not False and trace.get("visible", True) is not False


def test_no_legend_lists_more_than_max_series_series(charts: list[dict[str, Any]]) -> None:
    """A legend of 72 entries, 62 of them greyed, could not be read: the legend lists the
    series drawn, and its title says how many of how many and how to draw the others."""
    crowded = []
    for c in charts:
        series = [t for t in c["traces"] if _in_legend(t) and t.get("meta", {}).get("so") is not None]
        if len({t["name"] for t in series}) > MAX_SERIES:
            crowded.append((_title(c), len(series)))
    assert not crowded, crowded
    thinned = [c for c in charts if c["layout"]["legend"].get("title")]
    assert thinned and all("tick fewer" in c["layout"]["legend"]["title"]["text"] for c in thinned)


def test_a_work_precision_chart_of_two_profiles_keys_each_solver_once_and_each_size(
        charts: list[dict[str, Any]]) -> None:
    wp = [c for c in charts if _title(c).startswith("run time against kkt_error (paper-sweep")]
    assert len(wp) == 1
    legend = [t["name"] for t in wp[0]["traces"] if _in_legend(t)]
    sizes = [n for n in legend if n.startswith("profile ")]
    profiles = {t["meta"]["pr"] for t in wp[0]["traces"] if _drawn(t) and t.get("meta", {}).get("so")}
    assert profiles and sorted(sizes) == sorted(f"profile {p} (marker size)" for p in profiles)
    solvers = [n for n in legend if n not in sizes]
    assert len(solvers) == len(set(solvers)) <= MAX_SERIES


def _colour(trace: dict[str, Any]) -> str:
    m = trace.get("marker", {})
    c = m.get("line", {}).get("color") if trace.get("mode") == "markers" else None
    c = c or (trace.get("line") or {}).get("color") or m.get("color")
    return c[0] if isinstance(c, list) else c


def _symbol(trace: dict[str, Any]) -> str:
    s = trace.get("marker", {}).get("symbol", "circle")
    return s[0] if isinstance(s, list) else s


def test_no_two_drawn_solvers_of_close_colour_share_a_marker(charts: list[dict[str, Any]]) -> None:
    """On a chart of markers only, colour or shape is all that tells two solvers apart: any two
    of its series (the picker draws any ten of them together)."""
    close = []
    for c in charts:
        if not _title(c).startswith("run time against"):
            continue
        drawn = {t["meta"]["so"]: t for t in c["traces"] if t.get("meta", {}).get("so") and
                 any(x is not None for x in t.get("x", []))}
        for a, b in combinations(sorted(drawn), 2):
            ta, tb = drawn[a], drawn[b]
            d = float(delta_e00(cielab(to_rgb(_colour(ta))), cielab(to_rgb(_colour(tb)))))
            if _symbol(ta) == _symbol(tb) and d < COLOUR_APART:
                close.append((_title(c), a, b, round(d, 1)))
    assert not close, close


def test_no_point_of_a_log_axis_is_dropped(charts: list[dict[str, Any]]) -> None:
    """A log axis leaves out a point at 0: the traces from iteration 0 are drawn at iteration + 1
    (every series, those the legend leaves out too: the picker draws them)."""
    dropped = []
    for c in charts:
        for key, axis in (("x", c["layout"]["xaxis"]), ("y", c["layout"]["yaxis"])):
            if axis.get("type") != "log":
                continue
            for t in c["traces"]:
                bad = [v for v in t.get(key, []) if isinstance(v, (int, float)) and v <= 0]
                if bad:
                    dropped.append((_title(c), t["name"], bad[:3]))
    assert not dropped, dropped
    (it,) = [c for c in charts if "own residual against iteration" in _title(c)]
    assert it["layout"]["xaxis"]["title"]["text"].startswith("iteration + 1")
