"""Backend-neutral charts: what a report section returns for a chart, drawn by both
backends -- a PNG in report.md (matplotlib, ``to_figure``) and an interactive chart on
report.html (Plotly, ``to_plotly``).

A ``Chart`` is data, not drawing code: a title, the axis titles, whether each axis is
logarithmic, and its ``Series`` (a named list of points drawn as a line with markers,
or as markers only).  A section puts its charts in ``Section.charts``; the report
assembly (harness/report/build.py) draws each one into report.md under the section and
hands it to report.html under the section's scene.  Nothing is keyed by a scene name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from matplotlib.figure import Figure

#: How a series is drawn: "lines" (lines and markers) or "markers" (markers only).
SERIES_MODES: tuple[str, ...] = ("lines", "markers")


@dataclass(frozen=True)
class Series:
    """One named series of (x, y) points; ``color`` a CSS/matplotlib colour or None
    (the backend's cycle)."""

    name: str
    x: tuple[float, ...]
    y: tuple[float, ...]
    mode: str = "lines"
    color: str | None = None

    def __post_init__(self) -> None:
        if len(self.x) != len(self.y):
            raise ValueError(f"series {self.name!r}: {len(self.x)} x values but {len(self.y)} y values")
        if self.mode not in SERIES_MODES:
            raise ValueError(f"series {self.name!r}: mode must be one of {SERIES_MODES}, got {self.mode!r}")


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
    notes: dict[str, Any] = field(default_factory=dict)

    def to_plotly(self) -> dict[str, Any]:
        """``{"data": [...], "layout": {...}}`` for ``Plotly.react`` (JSON-safe: NaN and
        inf become null, which Plotly leaves out)."""
        data = [{"type": "scatter", "mode": "lines+markers" if s.mode == "lines" else "markers", "name": s.name,
                 "x": [_finite(v) for v in s.x], "y": [_finite(v) for v in s.y],
                 **({"line": {"color": s.color}, "marker": {"color": s.color}} if s.color else {})}
                for s in self.series]
        layout = {"title": {"text": self.title, "font": {"size": 13}}, "margin": {"l": 60, "r": 10, "t": 40, "b": 50},
                  "xaxis": {"title": {"text": self.x_title}, "type": "log" if self.x_log else "linear",
                            "exponentformat": "power"},
                  "yaxis": {"title": {"text": self.y_title}, "type": "log" if self.y_log else "linear",
                            "exponentformat": "power"},
                  "legend": {"font": {"size": 10}}, "hovermode": "closest"}
        return {"data": data, "layout": layout}

    def to_figure(self) -> Figure:
        """The same chart as a matplotlib figure (report.md's PNG)."""
        fig = Figure(figsize=(6.4, 4.0))
        ax = fig.add_subplot(1, 1, 1)
        for s in self.series:
            style = "o-" if s.mode == "lines" else "o"
            ax.plot(s.x, s.y, style, label=s.name, ms=4, **({"color": s.color} if s.color else {}))
        ax.set_title(self.title)
        ax.set_xlabel(self.x_title)
        ax.set_ylabel(self.y_title)
        if self.x_log:
            ax.set_xscale("log")
        if self.y_log:
            ax.set_yscale("log")
        if self.series:
            ax.legend(fontsize=8)
        return fig


def _finite(v: float) -> float | None:
    f = float(v)
    return f if math.isfinite(f) else None
