"""report.html's time-against-load charts (harness/report/html.py, page_script.py) mark and
place the rows as the static figures do (sections/paper.py): a row not solved is marked by
its status (``UNSOLVED_MARKS``, one legend entry per kind drawn), a row sits at its step's
load (the median load of the step's solved answers: ``load_abscissa``), a row whose step
nobody solved is left out, and a chart with nothing to draw says why."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import build_report
from contactbench.harness.report import core as rp
from contactbench.harness.report import html as html_report
from contactbench.harness.report.browser import browser_missing, load_page, open_driver
from contactbench.harness.report.sections.paper import UNSOLVED_MARKS
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row, write_out

#: A solver -> (status, own dim_load) per step of instance i0 at profile "high"; solve time
#: 0.1 (k + 1) s.  Step 3: nobody solved it.
SWEEP: dict[str, list[tuple[str, float]]] = {
    "a": [("solved", 1e-4), ("solved", 2e-4), ("solved", 3e-4), ("timeout", 9e-3)],
    "b": [("solved", 1.2e-4), ("timeout", 5e-3), ("inaccurate", 7e-3), ("failed", np.nan)],
    "c": [("failed", np.nan), ("solved", 2.2e-4), ("solved", 3.2e-4), ("inaccurate", 4e-3)],
}


def sweep_table(sweep: dict[str, list[tuple[str, float]]]) -> pd.DataFrame:
    rows = [report_row(scene="paper-sweep", instance="i0", step=k, n=100 * (k + 1), N=64, solver=s, profile="high",
                       status=st, solve_time_s=0.1 * (k + 1), dim_load=dl, warm_start=False,
                       kkt_error=1e-3 if st == "inaccurate" else 1e-10)
            for s, steps in sweep.items() for k, (st, dl) in enumerate(steps)]
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def page_rows(sweep: dict[str, list[tuple[str, float]]], tmp: Path) -> dict[tuple[str, int], dict[str, Any]]:
    ctx = rp.ReportContext(tmp, sweep_table(sweep), dict(META))
    return {(r["so"], int(r["st"])): r for r in html_report.page_rows(ctx)}


def test_page_marks_are_the_static_figures_unsolved_marks() -> None:
    """One mark per ``UNSOLVED_MARKS`` kind, in its order, with its label and colour, the
    cross filled and the others open, as the static figure draws them."""
    marks = html_report.unsolved_marks()
    assert list(marks) == list(UNSOLVED_MARKS)
    for kind, (marker, color, label) in UNSOLVED_MARKS.items():
        assert marks[kind]["label"] == label
        assert marks[kind]["color"] == html_report.to_hex(color)
        assert marks[kind]["symbol"].endswith("-open") == (marker != "x")
    assert marks["timeout"]["symbol"] != marks["failed"]["symbol"] != marks["inaccurate"]["symbol"]


def test_a_page_row_sits_at_its_steps_solved_load_with_its_status_kind(tmp_path: Path) -> None:
    rows = page_rows(SWEEP, tmp_path)
    assert rows[("b", 1)]["dl"] == pytest.approx(np.median([2e-4, 2.2e-4]))  # a timeout: not its own 5e-3
    assert rows[("b", 2)]["dl"] == pytest.approx(np.median([3e-4, 3.2e-4]))  # an inaccurate answer
    assert rows[("c", 0)]["dl"] == pytest.approx(np.median([1e-4, 1.2e-4]))  # a failure without a load
    assert rows[("a", 0)]["dl"] == pytest.approx(np.median([1e-4, 1.2e-4]))
    assert all(rows[(s, 3)]["dl"] is None for s in SWEEP)  # nobody solved step 3: no place on the axis
    assert {k: r["uk"] for k, r in rows.items() if k[1] == 1} == {("a", 1): None, ("b", 1): "timeout",
                                                                  ("c", 1): None}
    assert (rows[("b", 2)]["uk"], rows[("b", 3)]["uk"], rows[("c", 0)]["uk"]) == ("inaccurate", "failed", "failed")


def test_the_page_data_carries_the_marks(tmp_path: Path) -> None:
    ctx = rp.ReportContext(tmp_path, sweep_table(SWEEP), dict(META))
    assert html_report.page_data(ctx)["unsolved"] == html_report.unsolved_marks()


def test_each_solver_wears_its_own_symbol_on_the_page_and_none_an_unsolved_mark(tmp_path: Path) -> None:
    """Members of one family (shades of one hue) differ in shape on the page's line charts as
    in the static figures: each solver's symbol is its style marker's, and no solved point
    wears a mark of ``UNSOLVED_MARKS``."""
    one_family = {f"q{i}": [("solved", 1e-4 * (i + 1))] for i in range(6)}
    ctx = rp.ReportContext(tmp_path, sweep_table(one_family), dict(META))
    members = [s for f in html_report.page_data(ctx)["families"] for s in f["solvers"]]
    assert {s["name"] for s in members} == set(one_family)
    assert all(s["symbol"] == html_report.SOLVER_SYMBOLS[ctx.marker(s["name"])] for s in members)
    assert len({s["symbol"] for s in members}) == len(members)
    unsolved = {m["symbol"] for m in html_report.unsolved_marks().values()}
    assert not unsolved & set(html_report.SOLVER_SYMBOLS.values())


def _fig4(driver: Any) -> dict[str, Any]:
    """The drawn Fig. 4 chart of the open page: its traces and layout."""
    return driver.execute_script("""
        const d = [...document.querySelectorAll('.js-plotly-plot')].find(x => x.layout.title.text.startsWith('Fig. 4'));
        return {data: d.data.map(t => ({name: t.name, x: t.x, y: t.y, marker: t.marker})),
                title: d.layout.title.text, notes: (d.layout.annotations || []).map(a => a.text)};""")


@pytest.mark.slow
def test_the_page_fig4_marks_by_status_and_says_when_it_is_empty(tmp_path: Path) -> None:
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    marks = html_report.unsolved_marks()
    nobody = {s: [("timeout", np.nan), ("failed", np.nan)] for s in ("a", "b")}
    pages = {}
    for name, sweep in (("mixed", SWEEP), ("none", nobody)):
        out = write_out(tmp_path / name, sweep_table(sweep))
        build_report(out)
        pages[name] = out / "report.html"
    driver = open_driver()
    try:
        load_page(driver, pages["mixed"])
        fig = _fig4(driver)
        load_page(driver, pages["none"])
        empty = _fig4(driver)
    finally:
        driver.quit()
    b = next(t for t in fig["data"] if t["name"] == "b")
    # b: solved at step 0, timeout at 1, inaccurate at 2; step 3 (nobody solved it) left out
    assert b["y"] == pytest.approx([0.1, 0.2, 0.3])
    assert b["x"] == pytest.approx([1.1e-4, 2.1e-4, 3.1e-4])
    own = html_report.SOLVER_SYMBOLS[rp.ReportContext(tmp_path, sweep_table(SWEEP), dict(META)).marker("b")]
    assert b["marker"]["symbol"] == [own, marks["timeout"]["symbol"], marks["inaccurate"]["symbol"]]
    assert b["marker"]["color"][1:] == [marks["timeout"]["color"], marks["inaccurate"]["color"]]
    c = next(t for t in fig["data"] if t["name"] == "c")
    assert c["marker"]["symbol"][0] == marks["failed"]["symbol"]
    legend = {t["name"]: t["marker"]["symbol"] for t in fig["data"] if t["name"] not in SWEEP}
    assert legend == {m["label"]: m["symbol"] for m in marks.values()}  # every kind present, once
    assert re.search(r"3 solves not drawn", fig["title"])  # step 3 of a, b and c
    assert empty["data"] == [] and len(empty["notes"]) == 1
    assert "none of the 4 solves here was solved" in empty["notes"][0]

