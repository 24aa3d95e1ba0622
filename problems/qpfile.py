"""The language-neutral file protocol of one contact QP (``contactbench-qp/1``, and
``contactbench-qp/2`` for a QP with bounds or a load equality).

A *problem directory* holds ``problem.json`` and raw little-endian, C-order array files;
a *solution directory* holds what an outside program answers.  Any program that reads
and writes these files -- C, Fortran, MATLAB/Octave, Julia, Python -- can be judged by
the harness (``contactbench.solvers.external``, docs/external-solvers.md).

Problem directory
-----------------
``problem.json``::

    {"format": "contactbench-qp/1", "n": 400, "grid": [20, 20], "spacing": 1.0,
     "spacing1": 1.0, "E": 0.01, "kernel": "bcc", "periodic": false, "tol": 1e-08, "time_limit": 60.0,
     "max_iter": null, "singular": false,
     "arrays": {"ubar": {"file": "ubar.f64", "dtype": "<f8", "shape": [400]}, ...}}

``max_iter`` is the iteration limit the program must honour (null: none; at the limit it
stops and reports a non-claiming status such as "max_iter"); ``singular`` is true when H
is singular -- a periodic QP on its whole grid, where H 1 = 0 -- and H is positive
definite otherwise (a reader of a file without these keys takes null and false).

``grid`` is [N1, N2]: N1 points along axis 0 (grid index i), N2 along axis 1 (index j);
``spacing`` is the grid spacing along axis 0 and ``spacing1`` the one along axis 1 (a
reader of a file without ``spacing1`` takes it equal to ``spacing``: square pixels).

The arrays (each listed under ``"arrays"`` with its file, dtype and shape):

``ubar``          (n,) float64: the rigid-body interpenetration; the QP is
                  min 1/2 p'Hp - ubar'p, p >= 0.
``index``         (n, 2) int64: grid indices (i, j) of each unknown on the N1 x N2 grid.
``H``             (n, n) float64, row-major: the influence matrix on the unknowns;
                  written whenever n <= ``DENSE_LIMIT`` (env CONTACTBENCH_QPFILE_DENSE_LIMIT).
``kernel_table``  (P1, P2) float64: the influence coefficients of the FFT operator.
                  Aperiodic: P = 2N, H[a, b] = K[(i_a - i_b) mod P1, (j_a - j_b) mod P2]
                  (offset -k stored at P - k; offset N is zero).  Periodic: P = N,
                  the same formula (the table has its mean removed).
``p0``            (n,) float64: a warm start, when the harness has one.
``upper``         (n,) float64 (format 2 only): upper bounds, 0 <= p <= upper (a
                  hardness; ``inf`` where an element has none).

Format 2 (``contactbench-qp/2``) is written only for a QP with bounds or a load equality
(``problems.constraints``); a plain QP is still written as format 1, and both are read.
Its ``problem.json`` adds ``"load"``: null, or the total force P of the equality row
1'p = P (load control), whose multiplier is the approach Delta: the KKT conditions are
w = Hp - ubar - Delta with w >= 0 where p = 0, w <= 0 where p = upper, w = 0 in between.

A QP without a grid (a generic SPD matrix of the conformance battery) has ``"grid":
null``, ``"spacing": null``, ``"spacing1": null``, ``"kernel": null`` and no ``index`` or
``kernel_table``: only ``H``.

Solution directory
------------------
``p.f64`` (n float64, little-endian) is required; ``w.f64`` (n float64) and
``solution.json`` (``iterations``: a whole number from 0 to 2^63 - 1; ``status``;
``time_s``: finite seconds >= 0; and under load control ``multiplier``, the approach
Delta: a finite number; each key once) are optional.
``read_solution_dir`` checks them and says, in one line, what is wrong.
"""

from __future__ import annotations

import json
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .constraints import Constraints, make_constraints
from .errors import COUNT_MAX, ProblemInputError, is_count, printable_excerpt
from .instances import QP, ContactInstance, Geometry
from .kernels import KERNELS, kernel_table
from .operators import ContactOperator, DenseOperator, FFTOperator, KernelTransform

