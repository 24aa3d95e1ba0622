"""A warm start's first iterations in the Bugnicourt loop (solvers/_ccg.py, "A warm start's
first iterations"): the points at the bound are held there while the penetrating set sheds,
then the loop is Bugnicourt's own, to the same answer."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, load_ramp, paper_max_displacement
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _ccg
from contactbench.solvers._ccg import GapState, bugnicourt, holds
from contactbench.solvers._preconditioners import make_preconditioner
from contactbench.solvers.base import SolveContext, SolverSettings, WarmStart
from tests.helpers import loop_context
from contactbench.solvers.registry import get_solver

HIGH = SolverSettings(tol=1e-9)


@pytest.fixture(scope="module")
def sweep_pair():
    """The last two steps of a 4-step paper BCC ramp at 64^2 and the first one's answer on
    the second one's trial set (the harness's warm start)."""
    s = rmd_surface_n(64, 0.7, length=100e-6, seed=5)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    steps = load_ramp(paper_max_displacement(s), 4)
    i1, i2 = b.build(steps[-2]), b.build(steps[-1])
    r1 = get_solver("fast-dual-pccg").solve(i1.qp, SolverSettings(tol=1e-12))
    full = np.zeros(s.heights.size)
    full[i1.geometry.indices] = r1.p
    return i2, full[i2.geometry.indices]


def context(qp, p0: np.ndarray | None, max_iter: int = 500) -> SolveContext:
    return loop_context(qp, max_iter, p0=p0)


def first_steps(inst, p0: np.ndarray, iterations: int, kind: str = "islands") -> np.ndarray:
    """p after ``iterations`` Bugnicourt iterations from the warm start p0 (float64)."""
    qp = inst.qp
    state = GapState(qp.H, qp.ubar, p0.copy())
    bugnicourt(context(qp, p0), state, make_preconditioner(kind, qp), max_iter=iterations)
    return state.p


def penetrating(inst, p: np.ndarray) -> int:
    g = inst.qp.H.matvec(p) - inst.qp.ubar
    return int(np.count_nonzero((p <= 0.0) & (g < 0.0)))


@pytest.mark.parametrize("kind", ["islands", "none"])
def test_the_first_steps_of_a_warm_start_keep_its_contact_set(sweep_pair, kind):
    """Held: no point at the bound takes a force in the first step, and the step lifts most
    penetrating points out; Bugnicourt's own step (the hold off) gives a force to points off
    the warm start's contact set."""
    inst, p0 = sweep_pair
    start = penetrating(inst, p0)
    assert start > 2 * np.count_nonzero(p0)  # the band the deeper approach makes
    p = first_steps(inst, p0, 1, kind)
    assert not np.any(p[p0 == 0.0] > 0.0)
    assert penetrating(inst, p) < start / 2
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_ccg, "holds", lambda *args: False)
        free = first_steps(inst, p0, 1, kind)
    assert np.any(free[p0 == 0.0] > 0.0)


def test_the_hold_ends_after_hold_max_steps(sweep_pair, monkeypatch):
    """With every step counted as shedding, the hold still ends after HOLD_MAX steps and
    points off the warm start's contact set then take forces."""
    inst, p0 = sweep_pair
    counts = iter([10**12 // 4**k for k in range(20)])  # each below HOLD_SHEDDING times the last
    monkeypatch.setattr(_ccg, "penetrating_count", lambda state: next(counts))
    monkeypatch.setattr(_ccg, "HOLD_MAX", 2)
    assert not np.any(first_steps(inst, p0, 2)[p0 == 0.0] > 0.0)
    assert np.any(first_steps(inst, p0, 12)[p0 == 0.0] > 0.0)


def test_only_a_warm_first_round_without_upper_bounds_holds(sweep_pair):
    inst, p0 = sweep_pair
    ctx = context(inst.qp, p0)
    assert holds(ctx, 0, None)
    assert not holds(ctx, 3, None)  # a later round (iterative refinement, the float64 finish)
    assert not holds(ctx, 0, np.ones(inst.qp.n))  # a hardness
    assert not holds(context(inst.qp, None), 0, None)  # cold


@pytest.mark.parametrize("name", ["fast-dual-ccg", "fast-dual-pccg"])
def test_a_held_warm_start_reaches_the_cold_answer(sweep_pair, name):
    inst, p0 = sweep_pair
    cold = get_solver(name).solve(inst.qp, HIGH)
    warm = get_solver(name).solve(inst.qp, HIGH, WarmStart(p0))
    assert warm.converged and warm.warm_started
    assert kkt_check(inst, warm.p).kkt_error <= 1e-8
    assert relative_error(warm.p, cold.p) <= 1e-6


@pytest.mark.parametrize("name", ["fast-dual-ccg", "fast-dual-pccg"])
def test_a_warm_start_with_no_contact_releases_at_once(sweep_pair, name):
    """p0 = 0 given as a warm start: the held residual is zero, the held direction gives no
    step, and the loop goes on as Bugnicourt's from a cold start."""
    inst, _ = sweep_pair
    res = get_solver(name).solve(inst.qp, HIGH, WarmStart(np.zeros(inst.qp.n)))
    assert res.converged
    assert kkt_check(inst, res.p).kkt_error <= 1e-8


def test_a_warm_start_at_the_answer_stops_at_once(sweep_pair):
    inst, _ = sweep_pair
    answer = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-12)).p
    again = get_solver("fast-dual-pccg").solve(inst.qp, HIGH, WarmStart(answer))
    assert again.iterations <= 1
    assert relative_error(again.p, answer) <= 1e-9
