"""Measured height maps: reading and cleaning.  :func:`load_surface` reads a map with
``problems.map_readers`` (the formats: .npy, text matrices and x,y,z columns, and every
format SurfaceTopography knows; what each refuses: that module's doc) and cleans it.

Units: heights and the lateral size of a file that states its unit are converted to
metres from it; a file with no unit (.npy, text, .mat, .npz) is read in ``height_unit``
(default metres: lengths of x,y,z columns too), and a ``height_unit`` given for a file
that states its own unit is refused (it would be ignored).

The lateral size: a file that states its physical size (x3p, gwy, nc, most instrument
formats) gives the spacings (rectangular pixels kept), so ``length`` may be omitted; when
both are given they must agree (relative 1e-6: NetCDF stores sizes in float32) and the
given length is used (x,y,z columns state theirs: the coordinates' steps).  Files that
state no size (.npy, a text matrix, .mat, .npz) need ``length``:
L0 (the size along the array's axis 0, rows: square pixels L0 / N0) or (L0, L1) (axis 0
and axis 1: spacings L0 / N0 and L1 / N1).  The length describes the map as read; a crop
keeps the spacing.

Cleaning, in this order.  Each step is recorded in ``Surface.meta`` and in the map's
``MapPreprocessing`` record (``Surface.preprocessing``, problems/preprocessing.py: the file's
base name, a hash of the raw heights and of the options that names the instance, the unit
and the spacing per axis, the filled points, the removed plane, the crop, the warnings).
Filling missing points and cropping or padding a non-square map warn; removing the tilt
warns only when it exceeds the rms slope (step 2), though every removal is recorded
(``announce``: stored in the record, and a ``UserWarning`` once per process for each file
and message, issued once the map has passed every check, so that a map refused warns of
nothing first):

1. NaN rule (``nan=``): ``"fill-mean"`` (default) replaces each missing point by the mean
   of the measured points; ``"fill-nearest"`` by its nearest measured neighbour;
   ``"fill-min"`` by the lowest measured height (never brought into contact before every
   measured point is); ``"error"`` refuses the file.  A map with no measured point, or
   with more than ``MAX_MISSING_FRACTION`` (half) of its points missing, is always an
   error: the filled points would be most of the surface solved on.  (Masked points of a
   SurfaceTopography channel are missing points.)  The filled share is printed so that it
   reads 0 % or 100 % only when it is exactly that (``share_text``).
   Where the plane is removed (step 2), the plane is fitted through the measured points
   and the rule acts on the heights above it: a hole in a tilted map is filled along the
   tilt, so that a filled point is never the map's summit because of the tilt.
2. Tilt (``detrend=``): ``"plane"`` (default), ``"mean"`` or ``"none"``: subtract the
   least-squares mean plane z = a + b j + c i over the grid (i rows, j columns), the mean,
   or nothing.  The plane is that of the map's bulk where a few outliers would tilt it
   (``bulk_plane_fit``: the bulk as ``units.bulk_figures`` takes it, of the heights above the
   plane), so that one spike does not tilt the whole map.  The plane's slope in physical
   units (``plane_tilt``, rise per length) is measured either way and recorded
   (``meta["tilt"]``); a tilt larger than the rms slope of the map without it warns
   (removed with "plane"; left in otherwise, where contact would then gather along the
   high edge).
3. Crop (``crop=``): ``"none"`` (default) keeps every point, rectangular maps included;
   ``"square"`` keeps the central min(N0, N1) square; ``"pad-square"`` pads to max(N0, N1)
   with the lowest height, the data kept in the top-left corner.  Either keeps the spacing.
   Points filled in step 1 that the crop leaves out are not in the problem: the record
   counts the filled points of the map as read (``filled``) and of the map as solved
   (``filled_solved``, the table's ``nan_filled``).
   Padding changes the problem, not only its shape: the nominal area A0 (N0 N1 d0 d1)
   grows by max(N0, N1)^2 / (N0 N1) (twice for a 2:1 map), the mean height drops towards
   the lowest one (so load steps measured from it, like the paper's ramp, grow), and the
   padded edge adds a cliff to the slopes; the crop's record (``meta["crop"]``, the report's
   "Problem changes") states the factor.

Coarsening and the PSD power-law test are not I/O: they live in ``problems/coarsen.py``.
"""

