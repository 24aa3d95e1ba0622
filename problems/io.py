"""Measured height maps: reading (every format SurfaceTopography knows, plus .npy and
text), and cleaning.

Formats read by :func:`load_surface`:

* ``.npy``  -- ``numpy.load(..., allow_pickle=False)``: pickled/object arrays and files
  without NumPy's header are refused, never loaded.  The array is (rows = y, columns = x).
* text      -- a plain matrix of numbers, one row per line; the delimiter (comma,
  semicolon, tab or white space) is detected from the first data line; ``#`` starts a
  comment; ``nan`` marks a missing point.
* everything else -- through SurfaceTopography's readers (about 40 instrument formats:
  ISO 25178-71 .x3p, Gwyddion .gwy, NetCDF .nc, MATLAB .mat, Keyence .vk4, Zygo .datx,
  Wyko .opd, Sensofar .plu, Digital Surf .sur, Bruker .spm, Olympus .lext, Alicona
  .al3d, ...).  The reader is chosen by the file's extension when SurfaceTopography
  knows it (so a damaged file gets that format's own error), else by content.  Heights
  and the lateral size are converted to metres from the file's own unit; a file with no
  unit (.npy, text, .mat, .npz) is read in ``height_unit`` (default metres), and a
  ``height_unit`` given for a file that states its own unit is refused (it would be
  ignored).  SurfaceTopography indexes heights
  [x, y]; a :class:`Surface` is [y, x] (rows = y), so maps are transposed on the way
  in -- except bare-matrix containers (.mat, .npz), whose matrix is taken as it is,
  like a .npy.  Refused with a clear error: non-uniform line scans, 1-D profiles,
  multi-channel files without a chosen ``channel``, units that do not convert to
  metres, heights so large that sums over the map overflow (``HEIGHT_CEILING``).  For .x3p the MD5 checksum of the point data stated in
  main.xml is verified (SurfaceTopography does not); this module parses no XML itself.

The lateral size: a file that states its physical size (x3p, gwy, nc, most instrument
formats) gives the spacings (rectangular pixels kept), so ``length`` may be omitted; when
both are given they must agree (relative 1e-6: NetCDF stores sizes in float32) and the
given length is used.  Files that state no size (.npy, text, .mat, .npz) need ``length``:
L0 (the size along the array's axis 0, rows: square pixels L0 / N0) or (L0, L1) (axis 0
and axis 1: spacings L0 / N0 and L1 / N1).  The length describes the map as read; a crop
keeps the spacing.

Cleaning, in this order.  Each step is recorded in ``Surface.meta`` and in the map's
``MapPreprocessing`` record (``Surface.preprocessing``, problems/preprocessing.py: the file's
base name, a hash of the raw heights and of the options that names the instance, the unit
and the spacing per axis, the filled points, the removed plane, the crop, the warnings); a
step that changes the data warns (``announce``: stored in the record, and a ``UserWarning``
once per process for each file and message):

1. NaN rule (``nan=``): ``"fill-mean"`` (default) replaces each missing point by the mean
   of the measured points; ``"fill-nearest"`` by its nearest measured neighbour;
   ``"fill-min"`` by the lowest measured height (never brought into contact before every
   measured point is); ``"error"`` refuses the file.  A file with no measured point is
   always an error.  (Masked points of a SurfaceTopography channel are missing points.)
   Where the plane is removed (step 2), the plane is fitted through the measured points
   and the rule acts on the heights above it: a hole in a tilted map is filled along the
   tilt, so that a filled point is never the map's summit because of the tilt.
2. Tilt (``detrend=``): ``"plane"`` (default), ``"mean"`` or ``"none"``: subtract the
   least-squares mean plane z = a + b j + c i over the grid (i rows, j columns), the mean,
   or nothing.  The plane's slope in physical units (``plane_tilt``, rise per length) is
   measured either way and recorded (``meta["tilt"]``); a tilt larger than the rms slope of
   the map without it warns (removed with "plane"; left in otherwise, where contact would
   then gather along the high edge).
3. Crop (``crop=``): ``"none"`` (default) keeps every point, rectangular maps included;
   ``"square"`` keeps the central min(N0, N1) square; ``"pad-square"`` pads to max(N0, N1)
   with the lowest height, the data kept in the top-left corner.  Either keeps the spacing.

Coarsening and the PSD power-law test are not I/O: they live in ``problems/coarsen.py``.
"""

