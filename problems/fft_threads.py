"""The threads and the row-call batching under every FFT of the package: how many threads
(``fft_workers``), the pool that shares a transform's blocks out over them (``share_out``),
which FFT library runs (``fft_backend``), how many float32 rows one ducc0 call takes
(``row_batch``), and the periodic convolution on a whole grid (``periodic_convolve``) that the
wave-number preconditioner and a periodic float32 product both run.  The operator's
convolution itself is problems/fft_transform.py.
"""

from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache, partial
from typing import Callable, TypeVar

import numpy as np
import scipy.fft as sfft

from .errors import ProblemInputError
from .units import plain_int

try:  # ducc0: the faster FFT (see KernelTransform); scipy.fft is the fallback
    from ducc0 import fft as _ducc_fft
    from ducc0.misc import transpose as _ducc_transpose
except ImportError:  # pragma: no cover - ducc0 is a declared dependency
    _ducc_fft = _ducc_transpose = None

T = TypeVar("T")


def _usable_cores() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one, else
    ``os.cpu_count``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


#: The CPUs this process may run on, read once at import (the call costs about 50 us,
#: and the products ask for it every time).
USABLE_CORES = _usable_cores()


#: The most threads one process's products, FFTs and BLAS may be given
#: (CONTACTBENCH_FFT_WORKERS, ``run --threads``): beyond any machine's cores, and far
#: below the C int the FFT libraries take a thread count as.
MAX_THREADS = 4096
#: What a thread count must be, as the refusals say it.
THREADS_RULE = f"a whole number of threads from 1 to {MAX_THREADS}"


def threads_problem(threads: object) -> str:
    """What is wrong with ``threads`` as a number of threads ("" when it is a whole
    number from 1 to ``MAX_THREADS``; a bool is none)."""
    if isinstance(threads, bool) or not isinstance(threads, int) or not 1 <= threads <= MAX_THREADS:
        return f"expected {THREADS_RULE}, got {threads!r}"
    return ""


def fft_workers() -> int:
    """Threads of the products, the FFTs and the preconditioners' pools: env
    CONTACTBENCH_FFT_WORKERS (a whole number from 1 to ``MAX_THREADS`` written plainly, as
    the command line's numbers are: ``units.plain_int``; anything else is a
    ``ProblemInputError`` naming it), default ``USABLE_CORES``."""
    env = os.environ.get("CONTACTBENCH_FFT_WORKERS", "").strip()
    if not env:
        return USABLE_CORES
    try:
        workers = plain_int(env)
    except ValueError:
        workers = 0
    if threads_problem(workers):
        raise ProblemInputError(f"CONTACTBENCH_FFT_WORKERS={env!r}: expected {THREADS_RULE}, written plainly")
    return workers


def fft_backend() -> str:
    """FFT library for the operator: "ducc" (ducc0, the default when it is importable)
    or "scipy" (scipy.fft/pocketfft); env CONTACTBENCH_FFT_BACKEND overrides."""
    env = os.environ.get("CONTACTBENCH_FFT_BACKEND", "").strip().lower()
    if env not in ("", "ducc", "scipy"):
        raise ProblemInputError(f"CONTACTBENCH_FFT_BACKEND={env!r}: expected 'ducc' or 'scipy'")
    if env == "scipy" or _ducc_fft is None:
        return "scipy"
    return "ducc"


#: Rows per ducc0 call in float32 for rows of at least ``FLOAT32_LONG_ROW`` points.  ducc0
#: 0.42 on AVX-512 transforms 16 float32 rows at a time in its vector lanes, and that path
#: is slow for long rows: the irFFT of the 2048 rows of a 2048^2 product takes 10.7 ms in
#: one call and 3.4 ms in calls of 8 rows (rFFT 3.8 -> 3.1 ms; 4096^2 irFFT 44 -> 13 ms;
#: 512^2 1.26 -> 0.38 ms; results/perf/matvec.md).  On shorter rows the calls'
#: own cost outweighs it.
FLOAT32_ROW_BATCH = 8
FLOAT32_LONG_ROW = 1024


