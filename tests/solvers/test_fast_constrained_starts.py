"""The fast CCGs' starts under a hardness and load control: the coarse grids' first guess
("auto" for a cold load; the same answer as from zero, within the box; none where the coarse
grid cannot pose the problem), the preconditioner "auto" takes, the load projection with
nothing to scale, and a load one summit would carry alone under a box."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.constraints import Constraints, make_constraints
from contactbench.problems.instances import QP, InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.surfaces import Surface, fourier_synthesis, rmd_surface_n
from contactbench.solvers.base import SolverSettings, WarmStart
from contactbench.solvers import fast_ccg
from contactbench.solvers.registry import get_solver

E = 1e9
TIGHT = SolverSettings(tol=1e-12)


def test_auto_first_guess_is_coarse_for_a_cold_load() -> None:
    """``resolved_first_guess``: "auto" is the coarse grids' answer only for a cold solve
    under load control, with or without a box; a choice made by name stays."""
    from contactbench.solvers._kit import resolved_first_guess

    def ctx(constraints, p0=None):
        return SimpleNamespace(constraints=constraints, p0=p0)

    load, box = make_constraints(4, None, 1.0), make_constraints(4, np.ones(4), 1.0)
    assert resolved_first_guess("auto", ctx(load)) == "coarse"
    assert resolved_first_guess("auto", ctx(load, np.ones(4))) == "zero"
    assert resolved_first_guess("auto", ctx(box)) == "coarse"
    assert resolved_first_guess("auto", ctx(box, np.ones(4))) == "zero"
    assert resolved_first_guess("auto", ctx(make_constraints(4, np.ones(4)))) == "zero"
    assert resolved_first_guess("auto", ctx(Constraints())) == "zero"
    assert resolved_first_guess("zero", ctx(load)) == "zero" and resolved_first_guess("coarse", ctx(box)) == "coarse"


@pytest.mark.parametrize("periodic", [False, True])
def test_a_load_controlled_solve_from_the_coarse_grid_gives_the_same_answer(periodic: bool) -> None:
    """A cold load-controlled 256^2 solve started from the 128^2 grid's answer at the same
    force (``first_guess`` auto) meets the tolerance, the judge and the load, and gives the
    answer of a cold start from zero, with fewer products on the fine grid."""
    s = fourier_synthesis(256, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    builder = InstanceBuilder(s, E, periodic=periodic)
    inst = builder.build_load(builder.load_force(0.005))
    runs = {guess: get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"first_guess": guess}))
            for guess in ("zero", "auto")}
    zero, auto = runs["zero"], runs["auto"]
    assert zero.converged and auto.converged
    assert auto.info["first_guess"].startswith("coarse 128^2") and auto.info["coarse_matvecs"] > 0
    assert "first_guess" not in zero.info
    assert np.max(np.abs(auto.p - zero.p)) <= 1e-6 * np.max(zero.p)
    assert abs(float(np.sum(auto.p)) - float(inst.qp.constraints.load)) <= 1e-12 * float(inst.qp.constraints.load)
    assert judge(inst, auto.p, True, 1e-8).status == "solved"
    assert auto.matvecs - auto.info["coarse_matvecs"] < zero.matvecs


@pytest.mark.parametrize("posing,periodic", [("load", False), ("load", True), ("displacement", False)])
def test_a_plastic_solve_from_the_coarse_grid_under_the_same_hardness_gives_the_same_answer(posing: str,
                                                                                           periodic: bool,
                                                                                           monkeypatch) -> None:
    """A cold 256^2 solve with a hardness (under load control, where "auto" takes it, and at
    a displacement, named) from the 128^2 grid's answer under the same hardness: the answer
    of a cold start from zero, within the box, judged solved, a plastic share; under load
    control with fewer products on the fine grid (at a displacement it saves none here,
    which is why "auto" does not take it there)."""
    s = fourier_synthesis(256, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    builder = InstanceBuilder(s, E, periodic=periodic)
    if posing == "load":
        inst = builder.build_load(builder.load_force(0.005), hardness=3.0 * 0.005 * E)
    else:
        inst = builder.build(paper_max_displacement(s), hardness=0.05 * E)
    guess = "auto" if posing == "load" else "coarse"
    guesses = []
    real = fast_ccg.coarse_first_guess

    def spy(solver, ctx):
        out = real(solver, ctx)
        guesses.append(None if out.p is None else out.p.copy())  # the solve moves p in place
        return out

    monkeypatch.setattr(fast_ccg, "coarse_first_guess", spy)
    runs = {g: get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"first_guess": g}))
            for g in ("zero", guess)}
    u = inst.qp.constraints.upper
    # the coarse grids posed the same hardness: the prolonged guess keeps under the fine
    # bounds and reaches them on the coarse plastic points
    (first,) = [p for p in guesses if p is not None and p.size == inst.qp.n]
    assert np.all(first <= u * (1.0 + 1e-12)) and np.mean(first >= u * (1.0 - 1e-12)) > 0.01
    zero, coarse = runs["zero"], runs[guess]
    assert zero.converged and coarse.converged
    assert coarse.info["first_guess"].startswith("coarse 128^2") and coarse.info["coarse_matvecs"] > 0
    assert np.all(coarse.p <= u) and inst.plastic_fraction(coarse.p) > 0.2
    # two answers at a KKT error of 1e-9: on the periodic kernel p differs by 2e-6 of its largest
    assert np.max(np.abs(coarse.p - zero.p)) <= 1e-5 * np.max(zero.p)
    assert judge(inst, coarse.p, True, 1e-8).status == "solved"
    if posing == "load":
        assert coarse.matvecs - coarse.info["coarse_matvecs"] < zero.matvecs


def test_a_box_no_single_hardness_poses_gives_no_coarse_guess() -> None:
    """Bounds that differ from point to point (not ``hardness_bounds``): the coarse grid
    cannot pose them, so the solve starts from zero and says why, and still meets."""
    s = fourier_synthesis(256, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    builder = InstanceBuilder(s, E)
    inst = builder.build_load(builder.load_force(0.005), hardness=3.0 * 0.005 * E)
    qp = inst.qp
    upper = qp.constraints.upper * np.linspace(1.0, 1.5, qp.n)
    odd = replace(qp, constraints=make_constraints(qp.n, upper, qp.constraints.load))
    r = get_solver("fast-dual-pccg").solve(odd, SolverSettings(tol=1e-9))
    assert r.converged and r.info["first_guess"] == "no coarse level (the box is not one hardness)"
    assert np.all(r.p <= upper) and abs(float(np.sum(r.p)) - qp.constraints.load) <= 1e-9 * qp.constraints.load


def test_the_coarse_guess_under_a_hardness_on_rectangular_pixels_keeps_under_the_bounds(monkeypatch) -> None:
    """Pixels of 1.5:1 (``delta1``): the hardness read back from the fine bounds
    (u / (d0 d1)) and posed on the coarse level's larger elements gives a prolonged guess
    within the fine box and plastic where the coarse answer is; the solve meets."""
    base = fourier_synthesis(256, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    s = Surface(base.heights, base.delta, delta1=1.5 * base.delta)
    builder = InstanceBuilder(s, E, "love")
    load = builder.load_force(0.005)
    inst = builder.build_load(load, hardness=2.0 * load / s.area)
    guesses = []
    real = fast_ccg.coarse_first_guess

    def spy(solver, ctx):
        out = real(solver, ctx)
        guesses.append(None if out.p is None else out.p.copy())
        return out

    monkeypatch.setattr(fast_ccg, "coarse_first_guess", spy)
    r = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9))
    u = inst.qp.constraints.upper
    (first,) = [p for p in guesses if p is not None and p.size == inst.qp.n]
    assert np.all(first <= u * (1.0 + 1e-12)) and np.mean(first >= u * (1.0 - 1e-12)) > 0.01
    assert r.converged and r.info["first_guess"].startswith("coarse 128^2") and np.all(r.p <= u)
    assert judge(inst, r.p, True, 1e-8).status == "solved"


def test_the_solve_reports_the_preconditioner_auto_took() -> None:
    """``info["preconditioner"]``: the kind "auto" resolved to -- the wave numbers for a
    cold load step, and for a warm one with a hardness (results/perf/load-hardness) or with
    more than ``WARM_LOAD_MAX_CONTACT`` of it in contact; the islands for a warm one below
    that without a hardness (results/perf/warm-load) and at a displacement."""
    from contactbench.solvers._preconditioners import WARM_LOAD_MAX_CONTACT

    s = fourier_synthesis(64, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    builder = InstanceBuilder(s, E)
    solver = get_solver("fast-dual-pccg")
    load = builder.load_force(0.005)
    for h in (None, 1.5 * load / s.area):
        first, second = (builder.build_load(f * load, hardness=h) for f in (0.9, 1.0))
        cold = solver.solve(first.qp, SolverSettings(tol=1e-9))
        warm = solver.solve(second.qp, SolverSettings(tol=1e-9), WarmStart(p=cold.p))
        assert cold.converged and warm.converged
        few = float(np.mean(cold.p > 0.0)) <= WARM_LOAD_MAX_CONTACT
        assert cold.info["preconditioner"] == "fourier"
        assert warm.info["preconditioner"] == ("islands" if h is None and few else "fourier"), (h, few)
        assert judge(second, warm.p, True, 1e-8).status == "solved"
    disp = solver.solve(builder.build(paper_max_displacement(s)).qp, SolverSettings(tol=1e-9))
    assert disp.info["preconditioner"] == "islands"


def test_a_coarse_box_that_cannot_carry_the_load_gives_no_guess() -> None:
    """An odd grid loses its last row and column on the coarse level, so under a hardness
    that barely carries the load (sum(u) = 1.001 P) the coarse box could not carry it:
    no guess, and the fine solve still meets, inside its box and at its load."""
    base = fourier_synthesis(258, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    s = Surface(base.heights[:257, :257], base.delta)
    builder = InstanceBuilder(s, E)
    load = builder.load_force(0.005)
    inst = builder.build_load(load, hardness=1.001 * load / s.area)
    r = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9))
    assert r.info["first_guess"].startswith("no coarse level (its box cannot carry the load")
    assert r.converged and np.all(r.p <= inst.qp.constraints.upper)
    assert abs(float(np.sum(r.p)) - load) <= 1e-9 * load
    assert judge(inst, r.p, True, 1e-8).status == "solved"


def test_a_projection_with_nothing_to_scale_leaves_the_load_to_the_box_projection() -> None:
    """``_project_raised`` on a p that carries no positive total (only a non-finite step
    gets there) clips it and says so, so the caller places the load (``_project``)."""
    from contactbench.solvers._ccg import GapState
    from contactbench.solvers._constrained import _project_raised

    s = fourier_synthesis(32, 0.7, rms_slope=0.3, length=1e-4, seed=5)
    qp = InstanceBuilder(s, E).build_load(1.0).qp
    state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    state.p[:] = -1e-9
    assert _project_raised(state, 1.0) is False and np.all(state.p >= 0.0)
    state.p[:] = np.nan
    assert _project_raised(state, 1.0) is False
    state.p[:] = 0.0
    state.p[3] = 2.0
    state.refresh()
    assert _project_raised(state, 1.0) is True and np.isclose(np.sum(state.p), 1.0, rtol=1e-14)


@pytest.mark.parametrize("name, precondition", [("fast-ccg", "islands"), ("fast-pccg", "farfield"),
                                                ("fast-pccg", "fourier")])
def test_a_load_on_one_summit_under_a_box_finds_its_contact_set(name: str, precondition: str) -> None:
    """One summit would carry the load alone; the box makes a few share it.  From the summits'
    start one step leaves a single point inside the box, the rest at 0 or u: a direction that
    keeps the load cannot move one point's force, and the Polonsky-Keer loop stopped "stalled"
    at a KKT error of 0.5-0.8 (the undecided points, 2,077, too many for the exact finish).
    Its CG set then takes every point that wants to move, as when no point is inside."""
    s = rmd_surface_n(64, 0.5, length=1e-4, seed=78)
    b = InstanceBuilder(s, E, "bcc", periodic=False)
    one = get_solver("fast-dual-pccg").solve(b.build(0.05 * paper_max_displacement(s)).qp, TIGHT)
    assert np.count_nonzero(one.p) == 1
    load = float(np.sum(one.p))
    inst = b.build_load(load)
    qp = QP(inst.qp.H, inst.qp.ubar, inst.qp.geometry, make_constraints(inst.n, np.full(inst.n, 0.9 * load), load))
    r = get_solver(name).solve(qp, SolverSettings(tol=1e-9, params={"precondition": precondition, "screening": "none"}))
    assert r.converged, r.message
    assert judge(replace(inst, qp=qp), r.p, True, 2e-9).status == "solved"
    assert np.count_nonzero(r.p) >= 2 and np.max(r.p) <= 0.9 * load


def test_a_layer_thinner_than_the_coarse_spacing_gives_no_coarse_guess() -> None:
    """A layer between one and two fine spacings thick: the 2x-coarser grid cannot pose
    its 'love' kernel (T >= the spacing), and the default solve under a load raised that
    as an error.  It starts from zero, says why, and meets."""
    from contactbench.problems.layers import Layer

    s = fourier_synthesis(256, 0.7, rms_slope=0.3, length=1e-4, seed=8)
    builder = InstanceBuilder(s, E, "love", layer=Layer(1.5 * s.delta, 0.3))
    inst = builder.build_load(builder.load_force(0.005))
    r = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9))
    assert r.converged and r.info["first_guess"] == "no coarse level (the layer is thinner than its spacing)"
    assert kkt_check(inst, r.p, r.multiplier).kkt_error <= 1e-8
