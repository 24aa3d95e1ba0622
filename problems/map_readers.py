"""Measured height maps: reading every format SurfaceTopography knows, plus .npy and text,
into a ``RawMap`` (heights before cleaning; ``problems.io.load_surface`` cleans them).

Formats read by :func:`read_height_map`:

* ``.npy``  -- ``numpy.load(..., allow_pickle=False)``: pickled/object arrays and files
  without NumPy's header are refused, never loaded.  The array is (rows = y, columns = x).
* text      -- a plain matrix of numbers, one row per line; the delimiter (comma,
  semicolon, tab or white space) is detected from the first data line; ``#`` starts a
  comment; ``nan`` marks a missing point.  Numbers are written plainly (``problems.units.plain_float``)
  with a decimal point: a decimal comma ("-0,61;...", a European spreadsheet's export) and
  underscores between digits ("1_0e-7") are refused in one line.
* x,y,z columns -- a text file of 3 columns and at least ``XYZ_MIN_ROWS`` rows whose
  first two columns look like coordinates is read as x, y, z, not as a matrix of 3
  columns.  A column looks like a coordinate when its distinct values (at least 2) are
  evenly spaced (``COORD_RTOL`` of the step).  When x and y both do and every point of
  the nx x ny grid occurs exactly once, the map is that grid: rows in increasing y,
  columns in increasing x, spacings the steps of y and x, and x, y, z in one unit (the
  height unit: the file states the lateral size, so ``length`` may be omitted).  When
  column 0 or 1 is such a coordinate and also monotone, but the points do not fill a
  regular grid (scattered or missing points), the file is refused in one line.  A file of
  2 columns and at least ``XYZ_MIN_ROWS`` rows whose column 0 is a monotone coordinate
  is an x,z profile: refused (a 1-D profile is no map).  A measured map's heights are
  never evenly spaced, so N x 2 or N x 3 heights are a matrix (refused as too narrow, as
  follows), and a file of fewer than ``XYZ_MIN_ROWS`` rows always is.
* everything else -- through SurfaceTopography's readers (about 40 instrument formats:
  ISO 25178-71 .x3p and .sdf, Gwyddion .gwy, NetCDF .nc, MATLAB .mat, Keyence .vk4,
  Zygo .datx, Wyko .opd, Sensofar .plu, Digital Surf .sur, Bruker .spm, Olympus .lext,
  Alicona .al3d, ...).  The reader is chosen by the file's extension when
  SurfaceTopography knows it (so a damaged file gets that format's own error), else by
  content.  Heights and the lateral size are converted to metres from the file's own
  unit (``RawMap.unit_known``); a file with no unit (.npy, text, .mat, .npz) is read in
  the caller's height unit.  SurfaceTopography indexes heights [x, y]; a map is [y, x]
  (rows = y), so maps are transposed on the way in -- except bare-matrix containers
  (.mat, .npz), whose matrix is taken as it is, like a .npy.

Refused with a ``SurfaceFileError`` (one line naming the file): non-uniform line scans,
1-D profiles, multi-channel files without a chosen ``channel`` (a channel name that two
channels share is ambiguous: they are chosen by index), units that do not convert to
metres, heights so large that sums over the map overflow (``HEIGHT_CEILING``), infinite
heights, true/false or complex values, maps of fewer than ``MIN_MAP_SIDE`` points along a
side, and a zip archive that is no map (several map files, one to unzip, or none).  A file
holding more data than its header states is refused, not read as a smaller, scrambled map: .npy (the header's shape), .x3p (main.xml's sizes and data type,
and the MD5 checksum of the point data that main.xml states, which SurfaceTopography does
not verify), binary .sdf (the header's NumPoints x NumProfiles values; bytes after them
must be the text trailer the format allows) and ASCII .sdf (SurfaceTopography's reader
counts the values).  An .x3p of integer heights (DataType I or L) with no CZ increment
states no height unit, and a CZ increment <= 0 would scale or flip the heights: both are
refused.  This module parses no XML itself (SurfaceTopography's parse is read).
"""

from __future__ import annotations

import functools
import math
import hashlib
import re
import struct
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ProblemInputError, check_positive, printable_excerpt
from .output_streams import ForeignOutput, foreign_output_held
from .units import plain_float

