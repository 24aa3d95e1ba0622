"""The flag of the plastic share (``problems.plastic_share.plastic_uncertain``): elements
left a little below their bound by an accepted answer -- counted elastic, plastic in the
exact answer -- are covered by it; the exact answer's flag is small; a problem without a
hardness has none (NaN).  The judge writes it beside ``plastic_fraction``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from contactbench.harness.judging import answer_figures, answer_report
from contactbench.problems.instances import ContactInstance, InstanceBuilder, paper_max_displacement
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.plastic_share import plastic_open, plastic_uncertain
from contactbench.problems.surfaces import fourier_synthesis

E = 1e11
TOL = 1e-6


@pytest.fixture(scope="module")
def plastic() -> tuple[ContactInstance, ContactInstance, np.ndarray]:
    """A 16 x 16 rough surface pressed to twice the paper's top step, without a hardness and
    with one at 0.4 x the elastic peak force, and the bounded problem's exact answer."""
    b = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=2), E, operator="dense")
    d = 2.0 * paper_max_displacement(b.surface)
    plain = b.build(d)
    p_el = exact_solution(plain.qp.H.H, plain.qp.ubar).p
    inst = b.build(d, hardness=0.4 * float(np.max(p_el)) / b.surface.delta ** 2)
    ref = constrained_exact_solution(inst.qp.H.H, inst.qp.ubar, inst.qp.constraints)
    return plain, inst, ref.p


def test_the_exact_answer_has_a_small_flag(plastic) -> None:
    _, inst, p = plastic
    share = inst.plastic_fraction(p, TOL)
    touching = int(np.count_nonzero(inst.contact_mask(p, TOL)))
    assert 0.1 < share < 0.9
    assert plastic_uncertain(inst, p, TOL) * touching <= 1  # at most one element left open


def test_points_just_below_their_bound_are_covered(plastic) -> None:
    _, inst, p = plastic
    u = inst.qp.constraints.upper_or_inf(inst.n)
    p_s = inst.force_scale()
    at_bound = np.flatnonzero(inst.plastic_mask(p, TOL))
    q = p.copy()
    q[at_bound] = u[at_bound] - 0.3 * math.sqrt(TOL) * p_s  # counted elastic, plastic in the exact answer
    touching = int(np.count_nonzero(inst.contact_mask(q, TOL)))
    off = abs(inst.plastic_fraction(q, TOL) - inst.plastic_fraction(p, TOL))
    assert off * touching == pytest.approx(at_bound.size)  # the count is fooled ...
    assert plastic_uncertain(inst, q, TOL) >= off  # ... the flag covers it
    assert plastic_open(inst, q, TOL)[at_bound].all()
    q[at_bound] = u[at_bound] - 0.3 * TOL * p_s  # counted plastic, inside the band below the floor
    assert inst.plastic_fraction(q, TOL) == inst.plastic_fraction(p, TOL)
    assert plastic_open(inst, q, TOL)[at_bound].all()
    q[at_bound] = u[at_bound] - 10.0 * math.sqrt(TOL) * p_s  # well off the bound: plainly elastic
    assert not plastic_open(inst, q, TOL)[at_bound].any()


def test_the_judge_writes_the_flag_beside_the_share(plastic) -> None:
    plain, inst, p = plastic
    u = inst.qp.constraints.upper_or_inf(inst.n)
    q = p.copy()
    at_bound = inst.plastic_mask(p, TOL)
    q[at_bound] = u[at_bound] - 0.3 * math.sqrt(TOL) * inst.force_scale()
    fig = answer_figures(inst, q, answer_report(inst, q), p, None, TOL)
    assert fig["plastic_uncertain"] == plastic_uncertain(inst, q, TOL)
    assert fig["plastic_uncertain"] >= abs(fig["plastic_fraction"] - inst.plastic_fraction(p, TOL)) > 0
    p_el = exact_solution(plain.qp.H.H, plain.qp.ubar).p
    assert "plastic_uncertain" not in answer_figures(plain, p_el, answer_report(plain, p_el), None, None, TOL)


def test_no_hardness_no_flag(plastic) -> None:
    plain, _, _ = plastic
    p = np.ones(plain.n)
    assert math.isnan(plastic_uncertain(plain, p, TOL))
    assert not plastic_open(plain, p, TOL).any()