#: The format tag of problem.json for a plain QP (p >= 0 only).
FORMAT = "contactbench-qp/1"
#: The format tag of a QP with bounds or a load equality (module doc).
FORMAT_CONSTRAINED = "contactbench-qp/2"
#: The tags ``read_problem_dir`` reads.
READABLE_FORMATS = (FORMAT, FORMAT_CONSTRAINED)
#: H is written as a dense n x n file when n is at most this (4096: 128 MiB).
DENSE_LIMIT = int(os.environ.get("CONTACTBENCH_QPFILE_DENSE_LIMIT", "4096"))
#: File names of the arrays in a problem directory.
ARRAY_FILES = {"ubar": "ubar.f64", "index": "index.i64", "H": "H.f64", "kernel_table": "kernel_table.f64",
               "p0": "p0.f64", "upper": "upper.f64"}
#: The file of a problem directory that describes it.
PROBLEM_JSON = "problem.json"
#: Every file name the format defines for a problem directory: what ``write_problem_dir``
#: may write (and remove) there.
PROBLEM_DIR_FILES = frozenset({PROBLEM_JSON, *ARRAY_FILES.values()})
#: File names of a solution directory.
SOLUTION_P, SOLUTION_W, SOLUTION_JSON = "p.f64", "w.f64", "solution.json"
#: Statuses of solution.json that claim convergence (no status at all claims it too).
CLAIM_STATUSES = ("converged", "solved", "optimal")
#: Statuses that honestly claim nothing.
NON_CLAIM_STATUSES = ("not_converged", "max_iter", "time_limit", "stalled", "failed")
#: Every status an outside program may report; any other word is a ``SolutionFileError``.
SOLUTION_STATUSES = CLAIM_STATUSES + NON_CLAIM_STATUSES


class SolutionFileError(RuntimeError):
    """A solution directory whose answer cannot be used (missing, unreadable, wrong
    length, non-finite or negative p); the message names which.  Not a
    ``ProblemInputError``: the program answered badly, the problem was fine."""


# ---------------------------------------------------------------------------
# Writing a problem directory
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Physics:
    E: float | None
    kernel: str | None
    periodic: bool


def _physics(obj: QP | ContactInstance) -> tuple[QP, _Physics]:
    if isinstance(obj, ContactInstance):
        return obj.qp, _Physics(float(obj.E), str(obj.kernel), bool(obj.periodic))
    if isinstance(obj, QP):
        g = obj.geometry
        return obj, _Physics(None if g is None or g.E is None else float(g.E),
                             None if g is None else g.kernel, bool(g is not None and g.periodic))
    raise ProblemInputError(f"write_problem_dir takes a QP or a ContactInstance, got {type(obj).__name__}")


def _table_matches(table: np.ndarray, geom: Geometry, op: ContactOperator) -> bool:
    """Whether the table reproduces H on a few sampled pairs (it must, or it is not written)."""
    ij = _grid_index(geom)
    rng = np.random.default_rng(0)
    rows = rng.integers(0, op.n, size=min(64, op.n))
    cols = rng.integers(0, op.n, size=rows.size)
    d = ij[rows] - ij[cols]
    want, got = op.entries(rows, cols), table[d[:, 0] % table.shape[0], d[:, 1] % table.shape[1]]
    scale = float(np.max(np.abs(op.diagonal())))
    return bool(np.all(np.abs(want - got) <= 1e-12 * scale))


def problem_kernel_table(qp: QP, phys: _Physics) -> np.ndarray | None:
    """The influence coefficients of the operator (None: H is not a grid kernel)."""
    if isinstance(qp.H, FFTOperator):
        return np.asarray(qp.H.transform.table, dtype=np.float64)
    g = qp.geometry
    if g is None or phys.kernel not in KERNELS or phys.E is None:
        return None
    table = kernel_table(phys.kernel, g.grid_shape, g.spacing, phys.E, phys.periodic)
    return table if _table_matches(table, g, qp.H) else None


def _grid_index(geom: Geometry) -> np.ndarray:
    i, j = np.divmod(np.asarray(geom.indices, dtype=np.int64), int(geom.grid_shape[1]))
    return np.column_stack([i, j]).astype("<i8")