from __future__ import annotations

import errno
import stat
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .atomic_files import not_utf8_text
from .errors import ProblemInputError, check_positive
from .kernels import square_spacing
from .map_files import write_text, write_topography, write_x3p
from .units import farthest_points, plain_float
from .map_readers import (
    LENGTH_RTOL,
    RawMap,
    SurfaceFileError,
    read_height_map,
    read_npy,
    read_text,
    read_with_surfacetopography,
)
from .preprocessing import MapPreprocessing, key_options, options_key, plane_in_lengths, raw_heights_sha256
from .surfaces import Surface
from .units import HEIGHT_UNITS

CropRule = Literal["none", "square", "pad-square"]
NanRule = Literal["fill-mean", "fill-nearest", "fill-min", "error"]
DetrendRule = Literal["none", "mean", "plane"]
#: A lateral size: L0 along axis 0 (square pixels) or (L0, L1) along axis 0 and axis 1.
Length = float | tuple[float, float]

CROP_RULES = ("none", "square", "pad-square")
NAN_RULES = ("fill-mean", "fill-nearest", "fill-min", "error")
DETREND_RULES = ("none", "mean", "plane")

#: The cleaning warnings announced so far in this process (``announce``).
_ANNOUNCED: set[tuple[str, str]] = set()
#: How many ``unannounced`` blocks are open: reads inside one announce nothing.
_QUIET: list[int] = [0]


# --- Public entry point ---


def load_surface(
    path: str | Path,
    length: Length | None = None,
    *,
    crop: CropRule = "none",
    nan: NanRule = "fill-mean",
    detrend: DetrendRule = "plane",
    height_unit: str | None = None,
    channel: int | str | None = None,
    name: str | None = None,
) -> Surface:
    """Read a measured height map and return a non-periodic :class:`Surface` in metres,
    N0 x N1 as read (rectangular unless ``crop`` asks otherwise).

    ``length`` (metres) is the size of the map as read: L0 along axis 0 (square pixels,
    spacing L0 / N0) or (L0, L1) along axis 0 and axis 1 (spacings L0 / N0, L1 / N1).
    When None, the file's own lateral size is used; files that state none (.npy,
    text, .mat) then raise a clear error; when both are given they must agree.
    ``nan``, ``detrend`` and ``crop``: the cleaning steps of the module doc.
    ``height_unit`` ("m", "mm", "um", "nm"; None: metres) scales files that carry no
    unit of their own; given for a file that states its unit it is a
    ``SurfaceFileError`` (module doc); ``channel`` (index or name) picks one channel of a multi-channel file.
    """
    _check_choice("crop", crop, CROP_RULES)
    _check_choice("nan", nan, NAN_RULES)
    _check_choice("detrend", detrend, DETREND_RULES)
    if height_unit is not None:
        _check_choice("height_unit", height_unit, tuple(HEIGHT_UNITS))
    p = Path(path)
    check_surface_file(p)
    raw = read_height_map(p, channel=channel)
    if raw.unit_known and height_unit is not None:
        raise SurfaceFileError(p, f"the file states its own unit ({raw.info.get('file_unit')!r}), so a height unit "
                                  f"({height_unit!r}, --height-unit) would be ignored; leave it out")
    unit_from = "file" if raw.unit_known else "height_unit argument" if height_unit else "default (metres)"
    height_unit = str(raw.info.get("file_unit")) if raw.unit_known else height_unit or "m"
    metres = float(raw.info.get("metres_per_unit", 1.0)) if raw.unit_known else HEIGHT_UNITS[height_unit]
    scale = 1.0 if raw.unit_known else metres
    z = raw.z * scale
    file_spacing = None if raw.spacing is None else (raw.spacing[0] * scale, raw.spacing[1] * scale)
    meta: dict[str, Any] = {"source": str(p), "format": raw.fmt, "original_shape": list(z.shape), **raw.info,
                            "warnings": []}
    for note in raw.reader_notes:  # (what a foreign reader said while it read the map)
        announce(f"{warned_name(p)}: {note}", meta)
    if not raw.unit_known:
        meta["height_unit"] = height_unit
    spacing = map_spacing(p, z.shape, length, file_spacing, meta)
    measured = check_measured(z, p)  # (a refusal names the file as given; a warning, the file a link names)
    fitted = bulk_plane_fit(z, measured) if detrend == "plane" else None  # once, measured points
    z = fill_missing(z, nan, p, meta, plane=fitted)
    z = remove_tilt(z, detrend, meta, spacing, p, fitted)
    check_not_flat(z, raw.z[measured] * scale, spacing, p)
    z = crop_map(z, crop, p, meta)
    meta["nan_points_solved"] = int(np.count_nonzero(~measured[kept_window(measured.shape, crop)]))
    meta["spacing"] = list(spacing)
    chosen = None if raw.info.get("channel") is None else str(raw.info["channel"])
    raw_hash = raw_heights_sha256(raw.z)
    relative = meta["nan_points"] > 0 and detrend == "plane"
    key = options_key(raw_hash, key_options(nan=nan, detrend=detrend, crop=crop, metres_per_unit=metres,
                                            spacing=spacing, channel=chosen, filled_above_plane=relative))
    hashes = (raw_hash, key, raw_heights_sha256(z))  # (the last: the heights as solved, Surface.heights)
    record = preprocessing_record(p, raw, meta, z.shape, hashes, (height_unit, unit_from, metres))
    d0, d1 = spacing
    surface = Surface(z, d0, name=name or p.stem, periodic=False, meta=meta, delta1=None if d1 == d0 else d1,
                      preprocessing=record)
    announce_recorded(meta)  # (the map passed every check: a refused one warns of nothing)
    return surface


