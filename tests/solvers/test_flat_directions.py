"""A direction the operator is flat along ends no loop (``solvers/_steps.py``, "Flat
directions"): a periodic grid's H removes the mean, so on a free set that is the whole grid
the constant vector is a null direction.  Warm-started near full contact, the fast solvers
met directions whose curvature was round-off, took steps 1e14 times too long, clipped every
force to 0 and cycled to ``max_iter``; the step along a flat direction now goes to the first
force it takes to 0.  A loop stopped at its limit quotes the error of the iterate it
returns."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from contactbench.harness import solve_sequence
from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.surfaces import Surface
from contactbench.solvers._steps import curved_step, exact_step, flat_curvature, flat_step
from contactbench.solvers.base import SolverSettings

E = 1e9
DX = 1e-6
SETTINGS = SolverSettings(tol=1e-8, time_limit=20)


def periodic_steps(h: np.ndarray, shares: tuple[float, ...]) -> list[ContactInstance]:
    """Steps of a periodic BCC problem at ``shares`` of the top displacement (max h - mean h,
    full contact)."""
    b = InstanceBuilder(Surface(h, DX, periodic=True), E, kernel="bcc", periodic=True)
    top = float(h.max() - h.mean())
    return [b.build(s * top) for s in shares]


def checkerboard() -> np.ndarray:
    return (np.indices((8, 8)).sum(0) % 2) * 1e-7


def random_4x4(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal((4, 4)) * 1e-7


def test_a_flat_direction_steps_to_the_first_force_at_zero() -> None:
    """Along the constant vector of a periodic H the curvature is round-off: the step is
    the one that takes the least force to 0 (the objective's minimum along it on p >= 0),
    not the 'exact' -res'd / d'Hd; a flat direction that ascends gives no step."""
    inst = periodic_steps(checkerboard(), (0.9999,))[0]
    H = inst.qp.H.to_dense()
    floor = flat_curvature(float(np.max(np.diag(H))), np.float64)
    p = np.linspace(1.0, 2.0, inst.n)
    d = -np.ones(inst.n)
    Hd = H @ d
    res = np.full(inst.n, 1e-3)  # res'd < 0: the objective falls along d
    alpha, _ = exact_step(res, d, Hd, floor, p)
    assert alpha == pytest.approx(1.0)  # the least force, 1.0, reaches 0 first
    assert math.isnan(exact_step(-res, d, Hd, floor, p)[0])  # ascending: no step
    # Polonsky-Keer's form, p - tau t with t = -d
    tau = curved_step(float(res @ -d), float(-d @ (H @ -d)), -d, floor, p)
    assert tau == pytest.approx(1.0)
    # no longer than the exact step of the least curvature round-off hides
    assert flat_step(p, d, -1e-30, 1.0) == pytest.approx(1e-30)
    # a curved direction keeps its exact step
    e = np.zeros(inst.n)
    e[0] = -1.0
    alpha, curvature = exact_step(res, e, H @ e, floor, p)
    assert alpha == pytest.approx(1e-3 / curvature)


@pytest.mark.parametrize("solver,h,shares", [
    ("fast-dual-pccg", checkerboard(), (0.5, 0.9999)),
    ("fast-ccg", random_4x4(1), (0.5, 0.99999)),
    ("fast-pccg", random_4x4(4), (0.5, 0.99999)),
    ("fast-pccg", random_4x4(2), (0.9, 0.99999)),
    ("fast-pccg", random_4x4(2), (0.99999,)),
], ids=["checkerboard-dual", "4x4-s1-ccg", "4x4-s4-pccg", "4x4-s2-pccg", "4x4-s2-pccg-cold"])
def test_the_fast_solvers_solve_periodic_steps_near_full_contact(solver: str, h: np.ndarray,
                                                                  shares: tuple[float, ...]) -> None:
    """Each step solved (by the judge), warm from the one before where there is one."""
    steps = solve_sequence(solver, periodic_steps(h, shares), SETTINGS, check_tol=1e-6)
    for s in steps:
        assert s.verdict.status == "solved", (s.step, s.verdict.kkt_error, s.result.iterations, s.result.message)


@pytest.mark.parametrize("solver", ["fast-ccg", "fast-dual-ccg"])
def test_a_loop_stopped_at_its_limit_quotes_the_error_of_its_answer(solver: str) -> None:
    """The message's scaled KKT error is that of the returned iterate (the judge's figure
    to round-off), not that of the iterate before the last step."""
    h = np.random.default_rng(3).standard_normal((16, 16)) * 1e-7
    inst = periodic_steps(h, (0.4,))[0]
    for limit in (2, 3, 5):
        settings = SolverSettings(tol=1e-12, max_iter=limit, params={"screening": "none", "precision": "double"})
        (s,) = solve_sequence(solver, [inst], settings, check_tol=1e-12)
        quoted = float(re.search(r"scaled KKT error ([-+.0-9e]+)", s.result.message).group(1))
        assert s.result.iterations == limit and not s.result.converged
        assert quoted == pytest.approx(s.verdict.kkt_error, rel=1e-3), (limit, s.result.message)


def test_the_flat_step_keeps_its_vectors_on_the_device() -> None:
    """On a device's arrays (``tests.fake_device``: any implicit trip to the host raises) the
    flat step reads one scalar: the first force at 0 along d."""
    from tests.fake_device import SPACE

    p, d = SPACE.put(np.array([1.0, 2.0, 0.5])), SPACE.put(np.array([-1.0, 1.0, -2.0]))
    assert flat_step(p, d, -1.0, 1e-3) == pytest.approx(0.25)
    alpha, curvature = exact_step(SPACE.put(np.ones(3)), d, SPACE.put(np.zeros(3)), 1e-3, p)
    assert alpha == pytest.approx(0.25) and curvature == 0.0