def _finite_or_none(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _iteration_limit(max_iter: int | None) -> int | None:
    """``max_iter`` as problem.json writes it: None, or a whole number 0 .. 2^63 - 1."""
    if max_iter is None:
        return None
    if not is_count(max_iter):
        raise ProblemInputError(f"max_iter must be a whole number from 0 to {COUNT_MAX} or None, got {max_iter!r}")
    return int(max_iter)


def singular_H(qp: QP, phys: _Physics) -> bool:
    """Whether the QP's H is singular: a periodic grid QP whose unknowns are the whole
    grid (the kernel's q = 0 mode is removed, so H 1 = 0); H is positive definite on any
    proper subset of a periodic grid and on every aperiodic problem."""
    g = qp.geometry
    return bool(phys.periodic and g is not None and qp.n == int(np.prod(g.grid_shape)))


def payload_nbytes(qp_or_instance: QP | ContactInstance, dense_limit: int = DENSE_LIMIT) -> int:
    """The bytes of ``problem_payload``'s arrays without a warm start, counted without
    building them (the dense H is not made): what writing the QP takes on a disk, its
    problem.json aside."""
    qp, phys = _physics(qp_or_instance)
    n = qp.n
    vectors = 1 + (2 if qp.geometry is not None else 0) + (1 if qp.constraints.bounded else 0)
    table = problem_kernel_table(qp, phys)
    return 8 * (n * vectors + (n * n if n <= dense_limit else 0) + (0 if table is None else int(table.size)))


def problem_payload(qp_or_instance: QP | ContactInstance, *, tol: float | None, time_limit: float | None,
                    p0: np.ndarray | None = None, dense_limit: int = DENSE_LIMIT,
                    max_iter: int | None = None) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """What a problem directory holds (module doc), in memory: its ``problem.json``
    document and its arrays (name -> C-order array of the listed dtype).  The one
    builder of the format; ``write_problem_dir`` writes it to files, the HDF5 export
    packs it into a group.  ``max_iter`` (an integer >= 0, or None: written as null) is
    the iteration limit the reader must honour; ``"singular"`` says whether H is singular
    (a periodic QP on its whole grid: ``singular_H``)."""
    qp, phys = _physics(qp_or_instance)
    n = qp.n
    arrays: dict[str, np.ndarray] = {"ubar": np.asarray(qp.ubar, dtype=np.float64)}
    g = qp.geometry
    table = problem_kernel_table(qp, phys)
    if g is not None:
        arrays["index"] = _grid_index(g)
    if n <= dense_limit:
        arrays["H"] = qp.H.to_dense()
    if table is not None:
        arrays["kernel_table"] = table
    if p0 is not None:
        p0 = np.asarray(p0, dtype=np.float64)
        if p0.shape != (n,):
            raise ProblemInputError(f"warm start p0 has shape {p0.shape}, the problem has n = {n}")
        arrays["p0"] = p0
    c = qp.constraints
    if c.bounded:
        arrays["upper"] = c.upper_or_inf(n)
    if "H" not in arrays and "kernel_table" not in arrays:
        raise ProblemInputError(f"cannot write this QP: n = {n} is over the dense limit {dense_limit} and its "
                                "operator has no kernel table")
    arrays = {name: np.ascontiguousarray(a, dtype="<i8" if name == "index" else "<f8") for name, a in arrays.items()}
    doc = {
        "format": FORMAT if c.plain else FORMAT_CONSTRAINED,
        "n": int(n),
        "grid": None if g is None else [int(s) for s in g.grid_shape],
        "spacing": None if g is None else g.spacing[0],
        "spacing1": None if g is None else g.spacing[1],
        "E": _finite_or_none(phys.E),
        "kernel": phys.kernel if table is not None else None,
        "periodic": bool(phys.periodic),
        "tol": _finite_or_none(tol),
        "time_limit": _finite_or_none(time_limit),
        "max_iter": _iteration_limit(max_iter),
        "singular": singular_H(qp, phys),
        **({} if c.plain else {"load": None if c.load is None else float(c.load)}),
        "arrays": {name: {"file": ARRAY_FILES[name], "dtype": a.dtype.str, "shape": [int(s) for s in a.shape]}
                   for name, a in arrays.items()},
    }
    return doc, arrays


def problem_json(doc: dict[str, Any]) -> str:
    """The text of ``problem.json`` for a ``problem_payload`` document."""
    return json.dumps(doc, indent=2) + "\n"


def write_problem_dir(qp_or_instance: QP | ContactInstance, directory: str | os.PathLike[str], *,
                      tol: float | None, time_limit: float | None, p0: np.ndarray | None = None,
                      dense_limit: int = DENSE_LIMIT, max_iter: int | None = None) -> Path:
    """Write the problem directory of a QP (module doc) into ``directory`` (created if
    needed) and return its path.  ``tol`` is the scaled KKT error to reach,
    ``time_limit`` the seconds allowed and ``max_iter`` the iteration limit (each may be
    None: written as null).

    The directory ends up holding exactly this QP's files of the format: a file of
    ``PROBLEM_DIR_FILES`` that this QP does not write (an array of a QP written there
    before) is removed; files of other names are left as they are.  ``problem.json`` is
    removed first and written last, so a directory whose writing stopped part-way has
    none.  Each file is written as a new file (``_write_new``): a symbolic or hard link
    of its name is replaced, and what it points to is never written."""
    doc, arrays = problem_payload(qp_or_instance, tol=tol, time_limit=time_limit, p0=p0, dense_limit=dense_limit,
                                  max_iter=max_iter)
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    if (out / PROBLEM_JSON).is_symlink():
        (out / PROBLEM_JSON).unlink()
    written = {ARRAY_FILES[name] for name in arrays}
    for file in sorted(PROBLEM_DIR_FILES - written):
        path = out / file
        if path.is_file() and not path.is_symlink():
            path.unlink()
    for name, a in arrays.items():
        _write_new(out / ARRAY_FILES[name], memoryview(a))
    _write_new(out / PROBLEM_JSON, problem_json(doc).encode("utf-8"))
    return out


def _write_new(path: Path, data: bytes | memoryview) -> None:
    """``data`` (a C-contiguous buffer) as a new regular file ``path``: a file or link there is removed first (a
    link is removed, never followed) and the file is created exclusively, so nothing
    else is written; a folder there is an ``OSError`` naming it."""
    if path.is_symlink() or path.is_file():
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o666)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)