def warned_name(path: str | Path) -> str:
    """How a map's warnings name it: the base name of the file (a link's target), as
    ``MapPreprocessing.source``.  A refusal (``SurfaceFileError``) names the path as given."""
    return Path(path).resolve().name


def preprocessing_record(p: Path, raw: RawMap, meta: dict[str, Any], shape: tuple[int, int],
                         hashes: tuple[str, str, str],
                         unit: tuple[str, str, float]) -> MapPreprocessing:
    """The ``MapPreprocessing`` of a map read and cleaned by ``load_surface`` (``meta``:
    what its cleaning steps recorded; ``hashes``: (raw heights, key, heights as solved,
    each ``raw_heights_sha256`` but the key); ``unit``: (the unit
    of the file's numbers, where it came from, metres per number))."""
    n0, n1 = (int(v) for v in meta["original_shape"])
    spacing = (float(meta["spacing"][0]), float(meta["spacing"][1]))
    removed_mean, slope = None, None
    if meta["detrend"] == "mean":
        removed_mean = float(meta["removed_mean"])
    elif meta["detrend"] == "plane":
        removed_mean, slope = plane_in_lengths(meta["removed_plane"], (n0, n1), spacing)
    filled = int(meta["nan_points"])
    return MapPreprocessing(
        source=warned_name(p), path=str(p.resolve()), raw_sha256=hashes[0], key=hashes[1], format=raw.fmt,
        solved_sha256=hashes[2],
        channel=None if raw.info.get("channel") is None else str(raw.info["channel"]), height_unit=unit[0],
        unit_from=unit[1], metres_per_unit=unit[2], shape_read=(n0, n1), shape=(int(shape[0]), int(shape[1])),
        spacing=spacing, spacing_from=str(meta["spacing_from"]), nan_rule=str(meta["nan_rule"]), filled=filled,
        filled_solved=int(meta["nan_points_solved"]),
        filled_fraction=filled / (n0 * n1), fill_value=meta.get("fill_value"), detrend=str(meta["detrend"]),
        tilt=float(meta["tilt"]), removed_mean=removed_mean, removed_slope=slope, crop=str(meta["crop_rule"]),
        crop_done=str(meta["crop"]), warnings=tuple(meta["warnings"]),
        fill_relative_to=str(meta.get("fill_relative_to", "zero")),
        channel_index=None if raw.info.get("channel_index") is None else int(raw.info["channel_index"]))


