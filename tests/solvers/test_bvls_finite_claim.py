"""bvls claims convergence only with a finite answer: where the exact solution lies beyond
float64's range (ubar / H of 1e310), its own solve returns p = inf with a passing check, and the
outcome says FAILED, not converged, instead; and a certified answer is claimed only within the
check it is handed."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import QP, InstanceBuilder
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import Surface
from contactbench.solvers.base import Outcome, SolverSettings, Status
from contactbench.solvers._scaling import finite_claim
from contactbench.solvers.registry import get_solver


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the exact solve overflows, as it must here
@pytest.mark.parametrize("n", [1, 2, 3])
@pytest.mark.parametrize(("scale", "u"), [(1e-300, 1e10), (1e-10, 1e300)])
def test_an_answer_beyond_float64_is_not_claimed(n: int, scale: float, u: float) -> None:
    H = scale * (np.eye(n) + 0.3 * (np.ones((n, n)) - np.eye(n)))
    res = get_solver("bvls").solve(QP(DenseOperator(H), np.full(n, u)))
    assert not np.all(np.isfinite(res.p))
    assert not res.converged and res.status == "failed"
    assert "non-finite" in res.message


def test_a_finite_answer_keeps_its_claim() -> None:
    res = get_solver("bvls").solve(QP(DenseOperator(np.array([[2.0]])), np.array([1.0])))
    assert res.converged and res.status == "converged" and res.p == pytest.approx([0.5], rel=1e-12)


def test_an_unclaimed_failure_keeps_its_own_message() -> None:
    out = Outcome(np.full(2, np.nan), 0, False, "bvls: no approach carries the load 1", status=Status.FAILED)
    assert finite_claim(out) is out


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the answer overflows on its way back, as it must here
@pytest.mark.parametrize("name", ["qp-clarabel", "qp-osqp", "qp-highs", "qp-piqp", "qp-clarabel+polish", "cvxpy"])
def test_a_qp_adapter_s_answer_that_overflows_back_to_the_problem_s_units_is_not_claimed(name: str) -> None:
    solver = get_solver(name)
    ok, why = solver.availability()
    if not ok:
        pytest.skip(f"{name}: {why}")
    res = solver.solve(QP(DenseOperator(np.array([[1e-300]])), np.array([1e10])))
    assert not (res.converged and not np.all(np.isfinite(res.p))), (res.status, res.p, res.message)


def test_a_certified_answer_is_claimed_only_within_the_check_it_is_handed() -> None:
    """A periodic whole grid (solved on a proper subset) is exact to about 1e-14: claimed
    under a check of 1e-13, not under one of 1e-15, which round-off does not meet."""
    rng = np.random.default_rng(1)
    h = (rng.uniform(size=(16, 16)) < 0.5).astype(float)
    inst = InstanceBuilder(Surface(h, 1.0, periodic=True), 1.0, "love", True, operator="dense").build(0.3)
    for check in (1e-13, 1e-15):
        res = get_solver("bvls").solve(inst.qp, SolverSettings(check_tol=check))
        verdict = judge(inst, res.p, bool(res.converged), check)
        assert res.converged == (verdict.status == "solved"), (check, verdict.kkt_error)
        assert res.converged or res.status == Status.STALLED.value
