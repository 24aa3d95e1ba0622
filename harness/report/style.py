"""Legible figures at 30+ solvers: one style (colour, marker, line dash) per solver, the same in
every report, and the split of many series into panels of at most ``MAX_SERIES``.

* ``SolverStyles`` gives each solver a colour, a marker and a line dash.  A family (the table's
  ``family`` column: paper, fast, qp, wrapper, reference, external, peer, other, ...) has a fixed
  palette (``family_palette``): ``PALETTE_SIZE`` colours of the family's hue band, in an order
  in which every prefix is spread as far apart as the band allows (CIEDE2000, ``delta_e00``),
  each colour at least ``GREY_APART`` from the context grey ``GREY`` and at least ``FAMILY_APART``
  from every colour of the known families before it.  A solver takes one *slot* of its family's
  palette: the project's own solvers a fixed slot (``FAMILY_SLOTS``, so that ``pk`` is the same
  blue in every report whatever else ran); a solver the project does not name takes the free
  slots in name order.  Slot ``i`` is colour ``i % PALETTE_SIZE``, marker ``i % len(MARKERS)``
  and dash ``(i + i // len(MARKERS)) % len(DASHES)``, so two slots of one family below
  ``PALETTE_SIZE`` never share both marker and dash, and a palette colour is chosen far from
  the colours of the slots that share its marker or its dash (``ALIKE_SLACK``).  The ``reference`` family is black and dark greys,
  dashed: always clear of the light grey context lines.
* Within one chart, any two series differ by at least ``COLOUR_APART`` (CIEDE2000) in colour or
  differ in marker or dash (tests/harness/test_series_distinct.py holds it for every chart of a
  fabricated report); two of the project's solvers closer than ``COLOUR_APART`` never share a
  marker, whatever their families (``FAMILY_MARKER_OFFSETS``), so that a chart of markers only
  holds it too.
* ``family_panels`` splits a solver list into panels: one panel when it holds at most
  ``MAX_SERIES`` series, else one panel per family (a family larger than ``MAX_SERIES``
  in several), optionally preceded by an overview with the best solver of each family.
  ``panels_note`` words the caption: what each panel shows and where the rest is.

A registered section needs nothing of this beyond ``ctx.color(solver)``, ``ctx.marker(solver)``
and ``ctx.dash(solver)``; sections/generic.py and sections/paper.py use the panels.
"""

from __future__ import annotations

import colorsys
import functools
import zlib
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from .markdown_text import md_code

