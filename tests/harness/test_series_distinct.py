"""Series a reader can tell apart (harness/report/style.py, harness/report/charts.py): in every
figure of a report, two solvers drawn on one panel differ by at least ``COLOUR_APART`` in colour
(CIEDE2000) or differ in marker or line dash; a solver's colour stands clear of the light grey
context lines; and a solver's style does not depend on which other solvers the report holds.

The figures are checked as drawn: the report's every matplotlib figure is read back, panel by
panel, from the artists with a legend entry (lines, legend stand-ins and bars)."""

from __future__ import annotations

from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_rgb
from matplotlib.container import BarContainer
from matplotlib.figure import Figure

from contactbench.harness.report.build import write_report
from contactbench.harness.report.charts import Chart, Series
from contactbench.harness.report.core import ReportContext, natural_key
from contactbench.harness.report.style import (COLOUR_APART, FAMILY_SLOTS, GREY, SolverStyles, cielab,
                                               delta_e00)
from tests.helpers import every_solver_table, write_out

#: A solver's series and the context grey at least this far apart (CIEDE2000).
GREY_MIN = 15.0
WARM = " (warm)"


def test_delta_e00_gives_the_published_values() -> None:
    """Sharma, Wu and Dalal (2005), pairs 1, 7 and 17 of their table of test data."""
    assert float(delta_e00((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485))) == pytest.approx(2.0425, abs=1e-4)
    assert float(delta_e00((50.0, 0.0, 0.0), (50.0, -1.0, 2.0))) == pytest.approx(2.3669, abs=1e-4)
    assert float(delta_e00((50.0, 2.5, 0.0), (73.0, 25.0, -18.0))) == pytest.approx(27.1492, abs=1e-4)


def _every_solver() -> dict[str, str]:
    """The project's own solvers (``FAMILY_SLOTS``) with their families, plus outsiders."""
    out = {s: f for f, names in FAMILY_SLOTS.items() for s in names}
    return out | {f"nnls-gp[K={k}]": "paper" for k in (0, 10, 25, 50, 100, 150, 200)} | {
        "ext-a": "external", "ext-b": "external", "mine": "other", "odd": "olive"}


def test_a_solver_s_style_does_not_depend_on_the_others_present() -> None:
    """``pk`` is the same blue whether it runs alone, with its family or with every solver:
    every solver the project names keeps its colour, marker and dash in any subset."""
    every = _every_solver()
    full = SolverStyles(every, natural_key)
    rng = np.random.default_rng(0)
    names = [s for names in FAMILY_SLOTS.values() for s in names]
    subsets = [[s] for s in names] + [list(rng.choice(names, size=k, replace=False)) for k in (2, 5, 9, 20, 30)]
    for sub in subsets:
        part = SolverStyles({s: every[s] for s in sub}, natural_key)
        for s in sub:
            assert (part.color(s), part.marker(s), part.dash(s)) == (full.color(s), full.marker(s), full.dash(s)), s


def test_no_two_solvers_of_one_report_share_colour_marker_and_dash() -> None:
    """Over every solver of the project (and outsiders, and a family the project does not
    know), two whose colours are within ``COLOUR_APART`` differ in marker or dash, and every
    colour stands clear of the context grey."""
    every = _every_solver()
    st = SolverStyles(every, natural_key)
    lab = {s: cielab(st.color(s)) for s in every}
    close = [(a, b) for a, b in combinations(every, 2) if float(delta_e00(lab[a], lab[b])) < COLOUR_APART
             and (st.marker(a), st.dash(a)) == (st.marker(b), st.dash(b))]
    assert not close, close
    grey = cielab(GREY)
    assert min(float(delta_e00(lab[s], grey)) for s in every) >= GREY_MIN


def _series(ax: Any, solvers: set[str]) -> list[tuple[str, np.ndarray, str, str]]:
    """(label, L*a*b*, marker, dash) of each solver series with a legend entry on ``ax``."""
    out = []
    for line in ax.get_lines():
        lab = str(line.get_label())
        if lab.removesuffix(WARM) in solvers:
            marker = "" if line.get_marker() in (None, "None", "none", "") else str(line.get_marker())
            dash = "" if line.get_linestyle() in ("None", "none", "") else str(line.get_linestyle())
            out.append((lab, cielab(to_rgb(line.get_color())), marker, dash))
    for cont in ax.containers:
        if isinstance(cont, BarContainer) and str(cont.get_label()) in solvers and len(cont.patches):
            out.append((str(cont.get_label()), cielab(to_rgb(cont.patches[0].get_facecolor())), "bar", ""))
    return out


