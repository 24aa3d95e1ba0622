"""``precision="auto"`` (solvers/_refine.py) and ``precondition="auto"``
(solvers/_preconditioners.py): mixed from ``MIXED_GRID_POINTS`` grid points up and the far
field from ``FAR_FIELD_GRID_POINTS``, double and the islands alone below; decided by the grid
the unknowns sit on, not by their count."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import runs_dense_blocks
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _preconditioners, _refine
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver


def small_qp():
    """A 32^2 problem whose products run through the FFT (no dense switch): the stand-in,
    with its grid's shape replaced, for a set on a large grid."""
    surf = rmd_surface_n(32, 0.7, length=100e-6, seed=3)
    qp = InstanceBuilder(surf, 1e9, "bcc", periodic=False).build(paper_max_displacement(surf)).qp
    qp.H.auto_dense = False
    return qp


def test_auto_is_double_below_the_threshold_and_mixed_from_it() -> None:
    qp = small_qp()
    assert qp.geometry is not None and _preconditioners.grid_points(qp) == 32 * 32
    assert _refine.resolved_precision("auto", qp) == "double"
    geo = qp.geometry
    big = replace(qp, geometry=replace(geo, grid_shape=(512, 512)))
    assert _refine.resolved_precision("auto", big) == "mixed"
    just_below = replace(big, geometry=replace(geo, grid_shape=(512, 511)))
    assert _refine.resolved_precision("auto", just_below) == "double"
    # products that are a dense block of the set (a sweep's first screened steps): double
    switching = copy.copy(qp.H)
    switching.auto_dense = True
    blocks = replace(big, H=switching)
    assert runs_dense_blocks(blocks.H) and not runs_dense_blocks(big.H)
    assert _refine.resolved_precision("auto", blocks) == "double"
    # the explicit choices are never changed by the grid
    for p in ("double", "mixed"):
        assert _refine.resolved_precision(p, qp) == p and _refine.resolved_precision(p, big) == p


def test_auto_without_a_geometry_reads_the_unknowns() -> None:
    qp = replace(small_qp(), geometry=None)
    assert _preconditioners.grid_points(qp) == qp.n
    assert _refine.resolved_precision("auto", qp) == "double"


@pytest.mark.parametrize("threshold,expected", [(1, "mixed"), (10**12, "double")])
def test_a_solve_reports_the_precision_auto_chose(monkeypatch: pytest.MonkeyPatch, threshold: int,
                                                   expected: str) -> None:
    monkeypatch.setattr(_preconditioners, "MIXED_GRID_POINTS", threshold)
    qp = small_qp()
    res = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=1e-9, params={"precision": "auto"}))
    assert res.converged and res.info["precision"] == expected, res.info
    assert (res.info["matvecs_float32"] > 0) == (expected == "mixed")
    ref = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=1e-9, params={"precision": "double"}))
    assert np.max(np.abs(res.p - ref.p)) <= 100 * 1e-9 * np.max(ref.p)


def test_auto_preconditioner_takes_the_far_field_from_the_threshold() -> None:
    qp = small_qp()
    big = replace(qp, geometry=replace(qp.geometry, grid_shape=(1024, 1024)))
    just_below = replace(qp, geometry=replace(qp.geometry, grid_shape=(1024, 1023)))
    assert _preconditioners.resolved_kind("auto", qp) == "islands"
    assert _preconditioners.resolved_kind("auto", just_below) == "islands"
    assert _preconditioners.resolved_kind("auto", big) == "farfield"
    # float32's threshold is below the far field's: a 1024^2 grid runs mixed with the far field
    assert _refine.resolved_precision("auto", big) == "mixed"
    assert _refine.resolved_precision("auto", replace(qp, geometry=replace(qp.geometry, grid_shape=(512, 512)))) \
        == "mixed" and _preconditioners.resolved_kind("auto", replace(
            qp, geometry=replace(qp.geometry, grid_shape=(512, 512)))) == "islands"
    for k in ("islands", "farfield", "fourier", "none"):
        assert _preconditioners.resolved_kind(k, qp) == k == _preconditioners.resolved_kind(k, big)


