"""The exact reference of periodic load control (``problems.mixed_lcp``: the active set on
the bordered KKT system, ``load_active_set``).

A periodic kernel on the whole grid has H 1 = 0, so the displacement-controlled QP at a
fixed Delta is not the sub-problem (regula falsi on P(Delta) fails where P(Delta) jumps to
infinity at full contact); the reference solves sum(p) = P directly.  Checked here at 32^2:
its answer passes ``kkt_check`` at 1e-10 (with and without a hardness, and beyond full
contact); ``pk`` under periodic load control agrees with it; it reproduces the periodic
displacement-controlled answer at that answer's load; the active set itself (not only its
projected-gradient start) reaches the answer from a poor start."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.constraints import Constraints, project_feasible
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution_on_subset
from contactbench.problems.mixed_lcp import (constant_null_space, constrained_exact_solution,
                                            constrained_solution_on_subset, exchange_partner, load_active_set)
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

E = 1e9
N = 32


def periodic_builder(kernel: str = "bcc", operator: str = "dense", size: int = N) -> InstanceBuilder:
    return InstanceBuilder(fourier_synthesis(size, 0.8, 0.1, length=1e-4, seed=3), E, kernel, periodic=True,
                           operator=operator)


@pytest.fixture(scope="module")
def displacement_step() -> tuple[float, np.ndarray]:
    """(Delta, p) of the periodic displacement-controlled problem at Delta = (z_max - z_mean) / 2
    (BCC, 32^2): its exact solution on a proper subset, certified on the whole grid."""
    b = periodic_builder()
    delta = paper_max_displacement(b.surface)
    sol = exact_solution_on_subset(b.build(delta).qp)
    return delta, sol.p


def reference(inst):
    return constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints)


@pytest.mark.parametrize("kernel", ["bcc", "spectral"])
@pytest.mark.parametrize("scale,hardness", [(1.0, None), (1.0, 0.03 * E), (300.0, None)])
def test_the_reference_passes_the_kkt_check(displacement_step, kernel: str, scale: float,
                                            hardness: float | None) -> None:
    """At the sweep's load, with a hardness that makes most of the contact plastic, and at
    300x the load (beyond full contact, where every element is free and Delta = xi_max -
    xi_mean: the bordered system on the whole grid)."""
    _, p_disp = displacement_step
    inst = periodic_builder(kernel).build_load(scale * float(np.sum(p_disp)), hardness=hardness)
    H = inst.qp.H.to_dense()
    assert constant_null_space(H)
    sol = reference(inst)
    assert sol.solves == 0  # the active set, not regula falsi over displacement solves
    assert kkt_check(inst, sol.p, sol.multiplier).kkt_error <= 1e-10
    if hardness is not None:
        assert np.count_nonzero(sol.p >= inst.qp.constraints.upper * (1 - 1e-12)) > 0
    if scale > 1.0:
        assert np.all(sol.p > 0.0)
        top = float(np.max(inst.surface.heights) - np.mean(inst.surface.heights))
        assert sol.multiplier == pytest.approx(top, rel=1e-9)


def test_load_control_at_the_periodic_displacement_answers_load(displacement_step) -> None:
    """The comparison that is well posed.  The periodic displacement problem is posed on the
    whole grid with ubar = xi - xi_max + Delta, unclipped; its answer is unique (H's null
    vector is 1 and sum(ubar) < 0), but a periodic displacement solve fixes the mean gap, not
    the load, so its load P = sum(p) is an output.  The load-controlled QP at that P
    (ubar = xi - xi_max, multiplier Delta') has the displacement problem's KKT conditions
    exactly when Delta' = Delta, and its p is unique (H is positive definite on sum d = 0):
    so it must give the same p and its multiplier must be the displacement's Delta."""
    delta, p_disp = displacement_step
    inst = periodic_builder().build_load(float(np.sum(p_disp)))
    sol = reference(inst)
    assert np.max(np.abs(sol.p - p_disp)) <= 1e-10 * np.max(p_disp)
    assert sol.multiplier == pytest.approx(delta, rel=1e-10)


def test_pk_under_periodic_load_control_agrees_with_the_reference(displacement_step) -> None:
    """``pk`` on the FFT operator and the registered ``bvls`` reference (through
    ``Solver.solve``) against ``constrained_exact_solution`` on the dense H."""
    _, p_disp = displacement_step
    load = 0.6 * float(np.sum(p_disp))
    inst = periodic_builder(operator="fft").build_load(load)
    ref = constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints)
    for name, tol in (("pk", 1e-12), ("bvls", None)):
        r = get_solver(name).solve(inst.qp, SolverSettings(tol=tol))
        assert r.status == "converged", (name, r.message)
        assert np.max(np.abs(r.p - ref.p)) <= 1e-8 * np.max(ref.p), name
        assert r.multiplier == pytest.approx(ref.multiplier, rel=1e-8), name


