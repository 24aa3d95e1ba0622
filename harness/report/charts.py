"""Backend-neutral charts: what a report section returns for a chart, drawn by both
backends -- a PNG in report.md (matplotlib, ``to_figure``) and an interactive chart on
report.html (Plotly, ``to_plotly``).

A ``Chart`` is data, not drawing code: a title, the axis titles, whether each axis is
logarithmic, and its ``Series`` (a named list of points drawn as a line with markers,
or as markers only, each with its colour, marker and dash).  A series that names no marker
or dash takes the chart's next one (``SERIES_MARKERS``, ``SERIES_DASHES``, by its place in
the chart), so that two series of one chart differ in shape whatever their colours; both
backends draw the same colour, marker and dash.  A section puts its charts in ``Section.charts``; the report
assembly (harness/report/build.py) draws each one into report.md under the section and
hands it to report.html under the section's scene.  Nothing is keyed by a scene name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from matplotlib.figure import Figure

from .panels import EMPTY_NOTE, mark_empty

#: How a series is drawn: "lines" (lines and markers) or "markers" (markers only).
SERIES_MODES: tuple[str, ...] = ("lines", "markers")
#: Matplotlib marker -> Plotly symbol, for the markers a series may name.
PLOTLY_SYMBOLS: dict[str, str] = {"o": "circle", "s": "square", "^": "triangle-up", "D": "diamond",
                                  "v": "triangle-down", "P": "cross", "X": "x", "<": "triangle-left",
                                  ">": "triangle-right", "p": "pentagon", "h": "hexagon", "*": "star"}
#: Matplotlib line dash -> Plotly dash, for the dashes a series may name.
PLOTLY_DASHES: dict[str, str] = {"-": "solid", "--": "dash", "-.": "dashdot", ":": "dot"}
#: The markers and dashes of the series that name none, by their place in the chart (11 and 4
#: are coprime: two series share both only 44 places apart).
SERIES_MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "p", "h")
SERIES_DASHES: tuple[str, ...] = ("-", "--", "-.", ":")


@dataclass(frozen=True)
class Series:
    """One named series of (x, y) points; ``color`` a CSS/matplotlib colour or None
    (the backend's cycle); ``marker`` (a key of ``PLOTLY_SYMBOLS``) and ``dash`` (a key of
    ``PLOTLY_DASHES``) or None (the chart's next: ``Chart.styled``)."""

    name: str
    x: tuple[float, ...]
    y: tuple[float, ...]
    mode: str = "lines"
    color: str | None = None
    marker: str | None = None
    dash: str | None = None

    def __post_init__(self) -> None:
        if len(self.x) != len(self.y):
            raise ValueError(f"series {self.name!r}: {len(self.x)} x values but {len(self.y)} y values")
        if self.mode not in SERIES_MODES:
            raise ValueError(f"series {self.name!r}: mode must be one of {SERIES_MODES}, got {self.mode!r}")
        if self.marker is not None and self.marker not in PLOTLY_SYMBOLS:
            raise ValueError(f"series {self.name!r}: marker must be one of {tuple(PLOTLY_SYMBOLS)}, got {self.marker!r}")
        if self.dash is not None and self.dash not in PLOTLY_DASHES:
            raise ValueError(f"series {self.name!r}: dash must be one of {tuple(PLOTLY_DASHES)}, got {self.dash!r}")


@dataclass(frozen=True)
class Chart:
    """A chart as data (module doc).  ``name`` names its PNG (figures/<name>.png)."""

    name: str
    title: str
    x_title: str
    y_title: str
    series: tuple[Series, ...] = ()
    x_log: bool = False
    y_log: bool = False
    notes: dict[str, Any] = field(default_factory=dict)  # notes["empty"]: why it has no finite point

    @property
    def has_data(self) -> bool:
        """Whether any series has a finite (x, y) point."""
        return any(math.isfinite(float(x)) and math.isfinite(float(y)) for s in self.series for x, y in zip(s.x, s.y))

    def styled(self) -> list[tuple[Series, str, str]]:
        """Each series with the marker and dash it is drawn with: its own, else the one of
        ``SERIES_MARKERS`` / ``SERIES_DASHES`` at its place in the chart."""
        return [(s, s.marker or SERIES_MARKERS[i % len(SERIES_MARKERS)], s.dash or SERIES_DASHES[i % len(SERIES_DASHES)])
                for i, s in enumerate(self.series)]

    def to_plotly(self) -> dict[str, Any]:
        """``{"data": [...], "layout": {...}}`` for ``Plotly.react`` (JSON-safe: NaN and
        inf become null, which Plotly leaves out)."""
        data = [{"type": "scatter", "mode": "lines+markers" if s.mode == "lines" else "markers", "name": s.name,
                 "x": [_finite(v) for v in s.x], "y": [_finite(v) for v in s.y],
                 "line": {"dash": PLOTLY_DASHES[dash], **({"color": s.color} if s.color else {})},
                 "marker": {"symbol": PLOTLY_SYMBOLS[marker], **({"color": s.color} if s.color else {})}}
                for s, marker, dash in self.styled()]
        layout = {"title": {"text": self.title, "font": {"size": 13}}, "margin": {"l": 60, "r": 10, "t": 40, "b": 50},
                  "xaxis": {"title": {"text": self.x_title}, "type": "log" if self.x_log else "linear",
                            "exponentformat": "power"},
                  "yaxis": {"title": {"text": self.y_title}, "type": "log" if self.y_log else "linear",
                            "exponentformat": "power"},
                  "legend": {"font": {"size": 10}}, "hovermode": "closest"}
        if self.notes.get(EMPTY_NOTE) and not self.has_data:  # say on the page why it is empty
            layout["annotations"] = [{"text": str(self.notes[EMPTY_NOTE]), "showarrow": False, "xref": "paper",
                                      "yref": "paper", "x": 0.5, "y": 0.5, "font": {"color": "gray"}}]
        return {"data": data, "layout": layout}

    def to_figure(self) -> Figure:
        """The same chart as a matplotlib figure (report.md's PNG)."""
        fig = Figure(figsize=(6.4, 4.0))
        ax = fig.add_subplot(1, 1, 1)
        for s, marker, dash in self.styled():
            ax.plot(s.x, s.y, marker=marker, ls=dash if s.mode == "lines" else "none", label=s.name, ms=4,
                    **({"color": s.color} if s.color else {}))
        ax.set_title(self.title)
        ax.set_xlabel(self.x_title)
        ax.set_ylabel(self.y_title)
        if self.x_log:
            ax.set_xscale("log")
        if self.y_log:
            ax.set_yscale("log")
        if self.notes.get(EMPTY_NOTE) and not self.has_data:
            mark_empty(ax, str(self.notes[EMPTY_NOTE]))
        elif self.series:
            ax.legend(fontsize=8)
        return fig


def _finite(v: float) -> float | None:
    f = float(v)
    return f if math.isfinite(f) else None


#: The page's drawers of the table's own rows (report/page_script.py): "time-against"
#: (solve time per row against a row field, one curve per solver label and profile, a row
#: not solved marked by its status: sections/paper.py ``UNSOLVED_MARKS``) and "unsolved-share" (the
#: share of rows not solved per solver against n).
ROW_DRAWERS: tuple[str, ...] = ("time-against", "unsolved-share")
#: The row fields a "time-against" chart may put on its x axis: dimensionless load, n.
ROW_X_FIELDS: tuple[str, ...] = ("dl", "n")


@dataclass(frozen=True)
class RowChart:
    """An interactive chart that report.html draws from the scene's rows, so that the
    page's solver and profile pickers filter it (a ``Chart`` is fixed data instead).
    A section returns it in ``Section.page_charts``; the page knows only the drawers of
    ``ROW_DRAWERS``, never a scene name.  ``by_instance`` draws one curve per instance;
    ``reference`` (y, its legend name) draws a dashed horizontal line, e.g. a published
    value the bars are read against; ``colors`` ((solver, CSS colour), ...) draws those
    solvers first, in that order and colour, in every chart of the scene on the page (a
    section whose PNG colours its solvers by a parameter gives the page the same), the
    others in their family colours.  ``profile`` and ``instance``, where given, are the
    only profile and instance it draws, those its section's PNG draws (a chart of one
    profile mixed with another's rows reads as one solver's two speeds); it says so
    under its title, and draws nothing when the page's picker leaves that profile out."""

    title: str
    drawer: str = "time-against"
    x: str = "dl"
    x_title: str = "P/(E A) [-]"
    by_instance: bool = False
    reference: tuple[float, str] | None = None
    colors: tuple[tuple[str, str], ...] = ()
    profile: str | None = None
    instance: str | None = None

    def __post_init__(self) -> None:
        if self.drawer not in ROW_DRAWERS:
            raise ValueError(f"row chart {self.title!r}: drawer must be one of {ROW_DRAWERS}, got {self.drawer!r}")
        if self.x not in ROW_X_FIELDS:
            raise ValueError(f"row chart {self.title!r}: x must be one of {ROW_X_FIELDS}, got {self.x!r}")
