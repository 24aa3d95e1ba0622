"""The FFT floor of a matvec (problems/fft_transform.py): the bare transform pair one ducc0
matvec needs, in each of its layouts, the floor its cost is compared with
(benchmarks/bench_matvec.py, results/perf/matvec.md)."""

from __future__ import annotations

from functools import partial
from typing import Callable

import numpy as np

from .errors import ProblemInputError
from .fft_threads import _ducc_fft, block_chunks, fft_workers, irfft_rows, rfft_rows, row_batch, share_out
from .fft_transform import KernelTransform, operator_dtype, row_block, row_threads

FLOOR_LAYOUTS: tuple[str, ...] = ("strided", "transposed", "strided-row-blocks", "transposed-row-blocks")


def fft_floor_pair(transform: KernelTransform, dtype: object = np.float64, layout: str = "strided") -> Callable[[], None]:
    """The FFT floor of a matvec: a function that runs only the transform pair a ducc0
    matvec needs, on arrays of its own -- row rFFTs on the N1 rows, column FFTs and
    iFFTs over the whole spectrum, row irFFTs back on the N1 rows, in ``layout`` (one of
    ``FLOOR_LAYOUTS``) -- with ``fft_workers()`` threads, no scatter, gather, clearing or
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
    if layout.startswith("strided"):
        spec = np.empty((p0, m), dtype=cdt)
        rows, axis = spec[:n1], 0
    else:
        spec = np.empty((m, p0), dtype=cdt)
        rows, axis = spec[:, :n1].T, 1
    blocks = layout.endswith("-row-blocks")
    rb, batch = row_block(p1), row_batch(p1, dt.itemsize)

    def forward(starts: np.ndarray) -> None:
        for a in starts.tolist():
            rfft_rows(field_[a : a + rb], rows[a : a + rb], batch)

    def back(starts: np.ndarray) -> None:
        for a in starts.tolist():
            irfft_rows(rows[a : a + rb], out[a : a + rb], batch)

    def pair() -> None:
        w = row_threads(n1, p1, fft_workers(), dt.itemsize)
        chunks = block_chunks(n1, rb, w)
        if blocks:
            share_out([partial(forward, c) for c in chunks])
        else:
            _ducc_fft.r2c(field_, axes=(1,), out=rows, nthreads=w)
        _ducc_fft.c2c(spec, axes=(axis,), forward=True, out=spec, nthreads=w)
        _ducc_fft.c2c(spec, axes=(axis,), forward=False, inorm=2, out=spec, nthreads=w)
        if blocks:
            share_out([partial(back, c) for c in chunks])
        else:
            _ducc_fft.c2r(rows, axes=(1,), lastsize=p1, forward=False, inorm=2, out=out, nthreads=w)

    return pair