NPY_MAGIC = b"\x93NUMPY"
#: Bytes of one height of each x3p DataType (ISO 25178-72: int16, int32, float32, float64).
X3P_BYTES = {"I": 2, "L": 4, "F": 4, "D": 8}
#: The x3p DataTypes of integer heights: they state their unit only through the CZ increment.
X3P_INTEGER_TYPES = ("I", "L")
#: An ISO 25178-71 .sdf: the magic of each variant; a binary one's header length (magic
#: and fields), where its NumPoints and NumProfiles (uint16) start, and the bytes of one
#: value of each DataType (0-7: uint8, uint16, uint32, float32, int8, int16, int32, float64).
SDF_BINARY_MAGIC = b"bISO-1.0"
SDF_ASCII_MAGIC = b"aISO-1.0"
SDF_HEADER_BYTES = 81
SDF_SIZE_OFFSET = 42
SDF_BYTES = {0: 1, 1: 2, 2: 4, 3: 4, 4: 1, 5: 2, 6: 4, 7: 8}
#: Bytes a binary .sdf's text trailer may hold after its data: printable ASCII and white space.
SDF_TRAILER_BYTES = frozenset(range(0x20, 0x7F)) | frozenset(b"\t\r\n")
TEXT_SUFFIXES = (".txt", ".csv", ".tsv")
#: SurfaceTopography formats that hold a bare matrix: taken as (rows, columns) like a .npy.
MATRIX_FORMATS = ("mat", "npz")
#: A map's heights are refused above this over its point count: sqrt(the largest float), so
#: the cleaning's sums of squares stay finite.
HEIGHT_CEILING = float(np.sqrt(np.finfo(np.float64).max))
#: Relative disagreement allowed between a given length and the file's own lateral size.
LENGTH_RTOL = 1e-6
#: A text file of 2 or 3 columns is checked for coordinate columns (x,y,z or x,z) from
#: this many rows on; with fewer it is a matrix (module doc).
XYZ_MIN_ROWS = 16
#: Distinct values of a coordinate column are evenly spaced within this fraction of the
#: step (room for the rounding of printed coordinates).
COORD_RTOL = 1e-2
#: Values of a coordinate column closer than this fraction of its span are one value.
COORD_TIE = 1e-9
#: A number written with a decimal comma (a European spreadsheet's export): -0,61 or 6,1e-07.
DECIMAL_COMMA = re.compile(r"^[-+]?\d*,\d+([eE][-+]?\d+)?$")
#: The fewest points a map may have along each side: fewer fix no plane, no slope and no
#: roughness to speak of (a 2 x N "map" is two profiles, not a surface).
MIN_MAP_SIDE = 8


class SurfaceFileError(ProblemInputError):
    """A height-map file that cannot be used; the message names the file and the problem."""

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"cannot use surface file {self.path!r}: {problem}")


@dataclass
class RawMap:
    """A height map as read from a file, before cleaning: z (ny x nx, metres once
    ``unit_known``, NaN for missing points), the spacings (axis 0, axis 1) the file
    states, in the unit of z (None when it states none), and what its reader said."""

    z: np.ndarray
    spacing: tuple[float, float] | None
    fmt: str
    info: dict[str, Any] = field(default_factory=dict)
    unit_known: bool = False
    #: What a foreign reader said while it read the map, as our one-line warnings
    #: (``ForeignOutput.notes``): ``problems.io.load_surface`` announces them.
    reader_notes: tuple[str, ...] = ()


def read_height_map(path: str | Path, channel: int | str | None = None) -> RawMap:
    """Read the raw map of any supported format (module doc)."""
    p = Path(path)
    head = _read_head(p)
    suffix = p.suffix.lower()
    if head.startswith(NPY_MAGIC) or suffix == ".npy":
        _only_channel(p, channel)
        return read_npy(p)
    ext = suffix.lstrip(".")
    if suffix in TEXT_SUFFIXES or (ext not in _topography_formats() and _looks_like_text(p)):
        _only_channel(p, channel)
        return read_text(p)
    return read_with_surfacetopography(p, _topography_formats().get(ext), channel)


def _read_head(p: Path) -> bytes:
    try:
        with open(p, "rb") as f:
            return f.read(8)
    except OSError as e:
        raise SurfaceFileError(p, f"unreadable path ({e.strerror or e})") from None