# ---------------------------------------------------------------------------
# Reading a problem directory
# ---------------------------------------------------------------------------


@dataclass
class ProblemFile:
    """A problem directory, read back: its scalars and arrays (absent ones are None)."""

    n: int
    grid: tuple[int, int] | None
    spacing: float | None
    E: float | None
    kernel: str | None
    periodic: bool
    tol: float | None
    time_limit: float | None
    ubar: np.ndarray
    index: np.ndarray | None = None
    H: np.ndarray | None = None
    kernel_table: np.ndarray | None = None
    p0: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    upper: np.ndarray | None = None
    load: float | None = None
    #: The spacing along axis 1 (``spacing`` is axis 0's); None: equal to ``spacing``.
    spacing1: float | None = None

    def constraints(self) -> Constraints:
        """The QP's bounds and load equality (none for format 1)."""
        if self.upper is None and self.load is None:
            return Constraints()
        return make_constraints(self.n, self.upper, self.load)

    @property
    def flat_indices(self) -> np.ndarray | None:
        if self.index is None or self.grid is None:
            return None
        return self.index[:, 0] * int(self.grid[1]) + self.index[:, 1]

    def geometry(self) -> Geometry | None:
        flat = self.flat_indices
        if flat is None or self.grid is None:
            return None
        d0 = float(self.spacing or 1.0)
        d1 = None if self.spacing1 is None or float(self.spacing1) == d0 else float(self.spacing1)
        return Geometry(self.grid, d0, flat, E=self.E, kernel=self.kernel, periodic=self.periodic, delta1=d1)

    def operator(self) -> ContactOperator:
        """H as an operator: dense from ``H`` when present, else the FFT operator of the
        kernel table (the constructors of ``problems.operators``)."""
        if self.H is not None:
            return DenseOperator(self.H)
        flat = self.flat_indices
        if self.kernel_table is None or flat is None or self.grid is None:
            raise ProblemInputError("the problem directory has neither H nor a kernel table with grid indices")
        return FFTOperator(KernelTransform(self.kernel_table, self.grid), flat)

    def qp(self) -> QP:
        return QP(self.operator(), self.ubar, self.geometry(), self.constraints())