def announce(message: str, meta: dict[str, Any]) -> None:
    """Record a cleaning step's warning in ``meta["warnings"]`` (the map's
    ``MapPreprocessing.warnings``) and announce it as a ``UserWarning``: for a file being
    read by ``load_surface`` (``meta["source"]``) once the map has passed every check
    (``announce_recorded``: a map refused warns of nothing), else at once.  Messages name
    the file by its base name (``MapPreprocessing.source``)."""
    meta.setdefault("warnings", []).append(message)
    if not meta.get("source"):
        warnings.warn(message, UserWarning, stacklevel=3)


def announce_recorded(meta: dict[str, Any]) -> None:
    """Announce each warning recorded for the file ``meta["source"]`` (``announce``) as a
    ``UserWarning``, once per process for each distinct message (a run reads its map when
    it plans and again when it builds); ``load_surface`` calls it last, when the map has
    passed every check.  Inside ``unannounced`` nothing is announced nor counted as
    announced (the record keeps its warnings)."""
    if _QUIET[0]:
        return
    source = str(Path(str(meta["source"])).resolve())
    for message in meta.get("warnings", []):
        if (source, message) not in _ANNOUNCED:
            _ANNOUNCED.add((source, message))
            warnings.warn(message, UserWarning, stacklevel=3)


@contextmanager
def unannounced() -> Iterator[None]:
    """Reads of maps inside this block warn of nothing (``announce_recorded``): for reads
    that only ask what a map would be under other options (``harness.run.spelled_out``,
    another height unit or length than the run's), whose warnings are not the run's.  A
    later read announces its own warnings as usual."""
    _QUIET[0] += 1
    try:
        yield
    finally:
        _QUIET[0] -= 1


# --- Cleaning ---


def fill_missing(z: np.ndarray, rule: NanRule, path: str | Path, meta: dict[str, Any],
                 plane: tuple[float, float, float] | None = None) -> np.ndarray:
    """Replace NaN points by the documented rule (module doc, step 1); ``plane``: the
    measured points' plane (a, c, b) of ``bulk_plane_fit``, where the rule acts on
    the heights above it and the plane is added back (so that on a tilted map a hole is
    filled along the tilt, not at one level that may rise above every measured point)."""
    missing = np.isnan(z)
    n_missing = int(missing.sum())
    meta["nan_points"] = n_missing
    meta["nan_rule"] = rule
    if n_missing == 0:
        return z
    check_measured(z, path)
    if rule == "error":
        raise SurfaceFileError(path, f"{n_missing} missing (NaN) points and nan='error'")
    relative_to_plane = plane is not None
    level = plane_on_grid(z.shape, *plane) if plane is not None else np.zeros_like(z)
    z = z - level
    if rule == "fill-mean":
        z[missing] = float(np.mean(z[~missing]))
    elif rule == "fill-min":
        z[missing] = float(np.min(z[~missing]))
    else:  # fill-nearest
        from scipy.ndimage import distance_transform_edt

        _, (ii, jj) = distance_transform_edt(missing, return_indices=True)
        z = z[ii, jj]
    if rule != "fill-nearest":
        meta["fill_value"] = float(z[missing][0])  # above the plane, where filled relative to it
    meta["fill_relative_to"] = "the measured points' plane" if relative_to_plane else "zero"
    basis = " relative to the measured points' plane" if relative_to_plane else ""
    announce(f"{warned_name(path)}: {n_missing} missing points ({share_text(n_missing, z.size)}) filled by rule "
             f"{rule!r}{basis}", meta)
    return z + level