def row_batch(p1: int, itemsize: int) -> int:
    """Rows per ducc0 row-transform call (0: no limit)."""
    return FLOAT32_ROW_BATCH if itemsize == 4 and p1 >= FLOAT32_LONG_ROW else 0


def rfft_rows(src: np.ndarray, dst: np.ndarray, batch: int) -> None:
    """dst <- the rFFTs of the rows of src, ``batch`` rows a ducc0 call (0: one call)."""
    step = batch or max(1, src.shape[0])
    for a in range(0, src.shape[0], step):
        _ducc_fft.r2c(src[a : a + step], axes=(1,), out=dst[a : a + step], nthreads=1)


def irfft_rows(src: np.ndarray, dst: np.ndarray, batch: int) -> None:
    """dst <- the normalised irFFTs (length dst.shape[1]) of the rows of src, ``batch`` rows a call."""
    step = batch or max(1, src.shape[0])
    for a in range(0, src.shape[0], step):
        _ducc_fft.c2r(src[a : a + step], axes=(1,), lastsize=dst.shape[1], forward=False, inorm=2, out=dst[a : a + step], nthreads=1)


class _BlockPool:
    """Threads that share the row and column blocks of one convolution (ducc0 and numpy's
    copies release the GIL), a large partial product's column groups and an island bucket's
    blocks (``share_out``).  Made on first use; a forked child forgets its parent's pool."""

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


_POOL = _BlockPool()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_POOL.forget)


@lru_cache(maxsize=64)
def block_chunks(stop: int, step: int, parts: int) -> tuple[np.ndarray, ...]:
    """The block starts range(0, stop, step) cut into at most ``parts`` non-empty runs, one
    per thread (cached: the same few shapes recur on every matvec; read-only)."""
    chunks = tuple(c for c in np.array_split(np.arange(0, stop, step), max(1, parts)) if c.size)
    for c in chunks:
        c.flags.writeable = False
    return chunks


def share_out(jobs: list[Callable[[], None]]) -> None:
    """Run ``jobs``, one thread of the pool each (in this thread when there is one): work
    that releases the GIL (ducc0's transforms, NumPy's copies, gathers and small products)."""
    if len(jobs) <= 1:
        for job in jobs:
            job()
        return
    pool = _POOL.get(len(jobs))
    for done in [pool.submit(job) for job in jobs]:
        done.result()


def each_on_pool(compute: Callable[[int], T], count: int, workers: int | None = None) -> list[T]:
    """[compute(k) for k in range(count)], the k shared out over ``workers`` threads of the
    pool (default ``fft_workers()``; in this thread when one) as each thread comes free, so
    items of unequal cost balance.  Each item is computed whole on one thread, so the
    answers do not depend on the threads; ``compute`` must release the GIL to gain (NumPy's
    gathers, products and LAPACK calls) and must not itself ``share_out``."""
    out: list[T] = [None] * count  # type: ignore[list-item]
    order = itertools.count()

    def work() -> None:
        while (k := next(order)) < count:
            out[k] = compute(k)

    w = max(1, min(fft_workers() if workers is None else workers, count))
    share_out([work] * w)
    return out


#: Elements in a band of the solvers' vector work (``each_band``): its temporaries (1 MiB of
#: float64 each) stay in a core's cache.  On a 2-core Xeon at n = 2.2M, p += a d, g += a Hd
#: took 13.1 ms whole and 8.1 ms in bands on one thread, 6.2 ms on two.
VECTOR_BAND = 1 << 17

#: NumPy vectors of at least this many elements are worked on in bands; shorter ones whole
#: (the pool's round trip would cost more than it saves).
BANDED_VECTOR_MIN = 1 << 19


