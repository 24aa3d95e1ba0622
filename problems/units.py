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
probably meant: a height unit (``probable_unit``), else the side length -- unless a few
outliers alone make it implausible (``outlier_account``: with at most ``OUTLIER_SHARE`` of the
points, those farthest from the median height, set to the median the map is plausible),
when it names them and suggests no unit (a spike read in another unit would shrink the
whole map with it).  Scenes call it
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
from dataclasses import dataclass, replace

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
#: The largest share of a map's points ``outlier_account`` may leave out (at least one point):
#: a map plausible without them is implausible only by those outliers.
OUTLIER_SHARE = 1e-3


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


def implausibility(figures: UnitFigures, height_unit: str | None, outliers: str | None = None) -> str:
    """The one-line account of an implausible surface (``height_unit`` None: the file
    stated its own unit, so only the file or --length can be wrong; ``outliers``: the
    account of ``outlier_account``, which then replaces any advice on units)."""
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
    unit = probable_unit(figures, height_unit)
    if unit is None:
        return (f"{text}: no height unit makes this plausible, so the side length is the likelier mistake; check "
                f"--length (metres, the side of the map), or pass --allow-steep to run it anyway")
    return (f"{text}: heights look like {UNIT_NAMES[unit]} given as {UNIT_NAMES[height_unit]}; pass "
            f"--height-unit {unit} (or --allow-steep to run it anyway)")


def outlier_account(surface: Surface) -> str | None:
    """The one-line account of an implausible surface that a few outliers alone make so,
    else None: when the map with its ceil(``OUTLIER_SHARE`` n) points farthest from the
    median height (|h - median|) set to the median is plausible, the fewest m of them that
    must go (a bisection over m), the largest (its height in metres and its grid index) and
    the figures without them.  No height unit is suggested: another unit scales every
    height, the outliers' and the rest's alike."""
    h = surface.heights
    med = float(np.median(h))
    dev = np.abs(h - med).ravel()
    k = min(max(1, math.ceil(OUTLIER_SHARE * dev.size)), dev.size - 1)
    top = np.argpartition(dev, dev.size - k)[dev.size - k:]
    top = top[np.argsort(dev[top])[::-1]]  # (farthest first)

    def without(m: int) -> UnitFigures:
        flat = h.ravel().copy()
        flat[top[:m]] = med
        return unit_figures(replace(surface, heights=flat.reshape(h.shape), levels=()))

    if not without(k).plausible:
        return None
    lo, hi = 0, k  # (implausible with lo left out, plausible with hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if without(mid).plausible:
            hi = mid
        else:
            lo = mid
    rest = without(hi)
    idx = tuple(int(i) for i in np.unravel_index(int(top[0]), h.shape))
    many = f"{hi} outlier points alone make" if hi > 1 else "1 outlier point alone makes"
    return (f"{many} it so (the farthest from the median height: {float(h.ravel()[top[0]]):.3g} m at index {idx}, "
            f"the median being {med:.3g} m); without {'them' if hi > 1 else 'it'} the map is plausible (rms slope "
            f"{rest.rms_slope:.2g}, height range {rest.height_range:.3g} m), so no height unit is suggested: "
            "remove or fill the outliers in the file, or pass --allow-steep to run it anyway")


def check_plausible_units(surface: Surface, height_unit: str | None = "m", file: str | None = None) -> UnitFigures:
    """The figures of ``surface`` when they are within the plausible range (module doc),
    else an ``ImplausibleUnitsError``.  ``height_unit`` is the unit the file's numbers were read
    in (None when the file stated its own unit); ``file``, the map's path as given, which the
    refusal names as a map reader's does (else it names the surface)."""
    figures = unit_figures(surface)
    if figures.plausible:
        return figures
    what = f"cannot use surface file {file!r}" if file else f"surface {surface.name!r}"
    outliers = outlier_account(surface)
    if outliers is not None:
        raise ImplausibleUnitsError(f"{what}: {implausibility(figures, None, outliers)}", figures, None)
    suggestion = probable_unit(figures, height_unit) if height_unit is not None else None
    raise ImplausibleUnitsError(f"{what}: {implausibility(figures, height_unit)}", figures, suggestion)


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
