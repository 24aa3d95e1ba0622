"""What a reader sees on a figure's panels: whether each panel shows data.

A panel (a matplotlib axes of a report figure, or a ``Chart``) must show at least one
finite point, or say why it is empty: ``mark_empty(ax, note)`` writes the note on the
panel, drops its meaningless ticks and tags it, and ``Chart.notes[EMPTY_NOTE]`` does the
same for a backend-neutral chart.  A figure none of whose panels would show data is not
drawn at all: report.md says why in its place (``no_figure``), and report.html writes the
same words on the chart (page_script.py ``emptyNote``).  ``blank_panels(fig)`` and ``chart_is_blank(chart)``
find the panels that do neither; the report records them (``ReportContext.blank_panels``)
and the tests fail on any.

A curve drawn exactly under another (at 0 all along, or equal to another's) shows nothing of
its own: ``curve_notes`` finds them, for the legend and caption to say so.

A line without markers shows nothing below two finite points, so it counts as data only
from two; a marker, an image pixel, a bar of non-zero size or a drawn collection counts
from one.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator, FormatStrFormatter, FuncFormatter, MaxNLocator, NullFormatter

#: The tag (matplotlib gid) of a panel marked empty on purpose.
EMPTY_GID = "contactbench-empty-panel"
#: The key of ``Chart.notes`` that says why a chart has no finite point.
EMPTY_NOTE = "empty"


#: A line of many points wears its marker at points this share of the axes' diagonal apart
#: along it (matplotlib ``markevery``; the page measures it alike: page_script.py
#: ``sparseMarks``), so that a solver's shape tells it apart without hiding the line.
MARK_EVERY = 0.1


#: The most labelled ticks on a log axis too narrow for ``SHORT_LOG_MANTISSAS`` (``label_short_log_axes``).
SHORT_LOG_TICKS = 4
#: The mantissas of the labelled ticks of a log axis that shows fewer than two powers of ten,
#: coarsest first: the first set that puts two ticks or more in view labels it.
SHORT_LOG_MANTISSAS: tuple[tuple[float, ...], ...] = ((1.0, 2.0, 5.0), (1.0, 1.5, 2.0, 3.0, 5.0, 7.0))


def log_steps(lo: float, hi: float, mantissas: tuple[float, ...]) -> list[float]:
    """The values m * 10^k (m in ``mantissas``) from ``lo`` to ``hi`` (0 < lo < hi), ascending."""
    ks = range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1)
    return sorted(v for k in ks for m in mantissas if lo * (1 - 1e-9) <= (v := m * 10.0 ** k) <= hi * (1 + 1e-9))


def label_short_log_axes(fig: Figure) -> None:
    """Number every log axis of ``fig`` that shows fewer than two powers of ten at log-spaced
    steps written plainly ("0.002, 0.005, 0.01, 0.02": ``SHORT_LOG_MANTISSAS``; at most
    ``SHORT_LOG_TICKS`` evenly placed ticks where the axis is too narrow even for those), its
    minor labels dropped -- matplotlib labels only the powers of ten there, so an axis over
    0.02-0.034 s carried no number, and evenly placed ticks left an axis over 0.0015-0.035
    no label below 0.01; then drop the labels that would overlap (``drop_colliding_labels``)."""
    for ax in fig.axes:
        for axis, lims in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log":
                continue
            lo, hi = sorted(lims)
            majors = [t for t in axis.get_majorticklocs() if lo <= t <= hi]
            if len(majors) >= 2 or not (0.0 < lo < hi):
                continue
            steps = next((v for m in SHORT_LOG_MANTISSAS if len(v := log_steps(lo, hi, m)) >= 2), None)
            axis.set_major_locator(FixedLocator(steps) if steps else MaxNLocator(SHORT_LOG_TICKS))
            axis.set_major_formatter(FormatStrFormatter("%.3g"))
            axis.set_minor_formatter(NullFormatter())
    drop_colliding_labels(fig)


#: The widths of a tick label's characters in ems (the label's font size), as the default sans
#: font (DejaVu Sans) draws them: a digit 0.636, a point 0.318, a minus 0.838, else about 0.6;
#: and the least gap between two labels.
LABEL_CHAR_EM = {".": 0.318, ",": 0.318, "-": 0.838, "\u2212": 0.838, **{d: 0.636 for d in "0123456789"}}
LABEL_OTHER_EM = 0.6
LABEL_GAP_EM = 0.25


def label_width(text: str) -> float:
    """The width of tick label ``text`` in ems (``LABEL_CHAR_EM``)."""
    return sum(LABEL_CHAR_EM.get(c, LABEL_OTHER_EM) for c in text)


def _label_rank(value: float) -> tuple[int, float]:
    """Which label of a log axis to keep first where two would overlap: the powers of ten,
    then the 5s, then the 2s, then the others (and the larger first among equals)."""
    m = round(value / 10.0 ** math.floor(math.log10(value) + 1e-9), 6)
    return ({1.0: 0, 5.0: 1, 2.0: 2}.get(m, 3), -value)


def drop_colliding_labels(fig: Figure) -> None:
    """On every log axis of ``fig`` labelled in plain numbers, blank the labels that would
    overlap a label kept before them (``_label_rank``: powers of ten first), their ticks
    kept: a panel 3.5 inches wide over 0.0004-0.04 s wrote "0.00050.001".  A label's extent
    along the axis is estimated from its characters (x) or its font size (y), the axis's
    length from the figure's size and the panel's place; mathtext labels (10^k) are left alone."""
    width, height = fig.get_size_inches() * 72.0
    for ax in fig.axes:
        if not ax.get_visible() or not ax.axison:
            continue
        box = ax.get_position()
        for axis, length, lims, across in ((ax.xaxis, box.width * width, ax.get_xlim(), True),
                                           (ax.yaxis, box.height * height, ax.get_ylim(), False)):
            lo, hi = sorted(lims)
            if axis.get_scale() != "log" or not (0.0 < lo < hi) or not axis.get_major_ticks():
                continue
            locs = [float(t) for t in axis.get_majorticklocs() if lo <= t <= hi]
            fmt = axis.get_major_formatter()
            fmt.set_locs(locs)
            labels = {t: str(fmt(t, i)) for i, t in enumerate(locs)}
            if any(text.startswith("$") for text in labels.values()):
                continue
            size = float(axis.get_major_ticks()[0].label1.get_fontsize())
            span = math.log10(hi / lo)
            kept: list[tuple[float, float]] = []  # (centre, half extent) in points
            for t in sorted((t for t in locs if labels[t]), key=_label_rank):
                centre = length * math.log10(t / lo) / span
                half = (label_width(labels[t]) if across else 1.0) * size / 2
                if all(abs(centre - c) >= half + h + LABEL_GAP_EM * size for c, h in kept):
                    kept.append((centre, half))
                else:
                    labels[t] = ""
            if any(not text for text in labels.values()):
                axis.set_major_formatter(FuncFormatter(lambda x, _pos, shown=dict(labels): next(
                    (text for t, text in shown.items() if math.isclose(t, x, rel_tol=1e-9)), "")))


#: The legend's words for a curve at 0 all along (``curve_notes``): its solver solved none.
AT_ZERO = "none solved"


def curve_notes(curves: dict[str, np.ndarray], solvers: Iterable[str]) -> dict[str, str | None]:
    """The curves of ``solvers`` that cannot be seen: None for one at 0 all along (it lies
    on the axis, under every other such), the name of an earlier solver whose curve it equals
    (drawn under it); the others have no entry.  ``curve_note`` words an entry."""
    out: dict[str, str | None] = {}
    seen: list[str] = []
    for s in solvers:
        c = curves[s]
        if not np.any(c > 0):
            out[s] = None
        elif (twin := next((t for t in seen if np.array_equal(curves[t], c)), None)) is not None:
            out[s] = twin
        seen.append(s)
    return out


def curve_note(twin: str | None) -> str:
    """A legend's words for a ``curve_notes`` entry: ``AT_ZERO``, or "= <twin>"."""
    return AT_ZERO if twin is None else f"= {twin}"


