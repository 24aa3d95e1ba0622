"""Height-map writers (test data, the bundled samples), the counterpart of
problems/map_readers.py's readers: SurfaceTopography's writers for x3p, gwy and NetCDF, an
ISO 25178-71 .sdf (binary or ASCII, float64 heights in metres) and a text matrix.  A map
they write is one the readers take: a 2-D map of finite heights or NaN (missing points),
and finite spacings > 0.
"""

from __future__ import annotations

import io as _stdio
import struct
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ProblemInputError, check_positive


def _spacings(spacing: float | tuple[float, float]) -> tuple[float, float]:
    """(axis 0, axis 1) spacings: finite and > 0 (``check_positive``), else ``ProblemInputError``."""
    pair = (spacing, spacing) if np.ndim(spacing) == 0 else tuple(spacing)  # type: ignore[arg-type]
    if len(pair) != 2:
        raise ProblemInputError(f"a map's spacing is one or two numbers (metres), got {spacing!r}")
    return check_positive("a map's spacing", pair[0]), check_positive("a map's spacing", pair[1])


def write_topography(path: str | Path, z: np.ndarray, spacing: float | tuple[float, float], fmt: str = "x3p",
                     **kw: Any) -> Path:
    """Write a height map (ny x nx, metres; ``spacing`` one float or (axis 0, axis 1)) with
    SurfaceTopography's writer ``to_<fmt>`` (x3p, gwy, netcdf); ``kw`` go to the writer
    (x3p: ``dtype`` D, F, L or I)."""
    from SurfaceTopography import Topography

    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2:
        raise ProblemInputError(f"the {fmt} writer needs a 2-D map, got shape {z.shape}")
    if np.isinf(z).any():
        raise ProblemInputError("a map's heights are finite numbers or NaN (missing), got inf")
    dy, dx = _spacings(spacing)
    ny, nx = z.shape
    h = np.ma.masked_invalid(z.T) if np.isnan(z).any() else z.T
    topo = Topography(h, physical_sizes=(nx * float(dx), ny * float(dy)), unit="m")
    writer = getattr(topo, f"to_{fmt}", None)
    if writer is None:
        raise ProblemInputError(f"SurfaceTopography has no writer for {fmt!r} (x3p, gwy, netcdf)")
    writer(str(path), **kw)
    return Path(path)


def write_x3p(path: str | Path, z: np.ndarray, spacing: float | tuple[float, float], *, data_type: str = "D") -> Path:
    """An ISO 25178-71 .x3p file (SurfaceTopography's writer; integer types L, I are
    scaled over their full range)."""
    return write_topography(path, z, spacing, "x3p", dtype=data_type)


def write_sdf(path: str | Path, z: np.ndarray, spacing: float | tuple[float, float], *, binary: bool = True) -> Path:
    """An ISO 25178-71 .sdf of float64 heights in metres (DataType 7, Zscale 1): NumPoints
    = the columns (x, spacing axis 1), NumProfiles = the rows (y, spacing axis 0), one
    profile (row) after another; binary (little endian) or ASCII."""
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2 or np.isinf(z).any():
        raise ProblemInputError("the sdf writer needs a 2-D map of finite heights or NaN")
    dy, dx = _spacings(spacing)
    ny, nx = z.shape
    out = Path(path)
    stamp = "010120000000"
    if binary:
        header = struct.pack("<8s10s12s12sHHddddBBB", b"bISO-1.0", b"contactb", stamp.encode(), stamp.encode(),
                             nx, ny, dx, dy, 1.0, -1.0, 0, 7, 0)
        out.write_bytes(header + z.astype("<f8").tobytes())
        return out
    fields = {"ManufacID": "contactb", "CreateDate": stamp, "ModDate": stamp, "NumPoints": nx, "NumProfiles": ny,
              "Xscale": repr(dx), "Yscale": repr(dy), "Zscale": 1.0, "Zresolution": -1, "Compression": 0,
              "DataType": 7, "CheckType": 0}
    lines = ["aISO-1.0", *(f"{k} = {v}" for k, v in fields.items()), "*"]
    lines += [" ".join("BAD" if np.isnan(v) else repr(float(v)) for v in row) for row in z]
    out.write_text("\n".join([*lines, "*", ""]), encoding="ascii")
    return out


def write_text(path: str | Path, z: np.ndarray, delimiter: str = ",") -> Path:
    """Write a height map as a text matrix (full float precision)."""
    buf = _stdio.StringIO()
    np.savetxt(buf, np.asarray(z, dtype=np.float64), delimiter=delimiter, fmt="%.17g")
    out = Path(path)
    out.write_text(buf.getvalue(), encoding="utf-8")
    return out