@functools.cache
def _topography_formats() -> dict[str, str | None]:
    """File extension -> SurfaceTopography format id (None where several formats share it);
    listed once per process (listing the readers takes a good part of a second)."""
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


def check_npy_size(p: Path) -> None:
    """Refuse, in one ``SurfaceFileError`` line, a file with NumPy's header whose shape and
    data type need more bytes than follow the header: NumPy would allocate the declared
    array (terabytes for a 2 KB file) before finding the data short.  A file without the
    header, or one whose header does not parse, is left to the reader (``read_npy``)."""
    try:
        with open(p, "rb") as f:
            if not f.read(len(NPY_MAGIC)).startswith(NPY_MAGIC):
                return
            f.seek(0)
            version = np.lib.format.read_magic(f)
            read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                np.lib.format.read_array_header_2_0
            shape, _, dtype = read_header(f)
            held = p.stat().st_size - f.tell()
    except (OSError, ValueError, TypeError, SyntaxError, UnicodeDecodeError):
        return
    if dtype.hasobject or any(not isinstance(n, int) or n < 0 for n in shape):
        return
    needed = math.prod(shape) * dtype.itemsize
    if needed > held:
        dims = " x ".join(str(n) for n in shape) or "one"
        raise SurfaceFileError(p, f"its .npy header declares {dims} values of {dtype} ({needed:,} bytes), but only "
                                  f"{max(held, 0):,} bytes of data follow it (a truncated file or a header that lies)")


def read_npy(path: str | Path) -> RawMap:
    """A 2-D numeric .npy array; pickles are never loaded."""
    p = Path(path)
    if not _read_head(p).startswith(NPY_MAGIC):
        raise SurfaceFileError(p, "not a .npy file: it lacks NumPy's header")
    check_npy_size(p)
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
    """A plain text/CSV matrix, or x,y,z columns of a regular grid (module doc); the
    delimiter is detected from the first data line."""
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
            rows.append([plain_float(c) for c in cells])
        except ValueError:
            raise SurfaceFileError(p, _not_a_number(ln, cells, lineno)) from None
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        first = len(rows[0])
        k = next(i for i, r in enumerate(rows) if len(r) != first)
        raise SurfaceFileError(
            p, f"wrong shape: rows of different lengths ({first} values on the first row, "
               f"{len(rows[k])} on data row {k + 1}); truncated or not a matrix")
    a = np.array(rows, dtype=np.float64)
    info = {"delimiter": delim or "whitespace"}
    grid = xyz_grid(p, a)
    if grid is not None:
        z, spacing = grid
        return RawMap(_numeric_matrix(p, z), spacing, "text-xyz", {**info, "layout": "x,y,z columns"})
    return RawMap(_numeric_matrix(p, a), None, "text", info)


def _not_a_number(line: str, cells: list[str], lineno: int) -> str:
    """The one-line account of a text row with a cell that is not a number: a decimal
    comma (``DECIMAL_COMMA``) is named as such, with how to convert the file."""
    comma = next((t for t in re.split(r"[;\s]+", line) if DECIMAL_COMMA.match(t)), None)
    if comma is not None:
        return (f"decimal commas are not read ({comma!r} on line {lineno}); write the numbers with a decimal "
                "point: export with '.' as the decimal separator, or replace each ',' by '.' in a file whose "
                "columns are separated by ';', tabs or spaces")
    bad = next(c for c in cells if not _is_float(c))
    if bad.isascii() and "_" in bad and _is_float(bad.replace("_", "")):
        return f"{bad!r} on line {lineno} is not a plainly written number (no '_' between digits)"
    return f"non-numeric value {bad!r} on line {lineno}"


def _lattice(values: np.ndarray) -> tuple[np.ndarray, float, int] | None:
    """(index of each value, step, count) when the distinct values of ``values`` (at least
    2, finite; values within ``COORD_TIE`` of the span are one) are evenly spaced within
    ``COORD_RTOL`` of the step: a coordinate column; else None."""
    u = np.unique(values)
    if u.size < 2 or not np.all(np.isfinite(u)):
        return None
    span = float(u[-1] - u[0])
    u = u[np.concatenate([[True], np.diff(u) > COORD_TIE * span])]
    step = span / (u.size - 1)
    if u.size < 2 or np.max(np.abs(np.diff(u) - step)) > COORD_RTOL * step:
        return None
    return np.rint((values - u[0]) / step).astype(np.int64), step, int(u.size)


