"""Measured height maps: reading (npy, text, x3p), writing, and cleaning.

Formats read by :func:`load_surface` (chosen by content, not only by extension):

* ``.npy``  -- ``numpy.load(..., allow_pickle=False)``: pickled/object arrays are refused,
  never loaded.
* text      -- a plain matrix of numbers, one row per line; the delimiter (comma,
  semicolon, tab or white space) is detected from the first data line; ``#`` starts a
  comment; ``nan`` marks a missing point.
* ``.x3p``  -- ISO 25178-71 (XML + binary in a zip): a small reader/writer of our own
  (``read_x3p`` / ``write_x3p``), stdlib only.  It handles surface records ("SUR") with
  data types D (float64), F (float32), L (int32) and I (int16), the CX/CY increments
  (the grid spacing), the CZ increment/offset (the height scale) and an optional
  valid-points bit mask (``bindata/valid.bin``); checksums are verified when present.

Cleaning, in this order (each step recorded in ``Surface.meta`` and, when it changes the
data, announced by a ``UserWarning``):

1. NaN rule (``nan=``): ``"fill-mean"`` (default) replaces each missing point by the mean
   of the measured points; ``"fill-nearest"`` by its nearest measured neighbour;
   ``"fill-min"`` by the lowest measured height (never brought into contact before every
   measured point is); ``"error"`` refuses the file.  A file with no measured point is
   always an error.
2. Tilt (``detrend=``): ``"none"`` (default), ``"mean"`` (subtract the mean height) or
   ``"plane"`` (subtract the least-squares mean plane z = a + b x + c y fitted to the
   measured points).
3. Square grid (``square=``): ``"crop"`` (default) keeps the central min(ny, nx) square;
   ``"pad"`` pads to max(ny, nx) with the lowest height, the data kept in the top-left
   corner; ``"error"`` refuses a non-square map.

Coarsening and the PSD power-law test are not I/O: they live in ``problems/coarsen.py``.
"""

from __future__ import annotations

import hashlib
import io as _stdio
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal
from xml.etree import ElementTree as ET

import numpy as np

from .errors import ProblemInputError, check_positive
from .surfaces import Surface

SquareRule = Literal["crop", "pad", "error"]
NanRule = Literal["fill-mean", "fill-nearest", "fill-min", "error"]
DetrendRule = Literal["none", "mean", "plane"]

SQUARE_RULES = ("crop", "pad", "error")
NAN_RULES = ("fill-mean", "fill-nearest", "fill-min", "error")
DETREND_RULES = ("none", "mean", "plane")
HEIGHT_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "nm": 1e-9}

NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGIC = b"PK\x03\x04"
X3P_NS = "http://www.opengps.eu/2008/ISO5436_2"
X3P_DTYPES = {"D": "<f8", "F": "<f4", "L": "<i4", "I": "<i2"}


class SurfaceFileError(ProblemInputError):
    """A height-map file that cannot be used; the message names the file and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"cannot use surface file {self.path!r}: {problem}")


@dataclass
class RawMap:
    """A height map as read from a file, before cleaning: z (ny x nx, metres, NaN for
    missing points) and the spacing the file states (None when it states none)."""

    z: np.ndarray
    spacing: float | None
    fmt: str
    info: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------


def load_surface(
    path: str | Path,
    length: float | None = None,
    *,
    square: SquareRule = "crop",
    nan: NanRule = "fill-mean",
    detrend: DetrendRule = "none",
    height_unit: str = "m",
    name: str | None = None,
) -> Surface:
    """Read a measured height map and return a non-periodic :class:`Surface` in metres.

    ``length`` is the side length L (metres) of the final square grid, so the spacing is
    L / N.  When None, the file's own spacing is used (.x3p); files that state no spacing
    (.npy, text) then raise a clear error.  ``height_unit`` scales .npy/text heights
    ("m", "mm", "um", "nm"); .x3p heights are metres by the standard.
    """
    _check_choice("square", square, SQUARE_RULES)
    _check_choice("nan", nan, NAN_RULES)
    _check_choice("detrend", detrend, DETREND_RULES)
    _check_choice("height_unit", height_unit, tuple(HEIGHT_UNITS))
    p = Path(path)
    raw = read_height_map(p)
    z = raw.z if raw.fmt == "x3p" else raw.z * HEIGHT_UNITS[height_unit]
    meta: dict[str, Any] = {"source": str(p), "format": raw.fmt, "original_shape": list(z.shape), **raw.info}
    z = fill_missing(z, nan, p, meta)
    z = remove_tilt(z, detrend, meta)
    z = make_square(z, square, p, meta)
    delta = _spacing(p, z.shape[0], length, raw.spacing, meta)
    return Surface(z, delta, name=name or p.stem, periodic=False, meta=meta)


def read_height_map(path: str | Path) -> RawMap:
    """Read the raw map of any supported format, chosen by the file's first bytes."""
    p = Path(path)
    head = _read_head(p)
    if head.startswith(NPY_MAGIC):
        return read_npy(p)
    if head.startswith(ZIP_MAGIC):
        return read_x3p(p)
    if p.suffix.lower() == ".x3p":
        raise SurfaceFileError(p, "not a zip archive, so not an ISO 25178-71 .x3p file")
    if p.suffix.lower() == ".npy":
        raise SurfaceFileError(p, "not a .npy file (missing the NUMPY header); truncated or another format")
    return read_text(p)