#: The most series one panel draws (more are not told apart by colour and legend).
MAX_SERIES = 10
#: Families in the order panels and legends list them; others follow alphabetically.
FAMILY_ORDER: tuple[str, ...] = ("paper", "fast", "qp", "wrapper", "reference", "external", "peer", "other")
#: Hue (0-1) and saturation of each known family, hue centres at least 0.1 apart.  The
#: reference family has no hue: black and dark greys (``REFERENCE_LIGHTNESS``).
FAMILY_HUES: dict[str, tuple[float, float]] = {
    "paper": (0.60, 0.75),      # blue
    "fast": (0.33, 0.70),       # green
    "qp": (0.78, 0.55),         # purple
    "wrapper": (0.08, 0.85),    # orange
    "reference": (0.0, 0.0),    # black and dark grey
    "external": (0.98, 0.75),   # red
    "peer": (0.47, 0.70),       # teal: the field's codes (solvers/_peers.py)
    "other": (0.88, 0.75),      # magenta: a solver registered from outside
}
#: Hues for families not listed above (olive, indigo, ...): between the known bands; a family
#: takes the one its name hashes to (``family_hue``), whatever other families are present.
SPARE_HUES: tuple[float, ...] = (0.20, 0.69, 0.53, 0.40, 0.93, 0.14)
#: The share of the hue circle a family's palette lies in (centred on its hue), in ``HUE_STEPS`` steps ...
HUE_BAND = 0.12
HUE_STEPS = 9
#: ... at these lightness levels (HLS) ...
LIGHTNESS_LEVELS: tuple[float, ...] = tuple(round(0.26 + 0.025 * i, 3) for i in range(19))
#: ... and these shares of the family's saturation.
SATURATION_SHARES: tuple[float, ...] = (1.0, 0.8, 0.6, 0.4)
#: The lightness of a family's first colour (slot 0).
BASE_LIGHTNESS = 0.42
#: The reference family's palette: greys of these lightnesses (0 is black).
REFERENCE_LIGHTNESS: tuple[float, ...] = (0.0, 0.40, 0.20, 0.55)
#: Colours in a family's palette; a family with more members reuses them with other markers and dashes.
PALETTE_SIZE = 16
#: Two colours at least this far apart (CIEDE2000) are told apart by colour alone, even as thin
#: lines or small markers; two series of one chart closer than this differ in marker or dash.
COLOUR_APART = 15.0
#: Every palette colour lies at least this far (CIEDE2000) from the context grey ``GREY``.
GREY_APART = 20.0
#: A known family's colours lie at least this far (CIEDE2000) from every colour of the known
#: families before it in ``FAMILY_ORDER`` (where the band allows; else as far as it allows).
FAMILY_APART = 12.0
#: A palette colour is chosen for its distance from the colours of the slots that share its
#: marker or dash, and from all others less this slack (those differ in marker and dash).
ALIKE_SLACK = 10.0
#: Any two colours of a family's palette lie at least this far apart in CIE94 (``delta_e``),
#: where the band allows: colour alone tells two members apart in a figure drawn without markers.
FAMILY_FLOOR = 8.5
#: (Never closer than ``FAMILY_FLOOR + 1`` in CIE94, whatever the relaxation below.)  The
#: colours kept from are those of the slots the project's solvers hold (``FAMILY_SLOTS``), or the
#: first ``OUTSIDE_SLOTS`` of a family of outside solvers.
OUTSIDE_SLOTS = 4
#: ``FAMILY_APART`` is relaxed (one step at a time) until the band keeps this many candidates
#: per palette colour: a band crowded by its neighbours still spreads its own colours.
CANDIDATE_ROOM = 12
#: Every palette colour has at least this contrast ratio (WCAG 2: (L1 + 0.05) / (L2 + 0.05) of the
#: relative luminances) against the white page and figure: a pale yellow line (1.3:1) could not be seen.
MIN_CONTRAST = 2.0
#: Two palette neighbours (slots i and i + 1) differ at least this much in HLS lightness.
NEIGHBOUR_LIGHTNESS = 0.06
#: Markers, taken by slot (the page draws each: html.py ``SOLVER_SYMBOLS``); each known family
#: starts ``FAMILY_MARKER_OFFSETS`` along, a family of its own, so that the first members of two
#: families differ in shape too.
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "p", "h", "*")
#: Where each known family's markers start along ``MARKERS``: chosen so that no two solvers of the
#: project (``FAMILY_SLOTS``, the registry) nor the first outside solvers of a family share a
#: marker unless their colours lie at least ``COLOUR_APART`` (+3) apart -- a chart drawn with
#: markers only (run time against error) tells them apart by colour or shape, whatever families
#: it mixes.  (A step of 5 per family put ``nnls`` and ``qp-proxqp`` on one triangle 12.8 apart.)
FAMILY_MARKER_OFFSETS: dict[str, int] = {"paper": 0, "fast": 10, "qp": 7, "wrapper": 3, "reference": 8,
                                         "external": 2, "peer": 1, "other": 4}
