"""A load light for the surface's relief is judged on the gaps the load makes
(``kkt.load_length``): u_s is at most P max diag H, the most the load displaces any element,
so a wrong share of the load among points at (nearly) one height -- a flat punch, a
plateau, tied peaks -- is rejected, where the relief ||ubar||_inf as the scale let a
uniform pressure 60 % off the exact answer pass with kkt 3e-7."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contactbench.harness.judging import judge
from contactbench.problems.constraints import Constraints
from contactbench.problems.instances import ContactInstance, InstanceBuilder, flat_punch_surface
from contactbench.problems.kkt import RELIEF_SHARE, constrained_scales, load_length
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.surfaces import Surface
from contactbench.solvers import SolverSettings, get_solver

CHECK_TOL = 1e-6
E, L = 1e9, 100e-6


def punch(load: float, kernel: str = "bcc") -> ContactInstance:
    """A 16 x 16 flat punch (a quarter of the side) pressed by the dimensionless load ``load``."""
    b = InstanceBuilder(flat_punch_surface(16, L / 4, L), E, kernel, periodic=False)
    return b.build_load(b.load_force(load))


def checkerboard(load: float) -> ContactInstance:
    """A 16 x 16 checkerboard of equal peaks (128 tied maxima) under the load ``load``."""
    h = np.where(np.add.outer(np.arange(16), np.arange(16)) % 2 == 0, 1e-6, 0.0)
    b = InstanceBuilder(Surface(h, 1e-6, periodic=False), E, "bcc", periodic=False)
    return b.build_load(b.load_force(load))


def exact(inst: ContactInstance) -> np.ndarray:
    return constrained_exact_solution(inst.qp.H.to_dense(), inst.qp.ubar, inst.qp.constraints).p


@pytest.mark.parametrize("load", [1e-12, 1e-9, 1e-6, 1e-4])
def test_a_uniform_pressure_on_a_punch_is_not_its_answer(load: float) -> None:
    """Down to the lightest loads, where the punch's depth is no floor of the scale."""
    inst = punch(load)
    qp = inst.qp
    top = qp.ubar == qp.ubar.max()
    uniform = np.where(top, qp.constraints.load / top.sum(), 0.0)
    ref = exact(inst)
    assert np.max(np.abs(uniform - ref)) > 0.3 * np.max(ref)  # the edges carry far more
    assert judge(inst, uniform, True, CHECK_TOL).status != "solved"
    assert judge(inst, ref, True, CHECK_TOL).status == "solved"


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-ccg", "pk"])
def test_a_solver_that_stops_on_the_judge_s_figure_answers_tied_peaks(name: str) -> None:
    """The checkerboard at P/(E A) = 1e-9: the fast CCGs stopped on their uniform first
    guess (71 % off) when the relief was the scale."""
    inst = checkerboard(1e-9)
    ref = exact(inst)
    res = get_solver(name).solve(inst.qp, SolverSettings(check_tol=CHECK_TOL))
    assert judge(inst, res.p, res.converged, CHECK_TOL, multiplier=res.multiplier).status == "solved"
    assert np.max(np.abs(res.p - ref)) <= 1e-4 * np.max(ref)


def test_the_scale_is_bracketed_by_the_load_s_lengths() -> None:
    ubar = np.array([0.0, -1.0, -2.0])
    diag = 0.5
    for load, expected in ((1e-3, 0.5e-3), (1e-9, 0.5e-9), (10.0, 2.0), (60.0, 10.0)):
        u_s, p_s = constrained_scales(ubar, diag, Constraints(load=load))
        assert u_s == pytest.approx(expected, rel=1e-12) and p_s == pytest.approx(u_s / diag, rel=1e-12)
    assert load_length(ubar, 2.0, diag, Constraints()) is None


def test_an_offset_relief_keeps_its_round_off_floor_and_a_deep_pit_adds_none() -> None:
    """ubar offset by a constant (which Delta absorbs) is read no finer than 1e-6 of the
    relief the load can reach; a pit no answer touches does not widen the scale."""
    diag, load = 0.5, 1e-9
    offset = np.array([5.0, 4.0, 3.0])
    assert constrained_scales(offset, diag, Constraints(load=load))[0] == pytest.approx(5.0 * RELIEF_SHARE)
    pit = np.array([0.0, -1e-10, -1e3])
    assert constrained_scales(pit, diag, Constraints(load=load))[0] == pytest.approx(load * diag)


@pytest.mark.parametrize("kernel", ["bcc", "love"])
@given(seed=st.integers(0, 2**31 - 1), spread=st.integers(1, 40))
@settings(max_examples=25, deadline=None)
def test_no_force_field_of_the_load_displaces_an_element_past_the_scale(kernel: str, seed: int, spread: int) -> None:
    """The bound the scale rests on: ||Hp||_inf <= P max diag H for p >= 0 summing to P,
    on the grid kernels, however the load is spread."""
    inst = punch(1e-6, kernel)
    H = inst.qp.H.to_dense()
    rng = np.random.default_rng(seed)
    p = np.zeros(inst.qp.n)
    where = rng.choice(inst.qp.n, size=min(spread, inst.qp.n), replace=False)
    p[where] = rng.random(where.size)
    P = float(inst.qp.constraints.load)
    p *= P / p.sum()
    assert np.max(np.abs(H @ p)) <= P * np.max(np.diag(H)) * (1.0 + 1e-12)