def test_the_active_set_reaches_the_answer_from_a_poor_start() -> None:
    """The load piled on the lowest elements: infeasible for the contact set, so the active
    set must free and fix elements itself; it ends on the reference's answer (20^2: each of
    its steps is a dense solve)."""
    b = periodic_builder(size=20)
    p_disp = exact_solution_on_subset(b.build(paper_max_displacement(b.surface)).qp).p
    inst = b.build_load(float(np.sum(p_disp)), hardness=0.02 * E)
    H, ubar, c = inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints
    poor = project_feasible(-ubar, c)
    out = load_active_set(H, ubar, c, poor)
    assert out.converged and out.iterations > 0
    ref = reference(inst)
    assert np.max(np.abs(out.p - ref.p)) <= 1e-9 * np.max(ref.p)
    assert out.multiplier == pytest.approx(ref.multiplier, rel=1e-9)


def test_the_null_space_test_and_the_refusals() -> None:
    """An aperiodic kernel is not singular along 1 (its positive row sums); H = 0 is not
    called periodic; the active set refuses a QP without a load."""
    aperiodic = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=3), E, "bcc",
                                operator="dense").build_load(1e-3)
    assert not constant_null_space(aperiodic.qp.H.to_dense())
    assert not constant_null_space(np.zeros((4, 4)))
    plain = periodic_builder().build(1e-7)
    with pytest.raises(ValueError, match="load equality"):
        load_active_set(plain.qp.H.to_dense(), plain.qp.ubar, plain.qp.constraints, np.zeros(plain.qp.n))


def test_an_element_freed_alone_trades_force_with_its_exchange_partner() -> None:
    """Every element at a bound and the load carried by the saturated ones: the element at
    0 whose gap asks for force cannot move alone (its force is what the load leaves, 0), so
    it is freed with the saturated element most ready to shed force; the active set then
    reaches the answer instead of freeing it again and again until its step limit."""
    H = np.eye(4) + 0.1
    ubar = np.array([0.0, 0.0, 0.0, 1.0])
    c = Constraints(np.ones(4), 2.0)
    out = load_active_set(H, ubar, c, np.array([1.0, 1.0, 0.0, 0.0]), max_iter=20)
    assert out.converged, out
    assert out.p[3] == pytest.approx(1.0) and np.sum(out.p) == pytest.approx(2.0)
    np.testing.assert_allclose(out.p[:3], 1.0 / 3.0, rtol=1e-12)
    assert exchange_partner(H @ np.array([1.0, 1.0, 0.0, 0.0]) - ubar, np.array([2, 2, 0, 0], dtype=np.int8), 3) in (0, 1)


@pytest.mark.parametrize("hardness", [None, 0.03 * E])
def test_the_subset_solve_under_a_load_agrees_with_the_active_set(displacement_step, hardness: float | None) -> None:
    """``constrained_solution_on_subset`` (bvls's way out where the whole grid's Cholesky
    fails) gives the active set's answer and multiplier under a load, with and without a
    hardness, on a proper subset."""
    _, p_disp = displacement_step
    inst = periodic_builder("spectral").build_load(float(np.sum(p_disp)), hardness=hardness)
    ref = reference(inst)
    sub = constrained_solution_on_subset(inst.qp)
    assert sub.subset.size < inst.n and kkt_check(inst, sub.p, sub.multiplier).kkt_error <= 1e-10
    assert np.linalg.norm(sub.p - ref.p) <= 1e-8 * np.linalg.norm(ref.p)
    assert sub.multiplier == pytest.approx(ref.multiplier, rel=1e-8)
