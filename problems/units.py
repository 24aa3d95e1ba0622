"""The plausibility check of a measured height map's units.

The boundary element model of this package (a rigid surface on an elastic half-space,
influence coefficients of Love / BCC) holds for *small slopes*: the surface must be
nearly flat on the scale of its own lateral size.  A height map whose numbers are in
micrometres but read as metres, with a side length of 100 um, has an rms slope of about
10^4; every solver then "solves" a problem that describes nothing physical.  The other
way round, a map whose heights are read 10^3 or 10^6 too small (metres read as
micrometres), or whose side length is given 10^3 or 10^6 too large (``--length`` in
micrometres as metres), has an rms slope far below that of any measured surface at its
sampling.

``unit_figures`` computes what the check reads (rms slope by forward differences,
``Surface.rms_slope``; the height range z_max - z_min against the shorter side length,
min(N0 d0, N1 d1)); ``check_plausible_units`` refuses a surface outside the plausible
range -- rms slope > ``MAX_RMS_SLOPE``, a height range larger than the side length, or an
rms slope < ``MIN_RMS_SLOPE`` -- with one line that says what was found and what was
probably meant: a height unit (``probable_unit``) that makes the map's *bulk* plausible
(``bulk_figures``: the figures with its ``OUTLIER_SHARE`` of points farthest from the median
height left out), else the side length.  Where the whole and the bulk disagree -- the bulk
plausible and the whole not (``outlier_account``), or the bulk too smooth and the whole not
(``smooth_bulk_account``) -- a few outliers alone decide, so it names them (how many, the
largest) and suggests no unit (a spike read in another unit would shrink the whole map with
it); the whole map is also refused then, plausible or not.  Scenes call it
when they validate a measured (``--surface``) file, so ``contactbench run`` stops with
exit 2 before anything runs; ``--height-unit m|mm|um|nm`` converts the heights of a file
that states no unit, and ``--allow-steep`` skips the check (either bound) for those who
mean it.

The composite modulus: ``PLAUSIBLE_MODULUS`` (Pa) is the range outside which an E* is almost
always a unit slip (MPa or GPa given as Pa); the ``--E`` option record
(``problems.scenes.options``) checks it unless ``--allow-any-E`` is given.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import ProblemInputError
from .surfaces import Surface

#: Height units a unit-less file may be read in: name -> metres per unit (also what
#: ``problems.io.load_surface(height_unit=...)`` accepts).
HEIGHT_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}
UNIT_NAMES: dict[str, str] = {"m": "metres", "mm": "millimetres", "um": "micrometres", "nm": "nanometres"}
#: The small-slope range: rms slope at most this, and a height range at most the side length.
MAX_RMS_SLOPE = 1.0
#: The smoothest plausible map: an rms slope below this (at the map's own sampling) is a
#: thousand times below that of ground, turned or polished surfaces measured at the usual
#: samplings (1e-2 to 1), what a height unit or a side length off by 1e3 or 1e6 gives.
MIN_RMS_SLOPE = 1e-5
#: The composite modulus E* = E / (1 - nu^2) a run takes as plausible, Pa: from soft gels
#: and elastomers (~1e3 Pa) to beyond diamond (E* ~ 1.2e12 Pa).  Outside it the value is
#: almost surely in the wrong unit (and far outside it the influence coefficients under-
#: or overflow).
PLAUSIBLE_MODULUS: tuple[float, float] = (1e3, 1e13)
#: The share of a map's points, those farthest from its median height (at least one), that
#: its *bulk* leaves out (``bulk_figures``): units are judged on the bulk, and where the bulk
#: and the whole map disagree the outliers are named and no unit is suggested.
OUTLIER_SHARE = 1e-2


@dataclass(frozen=True)
class UnitFigures:
    """What the unit check reads of a surface (all lengths in metres as loaded)."""

    rms_slope: float
    height_range: float
    side_length: float

    def scaled(self, factor: float) -> UnitFigures:
        """The figures if every height were multiplied by ``factor``."""
        return UnitFigures(self.rms_slope * factor, self.height_range * factor, self.side_length)

    @property
    def too_steep(self) -> bool:
        return self.rms_slope > MAX_RMS_SLOPE

    @property
    def too_tall(self) -> bool:
        return self.height_range > self.side_length

    @property
    def too_smooth(self) -> bool:
        return self.rms_slope < MIN_RMS_SLOPE

    @property
    def plausible(self) -> bool:
        return not (self.too_steep or self.too_tall or self.too_smooth)


class ImplausibleUnitsError(ProblemInputError):
    """A surface outside the plausible range (module doc); the message names the figures
    and the unit or the length that was probably meant."""

    def __init__(self, message: str, figures: UnitFigures, suggestion: str | None) -> None:
        self.figures = figures
        self.suggestion = suggestion
        super().__init__(message)


def unit_figures(surface: Surface) -> UnitFigures:
    """rms slope, height range and side length of ``surface``."""
    h = surface.heights
    return UnitFigures(surface.rms_slope(), float(h.max() - h.min()), float(min(surface.lengths)))


def probable_unit(figures: UnitFigures, height_unit: str = "m") -> str | None:
    """The largest height unit, other than ``height_unit``, in which the file's numbers
    would give a plausible surface (None when none does: the side length is the
    likelier mistake).  For a surface too steep only a smaller unit can help, so this is
    the largest smaller one that does; for one too smooth, the largest larger one (the
    closest to the steep bound, where measured surfaces lie)."""
    given = HEIGHT_UNITS[height_unit]
    for unit, metres in sorted(HEIGHT_UNITS.items(), key=lambda kv: -kv[1]):
        if unit != height_unit and figures.scaled(metres / given).plausible:
            return unit
    return None


def implausibility(figures: UnitFigures, height_unit: str | None, outliers: str | None = None,
                   bulk: UnitFigures | None = None) -> str:
    """The one-line account of an implausible surface (``height_unit`` None: the file
    stated its own unit, so only the file or --length can be wrong; ``outliers``: the
    account of ``outlier_account``, which then replaces any advice on units; ``bulk``: the
    figures the unit advice is judged on, ``figures`` when None)."""
    found = []
    if figures.too_steep:
        found.append(f"rms slope {figures.rms_slope:.2g} "
                     f"(the half-space model needs small slopes, <= {MAX_RMS_SLOPE:g})")
    if figures.too_tall:
        found.append(f"height range {figures.height_range:.3g} m exceeds the side length {figures.side_length:.3g} m")
    if figures.too_smooth:
        found.append(f"rms slope {figures.rms_slope:.2g} (below {MIN_RMS_SLOPE:g}, smoother than any measured "
                     "surface: a height unit or a side length off by 1e3 or 1e6?)")
    text = "; ".join(found)
    if outliers is not None:
        return f"{text}: {outliers}"
    if height_unit is None:
        return (f"{text}: the heights or the lateral size stated by the file look wrong; check the file's units "
                "and --length, or pass --allow-steep to run it anyway")
    unit = probable_unit(figures if bulk is None else bulk, height_unit)
    if unit is None:
        return (f"{text}: no height unit makes this plausible, so the side length is the likelier mistake; check "
                f"--length (metres, the side of the map), or pass --allow-steep to run it anyway")
    return (f"{text}: heights look like {UNIT_NAMES[unit]} given as {UNIT_NAMES[height_unit]}; pass "
            f"--height-unit {unit} (or --allow-steep to run it anyway)")


def farthest_points(surface: Surface) -> tuple[np.ndarray, float, int]:
    """The flat indices of the ceil(``OUTLIER_SHARE`` n) points farthest from the median
    height (|h - median|, at least one, at most n - 1), farthest first; the median; their count."""
    h = surface.heights
    med = float(np.median(h))
    dev = np.abs(h - med).ravel()
    k = min(max(1, math.ceil(OUTLIER_SHARE * dev.size)), dev.size - 1)
    top = np.argpartition(dev, dev.size - k)[dev.size - k:]
    return top[np.argsort(dev[top])[::-1]], med, k


def figures_without(surface: Surface, out: np.ndarray) -> UnitFigures:
    """``unit_figures`` of ``surface`` with the points of flat indices ``out`` left out:
    the height range of the rest, and the rms slope over the forward differences (the pairs
    ``Surface.rms_slope`` takes, periodic wrap included) whose two points are both kept --
    so a left-out spike leaves no cliff behind.  With no pair left, the whole map's slope."""
    h = surface.heights
    keep = np.ones(h.shape, dtype=bool)
    keep.ravel()[out] = False
    d0, d1 = surface.spacing
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        if surface.periodic:
            gx, kx = (np.roll(h, -1, 0) - h) / d0, keep & np.roll(keep, -1, 0)
            gy, ky = (np.roll(h, -1, 1) - h) / d1, keep & np.roll(keep, -1, 1)
        else:
            gx, kx = np.diff(h, axis=0)[:, :-1] / d0, keep[:-1, :-1] & keep[1:, :-1]
            gy, ky = np.diff(h, axis=1)[:-1, :] / d1, keep[:-1, :-1] & keep[:-1, 1:]
        slope = (float(np.sqrt(np.mean(gx[kx] ** 2) + np.mean(gy[ky] ** 2))) if kx.any() and ky.any()
                 else surface.rms_slope())
    rest = h[keep]
    return UnitFigures(slope, float(rest.max() - rest.min()), float(min(surface.lengths)))