from __future__ import annotations

import hashlib
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .errors import ProblemInputError, check_positive
from .preprocessing import MapPreprocessing, key_options, options_key, plane_in_lengths, raw_heights_sha256
from .surfaces import Surface
from .map_files import write_text, write_topography, write_x3p
from .units import HEIGHT_UNITS

CropRule = Literal["none", "square", "pad-square"]
NanRule = Literal["fill-mean", "fill-nearest", "fill-min", "error"]
DetrendRule = Literal["none", "mean", "plane"]
#: A lateral size: L0 along axis 0 (square pixels) or (L0, L1) along axis 0 and axis 1.
Length = float | tuple[float, float]

CROP_RULES = ("none", "square", "pad-square")
NAN_RULES = ("fill-mean", "fill-nearest", "fill-min", "error")
DETREND_RULES = ("none", "mean", "plane")

NPY_MAGIC = b"\x93NUMPY"
#: Bytes of one height of each x3p DataType (ISO 25178-72: int16, int32, float32, float64).
X3P_BYTES = {"I": 2, "L": 4, "F": 4, "D": 8}
TEXT_SUFFIXES = (".txt", ".csv", ".tsv")
#: SurfaceTopography formats that hold a bare matrix: taken as (rows, columns) like a .npy.
MATRIX_FORMATS = ("mat", "npz")
#: A map's heights are refused above this over its point count: sqrt(the largest float), so
#: the cleaning's sums of squares stay finite.
HEIGHT_CEILING = float(np.sqrt(np.finfo(np.float64).max))
#: Relative disagreement allowed between a given length and the file's own lateral size.
LENGTH_RTOL = 1e-6
#: The cleaning warnings announced so far in this process (``announce``).
_ANNOUNCED: set[tuple[str, str]] = set()


