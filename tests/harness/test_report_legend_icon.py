"""report.html's time-against-load charts (page_script.py): a series' legend icon is the
series' own marker (its solver's symbol in its colour, the size of a solved step's),
whatever its points' marks; the steps it did not solve keep their ``UNSOLVED_MARKS`` mark on the plot,
and a click on the legend entry still shows or hides the series (one legend group)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from contactbench.harness import build_report
from contactbench.harness.report import core as rp
from contactbench.harness.report import html as html_report
from contactbench.harness.report.browser import browser_missing, load_page, open_driver
from tests.harness.test_report_page_marks import SWEEP, sweep_table
from tests.helpers import META, write_out

#: Per legend entry of the drawn Fig. 4 chart: its text, its marker's path and fill.
LEGEND_JS = """
const d = [...document.querySelectorAll('.js-plotly-plot')].find(x => x.layout.title.text.startsWith('Fig. 4'));
const icons = Object.fromEntries([...d.querySelectorAll('.legend .traces')].map(g => [
  g.querySelector('.legendtext').textContent,
  [...g.querySelectorAll('.legendpoints path')].map(p => [p.getAttribute('d'), p.style.fill])]));
const groups = Object.fromEntries(d.data.filter(t => t.showlegend !== false).map(t => [t.name, t.legendgroup || '']));
const series = d.data.filter(t => t.showlegend === false).map(t => [t.name, t.legendgroup, t.marker.symbol]);
const standIns = Object.fromEntries(d.data.filter(t => t.showlegend !== false && t.meta && t.meta.so)
  .map(t => [t.name, [t.marker.symbol, t.marker.size]]));
return {icons: icons, groups: groups, series: series, standIns: standIns};
"""


def _legend(driver: Any, page: Path) -> dict[str, Any]:
    load_page(driver, page)
    return driver.execute_script(LEGEND_JS)


@pytest.mark.slow
def test_a_series_legend_icon_is_its_own_marker_not_its_first_steps_unsolved_mark(tmp_path: Path) -> None:
    why = browser_missing()
    if why:
        pytest.skip(f"browser test skipped: {why}")
    out = write_out(tmp_path, sweep_table(SWEEP))  # c: its first step failed; b: a timeout, then a KKT failure
    build_report(out)
    driver = open_driver()
    try:
        seen = _legend(driver, out / "report.html")
    finally:
        driver.quit()
    icons = seen["icons"]
    marks = {m["label"]: m for m in html_report.unsolved_marks().values()}
    ctx = rp.ReportContext(tmp_path, sweep_table(SWEEP), dict(META))
    for name in ("b", "c"):
        (path, fill), = icons[name]
        # its own symbol at a solved step's size, not the first point's mark or their mean size
        assert seen["standIns"][name] == [html_report.SOLVER_SYMBOLS[ctx.marker(name)], 6]
        assert path not in {icons[label][0][0] for label in marks if label in icons}
        assert fill not in {icons[label][0][1] for label in marks if label in icons}
    assert icons["c"][0][1] != icons["b"][0][1]  # each in its own colour
    # the series themselves, out of the legend, keep their marks and share the stand-in's legend group
    series = {name: (group, symbol) for name, group, symbol in seen["series"]}
    failed = html_report.unsolved_marks()["failed"]["symbol"]
    assert series["c"][0] == seen["groups"]["c"] == "c" and series["c"][1][0] == failed