def bulk_figures(surface: Surface) -> UnitFigures:
    """The figures of the map's bulk: ``figures_without`` its ceil(``OUTLIER_SHARE`` n) points
    farthest from the median height.  Units are judged on these: a few outliers can make the
    whole map look steep (a spike) or rough (on a map too smooth to be measured)."""
    return figures_without(surface, farthest_points(surface)[0])


def _fewest(surface: Surface, top: np.ndarray, k: int, test: Callable[[UnitFigures], bool]) -> tuple[int, UnitFigures]:
    """The fewest m <= k of ``top`` (farthest first) that, left out, make ``test`` hold
    (``test`` fails on the whole map and holds with k left out; a bisection over m), and the
    figures without them."""
    lo, hi = 0, k
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if test(figures_without(surface, top[:mid])):
            hi = mid
        else:
            lo = mid
    return hi, figures_without(surface, top[:hi])


def _named(surface: Surface, top: np.ndarray, med: float, m: int, verb: str = "") -> str:
    """"m outlier point(s)<verb> (the farthest from the median height: z m at index (i, j),
    the median being ...)"; ``verb`` is given in the plural and put in the singular for m = 1
    ("make" -> "makes")."""
    h = surface.heights
    idx = tuple(int(i) for i in np.unravel_index(int(top[0]), h.shape))
    many = f"{m} outlier points{verb}" if m > 1 else f"1 outlier point{verb.replace(' make ', ' makes ', 1)}"
    return (f"{many} (the farthest from the median height: {float(h.ravel()[top[0]]):.3g} m at index {idx}, "
            f"the median being {med:.3g} m)")


