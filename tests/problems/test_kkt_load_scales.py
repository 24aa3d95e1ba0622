"""The judge's figures under load control hold at every load (``problems.kkt``,
``constraints.fit_multiplier``): a light load spread thin over the whole surface -- p = P / n,
its gaps open wherever the surface does not touch -- is wrong, whatever approach the solver
reports (the products' share of the load); and the exact answer, or one a rounding off it,
passes at loads from 1e-300 to 1e300, at loads heavy for the surface's relief, and with
every element at its bound."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import QP, ContactInstance, InstanceBuilder
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import rmd_surface_n

TOL = 1e-6
H2 = [[2.0, 1.0], [1.0, 2.0]]
H3 = [[2.0, 1.0, 0.5], [1.0, 2.0, 1.0], [0.5, 1.0, 2.0]]


def dense(H: list[list[float]], ubar: list[float], upper: float | None = None,
          load: float | None = None) -> ContactInstance:
    c = make_constraints(len(ubar), upper, load)
    qp = QP(DenseOperator(np.asarray(H, dtype=np.float64)), np.asarray(ubar, dtype=np.float64), None, c)
    return ContactInstance(qp, delta=float("nan"), E=1.0, kernel="dense", periodic=False)


@pytest.mark.parametrize("load", [1e-8, 1e-6, 1e-4])
def test_a_light_load_spread_over_the_whole_surface_is_wrong(load: float) -> None:
    s = rmd_surface_n(16, 0.7, length=100e-6, rms_height=1e-6, seed=1)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False, operator="dense")
    inst = b.build_load(b.load_force(load))
    P, n = float(inst.qp.constraints.load), inst.n
    uniform = np.full(n, P / n)
    lowest = float(np.min(inst.qp.H.matvec(uniform) - inst.qp.ubar))  # (every gap >= 0 at this approach)
    for reported in (None, lowest):
        v = judge(inst, uniform, True, TOL, multiplier=reported)
        assert v.status == "inaccurate" and v.reading == "wrong" and v.kkt_error > 0.1, v.message()
    exact = constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints)
    assert judge(inst, exact.p, True, TOL).status == "solved"
    assert judge(inst, exact.p, True, TOL, multiplier=exact.multiplier).status == "solved"


@pytest.mark.parametrize("load", [1e-300, 1e-160, 1.0, 1e160, 1e300])
def test_the_exact_answer_on_a_flat_surface_passes_at_any_load(load: float) -> None:
    v = judge(dense(H2, [0.0, 0.0], load=load), np.array([load / 2, load / 2]), True, TOL)
    assert v.status == "solved", v.message()


@pytest.mark.parametrize("relief, load", [(1e-3, 1e3), (1e-6, 1.0), (1e-6, 1e3), (1e-9, 1e3)])
def test_a_load_heavy_for_the_relief_is_judged_on_its_own_length(relief: float, load: float) -> None:
    """All three elements touch; w = Hp - ubar - Delta carries round-off of Delta's size,
    which the relief alone would magnify past the tolerance."""
    ubar = [0.0, -relief, -2 * relief]
    K = np.block([[np.asarray(H3), -np.ones((3, 1))], [np.ones((1, 3)), np.zeros((1, 1))]])
    x = np.linalg.solve(K, np.array([*ubar, load]))
    assert np.all(x[:3] > 0)
    inst = dense(H3, ubar, load=load)
    for reported in (None, float(x[3])):
        p = x[:3] * (1.0 + np.array([2e-16, -2e-16, 0.0]))  # (a rounding off)
        assert judge(inst, p, True, TOL, multiplier=reported).status == "solved"


def test_every_element_at_its_bound_within_a_rounding_passes() -> None:
    inst = dense(H2, [1.0, -1.0], upper=1.0, load=2.0)
    for p in ([1.0, 1.0], [np.nextafter(1.0, 0.0), 1.0], [1.0 - 2**-52, 1.0 + 2**-52]):
        v = judge(inst, np.array(p), True, TOL)
        assert v.status == "solved" or v.kkt.primal > 0, (p, v.message())
    assert judge(inst, np.array([np.nextafter(1.0, 0.0), 1.0]), True, TOL).status == "solved"


def test_a_reference_far_below_the_force_scale_is_not_read_digit_by_digit() -> None:
    """ubar = [5e-324, 0]: the exact p_1 = 2.5e-324 is no float64; its rounding 0 passes,
    while an answer off on the problem's force scale is still wrong."""
    inst = dense(H2, [5e-324, 0.0])
    v = judge(inst, np.zeros(2), True, TOL, p_ref=np.array([5e-324, 0.0]), p_tol=1e-6)
    assert v.reading == "pass", v.message()
    inst = dense(H2, [1.0, -1.0])
    v = judge(inst, np.array([0.5 * (1 + 1e-3), 0.0]), True, TOL, p_ref=np.array([0.5, 0.0]), p_tol=1e-6)
    assert v.reading == "wrong" and "off the exact reference" in v.message()


def dense_bounds(H: list[list[float]], ubar: list[float], upper: list[float]) -> ContactInstance:
    c = make_constraints(len(ubar), np.asarray(upper, dtype=np.float64), None)
    qp = QP(DenseOperator(np.asarray(H, dtype=np.float64)), np.asarray(ubar, dtype=np.float64), None, c)
    return ContactInstance(qp, delta=float("nan"), E=1.0, kernel="dense", periodic=False)


@pytest.mark.parametrize("bound", [1e-300, 1e-12, 1e-6])
def test_one_small_bound_does_not_shrink_the_force_scale_of_the_others(bound: float) -> None:
    """Bounds [b, inf] (a QP file may carry per-element bounds): the free element is read on
    the problem's force scale, its own bound on b -- a rounding off passes, a tenth past
    the small bound fails."""
    inst = dense_bounds(H2, [1.5, 1.5], [bound, np.inf])
    free = 0.75 - bound / 2
    assert judge(inst, np.array([bound, free * (1 - 1e-12)]), True, TOL).status == "solved"
    assert judge(inst, np.array([1.1 * bound, free]), True, TOL).status == "inaccurate"


def test_a_uniform_bound_reads_every_element_on_it() -> None:
    """Bounds [b, b]: the figures are those of the one scale min(p_s, b)."""
    inst = dense_bounds(H2, [1.5, 1.5], [0.1, 0.1])
    v = judge(inst, np.array([0.1, 0.1 * (1 - 1e-3)]), True, TOL)
    assert v.kkt.p_scale == pytest.approx(0.1) and v.kkt.primal == 0.0 and v.status == "inaccurate"
