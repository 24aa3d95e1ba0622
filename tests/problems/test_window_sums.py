"""Unit-force sums by small FFT windows (problems/window_sums.py, ``FFTOperator.unit_sums``):
the gathered sums to round-off on every kernel and boundary, whatever goes through a
window, on any thread count; the cost the far field's budget reads."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems import window_sums
from contactbench.problems.kernels import kernel_table
from contactbench.problems.operators import ContactOperator, FFTOperator, KernelTransform

N, DELTA, E = 48, 1.5e-6, 2.0e9
CASES = [("bcc", False), ("love", False), ("bcc", True), ("love", True), ("spectral", True)]


def operator(kernel: str, periodic: bool, idx: np.ndarray) -> FFTOperator:
    return FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)


def tile_items(idx: np.ndarray, rng: np.random.Generator, count: int, side: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Items as the far field makes them: the set's points on a side x side tile (cols) and
    on the tiles around it (rows), positions in the set."""
    gi, gj = np.divmod(idx, N)
    items = []
    for _ in range(count):
        i0, j0 = rng.integers(0, N - side, 2)
        cols = np.flatnonzero((gi >= i0) & (gi < i0 + side) & (gj >= j0) & (gj < j0 + side))
        rows = np.flatnonzero((gi >= i0 - side) & (gi < i0 + 2 * side) & (gj >= j0 - side) & (gj < j0 + 2 * side))
        items.append((rows, cols))
    return items


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_windows_give_the_gathered_sums(kernel: str, periodic: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Dense tiles go through windows (checked), a sparse item, empty ones and a far-apart
    pair are gathered; every sum equals the gathered one to 1e-13 of its largest, on 1 and
    3 threads alike."""
    rng = np.random.default_rng(4)
    idx = np.sort(rng.choice(N * N, int(0.9 * N * N), replace=False))
    op = operator(kernel, periodic, idx)
    items = tile_items(idx, rng, 5, 12)
    far = (np.flatnonzero(idx < 40), np.flatnonzero(idx >= N * N - 40))  # rows and cols at opposite corners
    items += [(items[0][0], items[0][1][:3]), (np.arange(0), items[1][1]), (items[1][0], np.arange(0)), far]
    pos = op._positions(items)
    planned = window_sums.plan(pos)
    chosen, shape = planned.chosen, planned.shape
    assert set(range(5)) <= set(chosen) and len(items) - 1 not in chosen
    assert all(np.all(np.array(window_sums.window_shape(*pos[k])) <= shape) for k in chosen)
    answers = []
    for workers in ("1", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        answers.append(op.unit_sums(items))
    for got, (rows, cols) in zip(answers[0], items):
        want = op.partial_product(rows, cols, np.ones(cols.size))
        assert got.shape == (rows.size,)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * max(np.abs(want).max(initial=0.0), 1e-300))
    assert all(np.array_equal(a, b) for a, b in zip(answers[0], answers[1]))


def test_a_window_too_small_for_its_offsets_would_alias(monkeypatch: pytest.MonkeyPatch) -> None:
    """The window holds every offset once (F >= 2h + 1): half of it, a periodic
    sum folds far offsets onto near ones and the sums no longer agree."""
    rng = np.random.default_rng(5)
    idx = np.arange(N * N)
    op = operator("bcc", True, idx)
    items = tile_items(idx, rng, 3, 12)
    pos = op._positions(items)
    planned = window_sums.plan(pos)
    chosen, shape = planned.chosen, planned.shape
    assert chosen == [0, 1, 2]
    want = [op.partial_product(r, c, np.ones(c.size)) for r, c in items]
    small = (shape[0] // 2, shape[1] // 2)
    got = window_sums.window_sums(op.transform.table, pos, small, window_sums.kernel_window_spectrum(op.transform.table, small))
    assert max(np.abs(g - w).max() / np.abs(w).max() for g, w in zip(got, want)) > 1e-6


def test_the_cost_is_the_gather_less_what_the_windows_save() -> None:
    """Gathered items cost |rows| |cols|, windowed ones WINDOW_ENTRY_FACTOR x F0 F1; never
    more than the gather.  A generic operator, which has no windows, costs the gather.  A
    budget one short of the cost refuses the sums (None)."""
    rng = np.random.default_rng(6)
    idx = np.arange(N * N)
    op = operator("love", False, idx)
    items = tile_items(idx, rng, 4, 12) + [(np.arange(5), np.arange(3))]
    gather = float(sum(r.size * c.size for r, c in items))
    planned = window_sums.plan(op._positions(items))
    chosen, (f0, f1) = planned.chosen, planned.shape
    assert chosen and 4 not in chosen
    cost = op.unit_sums_cost(items)
    assert cost == pytest.approx(gather - sum(items[k][0].size * items[k][1].size for k in chosen)
                                 + len(chosen) * window_sums.WINDOW_ENTRY_FACTOR * f0 * f1)
    assert cost < gather and cost == planned.cost
    assert ContactOperator.unit_sums_cost(op, items) == gather
    assert op.unit_sums(items, cost - 1) is None and op.unit_sums(items, cost) is not None
    assert ContactOperator.unit_sums(op, items, gather - 1) is None
    for got, want in zip(op.unit_sums(items), ContactOperator.unit_sums(op, items)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(want).max())


def test_window_shapes_are_each_items_own_window() -> None:
    """``window_shapes`` (all items' extents in a few reductions) gives each item's
    ``window_shape``, and (0, 0) where it has no rows or no cols, on items of any extent."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        items = []
        for _ in range(int(rng.integers(1, 25))):
            nr, nc = rng.integers(0, 15, 2)
            spread = int(rng.integers(1, 400))
            items.append(((rng.integers(0, spread, nr), rng.integers(0, spread, nr)),
                          (rng.integers(0, spread, nc), rng.integers(0, spread, nc))))
        want = [window_sums.window_shape(r, c) if r[0].size and c[0].size else (0, 0) for r, c in items]
        assert window_sums.window_shapes(items) == want
    assert window_sums.window_shapes([]) == []
