"""The FFT machinery of the matrix-free operator (problems/operators.py): the kernel's
transform shared by every restriction of one instance (``KernelTransform``), its pruned
ducc0 convolution in cached work arrays, the column pass done in cache-sized blocks, the
thread and precision settings, and ``fft_floor_pair`` -- the bare transform pair one
matvec needs, the floor its cost is compared with (benchmarks/bench_matvec.py).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.fft as sfft

from .errors import ProblemInputError

try:  # ducc0: the faster FFT (see KernelTransform); scipy.fft is the fallback
    from ducc0 import fft as _ducc_fft
    from ducc0.misc import transpose as _ducc_transpose
except ImportError:  # pragma: no cover - ducc0 is a declared dependency
    _ducc_fft = _ducc_transpose = None


def fft_workers() -> int:
    """Threads used by scipy.fft (env CONTACTBENCH_FFT_WORKERS, default: all cores)."""
    env = os.environ.get("CONTACTBENCH_FFT_WORKERS")
    if env:
        return max(1, int(env))
    return os.cpu_count() or 1


#: The precisions an operator can run in (``ContactOperator.with_precision``).
PRECISIONS: tuple[type, ...] = (np.float64, np.float32)


def operator_dtype(dtype: object) -> np.dtype:
    """``dtype`` as one of the operator precisions (float64 or float32), else a clear error."""
    try:
        dt = np.dtype(dtype)  # type: ignore[call-overload]
    except TypeError as exc:
        raise ProblemInputError(f"operator precision {dtype!r}: expected np.float64 or np.float32") from exc
    if dt not in tuple(np.dtype(p) for p in PRECISIONS):
        raise ProblemInputError(f"operator precision {dt}: expected float64 or float32")
    return dt


def fft_backend() -> str:
    """FFT library for the operator: "ducc" (ducc0, the default when it is importable)
    or "scipy" (scipy.fft/pocketfft); env CONTACTBENCH_FFT_BACKEND overrides."""
    env = os.environ.get("CONTACTBENCH_FFT_BACKEND", "").strip().lower()
    if env not in ("", "ducc", "scipy"):
        raise ProblemInputError(f"CONTACTBENCH_FFT_BACKEND={env!r}: expected 'ducc' or 'scipy'")
    if env == "scipy" or _ducc_fft is None:
        return "scipy"
    return "ducc"


#: Long columns are transformed one block at a time: b columns copied (transposed) into a
#: b x P0 buffer of about this many bytes, so a block stays in the core's cache from the
#: forward transform through the spectrum product to the inverse transform (one read and
#: one write of the spectrum rows per matvec instead of one per pass; results/perf/matvec.md).
COLUMN_BLOCK_BYTES = 1 << 19


#: A column of the padded spectrum (P0 complex entries) of at least this many bytes is
#: transformed as a contiguous row of a transposed block buffer; shorter columns are
#: transformed in place across the whole P0 x (P1/2+1) spectrum, one call per direction
#: (no per-block Python dispatch).  With ducc0 0.42 on AVX-512, contiguous transforms win
#: from 2048 points in float64 and 4096 in float32, and lose below (results/perf/matvec.md).
TRANSPOSED_COLUMN_BYTES = 1 << 15


def column_block(p0: int, complex_itemsize: int) -> int:
    """Columns per block: a power of two in 4..64 with b * P0 * itemsize ~ COLUMN_BLOCK_BYTES."""
    b = max(1, COLUMN_BLOCK_BYTES // max(1, p0 * complex_itemsize))
    return int(min(64, max(4, 1 << (b.bit_length() - 1))))


def blocked_columns(p0: int, complex_itemsize: int) -> bool:
    """Whether the column pass runs block by block on transposed buffers (``TRANSPOSED_COLUMN_BYTES``)."""
    return p0 * complex_itemsize >= TRANSPOSED_COLUMN_BYTES


class _ColumnPool:
    """Threads that share the column blocks of one convolution (ducc0 releases the
    GIL).  Made on first use; a forked child forgets its parent's pool."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self._size = 0

    def get(self, workers: int) -> ThreadPoolExecutor:
        with self._lock:
            if self._pool is None or self._size < workers:
                self._pool, self._size = ThreadPoolExecutor(workers, thread_name_prefix="contactbench-fft"), workers
            return self._pool

    def forget(self) -> None:
        self._lock, self._pool, self._size = threading.Lock(), None, 0