#: A map with more than this share of its points missing (NaN) is refused: the filled
#: points would be most of the surface solved on.
MAX_MISSING_FRACTION = 0.5


def check_measured(z: np.ndarray, path: str | Path) -> np.ndarray:
    """The mask of the measured (not NaN) points of ``z``; a ``SurfaceFileError`` when
    none is measured or more than ``MAX_MISSING_FRACTION`` of the points are missing."""
    measured = ~np.isnan(z)
    n_missing = int(z.size - np.count_nonzero(measured))
    if n_missing == z.size:
        raise SurfaceFileError(path, f"NaN-only: none of the {z.size} points was measured")
    if n_missing > MAX_MISSING_FRACTION * z.size:
        raise SurfaceFileError(path, f"{n_missing} of its {z.size} points are missing (NaN, "
                                     f"{share_text(n_missing, z.size)}), more than {MAX_MISSING_FRACTION:.0%}: the "
                                     "filled points would be most of the surface; crop the map to its measured part")
    return measured


def share_text(part: int, whole: int) -> str:
    """``part / whole`` as a percentage with one decimal, except that a share that is not
    exactly 0 or 1 never reads "0.0%" or "100.0%" ("<0.1%", ">99.9%")."""
    share = part / whole
    if 0 < share < 0.0005:
        return "<0.1%"
    if 0.9995 <= share < 1:
        return ">99.9%"
    return f"{share:.1%}"


def plane_on_grid(shape: tuple[int, ...], a: float, c: float, b: float) -> np.ndarray:
    """The plane a + c i + b j on an N0 x N1 grid (i rows, j columns)."""
    return a + c * np.arange(shape[0])[:, None] + b * np.arange(shape[1])[None, :]


def plane_fit(z: np.ndarray, measured: np.ndarray | None = None) -> tuple[float, float, float]:
    """(a, c, b) of the least-squares plane z = a + c i + b j (i rows, j columns; a at
    i = j = 0) through every point, or through the ``measured`` ones (a mask; the mean
    level where they fix no plane: fewer than three, or on one line)."""
    if measured is not None and not measured.all():
        i, j = np.nonzero(measured)
        basis = np.stack([np.ones(i.size), i.astype(np.float64), j.astype(np.float64)], axis=1)
        coef, _, rank, _ = np.linalg.lstsq(basis, z[measured], rcond=None)
        if rank < 3:
            return float(np.mean(z[measured])), 0.0, 0.0
        return float(coef[0]), float(coef[1]), float(coef[2])
    n0, n1 = z.shape
    i = np.arange(n0, dtype=np.float64) - 0.5 * (n0 - 1)
    j = np.arange(n1, dtype=np.float64) - 0.5 * (n1 - 1)
    c = float(np.sum(i[:, None] * z) / (n1 * np.sum(i * i)))
    b = float(np.sum(j[None, :] * z) / (n0 * np.sum(j * j)))
    mean = float(np.mean(z))
    return mean - c * 0.5 * (n0 - 1) - b * 0.5 * (n1 - 1), c, b


#: At most this many refits of the bulk's plane (``bulk_plane_fit``); the points left out
#: settle in two or three.
BULK_PLANE_ROUNDS = 10


