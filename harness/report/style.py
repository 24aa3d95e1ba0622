"""Legible figures at 30+ solvers: one colour per solver for the whole report (a family
shares a hue), and the split of many series into panels of at most ``MAX_SERIES``.

* ``SolverStyles`` gives each solver a colour, a marker and a line dash.  Solvers of one
  family (the table's ``family`` column: paper, fast, qp, wrapper, reference, external,
  other, ...) share the family's hue band and differ in colour, marker and dash: a family's
  colours are chosen from its band (``HUE_BAND`` x ``LIGHTNESS_LEVELS`` x
  ``SATURATION_SHARES``) as far apart (``delta_e``: CIE94 in CIE L*a*b*) as the band allows,
  from each other and from the colours of the families before it (``_spread``).  The assignment
  depends only on the table, so the same solver looks the same in every figure of a report
  (and on the interactive page, which reads the same styles).
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
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .markdown_text import md_code

#: The most series one panel draws (more are not told apart by colour and legend).
MAX_SERIES = 10
#: Families in the order panels and legends list them; others follow alphabetically.
FAMILY_ORDER: tuple[str, ...] = ("paper", "fast", "qp", "wrapper", "reference", "external", "peer", "other")
#: Hue (0-1) and saturation of each known family: hue centres at least 0.1 apart (``HUE_BAND``
#: wide bands, whose colours keep away from the families' before: ``_spread``), so that two
#: solvers of different families are at least 10 apart in CIE L*a*b* (tests/harness/test_report_html.py).
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
#: The share of the hue circle a family's colours lie in (centred on its hue), in ``HUE_STEPS`` steps ...
HUE_BAND = 0.10
HUE_STEPS = 7
#: ... at these lightness levels (HLS; neighbours in a family differ in lightness) ...
LIGHTNESS_LEVELS: tuple[float, ...] = (0.30, 0.34, 0.38, 0.42, 0.46, 0.50, 0.54, 0.58, 0.62, 0.66, 0.70, 0.74)
#: ... and these shares of the family's saturation.
SATURATION_SHARES: tuple[float, ...] = (1.0, 0.75, 0.5)
#: The lightness of a family's first colour (the colour of a family of one; one of the levels).
BASE_LIGHTNESS = 0.42
#: Markers cycled within a family (so two shades of one hue still differ in shape), each family
#: starting ``MARKER_STEP`` further along the cycle (so the first members of two families differ
#: in shape too, where their dark shades come close).
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "p", "h", "*")
MARKER_STEP = 5
#: Line dashes cycled within a family, for the figures that draw solvers as lines (two
#: neighbours in a family differ in dash and in lightness).
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


#: sRGB (linear) to CIE XYZ, and the D65 white point, for ``cielab``.
_SRGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375], [0.2126729, 0.7151522, 0.0721750],
                         [0.0193339, 0.1191920, 0.9503041]])
_WHITE_D65 = np.array([0.95047, 1.0, 1.08883])


def cielab(rgb: Any) -> np.ndarray:
    """CIE L*a*b* (D65) of sRGB colours, components in [0, 1] along the last axis; the
    Euclidean distance of two is their colour difference (CIE76 delta E: about 2 is one
    colour to the eye)."""
    c = np.asarray(rgb, dtype=float)
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = linear @ _SRGB_TO_XYZ.T / _WHITE_D65
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e(lab: Any, ref: Any) -> np.ndarray:
    """The CIE94 colour difference (graphic arts weights) of the L*a*b* colours ``lab`` (last
    axis) from ``ref``, with the geometric mean of the two chromas as the weighting chroma so
    that it is symmetric.  It weighs differences of chroma and hue down where the chroma is
    high, where the Euclidean distance overstates them (two saturated dark blues look alike
    more than their distance says); about 1 is a just noticeable difference."""
    a, b = np.asarray(lab, dtype=float), np.asarray(ref, dtype=float)
    c1, c2 = np.hypot(a[..., 1], a[..., 2]), np.hypot(b[..., 1], b[..., 2])
    d_chroma = c1 - c2
    d_hue_sq = np.maximum((a[..., 1] - b[..., 1]) ** 2 + (a[..., 2] - b[..., 2]) ** 2 - d_chroma ** 2, 0.0)
    c = np.sqrt(c1 * c2)
    return np.sqrt((a[..., 0] - b[..., 0]) ** 2 + (d_chroma / (1 + 0.045 * c)) ** 2 + d_hue_sq / (1 + 0.015 * c) ** 2)


def _candidates(hue: float, sat: float) -> list[tuple[float, float, float]]:
    """The distinct colours of a family's band: ``HUE_STEPS`` hues across ``HUE_BAND`` around
    ``hue``, each at every level of ``LIGHTNESS_LEVELS`` and ``SATURATION_SHARES`` of ``sat``."""
    hues = [(hue + HUE_BAND * (j / (HUE_STEPS - 1) - 0.5)) % 1.0 for j in range(HUE_STEPS)]
    out = [colorsys.hls_to_rgb(h, light, sat * share)
           for h in hues for light in LIGHTNESS_LEVELS for share in SATURATION_SHARES]
    return list(dict.fromkeys(out))


def _spread(hue: float, sat: float, k: int, taken: np.ndarray) -> list[tuple[float, float, float]]:
    """``k`` colours of a family's band (``_candidates``): the first at ``BASE_LIGHTNESS`` on the
    family's hue at full saturation, then each the one farthest (``delta_e``) from those
    chosen and from ``taken`` (the L*a*b* of the families before it; farthest-point choice,
    ties to the first); ordered by lightness, darkest and lightest taking turns
    (``_alternate``), so that neighbours differ in lightness.  A family of more than its
    band's colours repeats some."""
    if k == 0:
        return []
    cands = _candidates(hue, sat)
    lab = cielab(cands)
    picks = [int(np.argmin(delta_e(lab, cielab(colorsys.hls_to_rgb(hue, BASE_LIGHTNESS, sat)))))]
    near = np.full(len(cands), np.inf)
    for other in [*taken, lab[picks[0]]]:
        near = np.minimum(near, delta_e(lab, other))
    while len(picks) < k:
        picks.append(int(np.argmax(near)))
        near = np.minimum(near, delta_e(lab, lab[picks[-1]]))
    chosen = sorted((cands[i] for i in picks), key=lambda c: colorsys.rgb_to_hls(*c)[1])
    return [chosen[i] for i in _alternate(k)]


def _alternate(k: int) -> list[int]:
    """0, h, 1, h + 1, ... (h = ceil(k / 2)): each index of ``range(k)`` once, two neighbours
    about k / 2 apart."""
    h = (k + 1) // 2
    return [i for j in range(h) for i in (j, j + h) if i < k]


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
        taken = np.empty((0, 3))
        for k, f in enumerate(self.families):
            hue, sat = FAMILY_HUES.get(f) or (next(spare), 0.7)
            members = sorted((s for s in fam if fam[s] == f), key=key)
            colours = _spread(hue, sat, len(members), taken)
            taken = np.vstack([taken, cielab(colours).reshape(-1, 3)])
            for i, (s, c) in enumerate(zip(members, colours)):
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