def _confusable(series: list[tuple[str, np.ndarray, str, str]]) -> list[tuple[str, str, float]]:
    return [(a[0], b[0], round(float(delta_e00(a[1], b[1])), 1)) for a, b in combinations(series, 2)
            if (a[2], a[3]) == (b[2], b[3]) and float(delta_e00(a[1], b[1])) < COLOUR_APART]


def _big_table() -> pd.DataFrame:
    return every_solver_table()


@pytest.fixture(scope="module")
def drawn(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Figure]:
    """Every figure of the report of ``_big_table``, by name, as drawn."""
    figures: dict[str, Figure] = {}
    keep = ReportContext.save_figure

    def record(self: ReportContext, fig: Figure, name: str, on_page: bool = False) -> str:
        figures[name] = fig
        return keep(self, fig, name, on_page)

    mp = pytest.MonkeyPatch()
    mp.setattr(ReportContext, "save_figure", record)
    try:
        out = write_out(Path(tmp_path_factory.mktemp("distinct")), _big_table())
        write_report(out, html=False)
    finally:
        mp.undo()
    return figures


#: The convergence traces (sections/fields.py): lines of many points, each wearing its solver's
#: marker sparsely (panels.py ``MARK_EVERY``), checked on their own.
TRACES = ("traces-",)


def _confusable_panels(drawn: dict[str, Figure], names: list[str]) -> dict[str, list[tuple[str, str, float]]]:
    solvers = set(_big_table()["solver"].astype(str))
    bad = {}
    for name in names:
        fig = drawn[name]
        for i, ax in enumerate(fig.axes):
            pairs = _confusable(_series(ax, solvers))
            if pairs:
                bad[f"{name}[{i}]"] = pairs
    return bad


def test_every_panel_of_every_figure_tells_its_solvers_apart(drawn: dict[str, Figure]) -> None:
    assert {"fig4-paper-sweep", "fig5-greedy-linear-solvers", "wp-paper-sweep",
            "counterexample-violations", "analytic-hertz"} <= set(drawn)
    assert any(n.startswith("pp-paper-sweep") for n in drawn)  # one per profile where it ran several
    bad = _confusable_panels(drawn, [n for n in drawn if not n.startswith(TRACES)])
    assert not bad, bad


def test_the_convergence_traces_tell_their_solvers_apart(drawn: dict[str, Figure]) -> None:
    bad = _confusable_panels(drawn, [n for n in drawn if n.startswith(TRACES)])
    assert not bad, bad


def test_every_solver_series_stands_clear_of_the_context_grey(drawn: dict[str, Figure]) -> None:
    """The reference solver (``scipy-nnls``) among them: in a panel whose other families are
    drawn in light grey, no solver of the panel is drawn in a colour close to it."""
    solvers = set(_big_table()["solver"].astype(str))
    grey = cielab(GREY)
    near = sorted({(lab, round(float(delta_e00(c, grey)), 1)) for fig in drawn.values() for ax in fig.axes
                   for lab, c, _, _ in _series(ax, solvers) if float(delta_e00(c, grey)) < GREY_MIN})
    assert not near, near


def test_a_chart_s_series_differ_in_marker_in_both_backends() -> None:
    """Three series with no colour, marker or dash of their own: each backend draws them with
    three markers (the PNG's and the page's the same), and a series' own marker and dash stand."""
    chart = Chart("c", "t", "x", "y", (Series("a", (1.0, 2.0), (1.0, 2.0)), Series("b", (1.0, 2.0), (2.0, 3.0)),
                                       Series("c", (1.0, 2.0), (3.0, 4.0), marker="D", dash=":", color="#123456")))
    lines = chart.to_figure().axes[0].get_lines()
    assert len({str(ln.get_marker()) for ln in lines}) == 3
    assert (lines[2].get_marker(), lines[2].get_linestyle()) == ("D", ":")
    data = chart.to_plotly()["data"]
    assert [d["marker"]["symbol"] for d in data] == ["circle", "square", "diamond"]
    assert data[2]["line"] == {"dash": "dot", "color": "#123456"}
    with pytest.raises(ValueError, match="marker"):
        Series("d", (1.0,), (1.0,), marker="?")