def _monotone_coordinate(values: np.ndarray) -> bool:
    """Whether a column is an evenly spaced coordinate (``_lattice``: finite values) that
    never turns back."""
    if _lattice(values) is None:
        return False
    d = np.diff(values)
    return bool(np.all(d >= 0) or np.all(d <= 0))


def xyz_grid(p: Path, a: np.ndarray) -> tuple[np.ndarray, tuple[float, float]] | None:
    """The map (rows in increasing y, columns in increasing x) and its spacings (y step,
    x step) when the text matrix ``a`` is x,y,z columns of a full regular grid; None when it
    is a matrix of heights; a ``SurfaceFileError`` for x,y,z columns that fill no regular
    grid and for an x,z profile (module doc: the rule)."""
    n, m = a.shape
    if m not in (2, 3) or n < XYZ_MIN_ROWS:
        return None
    if m == 2:
        if _monotone_coordinate(a[:, 0]):
            raise SurfaceFileError(p, f"{n} rows of 2 columns whose first is an evenly spaced, monotone coordinate: "
                                      "an x,z profile, not a 2-D height map; give a matrix (one row per y line) or "
                                      "x,y,z columns of a regular grid")
        return None
    x, y = _lattice(a[:, 0]), _lattice(a[:, 1])
    if x is not None and y is not None and x[2] * y[2] == n:
        cells = y[0] * x[2] + x[0]
        if np.unique(cells).size == n:
            z = np.full((y[2], x[2]), np.nan)
            z[y[0], x[0]] = a[:, 2]
            return z, (y[1], x[1])
    if _monotone_coordinate(a[:, 0]) or _monotone_coordinate(a[:, 1]):
        found = ", ".join(f"{k} takes {c[2]} evenly spaced values" if c else f"{k} is not evenly spaced"
                          for k, c in (("x", x), ("y", y)))
        raise SurfaceFileError(p, f"{n} rows of 3 columns that look like x,y,z coordinates and heights, but the "
                                  f"points do not fill a regular grid ({found}); give a matrix (one row per y "
                                  "line) or x,y,z columns of a full regular grid")
    return None


def _is_float(s: str) -> bool:
    try:
        plain_float(s)
    except ValueError:
        return False
    return True