#: A family not in ``FAMILY_MARKER_OFFSETS`` starts this many markers along per its name's hash.
MARKER_STEP = 5
#: Line dashes, taken by slot (the reference family one further: its first member dashed).
DASHES: tuple[str, ...] = ("-", "--", "-.", ":")
#: The colour of the solvers a panel draws only as context.
GREY = (0.80, 0.80, 0.80)
#: The family label of a solver whose row names none.
DEFAULT_FAMILY = "other"
#: The fixed slots of the project's own solvers (solvers/registry.py), per family: a solver's
#: slot is its index here.  The solvers that figures draw side by side by colour alone come
#: first (every prefix of a palette is spread as far apart as it allows): the greedy variants of
#: Fig. 5, the solvers of the counterexample's bars and of the closed-form checks.
FAMILY_SLOTS: dict[str, tuple[str, ...]] = {
    "paper": ("pk", "greedy-cg", "nnls", "greedy-gs", "gp", "greedy-chol", "nnls-gp", "admm", "pk-printed"),
    "fast": ("fast-ccg", "fast-dual-pccg", "fast-pdas", "fast-pccg", "fast-dual-ccg"),
    "qp": ("cvxpy", "qp-clarabel", "qp-osqp", "qp-piqp", "qp-proxqp", "qp-highs", "qp-daqp", "qp-quadprog",
           "qp-clarabel+polish", "qp-scs", "qp-ecos", "qp-piqp+polish", "qp-cvxopt", "qp-qpalm"),
    "wrapper": ("cmr+pk", "cmr+nnls", "cmr+fast-ccg", "cmr+nnls-gp", "cmr+fast-dual-pccg", "cmr+scipy-nnls"),
    "reference": ("scipy-nnls", "bvls"),
    "peer": ("tamaas-pkr", "cm-pk-ccg", "aspher-nested", "tamaas-kato", "aspher-pcg", "cm-dual-ccg",
             "tamaas-condat", "aspher-active-f32", "tamaas-beck-teboulle", "aspher-nested-f32",
             "tamaas-kato-saturated"),
}


def family_rank(family: str) -> tuple:
    """The sort key of a family: ``FAMILY_ORDER`` first, the others alphabetically after."""
    known = {f: i for i, f in enumerate(FAMILY_ORDER)}
    return (known.get(family, len(known)), family)


