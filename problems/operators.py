"""Operators for the influence matrix H restricted to an index set I (the trial set).

One interface, two implementations:

``DenseOperator``
    holds H_II as an n x n array (small n only).
``FFTOperator``
    matrix-free.  H is Toeplitz-block-Toeplitz (aperiodic: embedded in a 2N x 2N
    circulant) or block-circulant (periodic), so H_II x = gather_I(K * scatter_I(x)),
    with the convolution done by real FFTs against a transform of the kernel that is
    computed once and shared by every restriction.  It never allocates n x n.

Both expose: ``matvec``, ``diagonal``, ``submatrix``/``column`` (gathered from the kernel
table: even the FFT operator hands out a dense block cheaply), ``restrict`` (a sub-operator
on a subset of I), ``to_dense`` (guarded by a memory budget), ``with_precision`` (float32
products for mixed-precision solvers; ``restrict`` keeps the precision) and memory
estimates; each counts its matvecs in ``matvec_count``.  The FFT machinery (the shared
kernel transform, its pruned ducc0/scipy convolution, ``fft_floor_pair``) is in
problems/fft_transform.py, its threads and FFT library in problems/fft_threads.py (their
public names re-exported here).
"""

from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any, ClassVar

import numpy as np
from scipy.sparse.linalg import LinearOperator

from . import window_sums
from .errors import MemoryBudgetError, ProblemInputError, real_number
from .fft_floor import FLOOR_LAYOUTS, fft_floor_pair  # noqa: F401 -- re-exported with the FFT names
from .fft_threads import _ducc_fft, each_on_pool, fft_backend, fft_workers, share_out  # noqa: F401 -- re-exported FFT names
from .fft_transform import PRECISIONS, KernelTransform, operator_dtype  # noqa: F401 -- re-exported FFT names
from .operator_state import SealRule

#: Default memory budget for assembling dense matrices (bytes).  Overridable by the
#: environment variable CONTACTBENCH_MEMORY_BUDGET_GB.
DEFAULT_MEMORY_BUDGET = float(os.environ.get("CONTACTBENCH_MEMORY_BUDGET_GB", "8")) * 2**30

#: This process's budget (``memory_budget``): the default until ``set_memory_budget``.
_budget: list[float] = [DEFAULT_MEMORY_BUDGET]


def memory_budget() -> float:
    """Bytes a dense matrix of this process may take: ``DEFAULT_MEMORY_BUDGET``, or what the
    process set (a run's worker sets its run's ``--memory-budget-gb``)."""
    return _budget[0]


def set_memory_budget(nbytes: float) -> None:
    """This process's budget for dense matrices from now on (> 0, finite)."""
    if not (isinstance(nbytes, (int, float)) and 0.0 < float(nbytes) < float("inf")):
        raise ProblemInputError(f"memory budget must be a finite number of bytes > 0, got {nbytes!r}")
    _budget[0] = float(nbytes)


@contextmanager
def memory_budget_scope(nbytes: float | None) -> Iterator[None]:
    """This process's budget is ``nbytes`` inside the block (unchanged for None), and what it
    was after it, however the block ends."""
    before = _budget[0]
    if nbytes is not None:
        set_memory_budget(nbytes)
    try:
        yield
    finally:
        _budget[0] = before


#: The FFT operator switches to a dense block after this many matvecs when that is
#: cheaper (small trial sets on large grids) ...
DENSE_SWITCH_AFTER = 4
#: ... and the block has at most this many entries (128 MiB) ...
DENSE_SWITCH_MAX_ENTRIES = 1 << 24
#: ... and at most this factor x P log2 P (P: padded grid points; 0.1 -> n <= ~1450 at
#: 512^2).  The block costs ~20 ns an entry to gather, 25 dense products' worth, so it must
#: be well under the FFT pair's break-even to pay within a step.  Calibrated on the 512^2
#: paper sweep (1 thread, alternating runs): 0.4 (the break-even of the earlier, slower
#: matvec) 3.51-3.59 s, 0.2 3.54-3.78 s, 0.1 3.24-3.54 s, 0.05 3.34-3.39 s, no switch
#: 3.58-3.60 s.
DENSE_SWITCH_FACTOR = 0.1
#: ... and at the first matvec, not after ``DENSE_SWITCH_AFTER``, when the block has at most
#: this factor x P log2 P entries: gathering it costs about one FFT pair or less (measured at
#: 512^2, 2 threads: 20-30 ns an entry; one float64 FFT pair 3 ms periodic, 8 ms on the padded
#: grid; break-even near 0.02), so no FFT product is spent first.  A sweep's first steps
#: screen to a few dozen points: the periodic 512^2 sweep's first step took 12 FFT pairs
#: (four per operator and precision before the switch) and 41 ms, 2 pairs and 21 ms at once.
DENSE_SWITCH_AT_ONCE_FACTOR = 0.02