def outlier_account(surface: Surface) -> str | None:
    """The one-line account of an implausible surface that a few outliers alone make so,
    else None: when its bulk (``bulk_figures``) is plausible, the fewest m of the points
    farthest from the median height that must be left out (a bisection over m), the largest
    (its height in metres and its grid index) and the figures without them.  No height unit
    is suggested: another unit scales every height, the outliers' and the rest's alike."""
    top, med, k = farthest_points(surface)
    if not figures_without(surface, top).plausible:
        return None
    m, rest = _fewest(surface, top, k, lambda f: f.plausible)
    many = _named(surface, top, med, m, " alone make it so")
    return (f"{many}; without {'them' if m > 1 else 'it'} the map is plausible (rms slope {rest.rms_slope:.2g}, "
            f"height range {rest.height_range:.3g} m), so no height unit is suggested: remove or fill the outliers "
            "in the file, or pass --allow-steep to run it anyway")


def smooth_bulk_account(surface: Surface, figures: UnitFigures) -> str | None:
    """The one-line account of a surface whose bulk is too smooth (``bulk_figures``) while the
    whole map (``figures``) is not -- a few outliers alone give it its slope -- else None: how
    many (the fewest that, left out, leave it too smooth), the largest, and the slope without
    them.  No height unit is suggested (it would scale the outliers too)."""
    top, med, k = farthest_points(surface)
    if figures.too_smooth or not figures_without(surface, top).too_smooth:
        return None
    m, rest = _fewest(surface, top, k, lambda f: f.too_smooth)
    return (f"rms slope {figures.rms_slope:.2g} only through {_named(surface, top, med, m)}: without "
            f"{'them' if m > 1 else 'it'} the rms slope is {rest.rms_slope:.2g} (below {MIN_RMS_SLOPE:g}, smoother "
            "than any measured surface: a height unit or a side length off by 1e3 or 1e6?), so no height unit is "
            "suggested: remove or fill the outliers and check the file's units and --length, or pass --allow-steep "
            "to run it anyway")


