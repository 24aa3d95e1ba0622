"""The judge's displacement scale is the approach, not the relief: on a periodic grid at a
light displacement (ubar = Delta - (max xi - xi) holds the whole relief, far below zero) an
answer off by 10 % to 300 % read against the relief passed as solved.  u_s is max ubar, the
deepest overlap, not below ``kkt.RELIEF_SHARE`` of ||ubar||_inf (``kkt.problem_scales``)."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import RELIEF_SHARE, problem_scales
from contactbench.problems.mixed_lcp import bvls
from contactbench.problems.surfaces import rmd_surface_n

TOL = 1e-6


@pytest.fixture(scope="module")
def light() -> tuple:
    s = rmd_surface_n(16, 0.7, length=100e-6, rms_height=1e-6, seed=1, family="periodic")
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=True, operator="dense").build(paper_max_displacement(s) / 1000)
    exact = bvls(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), None, tol=1e-14).p
    return inst, exact


@pytest.mark.parametrize("factor", [0.0, 0.5, 0.99, 1.01, 1.1, 2.0, 4.0])
def test_an_answer_off_by_a_percent_or_more_at_a_light_approach_is_not_solved(light: tuple, factor: float) -> None:
    inst, exact = light
    assert judge(inst, factor * exact, True, TOL).status != "solved"


def test_the_exact_answer_at_a_light_approach_is_solved(light: tuple) -> None:
    inst, exact = light
    assert judge(inst, exact, True, TOL).status == "solved"


def test_the_scale_is_the_approach_not_the_relief() -> None:
    ubar = np.array([1e-3, -5.0, -2.0, 0.0])
    assert problem_scales(ubar, 1.0)[0] == pytest.approx(1e-3)
    assert problem_scales(np.array([-5.0, -2.0]), 1.0)[0] == pytest.approx(RELIEF_SHARE * 5.0)  # (no overlap)
    assert problem_scales(ubar, 1.0, displacement=False)[0] == pytest.approx(5.0)  # (load control: the relief)