#: A partial product H[rows, cols] x (``ContactOperator.partial_product``) pays instead of an
#: FFT matvec when it gathers at most this factor x P log2 P entries.  Gathering an entry of
#: the kernel table costs ~3 ns (in cache-sized chunks) against ~0.26 ns per P log2 P for
#: the matvec (2048^2, 2 threads: 105 ms), so the break-even is near 0.09; under half of it
#: keeps the product a clear win.
PARTIAL_PRODUCT_FACTOR = 0.04

#: Entries gathered at a time by a partial product: a chunk's index and entries stay in the
#: core's cache (64 Ki entries: ~3 ns an entry at 2048^2, against ~12 ns for 4 Mi entries).
PARTIAL_PRODUCT_CHUNK = 1 << 16

#: A host partial product of at least ``PARALLEL_PARTIAL_ENTRIES`` entries is cut into this
#: many column groups, gathered on the FFT threads (NumPy's gathers release the GIL: 1.86x
#: on two threads) and added in group order -- so the answer does not depend on the threads.
PARTIAL_PRODUCT_GROUPS = 8
PARALLEL_PARTIAL_ENTRIES = 1 << 20


def dense_switch_enabled() -> bool:
    """The hybrid dense/FFT matvec is on unless CONTACTBENCH_DENSE_SWITCH=0."""
    return os.environ.get("CONTACTBENCH_DENSE_SWITCH", "1") not in ("0", "false", "no")


def dense_block_pays(n: int, padded_points: float) -> bool:
    """Whether the FFT operator of n unknowns on a padded grid of ``padded_points`` points
    switches to a dense H_II block (``DENSE_SWITCH_*``): n^2 entries within the entry limit
    and under ``DENSE_SWITCH_FACTOR`` x P log2 P.  The operator's rule and the time model's
    (``solvers._kit.matvec_seconds``)."""
    return _block_within(n, padded_points, DENSE_SWITCH_FACTOR)


def dense_block_at_once(n: int, padded_points: float) -> bool:
    """Whether that switch comes at the first matvec (``DENSE_SWITCH_AT_ONCE_FACTOR``)."""
    return _block_within(n, padded_points, DENSE_SWITCH_AT_ONCE_FACTOR)


def _block_within(n: int, padded_points: float, factor: float) -> bool:
    """n^2 entries within the entry limit and ``factor`` x P log2 P."""
    P = max(float(padded_points), 2.0)
    return n * n <= min(DENSE_SWITCH_MAX_ENTRIES, factor * P * np.log2(P))


def runs_dense_blocks(H: Any) -> bool:
    """Whether operator H multiplies as a dense block of its set: an FFT operator whose
    switch (``dense_block_pays``) applies, as on a sweep's first screened steps.  There a
    wave-number preconditioner's FFT pair on the whole grid costs more than a product, and
    a float32 twin saves nothing worth its refinement."""
    pays = getattr(H, "dense_pays", None)
    return bool(getattr(H, "auto_dense", False)) and callable(pays) and bool(pays())


def dense_nbytes(n: int) -> int:
    return 8 * int(n) * int(n)


def budget_or_default(budget: float | None) -> float:
    """``budget`` (bytes: a number > 0, inf for no limit), or this process's
    ``memory_budget()`` for None; anything else (NaN, <= 0, a bool, a string) is a one-line
    ``ProblemInputError``."""
    if budget is None:
        return memory_budget()
    b = real_number("memory budget", budget, "a number of bytes > 0")
    if not b > 0.0:
        raise ProblemInputError(f"memory budget must be a number of bytes > 0, got {budget!r}")
    return b


