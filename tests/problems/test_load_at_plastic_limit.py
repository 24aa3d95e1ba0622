"""A load at the all-plastic limit: the planner (``check_load_under_hardness``) and the build
(``Constraints.check``) decide by one test (``load_exceeds``), so the build accepts every
load P/(E* A) the planner accepts -- a load equal to H_A/E* included, where every element
at its bound carries it -- and both still refuse a load above it in one line that tells the
two numbers apart."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from contactbench.problems.constraints import check_load_under_hardness, load_exceeds, make_constraints
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import Surface

ES = (1e9, 2.1e11, 7e10, 1.3e8, 3e9)
HARDNESSES = (3e8, 1e9, 2.5e9, 7e7, 1.1e10)
SIZES = (32, 17, 64)
LENGTHS = (7e-5, 1e-4 / 3, 32e-6, 1e-3 / 7, 0.1 / 3)


def builder(N: int, L: float, E: float) -> InstanceBuilder:
    return InstanceBuilder(Surface(np.zeros((N, N)), L / N), E)


def test_every_load_the_planner_accepts_at_the_limit_is_built() -> None:
    """The load H_A/E* (and the float just above it, where the planner's slack admits it)
    passes both checks, on every (E*, H_A, N, L) tried: none accepted by one and refused by
    the other."""
    disagree = []
    for E, H, N, L in itertools.product(ES, HARDNESSES, SIZES, LENGTHS):
        b = builder(N, L, E)
        for load in (H / E, np.nextafter(H / E, np.inf)):
            try:
                check_load_under_hardness([float(load)], H, E)
            except ProblemInputError:
                continue
            try:
                b.constraints(N * N, H, b.load_force(float(load)))
            except ProblemInputError:
                disagree.append((E, H, N, L, float(load)))
        assert not load_exceeds(H, H, 0)
    assert not disagree, f"{len(disagree)} loads the planner accepts are refused at build: {disagree[:3]}"


def test_a_load_at_the_limit_is_accepted_and_one_above_refused_with_both_numbers() -> None:
    """0.3 at H_A/E* = 0.3 is accepted; 0.30000001 is refused by both checks in one line
    that tells 0.30000001 from 0.3 and states the relative excess."""
    H, E = 3e8, 1e9
    check_load_under_hardness([0.1, 0.3], H, E)
    with pytest.raises(ProblemInputError) as plan:
        check_load_under_hardness([0.30000001], H, E)
    line = str(plan.value)
    assert "0.30000001" in line and "H_A/E* = 0.3;" in line and "relative above it" in line and "\n" not in line
    b = builder(32, 7e-5, E)
    b.constraints(32 * 32, H, b.load_force(0.3))
    with pytest.raises(ProblemInputError) as build:
        b.constraints(32 * 32, H, b.load_force(0.30000001))
    force, cap = b.load_force(0.30000001), 32 * 32 * H * (7e-5 / 32) ** 2
    assert repr(force) in str(build.value) and "exceeds what the bounds can carry" in str(build.value)
    assert f"{force / cap - 1.0:.2g}"[:3] in str(build.value)


def test_the_slack_is_round_off_per_summed_term() -> None:
    """A load within a few n eps of the summed bounds is feasible (p = u carries it); one
    a relative 1e-9 above is not, whatever n; an unbounded box carries any load."""
    eps = float(np.finfo(np.float64).eps)
    for n in (1, 1024, 4096 * 4096):
        u = np.full(min(n, 4096), 2.5)
        cap = float(np.sum(u)) * (n / u.size)
        assert not load_exceeds(cap * (1.0 + n * eps), cap, n)
        assert load_exceeds(cap * (1.0 + 1e-9 + 16 * n * eps), cap, n)
    assert not load_exceeds(1e300, float("inf"), 3)
    make_constraints(4, 1.0, 4.0 * (1.0 + 8 * eps))
    with pytest.raises(ProblemInputError, match="exceeds what the bounds can carry"):
        make_constraints(4, 1.0, 4.0 * (1.0 + 1e-9))