def bulk_plane_fit(z: np.ndarray, measured: np.ndarray | None = None) -> tuple[float, float, float]:
    """(a, c, b) of the plane detrend "plane" removes: the least-squares plane of the
    ``measured`` points (``plane_fit``; every point when None), unless a few outliers tilt it.
    The bulk's plane is the least-squares plane of the measured points less the outliers of
    the heights above it (``units.farthest_points``: the points ``units.bulk_figures`` leaves out,
    chosen among the measured ones), refitted until they settle (``BULK_PLANE_ROUNDS``).  It
    is returned when it and the whole's plane part by more, from one side of the map to the
    other, than the rms height of the bulk above its plane: the outliers alone tilt the plane
    beyond the map's own relief.  Otherwise the whole's plane is returned unchanged, so that
    a map without such outliers keeps its plain least-squares plane exactly."""
    mask = np.ones(z.shape, dtype=bool) if measured is None else np.asarray(measured, dtype=bool)
    whole = plane_fit(z, measured)
    plane, out = whole, np.zeros(0, dtype=np.intp)
    for _ in range(BULK_PLANE_ROUNDS):
        above = z - plane_on_grid(z.shape, *plane)
        above[~mask] = float(np.median(above[mask]))  # (a missing point at the median: never an outlier)
        top = np.sort(farthest_points(Surface(above, 1.0))[0])
        if np.array_equal(top, out):
            break
        out = top
        keep = mask.copy()
        keep.ravel()[out] = False
        plane = plane_fit(z, keep)
    keep = mask.copy()
    keep.ravel()[out] = False
    relief = float(np.sqrt(np.mean((z - plane_on_grid(z.shape, *plane))[keep] ** 2)))
    parting = abs(plane[1] - whole[1]) * (z.shape[0] - 1) + abs(plane[2] - whole[2]) * (z.shape[1] - 1)
    return plane if parting > relief else whole


def plane_tilt(z: np.ndarray, spacing: tuple[float, float]) -> float:
    """|grad| of the least-squares plane of ``z`` in rise per length."""
    _, c, b = plane_fit(z)
    return float(np.hypot(c / spacing[0], b / spacing[1]))


def remove_tilt(z: np.ndarray, rule: DetrendRule, meta: dict[str, Any], spacing: tuple[float, float] = (1.0, 1.0),
                path: str | Path = "map", fitted: tuple[float, float, float] | None = None) -> np.ndarray:
    """Subtract nothing, the mean, or the least-squares mean plane (module doc, step 2),
    on the filled map (no point is missing): ``fitted``, the plane (a, c, b) already fitted
    through the measured points, or (None) ``bulk_plane_fit`` through every point; warn when the
    plane's tilt exceeds the rms slope of the map without it."""
    meta["detrend"] = rule
    a, c, b = bulk_plane_fit(z) if fitted is None else fitted
    plane = plane_on_grid(z.shape, a, c, b)
    tilt = float(np.hypot(c / spacing[0], b / spacing[1]))
    rough = Surface(z - plane, spacing[0], delta1=spacing[1]).rms_slope()
    meta["tilt"] = tilt
    if tilt > rough:
        what = "removed" if rule == "plane" else f"NOT removed (detrend={rule!r}): contact will gather on the high side"
        announce(f"{warned_name(path)}: the map's mean plane is tilted by {tilt:.3g} (rise per length), more than its rms "
                 f"slope {rough:.3g} without the tilt; the tilt was {what}", meta)
    if rule == "none":
        return z
    if rule == "mean":
        meta["removed_mean"] = float(np.mean(z))
        return z - float(np.mean(z))
    meta["removed_plane"] = {"a": a, "b_per_column": b, "c_per_row": c}
    return z - plane


#: A map whose heights, as solved, vary by at most this fraction of the largest height read
#: is flat: what is left is the round-off of a constant or of the plane removed.
FLAT_RTOL = 1e-10


def check_not_flat(z: np.ndarray, read: np.ndarray, spacing: tuple[float, float], path: str | Path) -> None:
    """``SurfaceFileError`` for a map with no relief to solve on (``z``: as solved; ``read``:
    the measured heights as read, in metres): its heights vary by no more than the round-off
    of the heights read (``FLAT_RTOL``: a constant, or a plane once removed), or its rms
    slope is 0 in float64 (heights so small their slopes underflow)."""
    relief = float(np.ptp(z))
    scale = float(np.max(np.abs(read))) if read.size else 0.0
    if relief <= FLAT_RTOL * scale or relief == 0.0:
        raise SurfaceFileError(path, f"the map is flat: its heights vary by {relief:.3g} m as solved, the round-off "
                                     f"of heights up to {scale:.3g} m (a constant map, or a plane once its tilt is "
                                     "removed), so no step makes contact")
    if Surface(z, spacing[0], delta1=spacing[1]).rms_slope() == 0.0:
        raise SurfaceFileError(path, f"the map is flat in float64: its heights vary by {relief:.3g} m, so little "
                                     "that its slopes underflow to 0 (a unit slip? see --height-unit)")