_COLUMN_POOL = _ColumnPool()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_COLUMN_POOL.forget)


@dataclass
class KernelTransform:
    """The kernel's offset table and its FFT on the (padded) grid, shared by all
    restrictions of one instance.

    Speed (measured in results/perf/matvec.md): the tables are even in both offsets,
    so the kernel's spectrum is *real* and is stored as a real array (half the memory
    and a real-times-complex product).  For the aperiodic 2N1 x 2N2 embedding the
    field is zero outside its N1 x N2 corner, so the convolution is done with
    *pruned* transforms: row rFFTs only on the N1 physical rows, column FFTs of
    length 2N1, and on the way back column iFFTs then row irFFTs only on the N1 rows
    that are read -- about 3/4 of the work of a full 2N x 2N rfft2 pair.  With ducc0
    the column FFTs, the spectrum product and the column iFFTs are done one block of
    columns at a time in a small buffer that stays in cache (zero-padded there, so
    only the N1 x (P1/2+1) half spectrum is held and nothing is cleared in memory);
    the blocks are copied in transposed, so each column is a contiguous row of the
    buffer, and shared out over ``fft_workers()`` threads; short columns
    (``blocked_columns``) take one call per direction over the whole spectrum instead.
    Row transforms run only on the rows holding input and back only on the rows that are
    read (``row_runs``).

    Precision: every convolution runs in float64 or float32 (``dtype`` argument).
    float32 uses its own work arrays and a float32 copy of the spectrum, made once
    per transform (``transposed_spectrum`` for ducc0, ``spectrum`` for scipy.fft): half
    the memory traffic and half the work-array memory.

    Two FFT libraries give the same numbers (to round-off): ducc0 (default; it works
    in place in work arrays kept between calls, one set per precision) and
    scipy.fft.  The work arrays make a transform single-use at a time: calls are
    serialised by a lock.
    """

    table: np.ndarray  # real-space circulant table, shape = padded grid
    grid_shape: tuple[int, int]  # physical N1 x N2
    khat: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.table = np.ascontiguousarray(self.table, dtype=np.float64)
        self.grid_shape = (int(self.grid_shape[0]), int(self.grid_shape[1]))
        spectrum = sfft.rfft2(self.table, workers=fft_workers())
        imag = float(np.max(np.abs(spectrum.imag), initial=0.0))
        scale = float(np.max(np.abs(spectrum.real), initial=0.0))
        # An even table has a real spectrum; keep it real (anything else: keep complex).
        self.khat = spectrum.real.copy() if imag <= 1e-12 * max(scale, 1e-300) else spectrum
        self.fft_count = 0  # forward + inverse 2-D transforms done by convolve_physical
        self._lock = threading.Lock()
        self._khat32: np.ndarray | None = None
        self._works: dict[str, _DuccWork] = {}
        self._transposed: dict[str, np.ndarray] = {}
        self._floor: float | None = None

    def __getstate__(self) -> dict:
        # The lock, the work arrays and the derived spectra (float32, transposed) are per
        # process: not pickled (an instance sent to a worker rebuilds them on first use).
        state = dict(self.__dict__)
        state["_lock"], state["_works"], state["_khat32"], state["_transposed"] = None, {}, None, {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        for name, empty in (("_works", {}), ("_transposed", {}), ("_khat32", None), ("_floor", None)):
            self.__dict__.setdefault(name, empty)
        self._lock = threading.Lock()

    @property
    def padded_shape(self) -> tuple[int, int]:
        return self.table.shape  # type: ignore[return-value]

    @property
    def floor(self) -> float:
        """min(0, smallest kernel entry): < 0 for the periodic kernels, whose mean is
        removed (computed once)."""
        if self._floor is None:
            self._floor = min(0.0, float(np.min(self.table, initial=0.0)))
        return self._floor

    @property
    def periodic(self) -> bool:
        return self.table.shape == tuple(self.grid_shape)

    def spectrum(self, dtype: object = np.float64) -> np.ndarray:
        """The kernel spectrum in precision ``dtype`` (float32: a copy made once)."""
        if operator_dtype(dtype) == np.float64:
            return self.khat
        if self._khat32 is None:
            self._khat32 = self.khat.astype(np.complex64 if np.iscomplexobj(self.khat) else np.float32)
        return self._khat32

    def transposed_spectrum(self, dtype: object) -> np.ndarray:
        """The spectrum in precision ``dtype``, transposed and contiguous: shape
        ((P1/2+1), P0), so the block of columns [c, c + b) is the contiguous slab [c : c + b]
        that the blocked column pass multiplies (``_transform_column_blocks``).  Made once per
        precision, column block by column block (no full-size temporary)."""
        dt = operator_dtype(dtype)
        out = self._transposed.get(dt.name)
        if out is None:
            p0, m = self.khat.shape
            kind = dt if not np.iscomplexobj(self.khat) else np.result_type(dt, np.complex64)
            out = np.empty((m, p0), dtype=kind)
            step = 256
            for c in range(0, m, step):
                out[c : c + step] = self.khat[:, c : c + step].T
            self._transposed[dt.name] = out
        return out

    def padded_index(self, flat_grid_idx: np.ndarray) -> np.ndarray:
        """Map flat indices on the physical grid to flat indices on the padded grid."""
        i, j = np.divmod(np.asarray(flat_grid_idx, dtype=np.int64), self.grid_shape[1])
        return i * self.padded_shape[1] + j

    def convolve(self, field_padded: np.ndarray) -> np.ndarray:
        """K * f on the padded grid (circular convolution; reference path, scipy.fft)."""
        w = fft_workers()
        F = sfft.rfft2(field_padded, workers=w)
        F *= self.khat
        return sfft.irfft2(F, s=self.padded_shape, workers=w)

    def convolve_physical(self, f: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """(K * f) on the physical N1 x N2 grid (a new array, in precision ``dtype``) for
        a field f given on it (zero elsewhere on the padded grid).  ``f`` may be overwritten."""
        dt = operator_dtype(dtype)
        if fft_backend() == "ducc":
            with self._lock:
                work = self._ducc_work(dt)
                work.load_field(f)
                return np.array(self._ducc_convolve(work), copy=True)
        return self._scipy_convolve(np.asarray(f, dtype=dt))

    def apply_on_set(self, pidx: np.ndarray, x: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """gather_I (K * scatter_I x) for the points with padded flat indices ``pidx``:
        the matvec of H_II in precision ``dtype``, without building the physical field
        when ducc is used."""
        dt = operator_dtype(dtype)
        if fft_backend() == "ducc":
            with self._lock:
                work = self._ducc_work(dt)
                work.load_points(pidx, x)
                self._ducc_convolve(work)
                return work.gather(pidx)
        n1, n2 = self.grid_shape
        i, j = np.divmod(np.asarray(pidx), self.padded_shape[1])
        f = np.zeros((n1, n2), dtype=dt)
        f[i, j] = x
        return self._scipy_convolve(f)[i, j]

    def _scipy_convolve(self, f: np.ndarray) -> np.ndarray:
        """K * f by scipy.fft in the precision of f (float32 stays float32)."""
        w = fft_workers()
        khat = self.spectrum(f.dtype)
        self.fft_count += 2
        if self.periodic:
            F = sfft.rfft2(f, workers=w, overwrite_x=True)
            F *= khat
            return sfft.irfft2(F, s=self.padded_shape, workers=w, overwrite_x=True)
        n1, _ = self.grid_shape
        p0, p1 = self.padded_shape
        rows = sfft.rfft(f, n=p1, axis=1, workers=w, overwrite_x=True)  # N1 x (N2+1)
        F = sfft.fft(rows, n=p0, axis=0, workers=w, overwrite_x=True)  # 2N1 x (N2+1)
        F *= khat
        back = sfft.ifft(F, axis=0, workers=w, overwrite_x=True)[:n1]
        u = sfft.irfft(back, n=p1, axis=1, workers=w)
        return u[:, : self.grid_shape[1]]

    def _ducc_work(self, dtype: np.dtype) -> "_DuccWork":
        work = self._works.get(dtype.name)
        if work is None:
            work = self._works[dtype.name] = _DuccWork(self.grid_shape, self.padded_shape, dtype)
        return work

    def _ducc_convolve(self, work: "_DuccWork") -> np.ndarray:
        """K * (work.field) with ducc0, in the work arrays; returns a view of the
        physical N1 x N2 result (valid until the next call).  Row transforms run only
        on ``work.in_runs`` (the rows holding non-zero input; the others' spectra are
        zero) and back only on ``work.out_runs`` (the rows that will be read)."""
        w = fft_workers()
        self.fft_count += 2
        p1 = self.padded_shape[1]
        start = 0
        for a, b in work.in_runs:
            work.rows[start:a] = 0.0
            _ducc_fft.r2c(work.field[a:b], axes=(1,), out=work.rows[a:b], nthreads=w)
            start = b
        work.rows[start:] = 0.0
        self._column_pass(work, w)
        for a, b in work.out_runs:
            _ducc_fft.c2r(work.rows[a:b], axes=(1,), lastsize=p1, forward=False, inorm=2, out=work.out[a:b], nthreads=w)
        return work.out[:, : self.grid_shape[1]]

    def _column_pass(self, work: "_DuccWork", workers: int) -> None:
        """work.rows <- first N1 rows of iFFT_0(khat * FFT_0(rows zero-padded to P0)): for
        short columns in one call per direction over the whole spectrum (``work.whole``,
        whose first N1 rows are ``work.rows``), else block by block of columns in transposed
        buffers, the blocks shared out over ``workers`` threads."""
        n1 = self.grid_shape[0]
        if work.whole is not None:
            spec = work.whole
            spec[n1:] = 0.0
            _ducc_fft.c2c(spec, axes=(0,), forward=True, out=spec, nthreads=workers)
            spec *= self.spectrum(work.dtype)
            _ducc_fft.c2c(spec, axes=(0,), forward=False, inorm=2, out=spec, nthreads=workers)
            return
        khat_t = self.transposed_spectrum(work.dtype)
        starts = np.arange(0, work.rows.shape[1], work.block)
        chunks = [c for c in np.array_split(starts, max(1, workers)) if c.size]
        buffers = work.buffers(len(chunks))
        if len(chunks) == 1:
            _transform_column_blocks(work.rows, khat_t, buffers[0], chunks[0], n1)
            return
        pool = _COLUMN_POOL.get(len(chunks))
        jobs = [pool.submit(_transform_column_blocks, work.rows, khat_t, buf, c, n1) for buf, c in zip(buffers, chunks)]
        for job in jobs:
            job.result()

    def matvec_work_nbytes(self, dtype: object = np.float64) -> int:
        """Bytes of the work arrays of one precision (what a matvec touches besides the spectrum)."""
        return _DuccWork.nbytes_for(self.grid_shape, self.padded_shape, operator_dtype(dtype), fft_workers())

    def work_nbytes(self, dtype: object = np.float64) -> int:
        """Kernel table + spectrum + its copy in ``dtype`` (transposed, or float32 for short
        columns) + the work arrays of ``dtype``."""
        dt = operator_dtype(dtype)
        blocked = blocked_columns(self.padded_shape[0], np.result_type(dt, np.complex64).itemsize)
        copy = 0 if not blocked and dt == np.float64 else self.khat.nbytes * dt.itemsize // 8  # transposed, or float32
        return int(self.table.nbytes + self.khat.nbytes + copy + self.matvec_work_nbytes(dt))


#: The two layouts of the column transforms that the FFT floor is timed in: "strided"
#: (in place along axis 0 of the P0 x (P1/2+1) spectrum) and "transposed" (along the
#: contiguous rows of a (P1/2+1) x P0 spectrum, the row transforms writing and reading it
#: through a transposed view).  Which one is faster depends on the size and the precision;
#: the floor of a matvec is the faster of the two (benchmarks/bench_matvec.py).
FLOOR_LAYOUTS: tuple[str, ...] = ("strided", "transposed")


def fft_floor_pair(transform: KernelTransform, dtype: object = np.float64, layout: str = "strided") -> Callable[[], None]:
    """The FFT floor of a matvec: a function that runs only the transform pair a ducc0
    matvec needs, on arrays of its own -- row rFFTs on the N1 rows, column FFTs and
    iFFTs over the whole spectrum in ``layout`` (one of ``FLOOR_LAYOUTS``), row irFFTs
    back on the N1 rows -- with ``fft_workers()`` threads, no scatter, gather, clearing or
    spectrum product.  Benchmarks time it beside the matvec (results/perf/matvec.md)."""
    if _ducc_fft is None:  # pragma: no cover - ducc0 is a declared dependency
        raise ProblemInputError("the FFT floor is measured with ducc0, which is not importable")
    if layout not in FLOOR_LAYOUTS:
        raise ProblemInputError(f"FFT floor layout {layout!r}: expected one of {', '.join(FLOOR_LAYOUTS)}")
    dt = operator_dtype(dtype)
    n1, _ = transform.grid_shape
    p0, p1 = transform.padded_shape
    m = p1 // 2 + 1
    field_ = np.random.default_rng(0).random((n1, p1)).astype(dt)
    cdt = np.result_type(dt, np.complex64)
    out = np.empty((n1, p1), dtype=dt)
    if layout == "strided":
        spec = np.empty((p0, m), dtype=cdt)
        rows, axis = spec[:n1], 0
    else:
        spec = np.empty((m, p0), dtype=cdt)
        rows, axis = spec[:, :n1].T, 1

    def pair() -> None:
        w = fft_workers()
        _ducc_fft.r2c(field_, axes=(1,), out=rows, nthreads=w)
        _ducc_fft.c2c(spec, axes=(axis,), forward=True, out=spec, nthreads=w)
        _ducc_fft.c2c(spec, axes=(axis,), forward=False, inorm=2, out=spec, nthreads=w)
        _ducc_fft.c2r(rows, axes=(1,), lastsize=p1, forward=False, inorm=2, out=out, nthreads=w)

    return pair


def _transform_column_blocks(rows: np.ndarray, khat_t: np.ndarray, buf: np.ndarray, starts: np.ndarray, n1: int) -> None:
    """For each block of columns [c, c + b) with c in ``starts``: copy the N1 rows in
    transposed into ``buf`` (b x P0, each column a contiguous row), zero the padding,
    FFT along the rows, multiply by the transposed spectrum's slab khat_t[c : c + b],
    iFFT, and write the first N1 entries back.  One thread's share of ``_column_pass``."""
    b, m = buf.shape[0], rows.shape[1]
    for c in starts.tolist():
        w = min(b, m - c)
        blk = buf[:w]
        _ducc_transpose(rows[:, c : c + w].T, blk[:, :n1])
        blk[:, n1:] = 0.0
        _ducc_fft.c2c(blk, axes=(1,), forward=True, out=blk, nthreads=1)
        blk *= khat_t[c : c + w]
        _ducc_fft.c2c(blk, axes=(1,), forward=False, inorm=2, out=blk, nthreads=1)
        rows[:, c : c + w] = blk[:, :n1].T


#: Row runs closer than this many rows are merged (one transform call instead of two).
RUN_GAP = 8


def row_runs(rows: np.ndarray, n1: int) -> list[tuple[int, int]]:
    """Half-open runs [a, b) of the rows in ``rows`` (any order, repeats allowed) among
    0..n1-1, runs less than ``RUN_GAP`` rows apart merged."""
    flags = np.zeros(n1 + 1, dtype=bool)
    flags[rows] = True
    edges = np.flatnonzero(np.diff(np.r_[False, flags].view(np.int8)))
    starts, ends = edges[0::2], edges[1::2]
    if starts.size == 0:
        return []
    keep = np.r_[True, starts[1:] - ends[:-1] >= RUN_GAP]
    return list(zip(starts[keep].tolist(), np.r_[ends[:-1][keep[1:]], ends[-1]].tolist()))


class _DuccWork:
    """Work arrays of the ducc0 convolution in one precision, reused between calls.

    ``field`` holds the input rows (N1 x P1, zero beyond the physical columns), ``rows``
    their half spectrum (N1 x P1/2+1), ``out`` the result rows.  Before a load only the
    entries written by the previous call are cleared, and nothing when the index set is
    the same array as last time (a solver's repeated matvecs on one operator: every
    entry written before is written again).  The whole grid in row-major order is
    loaded and read as a block, not by indices."""

    def __init__(self, grid_shape: tuple[int, int], padded_shape: tuple[int, int], dtype: np.dtype) -> None:
        n1, n2 = grid_shape
        p0, p1 = padded_shape
        self.n1, self.n2, self.p0, self.p1 = n1, n2, p0, p1
        self.dtype = np.dtype(dtype)
        self.cdtype = np.result_type(self.dtype, np.complex64)
        self.field = np.zeros((n1, p1), dtype=self.dtype)
        blocked = blocked_columns(p0, self.cdtype.itemsize)
        self.whole = None if blocked else np.empty((p0, p1 // 2 + 1), dtype=self.cdtype)
        self.rows = self.whole[:n1] if self.whole is not None else np.empty((n1, p1 // 2 + 1), dtype=self.cdtype)
        self.out = np.empty((n1, p1), dtype=self.dtype)
        self.block = column_block(p0, self.cdtype.itemsize)
        self._buffers: list[np.ndarray] = []
        self._dirty: np.ndarray | None = None  # the index array written last time (None: none)
        self._dirty_all = False
        self._layout: tuple[np.ndarray | None, bool] = (None, False)  # (index array, is the whole grid)
        self._point_rows: tuple[np.ndarray | None, np.ndarray, list[tuple[int, int]]] = (None, np.empty(0, np.int64), [])
        self.in_runs: list[tuple[int, int]] = [(0, n1)]  # rows with non-zero input (half-open runs)
        self.out_runs: list[tuple[int, int]] = [(0, n1)]  # rows the caller reads

    @staticmethod
    def nbytes_for(grid_shape: tuple[int, int], padded_shape: tuple[int, int], dtype: np.dtype, workers: int) -> int:
        n1, _ = grid_shape
        p0, p1 = padded_shape
        item = np.dtype(dtype).itemsize
        if not blocked_columns(p0, 2 * item):  # whole spectrum, no block buffers
            return int(2 * item * n1 * p1 + 2 * item * p0 * (p1 // 2 + 1))
        block = column_block(p0, 2 * item)
        return int(2 * item * n1 * p1 + 2 * item * n1 * (p1 // 2 + 1) + max(1, workers) * 2 * item * p0 * block)

    def buffers(self, count: int) -> list[np.ndarray]:
        """``count`` column-block buffers (block x P0 complex), one per thread."""
        while len(self._buffers) < count:
            self._buffers.append(np.empty((self.block, self.p0), dtype=self.cdtype))
        return self._buffers[:count]

    def _is_whole_grid(self, pidx: np.ndarray) -> bool:
        key, whole = self._layout
        if key is not pidx:
            whole = pidx.size == self.n1 * self.n2 and np.array_equal(
                pidx, (np.arange(self.n1)[:, None] * self.p1 + np.arange(self.n2)).ravel()
            )
            self._layout = (pidx, bool(whole))
        return bool(whole)

    def _clear(self) -> None:
        if self._dirty_all:
            self.field[:, : self.n2] = 0.0
        elif self._dirty is not None:
            self.field.ravel()[self._dirty] = 0.0
        self._dirty, self._dirty_all = None, False

    def load_points(self, pidx: np.ndarray, x: np.ndarray) -> None:
        """Field = x at the padded flat indices pidx (row stride P1), zero elsewhere; the
        row runs of the transforms are those of the non-zero entries (in) and of pidx (out)."""
        whole = self._is_whole_grid(pidx)
        if pidx is not self._dirty:
            self._clear()
        if whole:
            self.field[:, : self.n2] = np.reshape(x, (self.n1, self.n2))
            self.in_runs = self.out_runs = [(0, self.n1)]
        else:
            self.field.ravel()[pidx] = x
            rows, self.out_runs = self._rows_of(pidx)
            self.in_runs = row_runs(rows[np.asarray(x) != 0], self.n1)
        self._dirty, self._dirty_all = pidx, whole

    def _rows_of(self, pidx: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
        """The row of each index of pidx and their runs (cached for the last pidx array)."""
        key, rows, runs = self._point_rows
        if key is not pidx:
            rows = pidx // self.p1
            runs = row_runs(rows, self.n1)
            self._point_rows = (pidx, rows, runs)
        return rows, runs

    def load_field(self, f: np.ndarray) -> None:
        self._clear()
        self.field[:, : self.n2] = f
        self._dirty_all = True
        self.in_runs = self.out_runs = [(0, self.n1)]

    def gather(self, pidx: np.ndarray) -> np.ndarray:
        """The result at the padded flat indices (``out`` has the layout of ``field``)."""
        if self._is_whole_grid(pidx):
            return np.array(self.out[:, : self.n2]).ravel()
        return np.take(self.out.ravel(), pidx)
