"""Legible figures at 30+ solvers: one colour per solver for the whole report (a family
shares a hue), and the split of many series into panels of at most ``MAX_SERIES``.

* ``SolverStyles`` gives each solver a colour, a marker and a line dash.  Solvers of one
  family (the table's ``family`` column: paper, fast, qp, wrapper, reference, external,
  other, ...) share the family's hue and differ in lightness, marker and dash; the assignment depends
  only on the table, so the same solver looks the same in every figure of a report (and
  on the interactive page, which reads the same styles).
* ``family_panels`` splits a solver list into panels: one panel when it holds at most
  ``MAX_SERIES`` series, else one panel per family (a family larger than ``MAX_SERIES``
  in several), optionally preceded by an overview with the best solver of each family.
  ``panels_note`` words the caption: what each panel shows and where the rest is.

A registered section needs nothing of this beyond ``ctx.color(solver)`` and
``ctx.marker(solver)``; sections/generic.py and sections/paper.py use the panels.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass
from typing import Callable, Iterable, Mapping, Sequence

from .markdown_text import md_code

#: The most series one panel draws (more are not told apart by colour and legend).
MAX_SERIES = 10
#: Families in the order panels and legends list them; others follow alphabetically.
FAMILY_ORDER: tuple[str, ...] = ("paper", "fast", "qp", "wrapper", "reference", "external", "peer", "other")
#: Hue (0-1) and saturation of each known family: hue centres at least 0.1 apart, so that with
#: ``HUE_BAND`` no two families' bands meet (two solvers of different families at least 10 apart
#: in CIE L*a*b*, tests/harness/test_report_html.py).
FAMILY_HUES: dict[str, tuple[float, float]] = {
    "paper": (0.60, 0.75),      # blue
    "fast": (0.33, 0.70),       # green
    "qp": (0.78, 0.55),         # purple
    "wrapper": (0.08, 0.85),    # orange
    "reference": (0.0, 0.0),    # grey
    "external": (0.98, 0.75),   # red
    "peer": (0.47, 0.70),       # teal: the field's codes (solvers/_peers.py)
    "other": (0.88, 0.75),      # magenta: a solver registered from outside
}
#: Hues for families not listed above (olive, indigo, ...): between the known bands.
SPARE_HUES: tuple[float, ...] = (0.20, 0.69, 0.53, 0.40, 0.93, 0.14)
#: The share of the hue circle a family's members drift across ...
HUE_BAND = 0.10
#: ... while their lightness steps through these levels (neighbours differ in both).
LIGHTNESS_LEVELS: tuple[float, ...] = (0.22, 0.35, 0.48, 0.61, 0.72)
#: Markers cycled within a family (so two shades of one hue still differ in shape), each family
#: starting ``MARKER_STEP`` further along the cycle (so the first members of two families differ
#: in shape too, where their dark shades come close).
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "p", "h", "*")
MARKER_STEP = 5
#: Line dashes cycled within a family, for the figures that draw solvers as lines (a
#: period prime to the lightness levels': two lines of one panel differ in both).
DASHES: tuple[str, ...] = ("-", "--", "-.", ":")
#: The colour of the solvers a panel draws only as context.
GREY = (0.80, 0.80, 0.80)
#: The family label of a solver whose row names none.
DEFAULT_FAMILY = "other"


def family_rank(family: str) -> tuple:
    known = {f: i for i, f in enumerate(FAMILY_ORDER)}
    return (known.get(family, len(known)), family)


def sort_families(families: Iterable[str]) -> list[str]:
    return sorted(set(families), key=family_rank)


def _shades(hue: float, sat: float, k: int) -> list[tuple[float, float, float]]:
    """``k`` colours of one family's hue band: the hue drifts across ``HUE_BAND`` of the circle
    (so the family still reads as one, and apart from the others) and the lightness steps
    through ``LIGHTNESS_LEVELS``, so neighbours differ in both."""
    out = []
    for i in range(k):
        frac = i / (k - 1) if k > 1 else 0.5
        light = LIGHTNESS_LEVELS[i % len(LIGHTNESS_LEVELS)] if k > 1 else 0.4
        h = (hue + HUE_BAND * (frac - 0.5)) % 1.0
        out.append(colorsys.hls_to_rgb(h, light, sat))
    return out


@dataclass(frozen=True)
class SolverStyle:
    family: str
    color: tuple[float, float, float]
    marker: str
    dash: str = "-"


class SolverStyles:
    """Solver -> SolverStyle for one report.  ``solvers`` maps each solver label to its
    family (an empty family is ``DEFAULT_FAMILY``); labels are ordered by ``key``."""

    def __init__(self, solvers: Mapping[str, str], key: Callable[[str], tuple]) -> None:
        fam = {s: (f or DEFAULT_FAMILY) for s, f in solvers.items()}
        self.families = sort_families(fam.values())
        spare = iter(SPARE_HUES * 4)
        self.styles: dict[str, SolverStyle] = {}
        for k, f in enumerate(self.families):
            hue, sat = FAMILY_HUES.get(f) or (next(spare), 0.7)
            members = sorted((s for s in fam if fam[s] == f), key=key)
            for i, (s, c) in enumerate(zip(members, _shades(hue, sat, len(members)))):
                shape = MARKERS[(i + MARKER_STEP * k) % len(MARKERS)]
                self.styles[s] = SolverStyle(f, c, shape, DASHES[i % len(DASHES)])

    def family(self, solver: str) -> str:
        st = self.styles.get(solver)
        return st.family if st else DEFAULT_FAMILY

    def color(self, solver: str) -> tuple[float, float, float]:
        st = self.styles.get(solver)
        return st.color if st else (0.0, 0.0, 0.0)

    def marker(self, solver: str) -> str:
        st = self.styles.get(solver)
        return st.marker if st else "o"

    def dash(self, solver: str) -> str:
        st = self.styles.get(solver)
        return st.dash if st else "-"

    def hex(self, solver: str) -> str:
        r, g, b = self.color(solver)
        return f"#{round(255 * r):02x}{round(255 * g):02x}{round(255 * b):02x}"

    def members(self, family: str) -> list[str]:
        return [s for s, st in self.styles.items() if st.family == family]


@dataclass(frozen=True)
class Panel:
    """One panel of a split figure: ``solvers`` drawn in colour (at most MAX_SERIES);
    every other solver of the figure may be drawn in grey as context."""

    title: str
    solvers: tuple[str, ...]
    family: str = ""  # "" for the overview (best of each family) or a single all-solver panel


def family_panels(solvers: Sequence[str], family_of: Callable[[str], str], best: Mapping[str, str] | None = None,
                  max_series: int = MAX_SERIES) -> list[Panel]:
    """Split ``solvers`` (in drawing order) into panels of at most ``max_series``.

    At most ``max_series`` solvers: one panel with all of them.  More: when ``best``
    (family -> its best solver) is given, an overview panel with those first, then one
    panel per family (in FAMILY_ORDER), a family over ``max_series`` split in parts."""
    solvers = list(dict.fromkeys(solvers))
    if len(solvers) <= max_series:
        return [Panel("all solvers", tuple(solvers))]
    panels: list[Panel] = []
    if best:
        chosen = [best[f] for f in sort_families(best) if best[f] in solvers][:max_series]
        if chosen:
            panels.append(Panel("best of each family", tuple(chosen)))
    for f in sort_families(family_of(s) for s in solvers):
        members = [s for s in solvers if family_of(s) == f]
        parts = [members[i:i + max_series] for i in range(0, len(members), max_series)]
        for j, part in enumerate(parts):
            suffix = f" ({j + 1}/{len(parts)})" if len(parts) > 1 else ""
            panels.append(Panel(f"family {f}{suffix}", tuple(part), f))
    return panels


def panels_note(panels: Sequence[Panel], what: str = "solvers") -> str:
    """Caption text saying which panel holds what (empty for a single panel)."""
    if len(panels) <= 1:
        return ""
    total = len({s for p in panels if p.family for s in p.solvers})
    by_family = [f"{p.title.removeprefix('family ')} ({len(p.solvers)})" for p in panels if p.family]
    text = (f" {total} {what} do not fit one legible panel (at most {MAX_SERIES} series each), so the figure has "
            f"one panel per family: {', '.join(by_family)}; in each panel the other families are drawn in light "
            f"grey for context.")
    if not panels[0].family:
        text += (f" The first panel shows the best {what[:-1] if what.endswith('s') else what} of each family "
                 f"({', '.join(md_code(s) for s in panels[0].solvers)}).")
    return text
