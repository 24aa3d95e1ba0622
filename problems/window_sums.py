"""Displacements of unit forces on compact groups of grid points, by small FFTs.

For a translation-invariant kernel K on a grid (``FFTOperator``: H_kl = K(x_k - x_l), read
from the kernel table at offsets modulo the padded grid), the item (rows, cols) asks for

    u_r = sum_{c in cols} K(x_r - x_c)    for r in rows,

the displacement at ``rows`` of unit forces on ``cols``.  Gathered entry by entry this
costs |rows| |cols| table reads: for the far field's neighbouring tiles of a large contact
patch (solvers/_farfield.py), thousands of points a tile, that is hundreds of millions.

A *window* does it in two FFTs of a small F0 x F1 grid instead: the indicator of ``cols``,
placed relative to the smallest (row, column) of ``cols``, circularly convolved with the
kernel on the offsets -h..h of each axis (F >= 2h + 1, h the largest offset between a row
and a col), read at the rows' places.  Every offset the sum needs falls in exactly one
residue class of the window, so the convolution is the sum itself up to the FFT's
round-off (a few ulps of the largest u).  The kernel's window spectrum is one per
(F0, F1); items share it.

``WINDOW_ENTRY_FACTOR``: an item goes through a window when it would gather more than this
many times F0 x F1 entries (on a 2-core AVX-512 Xeon, a table read took 3-5 ns and a
window 6-9 ns per point of F0 x F1, both transforms and the product included).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

from .fft_threads import _ducc_fft, each_on_pool

#: An item is summed through a window when |rows| |cols| > this x F0 F1 (module doc).
WINDOW_ENTRY_FACTOR = 2.0

#: Windows transformed together, at most this many bytes of spectrum a batch.
WINDOW_BATCH_BYTES = 1 << 23

#: (row, column) grid positions of a set of points.
Positions = tuple[np.ndarray, np.ndarray]


def window_side(rows: np.ndarray, cols: np.ndarray) -> int:
    """The FFT length along one axis for rows' and cols' coordinates on it: the next fast
    length of 2h + 1, h the largest |row - col|."""
    h = max(int(rows.max()) - int(cols.min()), int(cols.max()) - int(rows.min()), 0)
    return fast_side(h)


def fast_side(h: int) -> int:
    """The window length for a largest offset h: the next fast length of 2h + 1."""
    return int(sfft.next_fast_len(2 * h + 1, real=True))


def window_shape(rows: Positions, cols: Positions) -> tuple[int, int]:
    """(F0, F1): the window of one item (``window_side`` on each axis)."""
    return window_side(rows[0], cols[0]), window_side(rows[1], cols[1])


def stacked(positions: Sequence[Positions]) -> tuple[Positions, np.ndarray, np.ndarray]:
    """Several position sets end to end: their rows and columns, the set each entry came
    from, and where each set starts."""
    sizes = [p[0].size for p in positions]
    slot = np.repeat(np.arange(len(positions)), sizes)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    return (np.concatenate([p[0] for p in positions]), np.concatenate([p[1] for p in positions])), slot, starts


def window_shapes(items: Sequence[tuple[Positions, Positions]]) -> list[tuple[int, int]]:
    """``window_shape`` of every item, (0, 0) for an item with no rows or no cols: the
    extents of all items in a few array reductions, not eight per item."""
    full = [k for k, (r, c) in enumerate(items) if r[0].size and c[0].size]
    shapes = [(0, 0)] * len(items)
    if not full:
        return shapes
    rows, _, rs = stacked([items[k][0] for k in full])
    cols, _, cs = stacked([items[k][1] for k in full])
    sides = []
    for r, c in zip(rows, cols):
        rmin, rmax = np.minimum.reduceat(r, rs), np.maximum.reduceat(r, rs)
        cmin, cmax = np.minimum.reduceat(c, cs), np.maximum.reduceat(c, cs)
        h = np.maximum(np.maximum(rmax.astype(np.int64) - cmin, cmax.astype(np.int64) - rmin), 0)
        values, where = np.unique(h, return_inverse=True)
        sides.append(np.array([fast_side(int(v)) for v in values], dtype=np.int64)[where])
    for slot, k in enumerate(full):
        shapes[k] = (int(sides[0][slot]), int(sides[1][slot]))
    return shapes


@dataclass(frozen=True)
class WindowPlan:
    """Which items go through windows, the one window shape they share, and the work of all
    the items' sums in table reads (``WINDOW_ENTRY_FACTOR`` x F0 F1 for a windowed item,
    |rows| |cols| for a gathered one)."""

    chosen: list[int]
    shape: tuple[int, int]
    cost: float


def plan(items: Sequence[tuple[Positions, Positions]]) -> WindowPlan:
    """The items worth a window: an item joins when its gather exceeds
    ``WINDOW_ENTRY_FACTOR`` x the points of the shared window (the largest of the joining
    items' own, decided again with it)."""
    gathers = [r[0].size * c[0].size for r, c in items]
    shapes = window_shapes(items)
    own = [k for k, (f0, f1) in enumerate(shapes) if gathers[k] > WINDOW_ENTRY_FACTOR * f0 * f1]
    shape = (max((shapes[k][0] for k in own), default=0), max((shapes[k][1] for k in own), default=0))
    window = WINDOW_ENTRY_FACTOR * shape[0] * shape[1]
    chosen = [k for k in own if gathers[k] > window]
    return WindowPlan(chosen, shape, float(sum(gathers)) - sum(gathers[k] - window for k in chosen))


def kernel_window_spectrum(table: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The rfft2 of the kernel on a window: entry (a, b) holds K at the offsets
    (a, b) taken into -F/2 .. F/2 - 1, read from ``table`` (the padded grid's circulant
    table) modulo its shape."""
    (f0, f1), (p0, p1) = shape, table.shape
    o0 = (np.arange(f0) + f0 // 2) % f0 - f0 // 2
    o1 = (np.arange(f1) + f1 // 2) % f1 - f1 // 2
    return sfft.rfft2(table[(o0 % p0)[:, None], (o1 % p1)[None, :]])


def window_sums(table: np.ndarray, items: Sequence[tuple[Positions, Positions]], shape: tuple[int, int],
                spectrum: np.ndarray) -> list[np.ndarray]:
    """The item sums (module doc) through windows of ``shape`` whose kernel spectrum is
    ``spectrum`` (``kernel_window_spectrum``); each item's window must hold its offsets
    (``window_shape`` <= shape).  Batches of windows run on the FFT pool's threads, one
    thread a batch, so the numbers do not depend on the thread count."""
    f0, f1 = shape
    per = max(1, WINDOW_BATCH_BYTES // (16 * f0 * (f1 // 2 + 1)))
    batches = [list(range(b, min(len(items), b + per))) for b in range(0, len(items), per)]

    def batch(k: int) -> list[np.ndarray]:
        which = batches[k]
        field = np.zeros((len(which), f0, f1))
        (ci, cj), col_slot, starts = stacked([items[item][1] for item in which])
        i0, j0 = np.minimum.reduceat(ci, starts), np.minimum.reduceat(cj, starts)  # each window's origin
        field[col_slot, ci - i0[col_slot], cj - j0[col_slot]] = 1.0
        spec = _ducc_fft.r2c(field, axes=(1, 2), nthreads=1)
        spec *= spectrum
        _ducc_fft.c2r(spec, axes=(1, 2), lastsize=f1, forward=False, inorm=2, out=field, nthreads=1,
                      allow_overwriting_input=True)
        (ri, rj), row_slot, row_starts = stacked([items[item][0] for item in which])
        return np.split(field[row_slot, (ri - i0[row_slot]) % f0, (rj - j0[row_slot]) % f1], row_starts[1:])

    return [u for part in each_on_pool(batch, len(batches)) for u in part]


def unit_sums(table: np.ndarray, items: Sequence[tuple[Positions, Positions]], planned: WindowPlan,
              gather: Callable[[list[int]], list[np.ndarray]],
              spectrum_of: Callable[[tuple[int, int]], np.ndarray]) -> list[np.ndarray]:
    """The sums of every item (module doc): the items ``planned.chosen`` (``plan``) through
    ``window_sums``, the others by ``gather`` (given their indices, their sums in order).
    ``spectrum_of(shape)``: the kernel's window spectrum (a caller's cache of
    ``kernel_window_spectrum``)."""
    out: list[np.ndarray | None] = [None] * len(items)
    if planned.chosen:
        windows = window_sums(table, [items[k] for k in planned.chosen], planned.shape, spectrum_of(planned.shape))
        for k, u in zip(planned.chosen, windows):
            out[k] = u
    rest = [k for k in range(len(items)) if out[k] is None]
    for k, u in zip(rest, gather(rest) if rest else []):
        out[k] = u
    return out  # type: ignore[return-value]
