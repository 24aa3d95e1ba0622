"""``GapState.raise_forces`` (solvers/_ccg.py, "Raised forces"): after a projection the
gap is exact on the contact set and at the penetrating points, and a lower bound
elsewhere, without a matvec while the partial products pay -- checked against the gap
recomputed from scratch after every step, on aperiodic (entries >= 0) and periodic
(entries of both signs) kernels, plain and anchored float32 states."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems import operators
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers._ccg import GapState, converged_now
from contactbench.solvers.base import SolverSettings
from tests.helpers import loop_context
from contactbench.solvers.registry import get_solver


def qp_of(N: int, periodic: bool, kernel: str = "bcc"):
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=4)
    return InstanceBuilder(s, 1e9, kernel, periodic=periodic).build(paper_max_displacement(s)).qp


def true_gap(state: GapState) -> np.ndarray:
    H = state.H
    count = H.matvec_count
    if state.anchor is None:
        g = H.matvec(state.p) - state.ubar
    else:
        g = state.anchor.g0 + H.matvec(state.p - state.anchor.p0)
    H.matvec_count = count
    return g


def projected_steps(state: GapState, rng: np.random.Generator, steps: int) -> int:
    """Random projected steps on the running free set; returns how many clipped."""
    clips = 0
    for _ in range(steps):
        free = (state.p > 0) | (state.g < 0)
        d = np.where(free, rng.normal(size=state.p.size), 0.0) * np.max(np.abs(state.ubar)) / state.H.diagonal()[0]
        clips += state.step(0.05, d, state.H.matvec(d))
        g = true_gap(state)
        need = (state.p > 0) | (state.g < 0)
        tol = np.max(np.abs(g)) * (1e-9 if state.H.dtype == np.float64 else 1e-5)  # float32: its round-off
        assert np.max(np.abs(state.g - g)[need], initial=0.0) <= tol
        assert np.all(state.g[~need] <= g[~need] + tol)  # a lower bound ...
        assert np.all(g[~need] >= -tol)  # ... of a gap that is >= 0
        assert np.all(state.p >= 0)
    return clips


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("anchored", [False, True])
def test_raised_forces_keep_the_gap_exact_where_it_is_read(periodic: bool, anchored: bool, monkeypatch) -> None:
    monkeypatch.setattr(operators, "PARTIAL_PRODUCT_FACTOR", 1e9)  # the partial product always pays
    qp = qp_of(32, periodic)
    base = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    state = GapState.anchored(qp.H.with_precision(np.float32), base) if anchored else base
    state.refresh_every = 10**6
    H = state.H
    before = H.matvec_count
    rng = np.random.default_rng(1)
    clips = projected_steps(state, rng, 40)
    assert clips >= 10 and not state.exact
    assert H.matvec_count - before == 40  # one matvec a step (the direction's), none for the projections
    assert (H.entry_floor() < 0) is periodic


def test_raised_forces_refresh_when_the_partial_product_does_not_pay(monkeypatch) -> None:
    monkeypatch.setattr(operators, "PARTIAL_PRODUCT_FACTOR", 0.0)
    qp = qp_of(32, False)
    state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    before = qp.H.matvec_count
    clips = projected_steps(state, np.random.default_rng(2), 20)
    assert clips >= 5 and state.exact
    assert qp.H.matvec_count - before == 20 + clips


def test_an_operator_without_an_entry_floor_recomputes_the_gap() -> None:
    qp = qp_of(16, False)
    H = DenseOperator(qp.H.to_dense())
    H.entry_floor = lambda: None  # type: ignore[method-assign]
    state = GapState(H, qp.ubar, np.zeros(qp.n))
    before = H.matvec_count
    state.raise_forces(np.array([0, 3]), np.array([1e-3, 2e-3]))
    assert H.matvec_count == before + 1 and state.exact
    np.testing.assert_allclose(state.g, true_gap(state), rtol=0, atol=1e-12 * np.max(np.abs(state.g)))


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-pccg", "fast-dual-ccg", "fast-ccg"])
@pytest.mark.parametrize("periodic", [False, True])
def test_fast_solvers_give_the_same_answer_with_fewer_matvecs(name: str, periodic: bool, monkeypatch) -> None:
    """The same solve with partial products never paying (a matvec after every projection)
    and always paying: the same p to the tolerance, fewer matvecs with them."""
    qp = qp_of(64, periodic)
    runs = {}
    for factor in (0.0, 1e9):
        monkeypatch.setattr(operators, "PARTIAL_PRODUCT_FACTOR", factor)
        qp.H.matvec_count = 0
        runs[factor] = get_solver(name).solve(qp, SolverSettings(tol=1e-10, params={"precision": "double"}))
    off, on = runs[0.0], runs[1e9]
    assert off.converged and on.converged
    assert np.max(np.abs(on.p - off.p)) <= 1e-7 * np.max(off.p)
    assert on.matvecs < off.matvecs


def test_a_cold_state_costs_no_matvec() -> None:
    """At p = 0 the gap is -ubar: refresh spends no product (a warm one does)."""
    qp = qp_of(17, False)
    count = qp.H.matvec_count
    state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    assert qp.H.matvec_count == count and np.array_equal(state.g, -qp.ubar)
    state.p[0] = 1.0
    state.refresh()
    assert qp.H.matvec_count == count + 1
    assert np.allclose(state.g, true_gap(state))


def test_an_anchored_round_leaves_the_confirmation_to_its_refinement() -> None:
    """A converged running gap is confirmed on a recomputed one (one matvec), except in an
    anchored float32 round, whose float64 refresh judges it."""
    qp = qp_of(17, False)
    exact = get_solver("fast-dual-ccg").solve(qp, SolverSettings(tol=1e-12)).p
    ctx = loop_context(qp, 10)
    plain = GapState(qp.H, qp.ubar, exact.copy())
    count = qp.H.matvec_count
    assert converged_now(ctx, plain)[0] and qp.H.matvec_count == count + 1
    H32 = qp.H.with_precision(np.float32)
    inner = GapState.anchored(H32, plain)
    count32 = H32.matvec_count
    assert converged_now(ctx, inner)[0] and H32.matvec_count == count32


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("anchored", [False, True])
def test_a_scaled_state_keeps_its_gap_without_a_matvec(periodic: bool, anchored: bool, monkeypatch) -> None:
    """``GapState.scale`` after raises still pending: the gap is H (s p) - ubar on the rows
    read and a lower bound elsewhere, the pending raises scale with p, and a raised
    ``level`` makes the rows below it exact -- all without a product."""
    monkeypatch.setattr(operators, "PARTIAL_PRODUCT_FACTOR", 1e9)
    qp = qp_of(32, periodic)
    base = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    state = GapState.anchored(qp.H.with_precision(np.float32), base) if anchored else base
    state.refresh_every = 10**6
    projected_steps(state, np.random.default_rng(3), 12)
    assert not state.exact
    H, rel = state.H, (1e-9 if state.H.dtype == np.float64 else 1e-5)
    before = H.matvec_count
    for factor in (0.8, 1.15):
        state.scale(factor)
        state.settle()
        g = true_gap(state)
        tol = rel * np.max(np.abs(g))
        need = (state.p > 0) | (state.g < state.level)
        assert np.max(np.abs(state.g - g)[need]) <= tol
        assert np.all(state.g[~need] <= g[~need] + tol)
    state.level = float(np.quantile(state.g[state.p == 0], 0.5))
    state.settle()
    g = true_gap(state)
    below = (state.p == 0) & (g < state.level - rel * np.max(np.abs(g)))
    assert below.any() and np.max(np.abs(state.g - g)[below]) <= rel * np.max(np.abs(g))
    assert H.matvec_count == before