def check_dense_budget(n: int, budget: float | None = None, what: str = "dense H") -> None:
    """Raise MemoryBudgetError if an n x n float64 matrix would exceed the budget
    (``budget_or_default``)."""
    b = budget_or_default(budget)
    need = dense_nbytes(n)
    if need > b:
        raise MemoryBudgetError(f"{what} ({n} x {n} float64)", need, b)


def check_positions(idx: object, n: int, what: str = "positions") -> np.ndarray:
    """``idx`` as distinct int64 positions in 0..n-1 (a 1-D integer array in any order, or a
    boolean mask of length n read as its True positions); else a one-line
    ``ProblemInputError`` naming ``what`` and the offending value.  O(len(idx)) for sorted
    positions, one ``bincount`` otherwise."""
    a = np.asarray(idx)
    if a.dtype == np.bool_:
        if a.shape != (n,):
            raise ProblemInputError(f"{what} as a boolean mask must have shape ({n},), got shape {a.shape}")
        return np.flatnonzero(a)
    if a.ndim != 1 or (a.size and not np.issubdtype(a.dtype, np.integer)):
        raise ProblemInputError(f"{what} must be 1-D integer positions in 0..{n - 1} or a boolean mask of "
                                f"length {n}, got dtype {a.dtype} and shape {a.shape}")
    a = a.astype(np.int64, copy=False)
    if a.size == 0:
        return a
    lo, hi = int(a.min()), int(a.max())
    if lo < 0 or hi >= n:
        raise ProblemInputError(f"{what} must lie in 0..{n - 1}, got {lo if lo < 0 else hi}")
    if a.size > 1 and not bool(np.all(a[1:] > a[:-1])):
        counts = np.bincount(a)
        if int(counts.max()) > 1:
            k = int(np.argmax(counts))
            raise ProblemInputError(f"{what} must not repeat, got {k} repeated {int(counts[k])} times")
    return a


