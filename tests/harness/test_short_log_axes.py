"""A log axis that spans less than a decade still carries numbers: a few evenly placed ticks
written plainly, its crowded minor labels dropped (``panels.label_short_log_axes``, run on
every saved figure), while an axis over several decades keeps its powers of ten."""

from __future__ import annotations

from matplotlib.figure import Figure

from contactbench.harness.report.panels import label_short_log_axes


def labels(fig: Figure, which: str) -> list[str]:
    fig.canvas.draw()
    ax = fig.axes[0]
    axis = ax.yaxis if which == "y" else ax.xaxis
    return [t.get_text() for t in axis.get_majorticklabels() + axis.get_minorticklabels()
            if t.get_text() and t.get_visible()]


def figure(y: list[float]) -> Figure:
    fig = Figure()
    ax = fig.add_subplot(1, 1, 1)
    ax.plot([1.0, 2.0, 3.0], y, marker="o")
    ax.set_yscale("log")
    ax.set_xscale("log")
    return fig


def test_a_log_axis_within_one_decade_is_labelled() -> None:
    fig = figure([0.021, 0.027, 0.034])
    label_short_log_axes(fig)
    lo, hi = fig.axes[0].get_ylim()
    shown = [float(t) for t in labels(fig, "y")]
    inside = [v for v in shown if lo <= v <= hi]
    assert 2 <= len(inside) <= 5 and len(shown) <= 6, shown


def test_a_log_axis_over_decades_keeps_its_powers_of_ten() -> None:
    fig = figure([1e-6, 1e-3, 1.0])
    before = labels(fig, "y")
    label_short_log_axes(fig)
    assert labels(fig, "y") == before