@pytest.mark.parametrize("threshold", [1, 10**12])
def test_the_default_below_the_threshold_is_the_islands_in_double(monkeypatch: pytest.MonkeyPatch,
                                                                  threshold: int) -> None:
    """Below the threshold the default takes the iterates of precision=double,
    precondition=islands; from it, those of mixed with the far field (the same counts, p to
    round-off: two solves of one configuration differ in the last bits with threads)."""
    monkeypatch.setattr(_preconditioners, "MIXED_GRID_POINTS", threshold)
    monkeypatch.setattr(_preconditioners, "FAR_FIELD_GRID_POINTS", threshold)
    qp = small_qp()
    solve = get_solver("fast-dual-pccg").solve
    default = solve(qp, SolverSettings(tol=1e-9))
    fixed = {"precision": "double", "precondition": "islands"} if threshold > 1 else \
        {"precision": "mixed", "precondition": "farfield"}
    same = solve(qp, SolverSettings(tol=1e-9, params=fixed))
    assert default.iterations == same.iterations and default.matvecs == same.matvecs
    np.testing.assert_allclose(default.p, same.p, rtol=1e-12, atol=1e-12 * float(np.max(same.p)))


def test_a_warm_start_of_a_plain_problem_takes_the_far_field_from_its_own_threshold() -> None:
    """``WARM_FAR_FIELD_GRID_POINTS`` (512^2) for a warm start of a non-periodic problem with no
    constraint beyond p >= 0; a cold start, a periodic grid and a hardness keep
    ``FAR_FIELD_GRID_POINTS``."""
    from contactbench.problems.constraints import make_constraints

    qp = small_qp()
    at_512 = replace(qp, geometry=replace(qp.geometry, grid_shape=(512, 512)))
    below = replace(qp, geometry=replace(qp.geometry, grid_shape=(512, 511)))
    assert _preconditioners.resolved_kind("auto", at_512, warm=True) == "farfield"
    assert _preconditioners.resolved_kind("auto", below, warm=True) == "islands"
    assert _preconditioners.resolved_kind("auto", at_512) == "islands"
    periodic = replace(at_512, geometry=replace(at_512.geometry, periodic=True))
    assert _preconditioners.resolved_kind("auto", periodic, warm=True) == "islands"
    hard = replace(at_512, constraints=make_constraints(qp.n, upper=np.full(qp.n, 1e9)))
    assert hard.constraints.bounded
    assert _preconditioners.resolved_kind("auto", hard, warm=True) == "islands"
    for k in ("islands", "fourier", "none"):
        assert _preconditioners.resolved_kind(k, at_512, warm=True) == k


@pytest.mark.parametrize("threshold,far", [(1, True), (10**12, False)])
def test_a_warm_solve_builds_the_far_field_the_rule_gives(monkeypatch: pytest.MonkeyPatch, threshold: int,
                                                          far: bool) -> None:
    """The warm solve's preconditioner is the rule's: the iterates of precondition=farfield
    from the threshold, of precondition=islands below it; a cold solve keeps the islands."""
    from contactbench.solvers.base import WarmStart

    monkeypatch.setattr(_preconditioners, "WARM_FAR_FIELD_GRID_POINTS", threshold)
    qp = small_qp()
    solve = get_solver("fast-dual-pccg").solve
    answer = solve(qp, SolverSettings(tol=1e-9)).p
    start = WarmStart(0.8 * answer)
    default = solve(qp, SolverSettings(tol=1e-9), start)
    same = solve(qp, SolverSettings(tol=1e-9, params={"precondition": "farfield" if far else "islands"}), start)
    assert default.converged and default.iterations == same.iterations and default.matvecs == same.matvecs
    np.testing.assert_allclose(default.p, same.p, rtol=1e-12, atol=1e-12 * float(np.max(same.p)))
