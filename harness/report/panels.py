"""What a reader sees on a figure's panels: whether each panel shows data.

A panel (a matplotlib axes of a report figure, or a ``Chart``) must show at least one
finite point, or say why it is empty: ``mark_empty(ax, note)`` writes the note on the
panel, drops its meaningless ticks and tags it, and ``Chart.notes[EMPTY_NOTE]`` does the
same for a backend-neutral chart.  A figure none of whose panels would show data is not
drawn at all: report.md says why in its place (``no_figure``), and report.html writes the
same words on the chart (page_script.py ``emptyNote``).  ``blank_panels(fig)`` and ``chart_is_blank(chart)``
find the panels that do neither; the report records them (``ReportContext.blank_panels``)
and the tests fail on any.

A line without markers shows nothing below two finite points, so it counts as data only
from two; a marker, an image pixel, a bar of non-zero size or a drawn collection counts
from one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter, MaxNLocator, NullFormatter

#: The tag (matplotlib gid) of a panel marked empty on purpose.
EMPTY_GID = "contactbench-empty-panel"
#: The key of ``Chart.notes`` that says why a chart has no finite point.
EMPTY_NOTE = "empty"


#: A line of many points wears its marker at points this share of the axes' diagonal apart
#: along it (matplotlib ``markevery``; the page measures it alike: page_script.py
#: ``sparseMarks``), so that a solver's shape tells it apart without hiding the line.
MARK_EVERY = 0.1


#: The most labelled ticks on a log axis that spans less than a decade (``label_short_log_axes``).
SHORT_LOG_TICKS = 4


def label_short_log_axes(fig: Figure) -> None:
    """Number every log axis of ``fig`` that shows fewer than two powers of ten: at most
    ``SHORT_LOG_TICKS`` evenly placed ticks written plainly ("0.025"), its minor labels
    dropped -- matplotlib labels only the powers of ten there, so an axis over 0.02-0.034 s
    carried no number, or crowded minor labels over each other."""
    for ax in fig.axes:
        for axis, lims in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log":
                continue
            lo, hi = sorted(lims)
            majors = [t for t in axis.get_majorticklocs() if lo <= t <= hi]
            if len(majors) >= 2 or not (0.0 < lo < hi):
                continue
            axis.set_major_locator(MaxNLocator(SHORT_LOG_TICKS))
            axis.set_major_formatter(FormatStrFormatter("%.3g"))
            axis.set_minor_formatter(NullFormatter())


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