def no_figure(why: str) -> str:
    """report.md's paragraph in place of a figure that would show no data: "**No figure.**"
    and ``why`` (what the figure draws and what the table lacks for it)."""
    return f"**No figure.** {why}\n"


def mark_empty(ax: Any, note: str) -> None:
    """Say on ``ax`` why it has no data (``note``), with no ticks to misread."""
    ax.set_xscale("linear")
    ax.set_yscale("linear")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.text(0.5, 0.5, note, ha="center", va="center", transform=ax.transAxes, fontsize=9, color="gray", wrap=True)
    ax.set_gid(EMPTY_GID)


def _has_marker(line: Any) -> bool:
    return line.get_marker() not in (None, "", " ", "None", "none")


def line_points(line: Any) -> int:
    x = np.asarray(line.get_xdata(), dtype=float)
    y = np.asarray(line.get_ydata(), dtype=float)
    if x.size != y.size:
        return 0
    n = int(np.count_nonzero(np.isfinite(x) & np.isfinite(y)))
    return n if _has_marker(line) or n >= 2 else 0


def _image_points(image: Any) -> int:
    a = np.ma.masked_invalid(np.ma.asarray(image.get_array(), dtype=float))
    return int(a.count())


def _patch_points(patch: Any) -> int:
    ext = patch.get_window_extent() if patch.get_visible() else None
    return int(ext is not None and ext.width > 0 and ext.height > 0 and patch.get_gid() != EMPTY_GID)


