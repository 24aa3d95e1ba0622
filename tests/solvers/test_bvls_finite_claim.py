"""bvls claims convergence only with a finite answer: where the exact solution lies beyond
float64's range (ubar / H of 1e310), its own solve returns p = inf with a passing check, and the
outcome says FAILED, not converged, instead."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import QP
from contactbench.problems.operators import DenseOperator
from contactbench.solvers.base import Outcome, Status
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