def _read_json(path: Path, what: str) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ProblemInputError(f"{what}: {path} is missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProblemInputError(f"{what}: {path} is unreadable ({exc})") from None
    if not isinstance(doc, dict):
        raise ProblemInputError(f"{what}: {path} does not hold a JSON object")
    return doc


def _read_array(directory: Path, name: str, entry: Any) -> np.ndarray:
    if not isinstance(entry, dict) or not {"file", "dtype", "shape"} <= set(entry):
        raise ProblemInputError(f"problem.json: array {name!r} needs file, dtype and shape, got {entry!r}")
    if entry["dtype"] not in ("<f8", "<i8"):
        raise ProblemInputError(f"problem.json: array {name!r} has dtype {entry['dtype']!r}; expected <f8 or <i8")
    shape = tuple(int(s) for s in entry["shape"])
    path = directory / str(entry["file"])
    try:
        a = np.fromfile(path, dtype=np.dtype(entry["dtype"]))
    except OSError as exc:
        raise ProblemInputError(f"array {name!r}: cannot read {path} ({exc})") from None
    if a.size != int(np.prod(shape)):
        raise ProblemInputError(f"array {name!r}: {path} holds {a.size} values, shape {list(shape)} needs "
                                f"{int(np.prod(shape))}")
    return a.reshape(shape)


def read_problem_dir(directory: str | os.PathLike[str]) -> ProblemFile:
    """Read a problem directory written by ``write_problem_dir`` (or by anyone following
    the layout); bad content is a ``ProblemInputError`` naming the problem."""
    d = Path(directory)
    doc = _read_json(d / PROBLEM_JSON, "problem directory")
    if doc.get("format") not in READABLE_FORMATS:
        raise ProblemInputError(f"problem.json: format {doc.get('format')!r}, expected one of "
                                f"{', '.join(map(repr, READABLE_FORMATS))}")
    arrays = doc.get("arrays")
    if not isinstance(arrays, dict) or "ubar" not in arrays:
        raise ProblemInputError("problem.json: 'arrays' must map names to files and include 'ubar'")
    got = {name: _read_array(d, name, entry) for name, entry in arrays.items()}
    n = int(doc["n"])
    if got["ubar"].shape != (n,):
        raise ProblemInputError(f"problem.json: ubar has shape {list(got['ubar'].shape)}, n = {n}")
    grid = doc.get("grid")
    known = {"ubar", "index", "H", "kernel_table", "p0", "upper"}
    load = doc.get("load") if doc["format"] == FORMAT_CONSTRAINED else None
    if load is not None and not (isinstance(load, (int, float)) and not isinstance(load, bool)):
        raise ProblemInputError(f"problem.json: load must be a number or null, got {load!r}")
    upper = got.get("upper") if doc["format"] == FORMAT_CONSTRAINED else None
    if upper is not None and upper.shape != (n,):
        raise ProblemInputError(f"problem.json: upper has shape {list(upper.shape)}, n = {n}")
    spacing, spacing1 = (_spacing(doc, key) for key in ("spacing", "spacing1"))
    return ProblemFile(
        n=n, grid=None if grid is None else (int(grid[0]), int(grid[1])), spacing=spacing,
        E=doc.get("E"), kernel=doc.get("kernel"), periodic=bool(doc.get("periodic", False)),
        tol=doc.get("tol"), time_limit=doc.get("time_limit"), ubar=got["ubar"], index=got.get("index"),
        H=got.get("H"), kernel_table=got.get("kernel_table"), p0=got.get("p0"),
        extra={k: v for k, v in got.items() if k not in known},
        upper=None if upper is None else np.asarray(upper, dtype=np.float64),
        load=None if load is None else float(load),
        spacing1=spacing if spacing1 is None else spacing1)


def _spacing(doc: dict[str, Any], key: str) -> float | None:
    """``doc[key]``: a positive number or null/absent (None); else a ``ProblemInputError``."""
    v = doc.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise ProblemInputError(f"problem.json: {key} must be a positive number or null, got {v!r}")
    return float(v)


# ---------------------------------------------------------------------------
# Reading a solution directory
# ---------------------------------------------------------------------------


@dataclass
class SolutionFile:
    """An outside program's answer: p, optionally w, and its own report."""

    p: np.ndarray
    w: np.ndarray | None = None
    iterations: int | None = None
    status: str | None = None
    time_s: float | None = None
    report: dict[str, Any] = field(default_factory=dict)
    multiplier: float | None = None  # the approach Delta it reports (load control)

    @property
    def claims_converged(self) -> bool:
        """The protocol's rule: a solution claims convergence when its solution.json's
        status is one of ``CLAIM_STATUSES``, or when it reports no status at all."""
        return self.status is None or self.status in CLAIM_STATUSES


#: The most bytes a solution.json may hold: its report is a few fields.
MAX_REPORT_BYTES = 1 << 20


def _bounded_bytes(path: Path, what: str, most: int) -> bytes:
    """The bytes of ``path`` if it is a regular file of at most ``most`` bytes, else a
    ``SolutionFileError``: a FIFO would block the reader, a folder or device cannot be an
    answer.  One open file is looked at and read, at most ``most`` + 1 bytes of it, so a
    file another process swaps or grows meanwhile is never read past the bound."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)  # (a FIFO opens without waiting for a writer)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise SolutionFileError(f"{what} ({path.name}) is missing") from None
    except OSError as exc:
        raise SolutionFileError(f"{what} ({path.name}) is unreadable: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise SolutionFileError(f"{what} ({path.name}) is not a regular file")
        chunks, size = [], 0
        while size <= most:
            chunk = os.read(fd, min(1 << 20, most + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise SolutionFileError(f"{what} ({path.name}) is unreadable: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > most:
        raise SolutionFileError(f"{what} ({path.name}) has more than the {most} bytes it may hold")
    return b"".join(chunks)


def _read_vector(path: Path, n: int, what: str, *, nonnegative: bool, checked: bool = True) -> np.ndarray:
    data = _bounded_bytes(path, what, 8 * (4 * max(n, 1) + 1024))  # a wrong length is read, within reason
    size = len(data)
    if n > 0 and size == 4 * n:  # (read as float64 it would be n/2 values, or a ragged tail, for either parity)
        raise SolutionFileError(f"{what} ({path.name}) has {size} bytes for n = {n}: looks like float32 (4 n bytes); "
                                "write float64 (8 n bytes)")
    if size % 8:
        raise SolutionFileError(f"{what} ({path.name}) has {size} bytes, not a whole number of float64 values")
    a = np.frombuffer(data, dtype="<f8")
    if not checked:  # any length and any values: for the judge to see
        return a.astype(np.float64)
    if a.size != n:
        raise SolutionFileError(f"{what} ({path.name}) has wrong length {a.size}, expected n = {n}")
    bad = int(np.count_nonzero(~np.isfinite(a)))
    if bad:
        raise SolutionFileError(f"{what} ({path.name}) has {bad} NaN/inf entries of {n}")
    if nonnegative and np.any(a < 0.0):
        neg = int(np.count_nonzero(a < 0.0))
        raise SolutionFileError(f"{what} ({path.name}) has {neg} negative entries (min {float(a.min()):.3g}); "
                                "p >= 0 is required")
    return a.astype(np.float64)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's members, each key once (a key given twice: ``ValueError``)."""
    doc: dict[str, Any] = {}
    for key, value in pairs:
        if key in doc:
            raise ValueError(f"the key {key!r} is given twice")
        doc[key] = value
    return doc


def _read_report(path: Path) -> dict[str, Any]:
    if not os.path.lexists(path):
        return {}
    data = _bounded_bytes(path, "the report", MAX_REPORT_BYTES)
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise SolutionFileError("solution.json is UTF-16 (it starts with a UTF-16 byte-order mark, as Windows "
                                "PowerShell 5's > and Out-File write it): write it as UTF-8")
    try:
        # (utf-8-sig: a byte-order mark, as Windows PowerShell 5 writes one, is skipped)
        doc = json.loads(data.decode("utf-8-sig"), object_pairs_hook=_unique_keys)
    except (UnicodeDecodeError, ValueError) as exc:  # (JSON errors; a number of more digits than Python reads)
        raise SolutionFileError(f"solution.json is unreadable: {printable_excerpt(str(exc))}") from None
    except RecursionError:
        raise SolutionFileError("solution.json is unreadable: its values nest deeper than a reader follows") from None
    if not isinstance(doc, dict):
        raise SolutionFileError("solution.json does not hold a JSON object")
    return doc


def _report_number(report: dict[str, Any], key: str, rule: str) -> float | int | None:
    """``report[key]`` (None when absent) if it is as ``rule`` says: "count" a whole number
    from 0 to ``COUNT_MAX`` (12.0 is 12), "seconds" a finite number >= 0, "real" a finite
    number; else a ``SolutionFileError`` naming the key."""
    value = report.get(key)
    if value is None:
        return None
    if rule == "count":
        if not is_count(value):
            raise SolutionFileError(f"solution.json: {key} {printable_excerpt(repr(value))} is not a whole number "
                                    f"from 0 to {COUNT_MAX}")
        return int(value)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    try:
        number = float(value) if ok else math.nan
    except OverflowError:
        number = math.nan
    if not math.isfinite(number) or (rule == "seconds" and number < 0):
        kind = "a finite number of seconds >= 0" if rule == "seconds" else "a finite number"
        raise SolutionFileError(f"solution.json: {key} {printable_excerpt(repr(value))} is not {kind}")
    return number


#: The keys solution.json may hold (module doc); any other fails the solve, naming it.
SOLUTION_KEYS: tuple[str, ...] = ("iterations", "status", "time_s", "multiplier")


def read_solution_dir(directory: str | os.PathLike[str], n: int, *, as_written: bool = False) -> SolutionFile:
    """The answer in a solution directory (module doc): p.f64 must be n finite float64
    values >= 0 (``as_written``: p is kept as written -- any length, NaN, inf or negative
    entries -- for the judge to see; it must still be a whole number of float64 values, and
    a file of exactly 4 n bytes, float32 by the look of it, is refused whatever n's parity);
    w.f64 is read when present; solution.json's iterations/status/time_s when given
    (UTF-8, with or without a byte-order mark).
    Anything wrong is a ``SolutionFileError`` that says which file and what."""
    d = Path(directory)
    p = _read_vector(d / SOLUTION_P, n, "solution p", nonnegative=True, checked=not as_written)
    w_path = d / SOLUTION_W
    w = _read_vector(w_path, n, "solution w", nonnegative=False) if w_path.exists() else None
    report = _read_report(d / SOLUTION_JSON)
    unknown = [k for k in report if k not in SOLUTION_KEYS]
    if unknown:  # (a misspelt "status" read as absent would be a claim of convergence)
        raise SolutionFileError(f"solution.json: unknown key(s) {printable_excerpt(', '.join(map(repr, unknown)))}; "
                                f"the protocol's keys: {', '.join(SOLUTION_KEYS)}")
    given_null = [k for k in SOLUTION_KEYS if k in report and report[k] is None]
    if given_null:  # (a null status is no protocol word: only a status left out claims convergence)
        raise SolutionFileError(f"solution.json: {given_null[0]} is null; leave a key out rather than give it null")
    iterations = _report_number(report, "iterations", "count")
    time_s = _report_number(report, "time_s", "seconds")
    mult = _report_number(report, "multiplier", "real")
    status = report.get("status")
    if status is not None and not isinstance(status, str):
        raise SolutionFileError(f"solution.json: status {status!r} is not a string")
    word = None if status is None else status.strip().lower()
    if word is not None and word not in SOLUTION_STATUSES:
        raise SolutionFileError(f"solution.json: status {status!r} is not a protocol word; claims: "
                                f"{', '.join(CLAIM_STATUSES)}; no claim: {', '.join(NON_CLAIM_STATUSES)}")
    return SolutionFile(p, w, None if iterations is None else int(iterations), word,
                        None if time_s is None else float(time_s), report, None if mult is None else float(mult))