def kept_window(shape: tuple[int, ...], rule: CropRule) -> tuple[slice, slice]:
    """The rows and columns of a map as read (N0 x N1 = ``shape``) that the map as solved
    keeps under crop ``rule``: the central min(N0, N1) square for "square" on a non-square
    map, every point otherwise ("pad-square" keeps them all and adds points)."""
    ny, nx = shape[0], shape[1]
    if rule != "square" or ny == nx:
        return slice(0, ny), slice(0, nx)
    n = min(ny, nx)
    i0, j0 = (ny - n) // 2, (nx - n) // 2
    return slice(i0, i0 + n), slice(j0, j0 + n)


def crop_map(z: np.ndarray, rule: CropRule, path: str | Path, meta: dict[str, Any]) -> np.ndarray:
    """Keep the map (``"none"``), crop it to its central square (``kept_window``) or pad it
    to a square with the lowest height (module doc, step 3); the spacing is the map's
    either way."""
    ny, nx = z.shape
    meta["crop_rule"] = rule
    if rule == "none" or ny == nx:
        meta["crop"] = "none" if ny != nx else "already square"
        return z
    if rule == "square":
        rows, cols = kept_window(z.shape, rule)
        out = z[rows, cols]
        n = out.shape[0]
        meta["crop"] = (f"cropped {ny}x{nx} to the central {n}x{n} (rows {rows.start}:{rows.stop}, "
                        f"cols {cols.start}:{cols.stop})")
    else:
        n = max(ny, nx)
        out = np.full((n, n), float(z.min()))
        out[:ny, :nx] = z
        meta["crop"] = (f"padded {ny}x{nx} to {n}x{n} with the lowest height {float(z.min()):.6g} (data top-left): "
                        f"the nominal area A0 grows by a factor {n * n / (ny * nx):.4g} and the mean height drops")
    announce(f"{warned_name(path)}: non-square map {meta['crop']}", meta)
    return out


def parse_length(text: str) -> Length:
    """``"L0"`` or ``"L0,L1"`` (metres) as ``load_surface``'s ``length``; anything else
    (not a plainly written number, ``plain_float``: "1_0e-7" is none; not finite or > 0;
    three values) is a one-line ``ProblemInputError``."""
    parts = [t.strip() for t in str(text).split(",")]
    if len(parts) not in (1, 2):
        raise ProblemInputError(f"--length takes L0 or L0,L1 (metres), got {text!r}")
    try:
        values = [plain_float(t) for t in parts]
    except ValueError:
        raise ProblemInputError(f"--length takes L0 or L0,L1 (metres), got {text!r}") from None
    out = [check_positive("--length", v) for v in values]
    return out[0] if len(out) == 1 else (out[0], out[1])


