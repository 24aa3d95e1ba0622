"""The scaled KKT figures hold at the ends of float64 (``problems.kkt``): a force scale
p_s in the subnormal range judges an answer as in any other unit system (its reciprocal
overflows; the figures divide by it), and a QP without unknowns has every figure 0."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operators import DenseOperator


def instance(H: np.ndarray, ubar: np.ndarray) -> ContactInstance:
    qp = QP(DenseOperator(H), ubar, None, make_constraints(ubar.size, None, None))
    return ContactInstance(qp, delta=float("nan"), E=1.0, kernel="bcc", periodic=False)


def spd(n: int) -> np.ndarray:
    a = np.random.default_rng(0).random((n, n))
    return a @ a.T / n + np.eye(n)


@pytest.mark.parametrize("length, force", [(1.0, 1.0), (1e-10, 1e-300), (1e-10, 5e-309), (1e-10, 1e-309)])
def test_the_exact_answer_is_solved_in_any_unit_system(length: float, force: float) -> None:
    H0, u0 = spd(6), np.array([1.0, -0.5, 0.7, 0.2, -1.0, 0.9])
    p0 = exact_solution(H0, u0).p
    v = judge(instance(H0 * (length / force), u0 * length), p0 * force, True, 1e-8)
    assert v.status == "solved" and v.kkt.kkt_error < 1e-12, v.message()


def test_a_qp_without_unknowns_has_every_figure_zero() -> None:
    report = kkt_check(instance(np.zeros((0, 0)), np.zeros(0)), np.zeros(0))
    assert report.kkt_error == 0.0 and report.primal == report.dual == report.complementarity == 0.0
