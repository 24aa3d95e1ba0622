"""The FFT machinery of the matrix-free operator (problems/operators.py): the kernel's
transform shared by every restriction of one instance (``KernelTransform``), its pruned
ducc0 convolution in cached work arrays, the row and column passes done in cache-sized
blocks (a periodic grid with short columns and short rows: one 2-D transform pair), and
the precision settings.  The threads, the FFT library and the row-call batching under it
are problems/fft_threads.py; the bare transform pair one matvec needs, the floor its cost
is compared with, is problems/fft_floor.py.
"""

from __future__ import annotations

import copy
import os
import threading
from dataclasses import dataclass, field
from functools import partial
from typing import Any, ClassVar

import numpy as np
import scipy.fft as sfft

from .errors import ProblemInputError
from .fft_threads import (
    _ducc_fft,
    _ducc_transpose,
    block_chunks,
    fft_backend,
    fft_workers,
    irfft_rows,
    periodic_convolve,
    rfft_rows,
    row_batch,
    share_out,
)
from .operator_state import SealRule

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


#: Long columns are transformed one block at a time: b columns copied (transposed) into a
#: b x P0 buffer of about this many bytes, so a block stays in the core's cache from the
#: forward transform through the spectrum product to the inverse transform (one read and
#: one write of the spectrum rows per matvec instead of one per pass; results/perf/matvec.md).
COLUMN_BLOCK_BYTES = 1 << 19

#: The spectrum's one-off transposition (``KernelTransform.transposed_spectrum``) copies square
#: tiles of this side, both in cache (8192 x 4097 float64: 1.38 s by column blocks, 0.12 s so).
TRANSPOSE_TILE = 256