def _collection_points(coll: Any) -> int:
    """A scatter's finite points; for another collection (contour lines, filled areas),
    whether it has a path with a finite vertex."""
    if isinstance(coll, PathCollection):
        offsets = np.asarray(coll.get_offsets(), dtype=float).reshape(-1, 2)
        return int(np.count_nonzero(np.isfinite(offsets).all(axis=1)))
    return int(any(len(p.vertices) and np.isfinite(p.vertices).all(axis=1).any() for p in coll.get_paths()))


def panel_points(ax: Any) -> int:
    """How many finite things ``ax`` draws (lines, images, bars, collections; see the
    module doc); 0 is a blank panel unless it is marked empty."""
    n = sum(line_points(ln) for ln in ax.get_lines() if ln.get_visible())
    n += sum(_image_points(im) for im in ax.get_images() if im.get_visible())
    n += sum(_collection_points(c) for c in ax.collections if c.get_visible())
    # A patch is data only among others of its kind (histogram bars), not an outline on an image.
    if n == 0:
        n += sum(_patch_points(p) for p in ax.patches)
    return n


def is_colorbar(ax: Any) -> bool:
    return getattr(ax, "_colorbar", None) is not None


def blank_panels(fig: Figure) -> list[str]:
    """The titles (or positions) of the visible panels of ``fig`` that draw nothing
    finite and are not marked empty (``mark_empty``)."""
    blank = []
    for i, ax in enumerate(fig.axes):
        if not ax.get_visible() or not ax.axison or is_colorbar(ax) or ax.get_gid() == EMPTY_GID:
            continue
        if panel_points(ax) == 0:
            blank.append(ax.get_title() or f"panel {i + 1}")
    return blank


def chart_is_blank(chart: Any) -> bool:
    """Whether a ``Chart`` has no finite point and no ``notes[EMPTY_NOTE]`` saying why."""
    return not chart.has_data and not chart.notes.get(EMPTY_NOTE)


#: The span (decades) over which the residual-against-iteration charts draw iterations on a
#: log axis (``iteration_axis``).
ITERATION_LOG_DECADES = 2.0


def iteration_axis(its: list[float]) -> dict[str, Any]:
    """How the residual-against-iteration charts (the page's and the PNG's) draw the iterations ``its`` (every
    solver's): on a log axis where they span over ``ITERATION_LOG_DECADES``, as iteration + 1
    (``shift`` 1) so that iteration 0, where traces start, is drawn (a log axis drops it);
    else as they are, on a linear axis.  ``title`` says which."""
    v = np.asarray([x for x in its if np.isfinite(x)], dtype=float)
    log = bool(len(v)) and float(np.log10((v.max() + 1) / (max(v.min(), 0.0) + 1))) > ITERATION_LOG_DECADES
    return {"log": log, "shift": 1 if log else 0,
            "title": "iteration + 1 (log axis: iteration 0 at 1)" if log else "iteration"}