class SurfaceFileError(ProblemInputError):
    """A height-map file that cannot be used; the message names the file and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"cannot use surface file {self.path!r}: {problem}")


@dataclass
class RawMap:
    """A height map as read from a file, before cleaning: z (ny x nx, metres once
    ``unit_known``, NaN for missing points) and the spacings (axis 0, axis 1) the file
    states (None when it states none)."""

    z: np.ndarray
    spacing: tuple[float, float] | None
    fmt: str
    info: dict[str, Any] = field(default_factory=dict)
    unit_known: bool = False


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
    if not raw.unit_known:
        meta["height_unit"] = height_unit
    spacing = map_spacing(p, z.shape, length, file_spacing, meta)
    named = p.resolve()  # the file a link names: its base name is the map's (MapPreprocessing.source)
    measured = ~np.isnan(z)
    fitted = plane_fit(z, measured) if detrend == "plane" else None  # once, through the measured points
    z = fill_missing(z, nan, named, meta, plane=fitted)
    z = remove_tilt(z, detrend, meta, spacing, named, fitted)
    check_not_flat(z, raw.z[measured] * scale, spacing, named)
    z = crop_map(z, crop, named, meta)
    meta["spacing"] = list(spacing)
    chosen = None if raw.info.get("channel") is None else str(raw.info["channel"])
    raw_hash = raw_heights_sha256(raw.z)
    relative = meta["nan_points"] > 0 and detrend == "plane"
    key = options_key(raw_hash, key_options(nan=nan, detrend=detrend, crop=crop, metres_per_unit=metres,
                                            spacing=spacing, channel=chosen, filled_above_plane=relative))
    record = preprocessing_record(p, raw, meta, z.shape, (raw_hash, key), (height_unit, unit_from, metres))
    d0, d1 = spacing
    return Surface(z, d0, name=name or p.stem, periodic=False, meta=meta, delta1=None if d1 == d0 else d1,
                   preprocessing=record)


def preprocessing_record(p: Path, raw: RawMap, meta: dict[str, Any], shape: tuple[int, int], hashes: tuple[str, str],
                         unit: tuple[str, str, float]) -> MapPreprocessing:
    """The ``MapPreprocessing`` of a map read and cleaned by ``load_surface`` (``meta``:
    what its cleaning steps recorded; ``hashes``: (raw heights, key); ``unit``: (the unit
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
        source=p.resolve().name, path=str(p.resolve()), raw_sha256=hashes[0], key=hashes[1], format=raw.fmt,
        channel=None if raw.info.get("channel") is None else str(raw.info["channel"]), height_unit=unit[0],
        unit_from=unit[1], metres_per_unit=unit[2], shape_read=(n0, n1), shape=(int(shape[0]), int(shape[1])),
        spacing=spacing, spacing_from=str(meta["spacing_from"]), nan_rule=str(meta["nan_rule"]), filled=filled,
        filled_fraction=filled / (n0 * n1), fill_value=meta.get("fill_value"), detrend=str(meta["detrend"]),
        tilt=float(meta["tilt"]), removed_mean=removed_mean, removed_slope=slope, crop=str(meta["crop_rule"]),
        crop_done=str(meta["crop"]), warnings=tuple(meta["warnings"]),
        fill_relative_to=str(meta.get("fill_relative_to", "zero")))


def announce(message: str, meta: dict[str, Any]) -> None:
    """Record a cleaning step's warning in ``meta["warnings"]`` (the map's
    ``MapPreprocessing.warnings``) and announce it as a ``UserWarning``: for a file read by
    ``load_surface`` (``meta["source"]``) once per process for each distinct message (a run
    reads its map when it plans and again when it builds), else every time.  Messages name
    the file by its base name (``MapPreprocessing.source``)."""
    meta.setdefault("warnings", []).append(message)
    key = (str(Path(str(meta["source"])).resolve()), message) if meta.get("source") else None
    if key is None or key not in _ANNOUNCED:
        if key is not None:
            _ANNOUNCED.add(key)
        warnings.warn(message, UserWarning, stacklevel=4)


def read_height_map(path: str | Path, channel: int | str | None = None) -> RawMap:
    """Read the raw map of any supported format (module doc)."""
    p = Path(path)
    head = _read_head(p)
    suffix = p.suffix.lower()
    if head.startswith(NPY_MAGIC) or suffix == ".npy":
        _only_channel(p, channel)
        return read_npy(p)
    known = _topography_formats()
    if suffix in TEXT_SUFFIXES or (suffix.lstrip(".") not in known and _looks_like_text(p)):
        _only_channel(p, channel)
        return read_text(p)
    return read_with_surfacetopography(p, known.get(suffix.lstrip(".")), channel)


def _read_head(p: Path) -> bytes:
    try:
        with open(p, "rb") as f:
            return f.read(8)
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None


def _topography_formats() -> dict[str, str | None]:
    """File extension -> SurfaceTopography format id (None where several formats share it)."""
    from SurfaceTopography.IO import readers

    out: dict[str, str | None] = {}
    for reader in readers:
        for ext in getattr(reader, "_file_extensions", None) or ():
            e = str(ext).lower()
            out[e] = reader.format() if e not in out else None
    return out


def _looks_like_text(p: Path) -> bool:
    try:
        with open(p, "rb") as f:
            f.read(4096).decode("utf-8")
    except UnicodeDecodeError:
        return False
    return True


def _only_channel(p: Path, channel: int | str | None) -> None:
    if channel not in (None, 0, "0"):
        raise SurfaceFileError(p, f"has a single channel; channel {channel!r} does not exist")


# --- Readers of our own: .npy and text ---


def read_npy(path: str | Path) -> RawMap:
    """A 2-D numeric .npy array; pickles are never loaded."""
    p = Path(path)
    if not _read_head(p).startswith(NPY_MAGIC):
        raise SurfaceFileError(p, "not a .npy file: it lacks NumPy's header")
    try:
        a = np.load(p, allow_pickle=False)
    except ValueError as e:
        if "pickle" in str(e).lower() or "object" in str(e).lower():
            raise SurfaceFileError(p, "the array holds Python objects (a pickle); refused, never unpickled") from None
        raise SurfaceFileError(p, f"truncated or corrupt .npy data ({e})") from None
    except (EOFError, OSError) as e:
        raise SurfaceFileError(p, f"truncated or corrupt .npy data ({e})") from None
    z = _numeric_matrix(p, a)  # (NumPy reads the count its header states: more data is a header that lies)
    if p.stat().st_size > np.load(p, mmap_mode="r").offset + a.nbytes:
        raise SurfaceFileError(p, f"it holds more data than its header's {a.shape[0]} x {a.shape[1]} values")
    return RawMap(z, None, "npy")


def read_text(path: str | Path) -> RawMap:
    """A plain text/CSV matrix; the delimiter is detected from the first data line."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # (a byte-order mark, as spreadsheets write one, is no value)
    except UnicodeDecodeError:
        raise SurfaceFileError(p, "binary content that is not .npy and not a text matrix") from None
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None
    lines = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
    rows_text = [(k + 1, ln) for k, ln in enumerate(lines) if ln]
    if not rows_text:
        raise SurfaceFileError(p, "no data rows (empty file or only comments)")
    delim = next((d for d in (",", ";", "\t") if d in rows_text[0][1]), None)  # None: any white space
    rows: list[list[float]] = []
    for lineno, ln in rows_text:
        cells = [c.strip() for c in (ln.split(delim) if delim else ln.split())]
        if delim and cells and cells[-1] == "":
            cells = cells[:-1]  # a trailing delimiter
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_float(c))
            raise SurfaceFileError(p, f"non-numeric value {bad!r} on line {lineno}") from None
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        first = len(rows[0])
        k = next(i for i, r in enumerate(rows) if len(r) != first)
        raise SurfaceFileError(
            p, f"wrong shape: rows of different lengths ({first} values on the first row, "
               f"{len(rows[k])} on data row {k + 1}); truncated or not a matrix")
    return RawMap(_numeric_matrix(p, np.array(rows, dtype=np.float64)), None, "text",
                  {"delimiter": delim or "whitespace"})


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _numeric_matrix(p: Path, a: np.ndarray) -> np.ndarray:
    if a.dtype.kind not in "biuf":
        raise SurfaceFileError(p, f"non-numeric data (dtype {a.dtype}); need real numbers")
    if a.ndim != 2:
        raise SurfaceFileError(p, f"wrong shape: need a 2-D height map, got a {a.ndim}-D array of shape {a.shape}")
    if min(a.shape) < 2:
        raise SurfaceFileError(p, f"wrong shape: need at least 2 x 2 points, got {a.shape[0]} x {a.shape[1]}")
    a = a.astype(np.float64)
    if np.isinf(a).any():
        raise SurfaceFileError(p, f"{int(np.isinf(a).sum())} infinite heights; only NaN may mark a missing point")
    top, ceiling = float(np.nanmax(np.abs(a), initial=0.0)), HEIGHT_CEILING / a.size
    if top > ceiling:  # (the cleaning's sums of squares would overflow to inf)
        at = np.unravel_index(int(np.nanargmax(np.abs(a))), a.shape)
        raise SurfaceFileError(p, f"a height of {top:.3g} at index {tuple(map(int, at))}: above {ceiling:.3g}, "
                                  "where sums over the map overflow; not a height map in any unit")
    return a


# --- Every other format: SurfaceTopography's readers ---


def read_with_surfacetopography(p: Path, fmt: str | None, channel: int | str | None = None) -> RawMap:
    """One channel of a file through SurfaceTopography (``fmt`` None: detect by content),
    in metres when the file states its unit; every failure is a :class:`SurfaceFileError`."""
    from SurfaceTopography.IO import open_topography

    what = fmt or "the detected format"
    try:
        reader = open_topography(str(p), format=fmt)
        what = f"{reader.name()} (.{reader.format()})"
        info = _pick_channel(p, reader, channel)
        kw = {"physical_sizes": tuple(float(n) for n in info.nb_grid_pts)} if info.physical_sizes is None else {}
        topo = reader.topography(channel_index=info.index, **kw)
        h = np.ma.asarray(topo.heights(), dtype=np.float64)
        heights = np.where(np.isinf(h.data), h.data, np.ma.filled(h, np.nan))  # an inf stays one (refused), no hole
    except SurfaceFileError:
        raise
    except Exception as e:  # the readers raise many kinds; each becomes one clear line
        raise SurfaceFileError(p, _reader_failure(e, what)) from None
    fmt_id = reader.format()
    z = heights if fmt_id in MATRIX_FORMATS else heights.T
    meta: dict[str, Any] = {"reader": f"SurfaceTopography {_st_version()}", "channel": info.name,
                            "file_unit": topo.unit}
    factor = _metres_per_unit(p, topo.unit)
    if factor is not None:
        meta["metres_per_unit"] = factor
    spacing = None
    if info.physical_sizes is not None:
        dx, dy = _file_spacing(p, topo.physical_sizes, topo.nb_grid_pts)
        k = factor or 1.0
        spacing = (dx * k, dy * k) if fmt_id in MATRIX_FORMATS else (dy * k, dx * k)  # (axis 0, axis 1) of z
        meta["file_size_m" if factor else "file_size"] = [float(s) * (factor or 1.0) for s in topo.physical_sizes]
    if fmt_id == "x3p":
        meta.update(_x3p_checks(p, topo.info.get("raw_metadata", {})))
    z = _numeric_matrix(p, z) * (factor or 1.0)
    return RawMap(z, spacing, fmt_id, meta, unit_known=factor is not None)


def _reader_failure(e: Exception, what: str) -> str:
    from SurfaceTopography.Exceptions import CannotDetectFileFormat, CorruptFile, FileFormatMismatch

    msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    if isinstance(e, CannotDetectFileFormat):
        return ("not a format contactbench reads (.npy, a text matrix) nor one SurfaceTopography "
                "recognises (every reader tried)")
    if isinstance(e, FileFormatMismatch):
        return f"not a valid {what} file ({msg})"
    if isinstance(e, CorruptFile):
        return f"corrupt or truncated {what} file ({msg})"
    if type(e).__name__ in ("EntitiesForbidden", "DTDForbidden", "ExternalReferenceForbidden"):
        return f"{what}: its XML declares a DTD/entities; refused"
    if type(e).__name__ == "ParseError":
        return f"{what}: its XML is not well-formed ({msg})"
    return f"{what} reader failed ({type(e).__name__}: {msg})"


def _pick_channel(p: Path, reader: Any, channel: int | str | None) -> Any:
    """The chosen channel's info; refuses an unchosen multi-channel file, line scans and
    profiles."""
    chans = list(reader.channels)
    listing = "; ".join(f"{c.index}: {c.name!r}" for c in chans)
    if channel is None:
        if len(chans) > 1:
            raise SurfaceFileError(p, f"{len(chans)} channels ({listing}); choose one with --channel INDEX|NAME")
        info = chans[0]
    else:
        key = str(channel)
        hits = [c for c in chans if str(c.index) == key] or [c for c in chans if c.name == key]
        if len(hits) != 1:
            raise SurfaceFileError(p, f"no channel {channel!r} (it has {listing})")
        info = hits[0]
    if not info.is_uniform:
        raise SurfaceFileError(p, f"channel {info.name!r} is a non-uniform line scan; need a gridded 2-D height map")
    if info.dim != 2:
        raise SurfaceFileError(p, f"channel {info.name!r} is a {info.dim}-D profile (line scan); need a 2-D height map")
    return info


def _metres_per_unit(p: Path, unit: str | None) -> float | None:
    """Metres per file unit (None: the file states no unit)."""
    if unit is None:
        return None
    from SurfaceTopography.Support.UnitConversion import get_unit_conversion_factor

    try:
        return float(get_unit_conversion_factor(unit, "m"))
    except ValueError as e:
        raise SurfaceFileError(p, f"unit {unit!r} cannot be converted to metres ({e})") from None


def _file_spacing(p: Path, sizes: Any, nb: Any) -> tuple[float, float]:
    """The grid spacings (x, y) the file states (file units); pixels equal to LENGTH_RTOL
    are made exactly square."""
    dx, dy = (float(size) / int(n) if int(n) > 0 else np.nan for size, n in zip(sizes[:2], nb[:2]))  # 0 points: NaN
    try:
        dx, dy = check_positive("file grid spacing x", dx), check_positive("file grid spacing y", dy)
    except ProblemInputError as e:
        raise SurfaceFileError(p, str(e)) from None
    return (dx, dx) if np.isclose(dx, dy, rtol=LENGTH_RTOL) else (dx, dy)


def _x3p_checks(p: Path, raw_meta: dict[str, Any]) -> dict[str, Any]:
    """Verify the point data against the MD5 and the size that main.xml states (read from
    SurfaceTopography's parsed metadata); return the x3p facts kept in meta."""
    axes = raw_meta.get("Record1", {}).get("Axes", {})
    link = raw_meta.get("Record3", {}).get("DataLink", {})
    member, md5 = link.get("PointDataLink"), link.get("MD5ChecksumPointData")
    cz, size = axes.get("CZ", {}), raw_meta.get("Record3", {}).get("MatrixDimension", {})
    if member:
        with zipfile.ZipFile(p) as zf:
            data = zf.read(str(member))
        if md5 and hashlib.md5(data).hexdigest().lower() != str(md5).strip().lower():
            raise SurfaceFileError(p, f"MD5 checksum of {member} does not match main.xml (corrupt data)")
        stated = int(np.prod([int(size.get(k, 1)) for k in ("SizeX", "SizeY", "SizeZ")])) * X3P_BYTES.get(cz.get("DataType"), 0)
        if stated and len(data) != stated:
            raise SurfaceFileError(p, f"{member} holds {len(data)} bytes where main.xml states {stated}")
    incs = [axes.get(a, {}).get("Increment") for a in ("CX", "CY")] + [cz.get("Increment", 1.0)]
    return {"x3p_data_type": cz.get("DataType"), "x3p_increments": [float(v) for v in incs if v is not None]}


def _st_version() -> str:
    import SurfaceTopography

    return str(getattr(SurfaceTopography, "__version__", "?"))


# --- Cleaning ---


def fill_missing(z: np.ndarray, rule: NanRule, path: str | Path, meta: dict[str, Any],
                 plane: tuple[float, float, float] | None = None) -> np.ndarray:
    """Replace NaN points by the documented rule (module doc, step 1); ``plane``: the
    measured points' least-squares plane (a, c, b) of ``plane_fit``, where the rule acts on
    the heights above it and the plane is added back (so that on a tilted map a hole is
    filled along the tilt, not at one level that may rise above every measured point)."""
    missing = np.isnan(z)
    n_missing = int(missing.sum())
    meta["nan_points"] = n_missing
    meta["nan_rule"] = rule
    if n_missing == 0:
        return z
    if n_missing == z.size:
        raise SurfaceFileError(path, f"NaN-only: none of the {z.size} points was measured")
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
    announce(f"{Path(path).name}: {n_missing} missing points ({n_missing / z.size:.1%}) filled by rule {rule!r}"
             f"{basis}", meta)
    return z + level


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


def plane_tilt(z: np.ndarray, spacing: tuple[float, float]) -> float:
    """|grad| of the least-squares plane of ``z`` in rise per length."""
    _, c, b = plane_fit(z)
    return float(np.hypot(c / spacing[0], b / spacing[1]))


def remove_tilt(z: np.ndarray, rule: DetrendRule, meta: dict[str, Any], spacing: tuple[float, float] = (1.0, 1.0),
                path: str | Path = "map", fitted: tuple[float, float, float] | None = None) -> np.ndarray:
    """Subtract nothing, the mean, or the least-squares mean plane (module doc, step 2),
    on the filled map (no point is missing): ``fitted``, the plane (a, c, b) already fitted
    through the measured points, or (None) the plane through every point; warn when the
    plane's tilt exceeds the rms slope of the map without it."""
    meta["detrend"] = rule
    a, c, b = plane_fit(z) if fitted is None else fitted
    plane = plane_on_grid(z.shape, a, c, b)
    tilt = float(np.hypot(c / spacing[0], b / spacing[1]))
    rough = Surface(z - plane, spacing[0], delta1=spacing[1]).rms_slope()
    meta["tilt"] = tilt
    if tilt > rough:
        what = "removed" if rule == "plane" else f"NOT removed (detrend={rule!r}): contact will gather on the high side"
        announce(f"{Path(path).name}: the map's mean plane is tilted by {tilt:.3g} (rise per length), more than its rms "
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


def crop_map(z: np.ndarray, rule: CropRule, path: str | Path, meta: dict[str, Any]) -> np.ndarray:
    """Keep the map (``"none"``), crop it to its central square or pad it to a square with
    the lowest height (module doc, step 3); the spacing is the map's either way."""
    ny, nx = z.shape
    meta["crop_rule"] = rule
    if rule == "none" or ny == nx:
        meta["crop"] = "none" if ny != nx else "already square"
        return z
    if rule == "square":
        n = min(ny, nx)
        i0, j0 = (ny - n) // 2, (nx - n) // 2
        out = z[i0:i0 + n, j0:j0 + n]
        meta["crop"] = f"cropped {ny}x{nx} to the central {n}x{n} (rows {i0}:{i0 + n}, cols {j0}:{j0 + n})"
    else:
        n = max(ny, nx)
        out = np.full((n, n), float(z.min()))
        out[:ny, :nx] = z
        meta["crop"] = f"padded {ny}x{nx} to {n}x{n} with the lowest height {float(z.min()):.6g} (data top-left)"
    announce(f"{Path(path).name}: non-square map {meta['crop']}", meta)
    return out


def parse_length(text: str) -> Length:
    """``"L0"`` or ``"L0,L1"`` (metres) as ``load_surface``'s ``length``; anything else
    (not a number, not finite or > 0, three values) is a one-line ``ProblemInputError``."""
    parts = [t.strip() for t in str(text).split(",")]
    if len(parts) not in (1, 2):
        raise ProblemInputError(f"--length takes L0 or L0,L1 (metres), got {text!r}")
    try:
        values = [float(t) for t in parts]
    except ValueError:
        raise ProblemInputError(f"--length takes L0 or L0,L1 (metres), got {text!r}") from None
    out = [check_positive("--length", v) for v in values]
    return out[0] if len(out) == 1 else (out[0], out[1])


def map_spacing(path: Path, shape: tuple[int, int], length: Length | None,
                file_spacing: tuple[float, float] | None, meta: dict[str, Any]) -> tuple[float, float]:
    """The spacings (axis 0, axis 1) of the map as read: the given length (L0: square
    pixels L0 / N0; (L0, L1): L0 / N0, L1 / N1), else the file's own; both given must agree
    (LENGTH_RTOL) on every axis given."""
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


def _check_choice(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ProblemInputError(f"{what} must be one of {', '.join(map(repr, allowed))}, got {value!r}")


__all__ = [
    "CROP_RULES",
    "DETREND_RULES",
    "NAN_RULES",
    "RawMap",
    "SurfaceFileError",
    "crop_map",
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
    "write_text",
    "write_topography",
    "write_x3p",
]