class ContactOperator(ABC):
    """H restricted to the trial set: symmetric positive definite, all entries > 0
    for the BCC and Love kernels (aperiodic)."""

    n: int
    matvec_count: int
    #: The precision of the products (float64 unless made by ``with_precision``).
    dtype: np.dtype = np.dtype(np.float64)
    #: Where a device-resident solve may keep its vectors (``operators_gpu.ArraySpace``, whose
    #: arrays ``matvec`` then takes and returns); None: the host only.
    space: Any = None
    SEAL_RULE: ClassVar[SealRule] = SealRule(counters=frozenset({"matvec_count"}))

    @abstractmethod
    def matvec(self, x: np.ndarray) -> np.ndarray:
        """H_II x (in the operator's precision, ``dtype``)."""

    def with_precision(self, dtype: object) -> "ContactOperator":
        """This operator on the same trial set with products in ``dtype`` (np.float64 or
        np.float32).  The operator's own precision returns ``self``; float32 runs the
        product in single precision (it takes float32 or float64 x and returns float32)
        for the inner sweeps of mixed-precision solvers.  Entries (``submatrix``,
        ``diagonal``, ``blocks``) stay float64."""
        dt = operator_dtype(dtype)
        return self if dt == self.dtype else self._in_precision(dt)

    @abstractmethod
    def _in_precision(self, dtype: np.dtype) -> "ContactOperator":
        """A copy of this operator whose products run in ``dtype``."""

    @abstractmethod
    def diagonal(self) -> np.ndarray:
        """diag(H_II)."""

    @abstractmethod
    def submatrix(self, rows: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
        """Dense block H[rows, cols] (positions 0..n-1 of this operator)."""

    @abstractmethod
    def restrict(self, idx: np.ndarray) -> "ContactOperator":
        """Operator on the subset ``idx`` of this operator's set: distinct positions in
        0..n-1 or a boolean mask of length n (``check_positions``)."""

    @property
    @abstractmethod
    def memory_nbytes(self) -> int:
        """Bytes the operator holds (plus its work arrays)."""

    @property
    def kind(self) -> str:
        return type(self).__name__

    def column(self, j: int) -> np.ndarray:
        return self.submatrix(np.arange(self.n), np.array([j]))[:, 0]

    def blocks(self, members: np.ndarray) -> np.ndarray:
        """Stack of diagonal blocks: out[k] = H[members[k], members[k]] for an (m, s)
        array of positions, with -1 as padding (identity rows and columns)."""
        members = np.asarray(members)
        m, s = members.shape
        a = np.broadcast_to(members[:, :, None], (m, s, s))
        b = np.broadcast_to(members[:, None, :], (m, s, s))
        both = (a >= 0) & (b >= 0)
        out = np.zeros((m, s, s))
        out[both] = self.entries(a[both], b[both])
        return _pad_identity(out, members)

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """H[rows[k], cols[k]] for each k (elementwise pairs, not a block)."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        out = np.empty(rows.size)
        for r in np.unique(rows):
            sel = np.flatnonzero(rows == r)
            out[sel] = self.submatrix(np.array([r]), cols[sel])[0]
        return out

    def partial_product(self, rows: np.ndarray, cols: np.ndarray, x: np.ndarray) -> np.ndarray:
        """H[rows, cols] x (float64) without holding the block: row chunks of at most
        ``PARTIAL_PRODUCT_CHUNK`` entries."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        x = np.asarray(x, dtype=np.float64)
        out = np.zeros(rows.size)
        if cols.size == 0:
            return out
        step = max(1, PARTIAL_PRODUCT_CHUNK // cols.size)
        for b0 in range(0, rows.size, step):
            out[b0:b0 + step] = self.submatrix(rows[b0:b0 + step], cols) @ x
        return out

    def partial_products(self, items: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        """[``partial_product``(rows, cols, x) for each item]: the same sums, the items on
        the threads where the operator can (here: in turn)."""
        return [self.partial_product(rows, cols, x) for rows, cols, x in items]

    def unit_sums(self, items: Sequence[tuple[np.ndarray, np.ndarray]],
                  budget: float = math.inf) -> list[np.ndarray] | None:
        """[H[rows, cols] 1 for each item (rows, cols)] (float64): the displacements at
        ``rows`` of unit forces on ``cols``; None, before any is computed, when they would
        cost more than ``budget`` (``unit_sums_cost``).  Here: ``partial_products``."""
        if gathered_entries(items) > budget:
            return None
        return self.partial_products(unit_forces(items))

    def unit_sums_cost(self, items: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
        """The work of ``unit_sums(items)`` in entries read (here: ``gathered_entries``)."""
        return gathered_entries(items)

    def partial_product_pays(self, entries: int) -> bool:
        """Whether a ``partial_product`` gathering ``entries`` entries costs well under a
        matvec (False here: a generic operator has no cost model)."""
        return False

    def entry_floor(self) -> float | None:
        """min(0, min_ij H_ij): a bound under every entry of H, 0 when no entry is negative
        (solvers/_ccg.py, "Raised forces"); None when unknown."""
        return None

    def dense_nbytes(self) -> int:
        return dense_nbytes(self.n)

    def to_dense(self, budget: float | None = None) -> np.ndarray:
        """H (float64; ``MemoryBudgetError`` over ``budget``), maybe read-only: copy to write."""
        check_dense_budget(self.n, budget)
        idx = np.arange(self.n)
        return self.submatrix(idx, idx)

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return self.matvec(x)

    def as_linear_operator(self) -> LinearOperator:
        return LinearOperator((self.n, self.n), matvec=self.matvec, rmatvec=self.matvec, dtype=self.dtype)

    def frobenius_norm(self) -> float:
        """||H_II||_F (the paper's Lipschitz bound for gradient projection)."""
        return float(np.linalg.norm(self.to_dense()))

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n, self.n)


def gathered_entries(items: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
    """The entries the items (rows, cols) read gathered one by one: |rows| |cols| each."""
    return float(sum(np.asarray(rows).size * np.asarray(cols).size for rows, cols in items))


def unit_forces(items: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The items (rows, cols) as ``partial_products`` items with unit forces on cols."""
    return [(rows, cols, np.ones(np.asarray(cols).size)) for rows, cols in items]


def _pad_identity(blocks: np.ndarray, members: np.ndarray) -> np.ndarray:
    """Zero the rows and columns of padded members (-1) and put 1 on their diagonal."""
    k, a = np.nonzero(np.asarray(members) < 0)
    if k.size:
        blocks[k, a, :] = 0.0
        blocks[k, :, a] = 0.0
        blocks[k, a, a] = 1.0
    return blocks


class DenseOperator(ContactOperator):
    """H_II held as a dense array, ``H``: a read-only view of the array given (``to_dense``)."""
    SEAL_RULE: ClassVar[SealRule] = SealRule(caches={"_floor": lambda op, key, current: op._fresh_floor()})

    def __init__(self, H: np.ndarray, dtype: object = np.float64) -> None:
        self.dtype = operator_dtype(dtype)
        H = np.asarray(H, dtype=self.dtype)
        if H.ndim != 2 or H.shape[0] != H.shape[1]:
            raise ProblemInputError(f"H must be a square matrix, got shape {H.shape}")
        self.H = H.view()  # (read-only: the class doc)
        self.H.flags.writeable = False
        self.n = H.shape[0]
        self.matvec_count = 0

    def matvec(self, x: np.ndarray) -> np.ndarray:
        self.matvec_count += 1
        return self.H @ np.asarray(x, dtype=self.dtype)

    def _in_precision(self, dtype: np.dtype) -> "DenseOperator":
        return DenseOperator(self.H, dtype=dtype)

    def diagonal(self) -> np.ndarray:
        return np.diag(self.H).astype(np.float64)

    def submatrix(self, rows: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
        cols = rows if cols is None else cols
        return self.H[np.ix_(np.asarray(rows), np.asarray(cols))].astype(np.float64, copy=False)

    def restrict(self, idx: np.ndarray) -> "DenseOperator":
        idx = check_positions(idx, self.n)
        return DenseOperator(self.H[np.ix_(idx, idx)], dtype=self.dtype)

    def to_dense(self, budget: float | None = None) -> np.ndarray:
        budget_or_default(budget)
        return self.H if self.dtype == np.float64 else self.H.astype(np.float64)

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return self.H[np.asarray(rows), np.asarray(cols)].astype(np.float64, copy=False)

    def frobenius_norm(self) -> float:
        return float(np.linalg.norm(self.H.astype(np.float64, copy=False)))

    def partial_product(self, rows: np.ndarray, cols: np.ndarray, x: np.ndarray) -> np.ndarray:
        return self.submatrix(rows, cols) @ np.asarray(x, dtype=np.float64)

    def partial_product_pays(self, entries: int) -> bool:
        return entries <= PARTIAL_PRODUCT_FACTOR * self.n * self.n  # (a gathered entry: a few streamed ones)

    def entry_floor(self) -> float | None:
        if getattr(self, "_floor", None) is None:
            self._floor = self._fresh_floor()
        return self._floor

    def _fresh_floor(self) -> float:
        return min(0.0, float(np.min(self.H, initial=0.0)))

    @property
    def memory_nbytes(self) -> int:
        return int(self.H.nbytes)


def even_table_product(table: Any, width: Any, rows: tuple[Any, Any], cols: tuple[Any, Any], x: Any,
                       chunk: int | None = None) -> Any:
    """sum_j K(rows, cols_j) x_j for an even kernel table (K(di, dj) = table[|di| width +
    |dj|], flat), rows and cols given by their grid (row, column) positions: gathered a few
    columns at a time (about ``chunk`` entries, default ``PARTIAL_PRODUCT_CHUNK``; at least
    one column), so for one column the rows' offsets are sorted and the reads of the table
    stay close together.  In the array
    module of its arguments (NumPy's functions dispatch: the device's partial products
    too, ``operators_gpu.ArrayFFTOperator.partial_product``, with a device's chunk)."""
    (ri, rj), (ci, cj) = rows, cols
    out = np.zeros_like(x, shape=(int(ri.size),))
    if ci.size == 0 or ri.size == 0:
        return out
    step = max(1, (PARTIAL_PRODUCT_CHUNK if chunk is None else chunk) // int(ri.size))
    for c0 in range(0, int(ci.size), step):
        flat = np.abs(ci[c0:c0 + step, None] - ri[None, :])
        flat *= width
        flat += np.abs(cj[c0:c0 + step, None] - rj[None, :])
        out += x[c0:c0 + step] @ np.take(table, flat)
    return out


class FFTOperator(ContactOperator):
    """Matrix-free H_II: scatter to the physical grid, convolve by FFT, gather; the
    products run in ``dtype`` (float64, or float32 from ``with_precision``).  ``grid_idx``:
    distinct flat indices of the physical grid (``check_positions``)."""
    SEAL_RULE: ClassVar[SealRule] = SealRule(caches={
        "_dense": lambda op, key, current: op._dense_block(),
        "_window_spectra": lambda op, shape, current: op._fresh_window_spectrum(shape)})

    def __init__(
        self, transform: KernelTransform, grid_idx: np.ndarray, auto_dense: bool | None = None, dtype: object = np.float64
    ) -> None:
        self.transform = transform
        self.dtype = operator_dtype(dtype)
        # Transforms that predate precisions (operators_gpu) are called without it in float64.
        self._precision_kw: dict[str, np.dtype] = {} if self.dtype == np.float64 else {"dtype": self.dtype}
        n0, n1 = transform.grid_shape
        self.grid_idx = check_positions(grid_idx, int(n0) * int(n1), "grid indices")
        self.pidx = transform.padded_index(self.grid_idx)
        self.n = int(self.grid_idx.size)
        self.matvec_count = 0
        self._window_spectra: dict[tuple[int, int], np.ndarray] = {}  # ``_window_spectrum``
        p0, p1 = transform.padded_shape
        pi, pj = np.divmod(self.pidx, p1)
        self._pi, self._pj = pi, pj
        self.auto_dense = dense_switch_enabled() if auto_dense is None else bool(auto_dense)
        self._dense: np.ndarray | None = None

    def dense_pays(self) -> bool:
        """Whether a dense H_II matvec (n^2 entries streamed) is cheaper than the FFT pair
        on the padded grid (P points) and small enough to hold."""
        return dense_block_pays(self.n, self._padded_points())

    def _maybe_switch_to_dense(self) -> None:
        # After a few matvecs (at once for a block no dearer than an FFT pair) a small trial
        # set on a large grid is cheaper as a dense block gathered from the kernel table:
        # same numbers, no FFT.
        if self._dense is not None or not self.auto_dense or not self.dense_pays():
            return
        if self.matvec_count >= DENSE_SWITCH_AFTER or dense_block_at_once(self.n, self._padded_points()):
            self._dense = self._dense_block()

    def _dense_block(self) -> np.ndarray:
        """H_II as a dense block in the operator's precision, gathered from the kernel table."""
        idx = np.arange(self.n)
        return self.submatrix(idx, idx).astype(self.dtype, copy=False)

    def _padded_points(self) -> int:
        return int(np.prod(self.transform.padded_shape))

    @property
    def uses_dense(self) -> bool:
        return self._dense is not None

    def scatter(self, x: np.ndarray) -> np.ndarray:
        """x placed on the padded grid (zero elsewhere)."""
        field_ = np.zeros(self.transform.padded_shape)
        field_.ravel()[self.pidx] = x
        return field_

    def _scatter_physical(self, x: np.ndarray) -> np.ndarray:
        f = np.zeros(self.transform.grid_shape, dtype=self.dtype)
        f.ravel()[self.grid_idx] = x
        return f

    def matvec(self, x: np.ndarray) -> np.ndarray:
        self.matvec_count += 1
        self._maybe_switch_to_dense()
        if self._dense is not None:
            return self._dense @ np.asarray(x, dtype=self.dtype)
        if self._precision_kw:  # float32: the work arrays take float32 or float64 x as it is
            return self.transform.apply_on_set(self.pidx, np.asarray(x), **self._precision_kw)
        return self.transform.apply_on_set(self.pidx, np.asarray(x, dtype=np.float64))

    def _in_precision(self, dtype: np.dtype) -> "FFTOperator":
        # Same transform and trial set: the index arrays are shared, not recomputed.
        op = type(self).__new__(type(self))
        op.__dict__.update(self.__dict__)
        op.dtype = dtype
        op._precision_kw = {} if dtype == np.float64 else {"dtype": dtype}
        op.matvec_count = 0
        op._dense = None if self._dense is None else self._dense.astype(dtype)
        return op

    def displacement_field(self, x: np.ndarray) -> np.ndarray:
        """Displacement on the whole physical grid caused by forces x on the set."""
        self.matvec_count += 1
        f = self._scatter_physical(x)
        return np.ascontiguousarray(self.transform.convolve_physical(f, **self._precision_kw))

    def diagonal(self) -> np.ndarray:
        return np.full(self.n, self.transform.table[0, 0])

    def submatrix(self, rows: np.ndarray, cols: np.ndarray | None = None) -> np.ndarray:
        rows = np.asarray(rows)
        cols = rows if cols is None else np.asarray(cols)
        p0, p1 = self.transform.padded_shape
        table = self.transform.table.ravel()
        ri, rj = self._pi[rows], self._pj[rows]
        ci, cj = self._pi[cols], self._pj[cols]
        out = np.empty((rows.size, cols.size))
        # Row blocks keep the offset temporaries near 32 MiB whatever the size of the block.
        step = max(1, (1 << 22) // max(1, cols.size))
        for b0 in range(0, rows.size, step):
            b1 = min(rows.size, b0 + step)
            flat = ((ri[b0:b1, None] - ci[None, :]) % p0) * p1
            flat += (rj[b0:b1, None] - cj[None, :]) % p1
            np.take(table, flat, out=out[b0:b1])
        return out

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        rows, cols = np.asarray(rows), np.asarray(cols)
        p0, p1 = self.transform.padded_shape
        flat = ((self._pi[rows] - self._pi[cols]) % p0) * p1 + (self._pj[rows] - self._pj[cols]) % p1
        return self.transform.table.ravel()[flat]

    def blocks(self, members: np.ndarray) -> np.ndarray:
        # The table is even in both offsets when its spectrum is real (BCC, Love,
        # spectral), so K(di, dj) = table[|di|, |dj|]: no modulo, and small offsets
        # stay in the first rows of the table (cache-friendly for compact groups).
        members = np.asarray(members)
        if np.iscomplexobj(self.transform.khat):
            return super().blocks(members)
        safe = np.where(members >= 0, members, 0)
        pi, pj = self._pi[safe].astype(np.int32), self._pj[safe].astype(np.int32)
        di = np.abs(pi[:, :, None] - pi[:, None, :])
        dj = np.abs(pj[:, :, None] - pj[:, None, :])
        di *= np.int32(self.transform.padded_shape[1])
        di += dj
        return _pad_identity(self.transform.table.ravel()[di], members)

    def partial_product(self, rows: np.ndarray, cols: np.ndarray, x: np.ndarray) -> np.ndarray:
        # An even table (real spectrum: BCC, Love, spectral) is read at |offsets|, without
        # a modulo, in int32 (as ``blocks``), a few columns at a time: for one column the
        # rows' offsets are sorted, so the reads of the table stay close together.
        if np.iscomplexobj(self.transform.khat):
            return super().partial_product(rows, cols, x)
        return self._even_product(rows, cols, x, workers=None)

    def partial_products(self, items: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> list[np.ndarray]:
        # Host arrays and an even table: each product whole on one thread of the pool, its
        # column groups in turn -- the sums ``partial_product`` gives, on every thread count.
        if np.iscomplexobj(self.transform.khat) or not all(isinstance(a, np.ndarray) for it in items for a in it):
            return super().partial_products(items)
        return each_on_pool(lambda k: self._even_product(*items[k], workers=1), len(items))

    def _even_product(self, rows: np.ndarray, cols: np.ndarray, x: np.ndarray, workers: int | None) -> np.ndarray:
        """H[rows, cols] x from the even table: one run of column chunks, or, from
        ``PARALLEL_PARTIAL_ENTRIES`` entries, ``PARTIAL_PRODUCT_GROUPS`` column groups on
        ``workers`` threads (None: ``fft_workers()``) added in group order."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        ri, rj = self._pi[rows].astype(np.int32), self._pj[rows].astype(np.int32)
        ci, cj = self._pi[cols].astype(np.int32), self._pj[cols].astype(np.int32)
        table, width = self.transform.table.ravel(), np.int32(self.transform.padded_shape[1])
        x = np.asarray(x, dtype=np.float64)
        if rows.size * cols.size < PARALLEL_PARTIAL_ENTRIES or cols.size < PARTIAL_PRODUCT_GROUPS:
            return even_table_product(table, width, (ri, rj), (ci, cj), x)
        groups = np.array_split(np.arange(cols.size), PARTIAL_PRODUCT_GROUPS)

        def gather(k: int) -> np.ndarray:
            c = groups[k]
            return even_table_product(table, width, (ri, rj), (ci[c], cj[c]), x[c])

        sums = each_on_pool(gather, len(groups), workers)
        out = sums[0]
        for more in sums[1:]:
            out += more
        return out

    def unit_sums(self, items: Sequence[tuple[np.ndarray, np.ndarray]],
                  budget: float = math.inf) -> list[np.ndarray] | None:
        # On the host: the items of compact, populous groups through small FFT windows
        # (problems/window_sums.py), the others gathered as ``partial_products``.
        if not isinstance(self.transform.table, np.ndarray):
            return super().unit_sums(items, budget)
        by_index = [(np.asarray(rows), np.asarray(cols)) for rows, cols in items]
        positions = self._positions(by_index)
        planned = window_sums.plan(positions)
        if planned.cost > budget:
            return None

        def gather(which: list[int]) -> list[np.ndarray]:
            return self.partial_products(unit_forces([by_index[k] for k in which]))

        return window_sums.unit_sums(self.transform.table, positions, planned, gather, self._window_spectrum)

    def unit_sums_cost(self, items: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
        if not isinstance(self.transform.table, np.ndarray):
            return super().unit_sums_cost(items)
        return window_sums.plan(self._positions([(np.asarray(r), np.asarray(c)) for r, c in items])).cost

    def _positions(self, items: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[tuple[window_sums.Positions, ...]]:
        """The items' rows and cols as (row, column) positions on the padded grid."""
        return [((self._pi[r], self._pj[r]), (self._pi[c], self._pj[c])) for r, c in items]

    def _window_spectrum(self, shape: tuple[int, int]) -> np.ndarray:
        """The kernel's spectrum on a window of ``shape`` (``window_sums``), kept per shape."""
        if shape not in self._window_spectra:
            self._window_spectra[shape] = self._fresh_window_spectrum(shape)
        return self._window_spectra[shape]

    def _fresh_window_spectrum(self, shape: tuple[int, int]) -> np.ndarray:
        return window_sums.kernel_window_spectrum(self.transform.table, shape)

    def partial_product_pays(self, entries: int) -> bool:
        P = int(np.prod(self.transform.padded_shape))
        return entries <= PARTIAL_PRODUCT_FACTOR * P * np.log2(max(P, 2))

    def entry_floor(self) -> float | None:
        return self.transform.floor

    def restrict(self, idx: np.ndarray) -> "FFTOperator":
        idx = check_positions(idx, self.n)
        op = FFTOperator(self.transform, self.grid_idx[idx], auto_dense=self.auto_dense, dtype=self.dtype)
        if self._dense is not None:
            op._dense = self._dense[np.ix_(idx, idx)]
        return op

    def frobenius_norm(self) -> float:
        """sqrt(1_I' (K^2 * 1_I)): one convolution with the squared kernel, no n x n."""
        sq = KernelTransform(self.transform.table**2, self.transform.grid_shape)
        ones = np.zeros(self.transform.padded_shape)
        ones.ravel()[self.pidx] = 1.0
        return float(np.sqrt(max(0.0, float(np.sum(sq.convolve(ones).ravel()[self.pidx])))))

    @property
    def memory_nbytes(self) -> int:
        item = self.dtype.itemsize
        dense = item * self.n * self.n if (self._dense is not None or (self.auto_dense and self.dense_pays())) else 0
        return self.transform.work_nbytes(**self._precision_kw) + 5 * 8 * self.n + dense

    @property
    def matvec_work_nbytes(self) -> int:
        """Bytes of the FFT work arrays a matvec in this precision runs in."""
        return self.transform.matvec_work_nbytes(self.dtype)


def spectral_norm_estimate(op: ContactOperator, iters: int = 30, seed: int = 0, rtol: float = 1e-6) -> float:
    """Largest eigenvalue of the SPD operator by power iteration (a few matvecs).

    The Rayleigh quotient converges from below; it is returned inflated by 1 % so it
    can serve as a safe step length bound for gradient projection.
    """
    rng = np.random.default_rng(seed)
    x = rng.random(op.n) + 0.5  # positive start: H has positive entries, Perron vector > 0
    x /= np.linalg.norm(x)
    lam = 0.0
    for _ in range(iters):
        y = op.matvec(x)
        lam_new = float(x @ y)
        ny = np.linalg.norm(y)
        if ny == 0.0:
            return 0.0
        x = y / ny
        if abs(lam_new - lam) <= rtol * abs(lam_new):
            lam = lam_new
            break
        lam = lam_new
    return 1.01 * lam
