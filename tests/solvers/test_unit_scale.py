"""The fast CCGs and P&K solve at unit scale (``solvers._unit_scale``): the QP is homogeneous
in (ubar, bounds, load), and past a relief of about 1e154 (below 1e-154) their inner products
overflowed (underflowed) and they stalled on answers float64 holds.  Within
``UNIT_SCALE_RANGE`` a problem is solved as it is."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import Surface
from contactbench.solvers._unit_scale import UNIT_SCALE_RANGE, unit_scale_factor
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

SOLVERS = ["fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "fast-pdas", "pk"]
HEIGHTS = np.random.default_rng(3).standard_normal((6, 6))


def builder(scale: float, operator: str = "dense") -> InstanceBuilder:
    return InstanceBuilder(Surface(HEIGHTS * scale, 1.0), 1.0, "bcc", False, operator=operator)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("scale", [1e-200, 1e-160, 1e160, 1e300])
@pytest.mark.parametrize("name", SOLVERS)
def test_a_problem_far_from_unit_scale_is_solved(name: str, scale: float) -> None:
    b = builder(scale)
    inst = b.build(0.5 * float(np.ptp(b.surface.heights)))
    res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10, check_tol=1e-8))
    verdict = judge(inst, res.p, bool(res.converged), 1e-8)
    assert res.converged and verdict.status == "solved", (res.status, verdict.kkt_error)
    ref = get_solver(name).solve(builder(1.0).build(0.5 * float(np.ptp(HEIGHTS))).qp, SolverSettings(tol=1e-10))
    np.testing.assert_allclose(res.p / scale, ref.p, rtol=1e-6, atol=1e-8 * float(np.max(ref.p)))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("name", ["fast-dual-pccg", "pk"])
def test_a_load_controlled_problem_far_from_unit_scale_is_solved(name: str) -> None:
    b = builder(1e170, "fft")
    inst = b.build_load(b.load_force(1e-2))
    res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10, check_tol=1e-8))
    verdict = judge(inst, res.p, bool(res.converged), 1e-8, multiplier=res.multiplier)
    assert res.converged and verdict.status == "solved", (res.status, verdict.kkt_error)
    magnitude = max(float(np.max(np.abs(inst.qp.ubar))), float(inst.qp.constraints.load))
    assert 0.5 <= res.info["unit_scale_factor"] * magnitude < 1.0


def test_within_the_range_a_problem_is_solved_as_it_is() -> None:
    b = builder(1e-6)
    inst = b.build(0.5 * float(np.ptp(b.surface.heights)))
    assert unit_scale_factor(inst.qp) == 1.0
    res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-10))
    assert "unit_scale_factor" not in res.info
    far = builder(UNIT_SCALE_RANGE * 10)
    assert unit_scale_factor(far.build(0.5 * float(np.ptp(far.surface.heights))).qp) < 1.0