def sort_families(families: Iterable[str]) -> list[str]:
    """The distinct ``families`` in ``family_rank`` order."""
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
    that it is symmetric; about 1 is a just noticeable difference."""
    a, b = np.asarray(lab, dtype=float), np.asarray(ref, dtype=float)
    c1, c2 = np.hypot(a[..., 1], a[..., 2]), np.hypot(b[..., 1], b[..., 2])
    d_chroma = c1 - c2
    d_hue_sq = np.maximum((a[..., 1] - b[..., 1]) ** 2 + (a[..., 2] - b[..., 2]) ** 2 - d_chroma ** 2, 0.0)
    c = np.sqrt(c1 * c2)
    return np.sqrt((a[..., 0] - b[..., 0]) ** 2 + (d_chroma / (1 + 0.045 * c)) ** 2 + d_hue_sq / (1 + 0.015 * c) ** 2)


def delta_e00(lab: Any, ref: Any) -> np.ndarray:
    """The CIEDE2000 colour difference of the L*a*b* colours ``lab`` (last axis) from ``ref``
    (broadcast; symmetric); about 1 is a just noticeable difference.  It corrects CIE94 in
    the blues, where saturated dark colours of near hues look more alike than CIE94 says."""
    l1, a1, b1 = np.moveaxis(np.asarray(lab, dtype=float), -1, 0)
    l2, a2, b2 = np.moveaxis(np.asarray(ref, dtype=float), -1, 0)
    c_mean = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(c_mean ** 7 / (c_mean ** 7 + 25.0 ** 7)))
    a1, a2 = (1 + g) * a1, (1 + g) * a2
    c1, c2 = np.hypot(a1, b1), np.hypot(a2, b2)
    h1, h2 = np.degrees(np.arctan2(b1, a1)) % 360, np.degrees(np.arctan2(b2, a2)) % 360
    grey = c1 * c2 == 0
    dh = (h2 - h1 + 180) % 360 - 180
    dh = np.where(grey, 0.0, dh)
    d_big_h = 2 * np.sqrt(c1 * c2) * np.sin(np.radians(dh / 2))
    l_mean, c_mean = (l1 + l2) / 2, (c1 + c2) / 2
    h_sum = h1 + h2
    h_mean = np.where(grey, h_sum, np.where(np.abs(h1 - h2) <= 180, h_sum / 2,
                                            np.where(h_sum < 360, (h_sum + 360) / 2, (h_sum - 360) / 2)))
    t = (1 - 0.17 * np.cos(np.radians(h_mean - 30)) + 0.24 * np.cos(np.radians(2 * h_mean))
         + 0.32 * np.cos(np.radians(3 * h_mean + 6)) - 0.20 * np.cos(np.radians(4 * h_mean - 63)))
    rot = -np.sin(np.radians(60 * np.exp(-(((h_mean - 275) / 25) ** 2)))) * 2 * np.sqrt(
        c_mean ** 7 / (c_mean ** 7 + 25.0 ** 7))
    s_l = 1 + 0.015 * (l_mean - 50) ** 2 / np.sqrt(20 + (l_mean - 50) ** 2)
    s_c, s_h = 1 + 0.045 * c_mean, 1 + 0.015 * c_mean * t
    dl, dc, dhh = (l2 - l1) / s_l, (c2 - c1) / s_c, d_big_h / s_h
    return np.sqrt(np.maximum(dl ** 2 + dc ** 2 + dhh ** 2 + rot * dc * dhh, 0.0))


def contrast_on_white(rgb: Any) -> np.ndarray:
    """The WCAG 2 contrast ratio of sRGB colour(s) ``rgb`` (in [0, 1]; shape (3,) or (k, 3))
    against white: 1.05 / (relative luminance + 0.05), from 1 (white) to 21 (black)."""
    c = np.asarray(rgb, dtype=float)
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return 1.05 / (lin @ np.array([0.2126, 0.7152, 0.0722]) + 0.05)


def family_hue(family: str) -> tuple[float, float]:
    """(hue, saturation) of ``family``: ``FAMILY_HUES``, else the spare hue its name hashes to."""
    if family in FAMILY_HUES:
        return FAMILY_HUES[family]
    return SPARE_HUES[zlib.crc32(family.encode()) % len(SPARE_HUES)], 0.7


def _candidates(hue: float, sat: float) -> list[tuple[float, float, float]]:
    """The distinct colours of a family's band: ``HUE_STEPS`` hues across ``HUE_BAND`` around
    ``hue``, each at every level of ``LIGHTNESS_LEVELS`` and ``SATURATION_SHARES`` of ``sat``."""
    hues = [(hue + HUE_BAND * (j / (HUE_STEPS - 1) - 0.5)) % 1.0 for j in range(HUE_STEPS)]
    out = [colorsys.hls_to_rgb(h, light, sat * share)
           for h in hues for light in LIGHTNESS_LEVELS for share in SATURATION_SHARES]
    return list(dict.fromkeys(out))


def _slot_marks(slot: int) -> set[tuple[str, str]]:
    """The marks slot ``slot`` shares with another slot of its family: its marker and its dash
    (``slot_style``); two slots that share one are told apart by colour in the figures that
    draw the other mark alike (a scatter: no dash; a line without markers)."""
    return {("marker", _slot_marker(slot, 0)), ("dash", _slot_dash(slot, False))}


def _slot_marker(slot: int, offset: int) -> str:
    """The marker of slot ``slot`` of a family whose markers start ``offset`` along ``MARKERS``
    (each round of ``MARKERS`` shifted by half of it: slot 12 takes slot 6's marker, whose
    colour the palette keeps far from slot 12's)."""
    return MARKERS[(slot + offset + slot // len(MARKERS) * (len(MARKERS) // 2)) % len(MARKERS)]


def _slot_dash(slot: int, reference: bool) -> str:
    """The dash of slot ``slot`` (one further in the reference family, and one further for each
    round of ``MARKERS``, so that two slots of one marker differ in dash)."""
    return DASHES[(slot + slot // len(MARKERS) + reference) % len(DASHES)]


@functools.lru_cache(maxsize=None)
def family_palette(family: str) -> tuple[tuple[float, float, float], ...]:
    """The ``PALETTE_SIZE`` colours of ``family``'s slots, fixed whatever the table holds.

    The first is the family's hue at ``BASE_LIGHTNESS``; each next one the candidate of the
    band (``_candidates``) farthest (``delta_e00``) from those chosen, among those of at least
    ``MIN_CONTRAST`` against white, at least ``GREY_APART`` from ``GREY``,
    ``FAMILY_APART`` from the palettes of the known families
    before it (relaxed step by step: ``CANDIDATE_ROOM``) and ``NEIGHBOUR_LIGHTNESS``
    lighter or darker than the one before it.  So every prefix is spread as far as the band
    allows, and two neighbours differ in lightness.  The reference family: black and greys."""
    if family == "reference":
        return tuple((v, v, v) for v in REFERENCE_LIGHTNESS)
    hue, sat = family_hue(family)
    cands = _candidates(hue, sat)
    lab = cielab(cands)
    light = np.array([colorsys.rgb_to_hls(*c)[1] for c in cands])
    known = FAMILY_ORDER[:FAMILY_ORDER.index(family)] if family in FAMILY_ORDER else FAMILY_ORDER
    before = [f for f in known if f != "reference"]
    others = cielab([c for f in before for c in family_palette(f)[:len(FAMILY_SLOTS.get(f, ())) or OUTSIDE_SLOTS]]
                    ) if before else np.empty((0, 3))
    apart = np.min(delta_e00(lab[:, None, :], others[None, :, :]), axis=1) if len(others) else np.full(len(cands), np.inf)
    apart94 = np.min(delta_e(lab[:, None, :], others[None, :, :]), axis=1) if len(others) else np.full(len(cands), np.inf)
    ok = ((delta_e00(lab, cielab(GREY)) >= GREY_APART) & (apart94 >= FAMILY_FLOOR + 1.0)
          & (contrast_on_white(cands) >= MIN_CONTRAST))
    need = FAMILY_APART
    while not (ok & (apart >= need)).sum() >= CANDIDATE_ROOM * PALETTE_SIZE and need > 0:
        need -= 1.0
    strict = ok & (apart >= need)
    start = cielab(colorsys.hls_to_rgb(hue, BASE_LIGHTNESS, sat))
    picks = [int(np.argmin(np.where(strict, delta_e00(lab, start), np.inf)))]
    while len(picks) < PALETTE_SIZE:
        slot = len(picks)
        dist = [delta_e00(lab, lab[i]) for i in picks]
        near = np.min(dist, axis=0)
        alike = [d for j, d in enumerate(dist) if _slot_marks(j) & _slot_marks(slot)]
        score = np.minimum(near + ALIKE_SLACK, np.min(alike, axis=0)) if alike else near
        floor = np.min([delta_e(lab, lab[i]) for i in picks], axis=0) >= FAMILY_FLOOR
        steps = np.abs(light - light[picks[-1]]) >= NEIGHBOUR_LIGHTNESS
        fresh = ok & (near > 0)  # (never a colour chosen already)
        # the first set that holds a candidate: the floor and the other families' distance first
        for mask in (floor & strict & steps, floor & strict, floor & fresh & steps, floor & fresh,
                     strict & steps & fresh, strict & fresh, fresh):
            if mask.any():
                break
        picks.append(int(np.argmax(np.where(mask, score, -np.inf))))
    return tuple(cands[i] for i in picks)


@dataclass(frozen=True)
class SolverStyle:
    """How one solver is drawn: its family, colour (sRGB in [0, 1]), marker and line dash
    (matplotlib codes)."""

    family: str
    color: tuple[float, float, float]
    marker: str
    dash: str = "-"


def slot_style(family: str, slot: int) -> SolverStyle:
    """The style of slot ``slot`` of ``family`` (module doc): colour ``slot % PALETTE_SIZE`` of
    ``family_palette``, marker and dash by slot (the family's marker offset: ``FAMILY_MARKER_OFFSETS``,
    else by its name's hash)."""
    palette = family_palette(family)
    offset = FAMILY_MARKER_OFFSETS.get(family, MARKER_STEP * zlib.crc32(family.encode()))
    return SolverStyle(family, palette[slot % len(palette)], _slot_marker(slot, offset),
                       _slot_dash(slot, family == "reference"))


class SolverStyles:
    """Solver -> SolverStyle for one report.  ``solvers`` maps each solver label to its
    family (an empty family is ``DEFAULT_FAMILY``).  A solver of ``FAMILY_SLOTS`` takes its
    fixed slot (the same style in every report); the others of a family take the slots left
    free, in the order of ``key``."""

    def __init__(self, solvers: Mapping[str, str], key: Callable[[str], tuple]) -> None:
        fam = {s: (f or DEFAULT_FAMILY) for s, f in solvers.items()}
        self.families = sort_families(fam.values())
        self.styles: dict[str, SolverStyle] = {}
        for f in self.families:
            fixed = FAMILY_SLOTS.get(f, ())
            members = sorted((s for s in fam if fam[s] == f), key=key)
            free = (i for i in range(len(fixed) + len(members)) if i >= len(fixed) or fixed[i] not in members)
            for s in members:
                self.styles[s] = slot_style(f, fixed.index(s) if s in fixed else next(free))

    def family(self, solver: str) -> str:
        """The family of ``solver`` (``DEFAULT_FAMILY`` for one not in the table)."""
        st = self.styles.get(solver)
        return st.family if st else DEFAULT_FAMILY

    def color(self, solver: str) -> tuple[float, float, float]:
        """The colour of ``solver`` (black for one not in the table)."""
        st = self.styles.get(solver)
        return st.color if st else (0.0, 0.0, 0.0)

    def marker(self, solver: str) -> str:
        """The marker of ``solver`` ("o" for one not in the table)."""
        st = self.styles.get(solver)
        return st.marker if st else "o"

    def dash(self, solver: str) -> str:
        """The line dash of ``solver`` ("-" for one not in the table)."""
        st = self.styles.get(solver)
        return st.dash if st else "-"

    def hex(self, solver: str) -> str:
        """The colour of ``solver`` as "#rrggbb"."""
        return to_hex(self.color(solver))

    def members(self, family: str) -> list[str]:
        """The solvers of ``family``, in the order styled."""
        return [s for s, st in self.styles.items() if st.family == family]


def to_hex(rgb: Sequence[float]) -> str:
    """An sRGB colour (components in [0, 1]) as "#rrggbb"."""
    r, g, b = rgb
    return f"#{round(255 * r):02x}{round(255 * g):02x}{round(255 * b):02x}"


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
    (family -> its best solver) is given and ``solvers`` hold two families or more, an
    overview panel with those first, then one
    panel per family (in FAMILY_ORDER), a family over ``max_series`` split in parts."""
    solvers = list(dict.fromkeys(solvers))
    if len(solvers) <= max_series:
        return [Panel("all solvers", tuple(solvers))]
    panels: list[Panel] = []
    if best and len({family_of(s) for s in solvers}) > 1:  # of one family, its best panel is one solver again
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


#: A colour rule of a scene's own: the scene's rows -> {solver: colour} (``register_scene_colors``).
SceneColorRule = Callable[[Any], dict[str, str]]
#: Scenes whose section colours their solvers itself, in every figure of the scene -- the
#: PNGs of every section and the page alike (a sweep of one method's parameter, drawn dark to
#: light along it, where the family's shades would hide the order).
SCENE_COLORS: dict[str, SceneColorRule] = {}


def register_scene_colors(scene: str) -> Callable[[SceneColorRule], SceneColorRule]:
    """Register the decorated function as ``scene``'s colour rule (in the module of the
    scene's own section: a scene is one place)."""
    def put(rule: SceneColorRule) -> SceneColorRule:
        SCENE_COLORS[scene] = rule
        return rule
    return put


def scene_colors(table: Any, scene: str) -> dict[str, str]:
    """The colours ``scene``'s rule gives its solvers from its rows of ``table`` (a results
    table); {} for a scene without a rule, or with no rows."""
    rule = SCENE_COLORS.get(scene)
    rows = table[table["scene"] == scene] if rule is not None else None
    return rule(rows) if rows is not None and len(rows) else {}
