"""The scaled KKT figures hold at the ends of float64 (``problems.kkt``): a force scale
p_s in the subnormal range judges an answer as in any other unit system (its reciprocal
overflows; the figures divide by it), a flat surface under load control takes its scales
from the load, and a QP without unknowns has every figure 0."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import QP, ContactInstance, InstanceBuilder
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import Surface


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


def test_a_flat_surface_under_load_control_is_judged_alike_in_every_unit_system() -> None:
    """ubar = 0: the load gives the scales (p_s = P / n), so the whole load on one element
    is as wrong in metres and newtons as in micrometres and micronewtons, and the exact
    answer is solved in both."""
    verdicts = []
    for length, force in ((1.0, 1.0), (1e6, 1e6)):  # metres and newtons; micrometres and micronewtons
        E = 1e11 * force / length**2
        flat = Surface(np.zeros((8, 8)), 1e-6 * length, name="flat", periodic=False)
        inst = InstanceBuilder(flat, E, operator="dense").build_load(1e-4 * E * (8e-6 * length) ** 2)
        H, ubar = inst.qp.H.to_dense(), np.asarray(inst.qp.ubar, dtype=np.float64)
        exact = constrained_exact_solution(H, ubar, inst.qp.constraints).p
        assert judge(inst, exact, True, 1e-6).status == "solved"
        lumped = np.zeros(inst.n)
        lumped[0] = float(inst.qp.constraints.load)
        verdicts.append(judge(inst, lumped, True, 1e-6))
    assert all(v.status == "inaccurate" for v in verdicts)
    assert verdicts[0].kkt_error == pytest.approx(verdicts[1].kkt_error, rel=1e-9)
