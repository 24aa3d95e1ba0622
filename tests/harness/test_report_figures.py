"""Figures checked by what a reader sees: no panel without data unless it says why, and
figure file names that keep the numbers of the names they come from."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from matplotlib.figure import Figure

from contactbench.harness.report.build import write_report
from contactbench.harness.report.charts import Chart, Series
from contactbench.harness.report.core import slug
from contactbench.harness.report.panels import EMPTY_NOTE, blank_panels, chart_is_blank, mark_empty
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.run.runner import run_benchmark
from contactbench.harness.table.fields import load_field
from contactbench.harness.table.store import load_table
from contactbench.problems.scenes import SceneConfig

#: A number as a name writes it: digits, an optional fraction, an optional signed exponent.
NUMBER = re.compile(r"\d+(?:\.\d+)?(?:[eE][+-]?\d+)?")


def numbers(text: str) -> list[float]:
    return [float(x) for x in NUMBER.findall(text)]


def _figure(*draw: str) -> Figure:
    fig = Figure()
    for i, what in enumerate(draw):
        ax = fig.add_subplot(1, len(draw), i + 1)
        ax.set_title(what)
        if what == "line":
            ax.plot([1.0, 2.0], [1.0, 3.0])
        elif what == "one point, no marker":
            ax.plot([1.0], [2.0])
        elif what == "nan line":
            ax.plot([1.0, 2.0], [np.nan, np.nan], "o-")
        elif what == "image":
            ax.imshow(np.ones((3, 3)))
        elif what == "nan image":
            ax.imshow(np.full((3, 3), np.nan))
        elif what == "histogram":
            ax.hist([1.0, 2.0, 2.5])
        elif what == "marked":
            mark_empty(ax, "nothing to draw here")
    return fig


def test_a_panel_with_nothing_finite_on_it_is_blank_unless_marked() -> None:
    fig = _figure("line", "one point, no marker", "nan line", "image", "nan image", "histogram", "empty", "marked")
    assert blank_panels(fig) == ["one point, no marker", "nan line", "nan image", "empty"]


def test_a_chart_without_a_finite_point_needs_a_note() -> None:
    empty = Chart("c", "t", "x", "y", (Series("s", (1.0, 2.0), (float("nan"), float("inf"))),))
    assert chart_is_blank(empty) and not empty.has_data
    noted = Chart("c", "t", "x", "y", empty.series, notes={EMPTY_NOTE: "no solve passed"})
    assert not chart_is_blank(noted)
    assert blank_panels(noted.to_figure()) == []  # the note is drawn on the panel
    assert noted.to_plotly()["layout"]["annotations"][0]["text"] == "no solve passed"
    full = Chart("c", "t", "x", "y", (Series("s", (1.0,), (2.0,)),))
    assert not chart_is_blank(full) and blank_panels(full.to_figure()) == []


@pytest.mark.parametrize("name, expected", [
    ("field-plastic-sweep-saupe-H0.7-N256-bcc-np-s5-HA3e+08-k9", "field-plastic-sweep-saupe-h0.7-n256-bcc-np-s5-ha3e+08-k9"),
    ("load 1E-3 / 2.5e+10", "load-1e-3-2.5e+10"),
])
def test_a_figure_name_keeps_its_numbers(name: str, expected: str) -> None:
    assert slug(name) == expected
    assert numbers(slug(name)) == numbers(name)


@given(st.lists(st.one_of(st.floats(min_value=1e-300, max_value=1e300, allow_nan=False, allow_infinity=False),
                          st.integers(min_value=0, max_value=10**9)), min_size=1, max_size=4),
       st.sampled_from(["-", "_", " ", "=", "/", "+", ", "]))
def test_every_figure_name_round_trips_its_numbers(values: list[float], sep: str) -> None:
    name = sep.join(f"x{v!r}" if isinstance(v, float) else f"k{v}" for v in values)
    assert numbers(slug(name)) == numbers(name) == [float(v) for v in values]


def _report(tmp_path: Path, scene: str, cfg: SceneConfig, solvers: list[str]) -> tuple[Path, object]:
    out = tmp_path / scene
    run_benchmark([scene], cfg, solvers, RunConfig(reference="none", warmup=False, progress=False), out)
    return out, write_report(out, html=False)


def test_the_load_control_field_stores_its_gap_and_draws_every_panel(tmp_path: Path) -> None:
    out, ctx = _report(tmp_path, "load-sweep", SceneConfig(size=16, steps=2), ["pk"])
    field = load_field(next((out / "arrays").glob("field-*.npz")), "load-sweep", "x")
    table = load_table(out)
    top = table[table["step"] == table["step"].max()]
    assert np.isfinite(field.gap).all() and np.nanmin(field.gap) > -1e-9 * np.ptp(field.heights)
    assert field.far_field == pytest.approx(float(top["delta"].iloc[0]), rel=1e-6)  # the judge's approach
    assert np.abs(field.gap[field.contact]).max() < 1e-6 * np.ptp(field.heights)  # closed where in contact
    text = (out / "report.md").read_text()
    assert "load control: approach Delta = " in text and "far-field displacement -" not in text
    assert ctx.blank_panels == []
    assert not [c.chart for c in ctx.charts if isinstance(c.chart, Chart) and chart_is_blank(c.chart)]


def test_the_counterexample_field_says_it_has_no_surface(tmp_path: Path) -> None:
    out, ctx = _report(tmp_path, "counterexample", SceneConfig(size=5, seeds=(0,)), ["scipy-nnls"])
    field = load_field(next((out / "arrays").glob("field-*.npz")), "counterexample", "x")
    assert np.isfinite(field.gap).all()  # w = Hp - ubar on the whole grid (every element is in the trial set)
    assert ctx.blank_panels == []
    text = (out / "report.md").read_text()
    assert "no surface panel" in text and "no far-field displacement" in text and "index order" in text


def test_the_plastic_field_figure_keeps_the_hardness_in_its_name(tmp_path: Path) -> None:
    out, ctx = _report(tmp_path, "plastic-sweep", SceneConfig(size=16, steps=2), ["pk"])
    instance = str(load_table(out)["instance"].iloc[0])
    figure = next(f for f in ctx.figures if f.startswith("figures/field-"))
    assert numbers(figure.removesuffix(".png")) == numbers(f"plastic-sweep-{instance}") + [1.0]  # ... -k1
    assert ctx.blank_panels == []


def test_a_scatter_of_nan_points_is_blank() -> None:
    fig = Figure()
    ax = fig.add_subplot(1, 1, 1)
    ax.scatter([1.0, 2.0], [np.nan, np.nan])
    ax.set_title("nan scatter")
    assert blank_panels(fig) == ["nan scatter"]
    ax.scatter([1.0], [2.0])
    assert blank_panels(fig) == []


@pytest.mark.slow
def test_no_figure_of_a_full_report_has_a_blank_panel(tmp_path: Path) -> None:
    """Every section of the fabricated table (the paper's figures, Example 1, the summary
    figures): each panel draws data or says why it has none."""
    from tests.harness.test_report import write_counterexample_arrays
    from tests.helpers import fabricate_table, write_out

    out = write_out(tmp_path, fabricate_table())
    write_counterexample_arrays(out)
    ctx = write_report(out, html=False)
    assert len(ctx.figures) >= 12
    assert ctx.blank_panels == []
    assert not [c.chart.name for c in ctx.charts if isinstance(c.chart, Chart) and chart_is_blank(c.chart)]


@pytest.mark.parametrize(("largest", "unit", "expected"), [
    (2e-3, "m", (1e3, "mm")), (6e-5, "m", (1e6, "um")), (5e-9, "m", (1e9, "nm")), (2.0, "m", (1.0, "m")),
    (1e-3, "m", (1e3, "mm")), (0.5, "mm", (1e3, "um")), (3.0, "a.u.", (1.0, "a.u.")), (0.0, "m", (1.0, "m"))])
def test_a_field_length_is_drawn_in_the_unit_that_puts_it_in_1_to_1000(
        largest: float, unit: str, expected: tuple[float, str]) -> None:
    """A 2 mm map reads 0.0 to 2.0 mm, not 0.0000 to 0.0020 m (whose zoom ticks ran together)."""
    from contactbench.harness.report.sections.fields import _length_scale

    factor, name = _length_scale(np.array([largest / 2, -largest]), unit)
    assert (name, factor) == (expected[1], pytest.approx(expected[0]))
    if largest > 0 and name in ("m", "mm", "um", "nm"):
        assert 1.0 <= largest * factor < 1000.0


def test_the_counterexample_field_draws_no_empty_surface_panel(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Example 1 has no height map: its field figure has no surface panel at all (one that
    would only say "none"), but the contact area, the pressure and the gap."""
    from contactbench.harness.report.core import ReportContext

    figures: dict[str, Figure] = {}
    keep = ReportContext.save_figure

    def record(self: ReportContext, fig: Figure, name: str, on_page: bool = False) -> str:
        figures[name] = fig
        return keep(self, fig, name, on_page)

    monkeypatch.setattr(ReportContext, "save_figure", record)
    _report(tmp_path, "counterexample", SceneConfig(size=5, seeds=(0,)), ["scipy-nnls"])
    (name,) = [n for n in figures if n.startswith("field-counterexample")]
    titles = [ax.get_title() for ax in figures[name].axes if ax.get_visible() and ax.get_title()]
    assert len(titles) == 3 and not [t for t in titles if t.startswith("surface")], titles