def _read_head(p: Path) -> bytes:
    try:
        with open(p, "rb") as f:
            return f.read(8)
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None


# ---------------------------------------------------------------------------
# Readers
# ---------------------------------------------------------------------------


def read_npy(path: str | Path) -> RawMap:
    """A 2-D numeric .npy array; pickles are never loaded."""
    p = Path(path)
    try:
        a = np.load(p, allow_pickle=False)
    except ValueError as e:
        if "pickle" in str(e).lower() or "object" in str(e).lower():
            raise SurfaceFileError(p, "the array holds Python objects (a pickle); refused, never unpickled") from None
        raise SurfaceFileError(p, f"truncated or corrupt .npy data ({e})") from None
    except (EOFError, OSError) as e:
        raise SurfaceFileError(p, f"truncated or corrupt .npy data ({e})") from None
    return RawMap(_numeric_matrix(p, a), None, "npy")


def _detect_delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None  # any white space


def read_text(path: str | Path) -> RawMap:
    """A plain text/CSV matrix; the delimiter is detected from the first data line."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise SurfaceFileError(p, "binary content that is not .npy or .x3p, and not a text matrix") from None
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None
    lines = [ln.split("#", 1)[0].strip() for ln in text.splitlines()]
    rows_text = [(k + 1, ln) for k, ln in enumerate(lines) if ln]
    if not rows_text:
        raise SurfaceFileError(p, "no data rows (empty file or only comments)")
    delim = _detect_delimiter(rows_text[0][1])
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
    return a


def _x3p_find(root: ET.Element, path: str) -> ET.Element | None:
    """Find a child by a '/'-separated path, ignoring XML namespaces."""
    node: ET.Element | None = root
    for part in path.split("/"):
        if node is None:
            return None
        node = next((c for c in node if c.tag.rsplit("}", 1)[-1] == part), None)
    return node


def _x3p_text(root: ET.Element, path: str, p: Path, default: str | None = None) -> str:
    node = _x3p_find(root, path)
    if node is None or node.text is None or not node.text.strip():
        if default is not None:
            return default
        raise SurfaceFileError(p, f"x3p main.xml lacks {path}")
    return node.text.strip()


def _x3p_float(root: ET.Element, path: str, p: Path, default: float | None = None) -> float:
    txt = _x3p_text(root, path, p, None if default is None else repr(default))
    try:
        return float(txt)
    except ValueError:
        raise SurfaceFileError(p, f"x3p main.xml: {path} is not a number ({txt!r})") from None


def read_x3p(path: str | Path) -> RawMap:
    """ISO 25178-71 .x3p: main.xml (Record1 axes, Record3 matrix size and data link)
    plus the binary point data (little endian, x fastest).  Heights are
    ``CZ.Offset + CZ.Increment * value``; points flagged invalid, or NaN, are missing."""
    p = Path(path)
    try:
        zf = zipfile.ZipFile(p)
    except zipfile.BadZipFile as e:
        raise SurfaceFileError(p, f"not a valid zip archive, so not an .x3p file ({e})") from None
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None
    with zf:
        names = set(zf.namelist())
        if "main.xml" not in names:
            raise SurfaceFileError(p, f"a zip that is not x3p: no main.xml (it holds {sorted(names)[:5]})")
        root = _parse_main_xml(p, _zip_read(zf, "main.xml", p))
        ftype = _x3p_text(root, "Record1/FeatureType", p)
        if ftype != "SUR":
            raise SurfaceFileError(p, f"x3p feature type {ftype!r} is not an areal surface ('SUR')")
        for ax in ("CX", "CY"):
            if _x3p_text(root, f"Record1/Axes/{ax}/AxisType", p) != "I":
                raise SurfaceFileError(p, f"x3p axis {ax} is not incremental (a point list); only gridded maps are supported")
        dx = _x3p_float(root, "Record1/Axes/CX/Increment", p)
        dy = _x3p_float(root, "Record1/Axes/CY/Increment", p)
        dz = _x3p_float(root, "Record1/Axes/CZ/Increment", p, 1.0)
        z0 = _x3p_float(root, "Record1/Axes/CZ/Offset", p, 0.0)
        dtype = _x3p_text(root, "Record1/Axes/CZ/DataType", p)
        if dtype not in X3P_DTYPES:
            raise SurfaceFileError(p, f"x3p data type {dtype!r} unsupported (D, F, L, I are)")
        nx, ny, nz = (int(_x3p_float(root, f"Record3/MatrixDimension/Size{a}", p)) for a in "XYZ")
        if nz != 1 or nx < 1 or ny < 1:
            raise SurfaceFileError(p, f"wrong shape: x3p matrix is {nx} x {ny} x {nz}; need one layer (SizeZ = 1)")
        z = _x3p_points(zf, root, p, names, dtype, nx, ny)
        valid = _x3p_valid_mask(zf, root, p, names, nx, ny)
    z = z0 + dz * z
    if valid is not None:
        z[~valid] = np.nan
    if not np.isclose(dx, dy, rtol=1e-6):
        raise SurfaceFileError(p, f"non-square pixels (CX increment {dx:g} m, CY increment {dy:g} m); resample first")
    info = {"x3p_data_type": dtype, "x3p_increments": [dx, dy, dz]}
    return RawMap(_numeric_matrix(p, z), check_positive("x3p CX increment", dx), "x3p", info)


def _zip_read(zf: zipfile.ZipFile, member: str, p: Path) -> bytes:
    try:
        return zf.read(member)
    except (zipfile.BadZipFile, EOFError, OSError, KeyError) as e:
        raise SurfaceFileError(p, f"truncated or corrupt zip member {member!r} ({e})") from None
    except Exception as e:  # zlib.error on a damaged deflate stream
        raise SurfaceFileError(p, f"truncated or corrupt zip member {member!r} ({type(e).__name__}: {e})") from None


def _parse_main_xml(p: Path, data: bytes) -> ET.Element:
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise SurfaceFileError(p, "x3p main.xml declares a DTD/entities; refused")
    try:
        return ET.fromstring(data)
    except ET.ParseError as e:
        raise SurfaceFileError(p, f"x3p main.xml is not well-formed XML ({e})") from None


def _x3p_points(zf: zipfile.ZipFile, root: ET.Element, p: Path, names: set[str], dtype: str,
                nx: int, ny: int) -> np.ndarray:
    link = _x3p_find(root, "Record3/DataLink/PointDataLink")
    if link is None:
        data_list = _x3p_find(root, "Record3/DataList")
        if data_list is None:
            raise SurfaceFileError(p, "x3p Record3 has neither a DataLink nor a DataList")
        vals = [(d.text or "").strip() for d in data_list]
        if len(vals) != nx * ny:
            raise SurfaceFileError(p, f"wrong shape: DataList has {len(vals)} values, SizeX*SizeY = {nx * ny}")
        try:
            arr = np.array([float(v) if v else np.nan for v in vals])
        except ValueError:
            raise SurfaceFileError(p, "non-numeric value in the x3p DataList") from None
        return arr.reshape(ny, nx)
    member = (link.text or "").strip()
    if member not in names:
        raise SurfaceFileError(p, f"x3p point data {member!r} named in main.xml is missing from the zip")
    raw = _zip_read(zf, member, p)
    want = nx * ny * np.dtype(X3P_DTYPES[dtype]).itemsize
    if len(raw) != want:
        raise SurfaceFileError(p, f"truncated point data: {member} has {len(raw)} bytes, "
                                  f"{nx} x {ny} values of type {dtype} need {want}")
    md5 = _x3p_find(root, "Record3/DataLink/MD5ChecksumPointData")
    if md5 is not None and md5.text and md5.text.strip().lower() != hashlib.md5(raw).hexdigest():
        raise SurfaceFileError(p, f"MD5 checksum of {member} does not match main.xml (corrupt data)")
    arr = np.frombuffer(raw, dtype=X3P_DTYPES[dtype]).astype(np.float64)
    return arr.reshape(ny, nx)


def _x3p_valid_mask(zf: zipfile.ZipFile, root: ET.Element, p: Path, names: set[str], nx: int,
                    ny: int) -> np.ndarray | None:
    link = _x3p_find(root, "Record3/DataLink/ValidPointsLink")
    if link is None or not (link.text or "").strip():
        return None
    member = link.text.strip()
    if member not in names:
        raise SurfaceFileError(p, f"x3p valid-points mask {member!r} named in main.xml is missing from the zip")
    bits = np.unpackbits(np.frombuffer(_zip_read(zf, member, p), dtype=np.uint8), bitorder="little")
    if bits.size < nx * ny:
        raise SurfaceFileError(p, f"truncated valid-points mask: {bits.size} bits for {nx * ny} points")
    return bits[: nx * ny].astype(bool).reshape(ny, nx)


# ---------------------------------------------------------------------------
# Writer (round trips, test data)
# ---------------------------------------------------------------------------


def write_x3p(path: str | Path, z: np.ndarray, spacing: float, *, data_type: str = "D",
              z_increment: float = 1.0, spacing_y: float | None = None, comment: str = "") -> Path:
    """Write a gridded height map (ny x nx, metres) as an ISO 25178-71 .x3p file.

    Float types (D, F) store z directly (NaN for missing points); integer types (L, I)
    store round(z / z_increment) with missing points in bindata/valid.bin.
    """
    if data_type not in X3P_DTYPES:
        raise ProblemInputError(f"x3p data type must be one of {', '.join(X3P_DTYPES)}, got {data_type!r}")
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2:
        raise ProblemInputError(f"x3p writer needs a 2-D map, got shape {z.shape}")
    ny, nx = z.shape
    missing = ~np.isfinite(z)
    if data_type in "DF":
        inc = 1.0
        data = (z / 1.0).astype(X3P_DTYPES[data_type]).tobytes()
    else:
        inc = check_positive("z_increment", z_increment)
        info = np.iinfo(X3P_DTYPES[data_type])
        q = np.round(np.where(missing, 0.0, z) / inc)
        if q.min() < info.min or q.max() > info.max:
            raise ProblemInputError(f"heights overflow x3p type {data_type} at increment {inc:g}")
        data = q.astype(X3P_DTYPES[data_type]).tobytes()
    valid_xml = ""
    files: dict[str, bytes] = {"bindata/data.bin": data}
    if missing.any() and data_type in "LI":
        files["bindata/valid.bin"] = np.packbits(~missing.ravel(), bitorder="little").tobytes()
        valid_xml = "<ValidPointsLink>bindata/valid.bin</ValidPointsLink>"
    sy = spacing if spacing_y is None else spacing_y
    cz_inc = f"<Increment>{inc!r}</Increment>" if data_type in "LI" else ""
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="{X3P_NS}">
  <Record1>
    <Revision>ISO5436 - 2000</Revision>
    <FeatureType>SUR</FeatureType>
    <Axes>
      <CX><AxisType>I</AxisType><DataType>D</DataType><Increment>{float(spacing)!r}</Increment><Offset>0</Offset></CX>
      <CY><AxisType>I</AxisType><DataType>D</DataType><Increment>{float(sy)!r}</Increment><Offset>0</Offset></CY>
      <CZ><AxisType>A</AxisType><DataType>{data_type}</DataType>{cz_inc}<Offset>0</Offset></CZ>
    </Axes>
  </Record1>
  <Record2>
    <Date>2015-01-01T00:00:00</Date>
    <Creator>contactbench problems.io.write_x3p</Creator>
    <Instrument><Manufacturer>none</Manufacturer><Model>synthetic</Model><Serial>0</Serial><Version>1</Version></Instrument>
    <CalibrationDate>2015-01-01T00:00:00</CalibrationDate>
    <ProbingSystem><Type>NonContacting</Type><Identification>synthetic</Identification></ProbingSystem>
    <Comment>{_xml_escape(comment)}</Comment>
  </Record2>
  <Record3>
    <MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>
    <DataLink><PointDataLink>bindata/data.bin</PointDataLink><MD5ChecksumPointData>{hashlib.md5(data).hexdigest()}</MD5ChecksumPointData>{valid_xml}</DataLink>
  </Record3>
  <Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
</p:ISO5436_2>
""".encode()
    out = Path(path)
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("main.xml", xml)
        zf.writestr("md5checksum.hex", f"{hashlib.md5(xml).hexdigest()} *main.xml\n")
        for member, blob in files.items():
            zf.writestr(member, blob)
    return out