def check_plausible_units(surface: Surface, height_unit: str | None = "m", file: str | None = None) -> UnitFigures:
    """The figures of ``surface`` when they and its bulk's (``bulk_figures``: all but its
    farthest ``OUTLIER_SHARE`` of points) are within the plausible range (module doc), else an
    ``ImplausibleUnitsError`` in one line.  Where the whole and the bulk disagree -- the bulk
    plausible, the whole not; or the bulk too smooth, the whole not -- it names the outliers
    and suggests no unit; else a suggested unit is one that makes the bulk plausible.
    ``height_unit`` is the unit the file's numbers were read in (None when the file stated its
    own unit); ``file``, the map's path as given, which the refusal names as a map reader's does
    (else it names the surface)."""
    figures = unit_figures(surface)
    what = f"cannot use surface file {file!r}" if file else f"surface {surface.name!r}"
    smooth = smooth_bulk_account(surface, figures)
    if smooth is not None:
        raise ImplausibleUnitsError(f"{what}: {smooth}", figures, None)
    if figures.plausible:
        return figures
    outliers = outlier_account(surface)
    if outliers is not None:
        raise ImplausibleUnitsError(f"{what}: {implausibility(figures, None, outliers)}", figures, None)
    bulk = bulk_figures(surface)
    suggestion = probable_unit(bulk, height_unit) if height_unit is not None else None
    line = implausibility(figures, height_unit, bulk=bulk)
    if suggestion is not None:
        factor = HEIGHT_UNITS[suggestion] / HEIGHT_UNITS[str(height_unit)]
        if not figures.scaled(factor).plausible:
            top, med, k = farthest_points(surface)
            m, _ = _fewest(surface, top, k, lambda f: f.scaled(factor).plausible)
            line += (f"; in {UNIT_NAMES[suggestion]} {_named(surface, top, med, m)} would still make it "
                     "implausible: remove or fill them too")
    raise ImplausibleUnitsError(f"{what}: {line}", figures, suggestion)


def check_height_unit(height_unit: str) -> str:
    """``height_unit`` if it names a known unit, else a ``ProblemInputError`` listing them."""
    if height_unit not in HEIGHT_UNITS:
        raise ProblemInputError(f"unknown height unit {height_unit!r}; choose one of {', '.join(HEIGHT_UNITS)}")
    return height_unit


def plain_float(text: str) -> float:
    """``float(text)`` for a number written plainly: ASCII digits with an optional sign,
    decimal point and exponent, or ``nan`` / ``inf``; what else ``float`` takes (underscores
    between digits, "1_0e-7", and digits of other scripts) is a ``ValueError``."""
    if not text.isascii() or "_" in text:
        raise ValueError(f"not a plainly written number: {text!r}")
    return float(text)


def plain_int(text: str) -> int:
    """``int(text)`` for a whole number written plainly (``plain_float``'s rule: ASCII
    digits with an optional sign, no underscores, blanks around it taken as ``int`` takes
    them); anything ``int`` refuses ("1e1", "1.5") or takes only beyond that rule ("1_0",
    digits of other scripts) is a ``ValueError``."""
    plain_float(text)
    return int(text)