def _numeric_matrix(p: Path, a: np.ndarray) -> np.ndarray:
    """``a`` as float64 heights: integer or float numbers (booleans and complex numbers are
    no heights), 2-D, at least ``MIN_MAP_SIDE`` points along each side, no infinite value
    and none so large that sums over the map overflow (``HEIGHT_CEILING``)."""
    if a.dtype.kind in "bc":
        what = "true/false values" if a.dtype.kind == "b" else "complex numbers"
        raise SurfaceFileError(p, f"{what} (dtype {a.dtype}), not heights; need integer or float numbers")
    if a.dtype.kind not in "iuf":
        raise SurfaceFileError(p, f"non-numeric data (dtype {a.dtype}); need real numbers")
    if a.ndim != 2:
        raise SurfaceFileError(p, f"wrong shape: need a 2-D height map, got a {a.ndim}-D array of shape {a.shape}")
    if min(a.shape) < MIN_MAP_SIDE:
        raise SurfaceFileError(p, f"wrong shape: {a.shape[0]} x {a.shape[1]} points; a map needs at least "
                                  f"{MIN_MAP_SIDE} points along each side")
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
    in metres when the file states its unit; every failure is a :class:`SurfaceFileError`
    whose reason is printable (``printable_excerpt``).  What the readers print, log or warn
    while they run is held off the terminal (``foreign_output_held``); after a read that
    succeeds it is kept as ``RawMap.reader_notes``."""
    from SurfaceTopography.IO import open_topography

    what, said, reader = fmt or "the detected format", ForeignOutput(), None
    try:
        with foreign_output_held() as said:
            try:
                reader = open_topography(str(p), format=fmt)
                what = f"{reader.name()} (.{reader.format()})"
                info = _pick_channel(p, reader, channel)
                kw = {"physical_sizes": tuple(float(n) for n in info.nb_grid_pts)} if info.physical_sizes is None else {}
                topo = reader.topography(channel_index=info.index, **kw)
                h = np.ma.asarray(topo.heights(), dtype=np.float64)
                heights = np.where(np.isinf(h.data), h.data, np.ma.filled(h, np.nan))  # an inf stays one (refused)
            finally:
                close_reader(reader)
    except SurfaceFileError:
        raise
    except Exception as e:  # the readers raise many kinds; each becomes one clear line
        raise SurfaceFileError(p, _archive_account(p, what) or _reader_failure(e, what, said.written)) from None
    fmt_id = reader.format()
    z = heights if fmt_id in MATRIX_FORMATS else heights.T
    meta: dict[str, Any] = {"reader": f"SurfaceTopography {_st_version()}", "channel": info.name,
                            "channel_index": int(info.index), "file_unit": topo.unit}
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
    if fmt_id == "sdf":
        _sdf_checks(p)
    z = _numeric_matrix(p, z) * (factor or 1.0)
    return RawMap(z, spacing, fmt_id, meta, unit_known=factor is not None, reader_notes=said.notes())


#: The start of SciPy's RuntimeWarning when a netcdf_file opened with mmap=True (as
#: SurfaceTopography's NetCDF reader opens one) is closed while arrays still refer to its
#: data: about SciPy's own buffers, not the map, so never passed on (``close_reader``).
NETCDF_MMAP_WARNING = "Cannot close a netcdf_file opened with mmap=True"


def close_reader(reader: Any) -> None:
    """Close a SurfaceTopography reader (None: nothing to close) at once, with exactly
    SciPy's ``NETCDF_MMAP_WARNING`` silenced.  Closed here, not when the garbage collector
    drops the reader, so that warning cannot surface later, outside any read, as a warning
    of ours; every other warning of the close passes as usual."""
    if reader is None:
        return
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=re.escape(NETCDF_MMAP_WARNING), category=RuntimeWarning)
        reader.close()


def _reader_failure(e: Exception, what: str, written: str = "") -> str:
    """The reason, in our words, a SurfaceTopography reader refused a file: with the
    reader's own (its exception's message, else the start of what it ``written``), as
    printable text (``printable_excerpt``)."""
    from SurfaceTopography.Exceptions import CannotDetectFileFormat, CorruptFile, FileFormatMismatch

    msg = printable_excerpt(str(e)) or printable_excerpt(written) or type(e).__name__
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


def _archive_account(p: Path, what: str) -> str | None:
    """Why a zip archive that is no ISO 25178 .x3p (no main.xml) failed its reader: it holds
    several map files, or one (to unzip: members of a binary format a reader knows by its
    extension), or none (the members named); an .x3p under another extension is named as
    such.  None for a file that is no zip archive, and for an .x3p, whose own reader's
    failure says more."""
    if p.suffix.lower() == ".x3p" or not zipfile.is_zipfile(p):
        return None
    try:
        with zipfile.ZipFile(p) as zf:
            names = [n for n in zf.namelist() if not n.endswith("/")]
    except (OSError, zipfile.BadZipFile):
        return None
    if "main.xml" in names:
        return f"an ISO 25178 .x3p archive under the extension {p.suffix or '(none)'!r}: rename it to .x3p"
    known = {*_topography_formats(), "npy"} - {"zip", *(s.lstrip(".") for s in TEXT_SUFFIXES)}
    maps = [n for n in names if Path(n).suffix.lower().lstrip(".") in known]
    listing = ", ".join(maps[:5] or names[:5]) + (", ..." if len(maps or names) > 5 else "")
    if len(maps) > 1:
        return f"a zip archive of {len(maps)} map files ({listing}), not one map: unzip it and give one of them"
    if maps:
        return f"a zip archive of one map file ({listing}): unzip it and give that file"
    return (f"a zip archive with no map file in it that the {what} reader reads ({listing or 'empty'}); give the "
            "map file itself, unzipped")


def _pick_channel(p: Path, reader: Any, channel: int | str | None) -> Any:
    """The chosen channel's info (``channel``: its index, or a name no other channel has);
    refuses an unchosen multi-channel file, an ambiguous name, line scans and profiles."""
    chans = list(reader.channels)
    listing = "; ".join(f"{c.index}: {c.name!r}" for c in chans)
    if channel is None:
        if len(chans) > 1:
            raise SurfaceFileError(p, f"{len(chans)} channels ({listing}); choose one with --channel INDEX|NAME")
        info = chans[0]
    else:
        key = str(channel)
        hits = [c for c in chans if str(c.index) == key] or [c for c in chans if c.name == key]
        if len(hits) > 1:
            indices = ", ".join(str(c.index) for c in hits)
            raise SurfaceFileError(p, f"{len(hits)} channels are named {key!r} (indices {indices}; it has {listing}); "
                                      f"the name is ambiguous: choose one by index, --channel {hits[0].index}")
        if not hits:
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
    z_increment = _x3p_z_increment(p, cz)
    incs = [axes.get(a, {}).get("Increment") for a in ("CX", "CY")] + [z_increment]
    return {"x3p_data_type": cz.get("DataType"), "x3p_increments": [float(v) for v in incs if v is not None]}


def _x3p_z_increment(p: Path, cz: dict[str, Any]) -> float:
    """The CZ increment main.xml states (1 for float heights that state none); refused
    where it states no unit (integer heights without one) or would scale the heights by a
    value that is not finite and > 0 (0 flattens them, a negative one turns the map upside
    down)."""
    stated, data_type = cz.get("Increment"), cz.get("DataType")
    if stated is None:
        if data_type in X3P_INTEGER_TYPES:
            raise SurfaceFileError(p, f"integer heights (DataType {data_type}) with no CZ increment in main.xml: "
                                      "their unit is unknown (counts, not metres); refused")
        return 1.0
    try:
        return check_positive("the CZ increment of main.xml (metres per height value)", float(stated))
    except (ProblemInputError, TypeError, ValueError):
        raise SurfaceFileError(p, f"the CZ increment of main.xml is {stated!r}: heights are scaled by it, so it must "
                                  "be a finite number > 0 (0 flattens the map, a negative one turns it upside "
                                  "down)") from None


def _sdf_checks(p: Path) -> None:
    """An .sdf holds the NumPoints x NumProfiles values its header states, no more: a
    binary one followed by nothing or by a text trailer, an ASCII one up to the ``*`` that
    ends its data region.  SurfaceTopography reads the stated count (more data: a smaller,
    scrambled map) and refuses fewer."""
    raw = p.read_bytes()
    if raw.startswith(SDF_BINARY_MAGIC) and len(raw) >= SDF_HEADER_BYTES:
        points, profiles = struct.unpack_from("<HH", raw, SDF_SIZE_OFFSET)
        data_type = raw[SDF_HEADER_BYTES - 2]
        stated = points * profiles * SDF_BYTES.get(data_type, 0)
        trailer = raw[SDF_HEADER_BYTES + stated:]
        if stated and not all(b in SDF_TRAILER_BYTES for b in trailer):
            raise SurfaceFileError(p, f"it holds {len(raw) - SDF_HEADER_BYTES} bytes after its header where the "
                                      f"header states {points} x {profiles} values of {SDF_BYTES[data_type]} bytes "
                                      f"({stated}), and what follows is no text trailer")
    elif raw.startswith(SDF_ASCII_MAGIC):
        text = raw.decode("ascii", errors="replace")
        sizes = [re.search(rf"^\s*{k}\s*=\s*(\d+)", text, re.M) for k in ("NumPoints", "NumProfiles")]
        tokens = text.split()
        if "*" not in tokens or not all(sizes):
            return  # (SurfaceTopography's reader has refused such a header)
        start = tokens.index("*") + 1
        end = tokens.index("*", start) if "*" in tokens[start:] else len(tokens)
        points, profiles = (int(m.group(1)) for m in sizes if m)
        if end - start != points * profiles:
            raise SurfaceFileError(p, f"its data region holds {end - start} values where its header states "
                                      f"{points} x {profiles}")


def _st_version() -> str:
    import SurfaceTopography

    return str(getattr(SurfaceTopography, "__version__", "?"))




__all__ = [
    "COORD_RTOL",
    "HEIGHT_CEILING",
    "LENGTH_RTOL",
    "MIN_MAP_SIDE",
    "NETCDF_MMAP_WARNING",
    "XYZ_MIN_ROWS",
    "RawMap",
    "SurfaceFileError",
    "check_npy_size",
    "close_reader",
    "read_height_map",
    "read_npy",
    "read_text",
    "read_with_surfacetopography",
    "xyz_grid",
]