def _xml_escape(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def write_text(path: str | Path, z: np.ndarray, delimiter: str = ",") -> Path:
    """Write a height map as a text matrix (full float precision)."""
    buf = _stdio.StringIO()
    np.savetxt(buf, np.asarray(z, dtype=np.float64), delimiter=delimiter, fmt="%.17g")
    out = Path(path)
    out.write_text(buf.getvalue(), encoding="utf-8")
    return out


# ---------------------------------------------------------------------------
# Cleaning
# ---------------------------------------------------------------------------


def fill_missing(z: np.ndarray, rule: NanRule, path: str | Path, meta: dict[str, Any]) -> np.ndarray:
    """Replace NaN points by the documented rule (module doc, step 1)."""
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
    z = z.copy()
    if rule == "fill-mean":
        z[missing] = float(np.mean(z[~missing]))
    elif rule == "fill-min":
        z[missing] = float(np.min(z[~missing]))
    else:  # fill-nearest
        from scipy.ndimage import distance_transform_edt

        _, (ii, jj) = distance_transform_edt(missing, return_indices=True)
        z = z[ii, jj]
    warnings.warn(f"{path}: {n_missing} missing points ({n_missing / z.size:.1%}) filled by rule {rule!r}",
                  UserWarning, stacklevel=3)
    return z


def remove_tilt(z: np.ndarray, rule: DetrendRule, meta: dict[str, Any]) -> np.ndarray:
    """Subtract nothing, the mean, or the least-squares mean plane (module doc, step 2)."""
    meta["detrend"] = rule
    if rule == "none":
        return z
    if rule == "mean":
        meta["removed_mean"] = float(z.mean())
        return z - z.mean()
    ny, nx = z.shape
    yy, xx = np.mgrid[0:ny, 0:nx].astype(np.float64)
    A = np.column_stack([np.ones(z.size), xx.ravel(), yy.ravel()])
    coef, *_ = np.linalg.lstsq(A, z.ravel(), rcond=None)
    meta["removed_plane"] = {"a": float(coef[0]), "b_per_column": float(coef[1]), "c_per_row": float(coef[2])}
    return z - (A @ coef).reshape(z.shape)


def make_square(z: np.ndarray, rule: SquareRule, path: str | Path, meta: dict[str, Any]) -> np.ndarray:
    """Crop to the central square or pad with the lowest height (module doc, step 3)."""
    ny, nx = z.shape
    if ny == nx:
        meta["square"] = "already square"
        return z
    if rule == "error":
        raise SurfaceFileError(path, f"wrong shape: {ny} x {nx} is not square and square='error'")
    if rule == "crop":
        n = min(ny, nx)
        i0, j0 = (ny - n) // 2, (nx - n) // 2
        out = z[i0:i0 + n, j0:j0 + n]
        meta["square"] = f"cropped {ny}x{nx} to the central {n}x{n} (rows {i0}:{i0 + n}, cols {j0}:{j0 + n})"
    else:
        n = max(ny, nx)
        out = np.full((n, n), float(z.min()))
        out[:ny, :nx] = z
        meta["square"] = f"padded {ny}x{nx} to {n}x{n} with the lowest height {float(z.min()):.6g} (data top-left)"
    warnings.warn(f"{path}: non-square map {meta['square']}", UserWarning, stacklevel=3)
    return out


def _spacing(path: Path, n: int, length: float | None, file_spacing: float | None, meta: dict[str, Any]) -> float:
    if length is not None:
        L = check_positive("surface side length", length)
        meta["spacing_from"] = "length argument"
        return L / n
    if file_spacing is None:
        raise SurfaceFileError(path, "the file states no grid spacing; give the side length (length=..., --length)")
    meta["spacing_from"] = "file"
    return float(file_spacing)


def _check_choice(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ProblemInputError(f"{what} must be one of {', '.join(map(repr, allowed))}, got {value!r}")


__all__ = [
    "RawMap",
    "SurfaceFileError",
    "fill_missing",
    "load_surface",
    "make_square",
    "read_height_map",
    "read_npy",
    "read_text",
    "read_x3p",
    "remove_tilt",
    "write_text",
    "write_x3p",
]
