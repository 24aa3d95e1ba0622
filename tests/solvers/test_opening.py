"""The opening of a cold solve (solvers/_opening.py): the wave-number preconditioner until the
KKT error is OPENING_KKT, the island blocks after; the stages checked against the solves that
use either alone."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _opening
from contactbench.solvers._farfield import MAX_SET_FRACTION
from contactbench.solvers._opening import (
    OPENED_FAR_FRACTION,
    OPENING_KKT,
    StagedPreconditioner,
    opened,
    resolved_opening,
)
from contactbench.solvers._preconditioners import FourierPreconditioner, IslandPreconditioner, make_preconditioner
from contactbench.solvers.base import ParamError, SolveContext, SolverSettings
from tests.helpers import loop_context
from contactbench.solvers.registry import get_solver


def build(N: int = 65, hurst: float = 0.9, seed: int = 3):
    s = rmd_surface_n(N, hurst, length=100e-6, seed=seed)
    return InstanceBuilder(s, 1e9, "bcc").build(paper_max_displacement(s))


def context_of(qp) -> SolveContext:
    return loop_context(qp, 100)


def solve(inst, name: str = "fast-dual-pccg", **params):
    return get_solver(name).solve(inst.qp, SolverSettings(tol=1e-9, params=params))


def test_the_staged_preconditioner_is_its_first_stage_until_the_kkt_error_falls_to_the_threshold():
    inst = build()
    F = FourierPreconditioner.build(inst.qp)
    I = make_preconditioner("islands", inst.qp)
    M = StagedPreconditioner(F, I)
    S = inst.qp.ubar > 0.5 * inst.qp.ubar.max()
    r = np.random.default_rng(0).standard_normal(inst.qp.n)
    M.update(S)
    assert M.opening and np.array_equal(M.on, S)
    F.update(S)
    np.testing.assert_array_equal(M.apply(r), F.apply(r))
    assert not M.progress(1.0) and not M.progress(np.nextafter(OPENING_KKT, 1.0)) and M.opening
    assert not M.simplify()  # the opening has no coarse part to drop
    assert M.progress(OPENING_KKT) and not M.opening
    assert not M.progress(0.0)  # it switches once, and stays
    M.update(S)
    I.update(S)
    np.testing.assert_allclose(M.apply(r), I.apply(r), rtol=1e-12, atol=0)
    np.testing.assert_array_equal(M.solo(r), I.solo(r))
    assert M.builds == I.builds == 1


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-pccg"])
def test_an_opening_that_never_ends_is_the_wave_number_solve(name, monkeypatch):
    inst = build()
    fourier = solve(inst, name, precondition="fourier", opening="none", precision="double")
    monkeypatch.setattr(_opening, "OPENING_KKT", 0.0)  # never switches before convergence
    opened = solve(inst, name, precondition="islands", opening="fourier", precision="double")
    assert opened.status == fourier.status == "converged"
    assert opened.matvecs == fourier.matvecs and opened.iterations == fourier.iterations


def test_the_switch_waits_for_a_set_that_has_stopped_shedding():
    inst = build()
    M = StagedPreconditioner(FourierPreconditioner.build(inst.qp), make_preconditioner("islands", inst.qp))
    order = np.argsort(-inst.qp.ubar)
    sets = [np.isin(np.arange(inst.qp.n), order[:k]) for k in (400, 200, 180)]
    M.update(sets[0])
    assert not M.progress(0.0)  # nothing seen before: not known to have settled
    M.update(sets[1])  # half the set shed since the last check
    assert not M.progress(0.0) and M.opening
    M.update(sets[2])  # 10 % shed: settled
    assert not M.progress(float("nan")) and not M.progress(np.inf) and M.opening  # no error to trust
    assert M.progress(OPENING_KKT) and not M.opening


@pytest.mark.parametrize("precision", ["double", "mixed"])
def test_an_opened_solve_reaches_the_answer_of_the_unopened_one(precision):
    inst = build()
    plain = solve(inst, opening="none", precision=precision, precondition="farfield")
    opened = solve(inst, opening="fourier", precision=precision, precondition="farfield")
    assert opened.info["opening"] == "fourier" and "opening" not in plain.info
    assert opened.info["preconditioner_builds"] > 0  # the island stage came on
    assert kkt_check(inst, opened.p).kkt_error <= 1e-9
    assert relative_error(opened.p, plain.p) < 1e-6


def test_the_opened_island_stage_builds_its_far_field_on_larger_sets():
    inst = build()
    M = make_preconditioner("farfield", inst.qp)
    assert M.far_fraction == MAX_SET_FRACTION
    staged = opened(M, replace(context_of(inst.qp), params={"opening": "fourier"}))
    assert isinstance(staged, StagedPreconditioner) and staged.then is M and M.far_fraction == OPENED_FAR_FRACTION
    big = np.zeros(inst.qp.n, dtype=bool)
    big[: int(0.45 * inst.qp.n)] = True  # between the two fractions
    M.update(big)
    assert M._far is not None
    M.far_fraction = MAX_SET_FRACTION
    M.update(~big)  # a new set: the far field is rebuilt, or refused
    M.update(big)
    assert M._far is None


def test_auto_opens_a_cold_unconstrained_island_solve_only():
    inst = build()
    M = make_preconditioner("islands", inst.qp)
    cold = context_of(inst.qp)
    assert resolved_opening("auto", M, cold) == "fourier"
    assert resolved_opening("none", M, cold) == "none"
    assert resolved_opening("auto", None, cold) == resolved_opening("fourier", None, cold) == "none"
    assert resolved_opening("auto", make_preconditioner("fourier", inst.qp), cold) == "none"
    assert isinstance(M, IslandPreconditioner)
    warm = replace(cold, p0=np.zeros(inst.qp.n))
    assert resolved_opening("auto", M, warm) == "none"
    loaded = context_of(replace(inst.qp, constraints=make_constraints(inst.qp.n, load=1e-3)))
    assert resolved_opening("auto", M, loaded) == "none"
    assert resolved_opening("fourier", M, loaded) == "fourier"  # asked for, it is given


def test_auto_does_not_open_a_set_whose_products_are_a_dense_block():
    """A set small for its grid (a sweep's first steps, screened to a few dozen points:
    ``operators.dense_block_pays``) is not opened: a wave-number application is an FFT pair
    on the whole grid, dearer than the product.  Asked for, the opening is given."""
    from contactbench.problems.operators import FFTOperator

    inst = build(129)
    M = make_preconditioner("islands", inst.qp)
    assert isinstance(inst.qp.H, FFTOperator) and not inst.qp.H.dense_pays()
    assert resolved_opening("auto", M, context_of(inst.qp)) == "fourier"
    few = np.argsort(inst.qp.ubar)[-40:]
    small = inst.qp.restrict(np.sort(few))
    assert small.H.dense_pays()
    M_small = make_preconditioner("islands", small)
    assert resolved_opening("auto", M_small, context_of(small)) == "none"
    assert resolved_opening("fourier", M_small, context_of(small)) == "fourier"
    r = get_solver("fast-dual-pccg").solve(small, SolverSettings(tol=1e-9))
    assert r.converged and "opening" not in r.info


def test_an_opened_auto_solve_takes_the_far_field_from_its_own_grid_size(monkeypatch):
    """From ``OPENED_FAR_FIELD_GRID_POINTS`` an opened solve whose islands "auto" chose gets
    the far field; below it, when the islands were asked for, or when the solve is not opened
    (a warm step), the islands stay alone; and a default solve at the size builds one."""
    inst = build()
    points = int(np.prod(inst.qp.geometry.grid_shape))
    cold = {**context_of(inst.qp).params, "opening": "auto"}
    ctx = replace(context_of(inst.qp), params=cold)
    for threshold, auto_kind, far in ((points, True, True), (points + 1, True, False), (points, False, False)):
        monkeypatch.setattr(_opening, "OPENED_FAR_FIELD_GRID_POINTS", threshold)
        M = opened(make_preconditioner("islands", inst.qp), ctx, auto_kind=auto_kind)
        assert isinstance(M, StagedPreconditioner) and M.then.far_field is far
    monkeypatch.setattr(_opening, "OPENED_FAR_FIELD_GRID_POINTS", points)
    warm = opened(make_preconditioner("islands", inst.qp), replace(ctx, p0=np.zeros(inst.qp.n)), auto_kind=True)
    assert isinstance(warm, IslandPreconditioner) and not warm.far_field


def test_a_warm_solve_builds_its_far_field_on_sets_of_the_opened_fraction():
    """Warm-started (its first steps held on its contact set), the island blocks take their far
    field on sets of up to ``OPENED_FAR_FRACTION``, as an opened solve's; a cold unopened
    solve keeps ``MAX_SET_FRACTION``."""
    inst = build()
    ctx = context_of(inst.qp)
    cold = opened(make_preconditioner("farfield", inst.qp), ctx)
    warm = opened(make_preconditioner("farfield", inst.qp), replace(ctx, p0=np.zeros(inst.qp.n)))
    assert isinstance(cold, IslandPreconditioner) and cold.far_fraction == MAX_SET_FRACTION
    assert isinstance(warm, IslandPreconditioner) and warm.far_fraction == OPENED_FAR_FRACTION
    assert OPENED_FAR_FRACTION > MAX_SET_FRACTION


def test_an_unknown_opening_is_a_parameter_error():
    with pytest.raises(ParamError, match="opening"):
        solve(build(17), opening="sometimes")