def has_avx512() -> bool:
    """Whether numpy's runtime dispatch sees AVX-512F on this CPU (False when it cannot tell)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # pragma: no cover - numpy < 2 or another build
        return False
    return bool(__cpu_features__.get("AVX512F", False))


#: A column of the padded spectrum (P0 complex entries) of at least this many bytes is
#: transformed as a contiguous row of a transposed block buffer; shorter columns are
#: transformed in place across the whole P0 x (P1/2+1) spectrum, one call per direction
#: (no per-block Python dispatch).  The two layouts give bitwise the same products; which is
#: faster depends on ducc0's vector code.  With AVX-512, contiguous transforms win from 2048
#: points in float64 and 4096 in float32 (32 KiB) and lose below; with AVX2 alone they win
#: from 1024 points in float64 and 2048 in float32 (16 KiB): 1024^2 float32 matvec 27-34 ms
#: against 39-46 ms in place (results/perf/matvec.md).  Env CONTACTBENCH_TRANSPOSED_COLUMN_BYTES
#: overrides.
TRANSPOSED_COLUMN_BYTES = int(os.environ.get("CONTACTBENCH_TRANSPOSED_COLUMN_BYTES", 0)) or (
    1 << 15 if has_avx512() else 1 << 14)


#: Rows are transformed in blocks of about this many bytes of float64 padded rows (P1
#: entries each), ``MIN_ROW_BLOCK`` to 64 rows: the block's input is copied or scattered
#: into a small per-thread buffer, whose padding stays zero, and transformed from there; on
#: the way back a block is transformed into a second buffer and read from it.  The N1 x P1
#: input and output fields are never built, and the copies happen in cache
#: (results/perf/matvec.md).  At least ``MIN_ROW_BLOCK`` rows, so the Python
#: work per block stays small next to its transforms on wide grids.
ROW_BLOCK_BYTES = 1 << 20
MIN_ROW_BLOCK = 16


def row_block(p1: int) -> int:
    """Rows per block: a power of two in MIN_ROW_BLOCK..64 with rows * P1 * 8 ~ ROW_BLOCK_BYTES."""
    b = max(1, ROW_BLOCK_BYTES // max(1, 8 * p1))
    return int(min(64, max(MIN_ROW_BLOCK, 1 << (b.bit_length() - 1))))


#: A float32 product on a periodic grid (not padded) whose spectrum is held whole (short
#: columns, not ``blocked_columns``) and whose rows ducc0 takes in one call (``row_batch``: rows
#: shorter than ``FLOAT32_LONG_ROW``) runs as one 2-D ducc0 transform pair on an N1 x N2 field
#: (``KernelTransform._periodic_pair``): no row of it is empty, so the row blocks save no
#: transform, and their Python work and the separate column pass cost more -- at 512^2
#: 0.78-0.90x their time on an AMD EPYC (AVX2), 0.95-1.05x on an AVX-512 Xeon.  Longer rows
#: keep the row blocks: on the Xeon the 2-D pair took 1.39-1.48x their time at 1024^2 and 2048^2,
#: and 0.96-1.19x with its rows in ``row_batch`` calls.  Not in float64, where the pair's
#: field and spectrum leave the cache: 0.95-1.12x (results/perf/periodic-pair).
WHOLE_PERIODIC_PAIR = True

#: A convolution's row blocks and column pass are shared over threads only for at least
#: this many bytes of padded-row field (N1 x P1 x itemsize) per thread: below, one thread
#: does them (a thread's dispatch costs more than its share of a small grid).  On two cores
#: two threads took up to 1.39x one thread's time on a 256^2-512^2 product and up to 1.47x
#: less from 1024^2 (results/perf/small-grid-threads).
ROW_THREAD_BYTES = 4 << 20


def row_threads(n1: int, p1: int, workers: int, itemsize: int = 8) -> int:
    """Threads for the row blocks and column pass of an N1 x P1 padded-row field of
    ``itemsize``-byte reals (``ROW_THREAD_BYTES``), at most ``workers``."""
    return int(min(max(1, workers), max(1, n1 * p1 * itemsize // ROW_THREAD_BYTES)))


def column_block(p0: int, complex_itemsize: int) -> int:
    """Columns per block: a power of two in 4..64 with b * P0 * itemsize ~ COLUMN_BLOCK_BYTES."""
    b = max(1, COLUMN_BLOCK_BYTES // max(1, p0 * complex_itemsize))
    return int(min(64, max(4, 1 << (b.bit_length() - 1))))


def blocked_columns(p0: int, complex_itemsize: int) -> bool:
    """Whether the column pass runs block by block on transposed buffers (``TRANSPOSED_COLUMN_BYTES``)."""
    return p0 * complex_itemsize >= TRANSPOSED_COLUMN_BYTES


def embedded_even_spectrum(table: np.ndarray, grid_shape: tuple[int, int]) -> np.ndarray | None:
    """The spectrum (``rfft2``'s layout, real) of the 2 N1 x 2 N2 embedding of an aperiodic
    kernel (``kernels.aperiodic_table``: even in both offsets, offset +-N zero), from a 2-D
    DCT-I of its quarter of offsets 0..N: the same numbers to round-off from a quarter of the
    input, with no complex array.  None for any other table (checked: exactly even)."""
    n1, n2 = grid_shape
    if table.shape != (2 * n1, 2 * n2) or n1 < 2 or n2 < 2 or table[n1].any() or table[:, n2].any():
        return None
    mirrored = np.array_equal(table[n1 + 1:], table[n1 - 1:0:-1])
    if not (mirrored and np.array_equal(table[:, n2 + 1:], table[:, n2 - 1:0:-1])):
        return None
    quarter = sfft.dctn(table[: n1 + 1, : n2 + 1], type=1, workers=fft_workers())
    out = np.empty((2 * n1, n2 + 1))
    out[: n1 + 1] = quarter
    out[n1 + 1:] = quarter[n1 - 1:0:-1]
    return out


def pristine_transform(transform: KernelTransform) -> KernelTransform:
    """A twin of ``transform`` sharing its table and spectrum, with none of its caches
    (its own pickling state: ``KernelTransform.__getstate__``)."""
    twin = copy.copy(transform)
    twin._floor = None
    return twin


def _fresh_work(transform: KernelTransform, name: str, current: Any) -> _DuccWork:
    """The ducc0 work arrays of precision ``name`` made afresh, with as many per-thread
    buffers as ``current`` holds (made on first use by as many threads): the seal's rebuild
    of ``KernelTransform._works``."""
    work = pristine_transform(transform)._ducc_work(np.dtype(name))
    for attr, make in (("_buffers", work.buffers), ("_row_buffers", work.row_buffers)):
        held = getattr(current, attr, None)
        make(len(held) if type(held) is list else 0)
    if isinstance(getattr(current, "_field", None), np.ndarray):
        work.field()
    return work


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
    buffer, and shared out over up to ``fft_workers()`` threads (``row_threads``: one for a
    small grid); short columns
    (``blocked_columns``) take one call per direction over the whole spectrum instead.
    The row transforms run block by block of rows (``ROW_BLOCK_BYTES``, ``_RowPlan``): the
    block's input is copied or scattered into a small buffer and transformed from there,
    only over the rows from its first to its last non-zero input; on the way back only the
    rows holding points are transformed, into a second buffer that the result is read
    from.  The blocks are shared out over the threads too.

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
    #: What the seal reads besides content (problems/operator_state.py): the transform
    #: count, and the caches each rebuilt on a twin with none (``pristine_transform``).
    SEAL_RULE: ClassVar[SealRule] = SealRule(counters=frozenset({"fft_count"}), caches={
        "_khat32": lambda t, key, current: pristine_transform(t).spectrum(np.float32),
        "_transposed": lambda t, name, current: pristine_transform(t).transposed_spectrum(np.dtype(name)),
        "_floor": lambda t, key, current: pristine_transform(t).floor,
        "_works": _fresh_work,
    })

    def __post_init__(self) -> None:
        self.table = np.ascontiguousarray(self.table, dtype=np.float64)
        self.grid_shape = (int(self.grid_shape[0]), int(self.grid_shape[1]))
        even = embedded_even_spectrum(self.table, self.grid_shape)
        if even is not None:
            self.khat = even
        else:
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
        precision, ``TRANSPOSE_TILE``-square tile by tile (no full-size temporary), the bands
        of tile rows shared out over the threads (8192 x 4097 float64 on two: 0.48 -> 0.25 s)."""
        dt = operator_dtype(dtype)
        out = self._transposed.get(dt.name)
        if out is None:
            p0, m = self.khat.shape
            kind = dt if not np.iscomplexobj(self.khat) else np.result_type(dt, np.complex64)
            out = np.empty((m, p0), dtype=kind)
            bands = block_chunks(p0, TRANSPOSE_TILE, fft_workers())
            share_out([partial(_transpose_tiles, self.khat, out, starts) for starts in bands])
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
        a field f given on it (zero elsewhere on the padded grid)."""
        dt = operator_dtype(dtype)
        if fft_backend() == "ducc":
            out = np.empty(self.grid_shape, dtype=dt)
            with self._lock:
                self._ducc_convolve(self._ducc_work(dt), None, np.asarray(f), out)
            return out
        return self._scipy_convolve(np.array(f, dtype=dt))

    def apply_on_set(self, pidx: np.ndarray, x: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """gather_I (K * scatter_I x) for the points with padded flat indices ``pidx``:
        the matvec of H_II in precision ``dtype``, without building the physical field
        when ducc is used.  ``pidx`` must not repeat (the scatter writes each point once;
        ``FFTOperator`` checks its indices)."""
        dt = operator_dtype(dtype)
        if fft_backend() == "ducc":
            out = np.empty(pidx.size, dtype=dt)
            with self._lock:
                self._ducc_convolve(self._ducc_work(dt), pidx, np.asarray(x), out)
            return out
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

    def _ducc_convolve(self, work: "_DuccWork", pidx: np.ndarray | None, x: np.ndarray, out: np.ndarray) -> None:
        """out <- gather (K * scatter x) with ducc0: x and out hold the values at the padded
        flat indices ``pidx``, or the whole physical grid when ``pidx`` is None or is the
        whole grid in row-major order.  Row blocks (``_RowPlan``) and the column pass are
        shared out over ``row_threads`` of the ``fft_workers()`` threads."""
        w = row_threads(work.n1, work.p1, fft_workers(), work.dtype.itemsize)
        self.fft_count += 2
        plan = work.plan(pidx)
        short_rows = work.dtype.itemsize == 4 and not work.batch  # float32 rows ducc0 takes in one call
        if WHOLE_PERIODIC_PAIR and self.periodic and work.whole is not None and short_rows:
            self._periodic_pair(work, plan, x, out, w)
            return
        if plan.whole:
            x, out = np.reshape(x, self.grid_shape), np.reshape(out, self.grid_shape)
        chunks = block_chunks(work.row_blocks, 1, w)
        buffers = work.row_buffers(len(chunks))
        share_out([partial(_rows_forward, work, plan, x, c, b) for c, b in zip(chunks, buffers)])
        self._column_pass(work, w)
        share_out([partial(_rows_back, work, plan, out, c, b) for c, b in zip(chunks, buffers)])

    def _periodic_pair(self, work: "_DuccWork", plan: "_RowPlan", x: np.ndarray, out: np.ndarray, workers: int) -> None:
        """out <- gather (K * scatter x) on an unpadded grid (``WHOLE_PERIODIC_PAIR``): x copied
        or scattered into the N1 x N2 field, convolved through the whole spectrum
        (``periodic_convolve``), and the result copied or gathered out."""
        field_, spec = work.field(), work.whole
        flat = field_.ravel()
        if plan.whole:
            field_[...] = np.reshape(x, field_.shape)
        else:
            flat[...] = 0.0
            flat[plan.key] = x
        periodic_convolve(field_, spec, self.spectrum(work.dtype), workers)
        if plan.whole:
            np.copyto(np.reshape(out, field_.shape), field_)
        else:
            np.take(flat, plan.key, out=out)

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
        chunks = block_chunks(work.rows.shape[1], work.block, workers)
        buffers = work.buffers(len(chunks))
        share_out([partial(_transform_column_blocks, work.rows, khat_t, buf, c, n1) for buf, c in zip(buffers, chunks)])

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


#: The layouts the FFT floor is timed in.  Column transforms: "strided" (in place along
#: axis 0 of the P0 x (P1/2+1) spectrum) or "transposed" (along the contiguous rows of a
#: (P1/2+1) x P0 spectrum, the row transforms writing and reading it through a transposed
#: view).  Row transforms: one ducc0 call per direction over the N1 rows with ducc0's own
#: threads, or, with "-row-blocks", the matvec's row blocks (``row_block`` rows a call,
#: shared over the threads).  Which is fastest depends on the size and the precision; the
#: floor of a matvec is the fastest of them (benchmarks/bench_matvec.py).
def _transpose_tiles(src: np.ndarray, out: np.ndarray, starts: np.ndarray) -> None:
    """out[:, r : r + t] <- src[r : r + t].T for each row start r in ``starts`` (t =
    ``TRANSPOSE_TILE``), square tile by square tile: one thread's band of
    ``KernelTransform.transposed_spectrum``."""
    t, m = TRANSPOSE_TILE, src.shape[1]
    for r in starts.tolist():
        for c in range(0, m, t):
            out[c : c + t, r : r + t] = src[r : r + t, c : c + t].T


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


@dataclass
class _RowPlan:
    """Where the points of one index set fall in the row blocks (``_DuccWork.row_rows`` rows
    each): block k holds rows [k * row_rows, (k + 1) * row_rows) and the points at positions seg[k]:seg[k+1]
    of the set in increasing index order (``order``: that order as positions in the set,
    None when the set is increasing already), at flat offsets ``local`` inside the block's
    rows (row * P1 + column).  ``whole``: the whole physical grid in row-major order, read
    and written as blocks of rows with no indices."""

    key: np.ndarray | None
    whole: bool
    seg: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int64))
    local: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    order: np.ndarray | None = None


def _rows_forward(work: "_DuccWork", plan: _RowPlan, x: np.ndarray, blocks: np.ndarray, bufs: tuple) -> None:
    """work.rows <- the row rFFTs of the input, block by block in ``bufs[0]``: the block's
    values copied (whole grid) or scattered in, rFFT on the rows from the first to the last
    non-zero input (the block's other spectrum rows are zero), and the entries written
    cleared again (the buffer is zero between calls)."""
    buf, rows, p1, rb = bufs[0], work.rows, work.p1, work.row_rows
    flat = buf.ravel()
    for k in blocks.tolist():
        a = k * rb
        b = min(a + rb, work.n1)
        if plan.whole:
            buf[: b - a, : work.n2] = x[a:b]
            lo, hi = 0, b - a
        else:
            s, e = plan.seg[k], plan.seg[k + 1]
            xs = x[s:e] if plan.order is None else x[plan.order[s:e]]
            nz = np.flatnonzero(xs)
            if nz.size == 0:
                rows[a:b] = 0.0
                continue
            loc = plan.local[s:e]
            flat[loc] = xs
            lo, hi = int(loc[nz[0]]) // p1, int(loc[nz[-1]]) // p1 + 1
            rows[a : a + lo] = 0.0
            rows[a + hi : b] = 0.0
        rfft_rows(buf[lo:hi], rows[a + lo : a + hi], work.batch)
        if plan.whole:  # the buffer goes back to zero for the next call (in cache)
            buf[: b - a, : work.n2] = 0.0
        else:
            flat[loc] = 0.0


def _rows_back(work: "_DuccWork", plan: _RowPlan, out: np.ndarray, blocks: np.ndarray, bufs: tuple) -> None:
    """out <- the result at the plan's points: per block, the row irFFTs of the rows that
    hold points into ``bufs[1]``, then copied (whole grid) or gathered out of it."""
    buf, rows, p1, rb = bufs[1], work.rows, work.p1, work.row_rows
    for k in blocks.tolist():
        a = k * rb
        b = min(a + rb, work.n1)
        if plan.whole:
            irfft_rows(rows[a:b], buf[: b - a], work.batch)
            out[a:b] = buf[: b - a, : work.n2]
            continue
        s, e = plan.seg[k], plan.seg[k + 1]
        if s == e:
            continue
        loc = plan.local[s:e]
        lo, hi = int(loc[0]) // p1, int(loc[-1]) // p1 + 1
        irfft_rows(rows[a + lo : a + hi], buf[lo:hi], work.batch)
        if plan.order is None:
            np.take(buf.ravel(), loc, out=out[s:e])
        else:
            out[plan.order[s:e]] = buf.ravel()[loc]


class _DuccWork:
    """Work arrays of the ducc0 convolution in one precision, reused between calls.

    ``rows`` holds the half spectrum of the N1 physical rows (N1 x P1/2+1; for short
    columns the first N1 rows of ``whole``, the P0 x (P1/2+1) spectrum); each thread has
    two row buffers (``row_block`` rows x P1: input, zero beyond what a block writes, and
    output) and, for long columns, a column-block buffer.  The row plan of the last index
    set is kept (a solver's repeated products on one operator reuse it)."""

    #: What the seal reads besides content (problems/operator_state.py): the buffers by their
    #: layout, the last row plan held to the plan its key gives.
    SEAL_RULE: ClassVar[SealRule] = SealRule(
        work=frozenset({"whole", "rows", "_buffers[*]", "_row_buffers[*][1]", "_field"}),
        per_product={"_last": lambda work, key, current: work.fresh_plan(current.key)})

    def __init__(self, grid_shape: tuple[int, int], padded_shape: tuple[int, int], dtype: np.dtype) -> None:
        n1, n2 = grid_shape
        p0, p1 = padded_shape
        self.n1, self.n2, self.p0, self.p1 = n1, n2, p0, p1
        self.dtype = np.dtype(dtype)
        self.cdtype = np.result_type(self.dtype, np.complex64)
        blocked = blocked_columns(p0, self.cdtype.itemsize)
        self.whole = None if blocked else np.empty((p0, p1 // 2 + 1), dtype=self.cdtype)
        self.rows = self.whole[:n1] if self.whole is not None else np.empty((n1, p1 // 2 + 1), dtype=self.cdtype)
        self.block = column_block(p0, self.cdtype.itemsize)
        self.row_rows = row_block(p1)
        self.row_blocks = -(-n1 // self.row_rows)
        self.batch = row_batch(p1, self.dtype.itemsize)
        self._buffers: list[np.ndarray] = []
        self._row_buffers: list[tuple[np.ndarray, np.ndarray]] = []
        self._plan = _RowPlan(None, True)  # the whole grid
        self._last: _RowPlan | None = None
        self._field: np.ndarray | None = None

    @staticmethod
    def nbytes_for(grid_shape: tuple[int, int], padded_shape: tuple[int, int], dtype: np.dtype, workers: int) -> int:
        n1, _ = grid_shape
        p0, p1 = padded_shape
        item = np.dtype(dtype).itemsize
        threads = max(1, workers)
        row_buffers = threads * 2 * item * row_block(p1) * p1
        if not blocked_columns(p0, 2 * item):  # whole spectrum, no column-block buffers
            periodic_field = item * n1 * p1 if item == 4 and (n1, p1) == (p0, grid_shape[1]) else 0  # 2-D pair
            return int(2 * item * p0 * (p1 // 2 + 1) + row_buffers + periodic_field)
        return int(2 * item * n1 * (p1 // 2 + 1) + threads * 2 * item * p0 * column_block(p0, 2 * item) + row_buffers)

    def field(self) -> np.ndarray:
        """The N1 x N2 real field of a periodic 2-D pair (``KernelTransform._periodic_pair``)."""
        if self._field is None:
            self._field = np.empty((self.n1, self.n2), dtype=self.dtype)
        return self._field

    def buffers(self, count: int) -> list[np.ndarray]:
        """``count`` column-block buffers (block x P0 complex), one per thread."""
        while len(self._buffers) < count:
            self._buffers.append(np.empty((self.block, self.p0), dtype=self.cdtype))
        return self._buffers[:count]

    def row_buffers(self, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """``count`` pairs of row buffers (input zero-initialised, output), one per thread."""
        while len(self._row_buffers) < count:
            shape = (self.row_rows, self.p1)
            self._row_buffers.append((np.zeros(shape, dtype=self.dtype), np.empty(shape, dtype=self.dtype)))
        return self._row_buffers[:count]

    def plan(self, pidx: np.ndarray | None) -> _RowPlan:
        """The row plan of the padded flat indices ``pidx`` (None: the whole grid)."""
        if pidx is None:
            return self._plan
        last = self._last
        if last is not None and last.key is pidx:
            return last
        self._last = plan = self.fresh_plan(pidx)
        return plan

    def fresh_plan(self, pidx: np.ndarray) -> _RowPlan:
        """The row plan of the padded flat indices ``pidx``, made afresh (not kept)."""
        pidx = np.asarray(pidx)
        if pidx.size == self.n1 * self.n2 and np.array_equal(
            pidx, (np.arange(self.n1)[:, None] * self.p1 + np.arange(self.n2)).ravel()
        ):
            return _RowPlan(pidx, True)
        return self._points_plan(pidx)

    def _points_plan(self, pidx: np.ndarray) -> _RowPlan:
        rb = self.row_rows
        order = None
        ordered = pidx.astype(np.int64, copy=False)
        if ordered.size > 1 and not np.all(ordered[1:] > ordered[:-1]):
            order = np.argsort(ordered, kind="stable")
            ordered = ordered[order]
        start = (ordered // self.p1) // rb * (rb * self.p1)  # flat offset of each point's block
        seg = np.searchsorted(start, np.arange(self.row_blocks + 1) * rb * self.p1)
        return _RowPlan(pidx, False, seg, ordered - start, order)