def each_band(work: Callable[[slice], T], x: object) -> list[T]:
    """[work(s)] for the bands s of ``VECTOR_BAND`` elements of range(len(x)), shared out over
    the pool (``each_on_pool``), when x is a NumPy vector of at least ``BANDED_VECTOR_MIN``
    elements; otherwise [work(slice(None))] (a short vector, or another array module's).
    For elementwise work and exact reductions (min, max): its numbers are those of the whole
    on every thread count.  A band's writes must stay in the band."""
    n = int(x.size) if isinstance(x, np.ndarray) and x.ndim == 1 else 0
    if n < BANDED_VECTOR_MIN:
        return [work(slice(None))]
    return each_on_pool(lambda k: work(slice(k * VECTOR_BAND, (k + 1) * VECTOR_BAND)), -(-n // VECTOR_BAND))


def dots_in_bands(pairs: list[tuple[np.ndarray, np.ndarray]]) -> list[object]:
    """The inner products x @ y of ``pairs`` (vectors of one length): for NumPy vectors of at
    least ``BANDED_VECTOR_MIN`` elements, floats summed from the bands' products in band
    order (``each_band``: the same sums on every thread count, rounded otherwise than one
    whole product); otherwise the whole products as the array module gives them (for
    ``kkt.read_scalars``)."""
    parts = each_band(lambda s: [x[s] @ y[s] for x, y in pairs], pairs[0][0])
    if len(parts) == 1:
        return parts[0]
    return [sum(float(band[k]) for band in parts) for k in range(len(pairs))]


def flatnonzero_in_bands(mask_of: Callable[[slice], np.ndarray], x: object) -> np.ndarray:
    """np.flatnonzero of the mask over range(len(x)) whose band s is ``mask_of(s)``, the
    bands on the threads (``each_band``): the same positions, in order."""

    def positions(s: slice) -> np.ndarray:
        found = np.flatnonzero(mask_of(s))
        return found + s.start if s.start else found

    parts = each_band(positions, x)
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def periodic_convolve(f: np.ndarray, spec: np.ndarray, m: np.ndarray, workers: int) -> np.ndarray:
    """f <- F^-1[m F[f]] (normalised), in place, for a real N1 x N2 grid ``f`` and a multiplier
    ``m`` on its half spectrum, through ``spec`` (N1 x (N2/2+1) complex, overwritten), with
    ducc0 on ``workers`` threads: one 2-D call each way, or, where ``row_batch`` limits a
    call (long float32 rows), the row transforms in such calls shared out over the threads
    and the column transforms one call each way (a 2-D call takes all the rows in one: on an
    AVX-512 Xeon one 2-D float32 call each way took 1.14-1.43x this at 1024^2-4096^2,
    results/perf/periodic-pair)."""
    n1, n2 = f.shape
    batch = row_batch(n2, f.dtype.itemsize)
    if not batch:
        _ducc_fft.r2c(f, axes=(0, 1), out=spec, nthreads=workers)
        spec *= m
        return _ducc_fft.c2r(spec, axes=(0, 1), lastsize=n2, forward=False, inorm=2, out=f, nthreads=workers,
                             allow_overwriting_input=True)
    runs = [(int(c[0]), min(n1, int(c[-1]) + batch)) for c in block_chunks(n1, batch, workers)]
    share_out([partial(rfft_rows, f[a:b], spec[a:b], batch) for a, b in runs])
    _ducc_fft.c2c(spec, axes=(0,), forward=True, out=spec, nthreads=workers)
    spec *= m
    _ducc_fft.c2c(spec, axes=(0,), forward=False, inorm=2, out=spec, nthreads=workers)
    share_out([partial(irfft_rows, spec[a:b], f[a:b], batch) for a, b in runs])
    return f


def spectral_multiply(f: np.ndarray, m: np.ndarray) -> np.ndarray:
    """F^-1[m F[f]] for a real 2-D grid ``f`` (overwritten) and a multiplier ``m`` on its
    rfft2 half-spectrum (the last axis N2 // 2 + 1), in the operator's FFT library
    (``fft_backend``) on ``fft_workers()`` threads: the periodic convolution the
    wave-number preconditioner applies (solvers/_preconditioners.py)."""
    w = fft_workers()
    if fft_backend() == "scipy":
        F = sfft.rfft2(f, workers=w, overwrite_x=True)
        F *= m
        return sfft.irfft2(F, s=f.shape, workers=w, overwrite_x=True)
    spec = np.empty((f.shape[0], f.shape[1] // 2 + 1), dtype=np.result_type(f.dtype, np.complex64))
    return periodic_convolve(f, spec, m, w)