def map_spacing(path: Path, shape: tuple[int, int], length: Length | None,
                file_spacing: tuple[float, float] | None, meta: dict[str, Any]) -> tuple[float, float]:
    """The spacings (axis 0, axis 1) of the map as read: the given length (L0: square
    pixels L0 / N0; (L0, L1): L0 / N0, L1 / N1, made exactly square, L0 / N0 twice, when
    they are equal to round-off: ``kernels.square_spacing``), else the file's own; both
    given must agree (LENGTH_RTOL) on every axis given."""
    n0, n1 = shape
    if length is not None:
        if np.ndim(length) == 0:
            d0 = check_positive("surface length L0", length)  # type: ignore[arg-type]
            given = (d0 / n0, d0 / n0)
        else:
            pair = tuple(length)  # type: ignore[arg-type]
            if len(pair) != 2:
                raise ProblemInputError(f"length must be L0 or (L0, L1), got {length!r}")
            given = (check_positive("surface length L0", pair[0]) / n0, check_positive("surface length L1", pair[1]) / n1)
            square = square_spacing(given)  # (L0 / N0 and L1 / N1 equal to round-off: square pixels)
            given = given if square is None else (square, square)
        if file_spacing is not None:
            for axis, (g, f, n) in enumerate(zip(given, file_spacing, shape)):
                if not np.isclose(g * n, f * n, rtol=LENGTH_RTOL, atol=0.0):
                    raise SurfaceFileError(path, f"the given length {g * n:g} m along axis {axis} disagrees with "
                                                 f"the file's own side length {f * n:g} m ({n} points x {f:g} m); "
                                                 "drop --length or correct it")
        meta["spacing_from"] = "length argument" if file_spacing is None else "length argument (agrees with file)"
        return given
    if file_spacing is None:
        raise SurfaceFileError(path, "the file states no lateral size; give the length (length=L0 or (L0, L1), "
                                     "--length L0[,L1])")
    meta["spacing_from"] = "file"
    return (float(file_spacing[0]), float(file_spacing[1]))


#: What a path that is not a regular file is, by ``stat`` test, in words.
NOT_FILE_KINDS: tuple[tuple[Any, str], ...] = (
    (stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"))


def resolved_path(p: Path) -> Path:
    """``p.resolve()``, or a one-line ``SurfaceFileError`` naming ``p`` where its links cannot
    be followed to an end: a symlink loop (``RuntimeError`` before Python 3.13, ``OSError``
    ELOOP after) or another ``OSError`` (named by its reason)."""
    try:
        return p.resolve()
    except RuntimeError:
        raise SurfaceFileError(p, "it is a symlink loop (its links lead back to themselves); give a height-map "
                                  "file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise SurfaceFileError(p, "it is a symlink loop (its links lead back to themselves, or too many); give "
                                      "a height-map file") from None
        raise SurfaceFileError(p, f"its path cannot be followed ({exc.strerror or exc})") from None


def check_surface_file(p: Path) -> None:
    """Refuse, in one ``SurfaceFileError`` line and before any of it is read, a surface
    path that is neither a regular file nor a folder (a named pipe, a device, a socket:
    read without end, or waited on forever).  A path that cannot be looked at, or a
    folder, is left to the reader, which names why (a .npy header that declares more
    than the file holds: ``map_readers.check_npy_size``, before NumPy allocates).  A path,
    or the file a link leads to, whose name is not UTF-8 text is refused too: the map's
    name and path are recorded in the results table and meta.json, which hold UTF-8 text.
    A link that cannot be followed to its end (``resolved_path``: a symlink loop) is refused
    here, naming the path."""
    for name in (p, resolved_path(p)):
        shown = not_utf8_text(name)
        if shown is not None:
            raise SurfaceFileError(shown, "its name is not UTF-8 text (the results record it); rename the file")
    try:
        mode = p.stat().st_mode
    except OSError:
        return
    if stat.S_ISDIR(mode):
        return
    if not stat.S_ISREG(mode):
        kind = next((word for test, word in NOT_FILE_KINDS if test(mode)), "not a regular file")
        raise SurfaceFileError(p, f"it is {kind}, not a file; give a height-map file")


def _check_choice(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ProblemInputError(f"{what} must be one of {', '.join(map(repr, allowed))}, got {value!r}")


__all__ = [
    "CROP_RULES",
    "DETREND_RULES",
    "BULK_PLANE_ROUNDS",
    "MAX_MISSING_FRACTION",
    "NAN_RULES",
    "RawMap",
    "SurfaceFileError",
    "bulk_plane_fit",
    "crop_map",
    "check_measured",
    "check_surface_file",
    "fill_missing",
    "load_surface",
    "map_spacing",
    "parse_length",
    "plane_fit",
    "plane_tilt",
    "read_height_map",
    "read_npy",
    "read_text",
    "read_with_surfacetopography",
    "remove_tilt",
    "share_text",
    "write_text",
    "write_topography",
    "write_x3p",
]
