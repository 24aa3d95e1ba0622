"""ASPHER as registered solvers (solvers/peer_aspher.py): unavailable with the install hint
when the package is missing; what it cannot pose skipped with the reason; and, where it is
installed, each configuration's answer on a 32^2 load-controlled case (non-periodic Love,
periodic 2/(E*|q|)) judged by our judge on our operator and compared with our exact
reference (the certified dense solve of problems.mixed_lcp)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.harness.run.worker import problem_traits
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.scenes.battery_families import rectangular_instance
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.solvers import ProblemTraits, SolverSettings, WarmStart, get_solver
from contactbench.solvers import _peers
from contactbench.solvers.peer_aspher import ACTIVE_F32_FLOOR, EXACT_LOAD_MAX_N, coarsest_level

#: The configurations that reach our tolerance, and the single-precision active-set path.
EXACT = ("aspher-pcg", "aspher-nested", "aspher-nested-f32")
ASPHER = (*EXACT, "aspher-active-f32")
OK, WHY = get_solver("aspher-pcg").availability()
needs_aspher = pytest.mark.skipif(not OK, reason=WHY)
CHECK_TOL = 1e-8
P_TOL = 1e-8
#: The load of the 32^2 cases, P / (E* A).
LOAD_OVER_EA = 0.02


@pytest.mark.parametrize("name", ASPHER)
def test_missing_package_is_unavailable_with_the_install_hint(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    real = importlib.import_module

    def no_aspher(mod: str, *a: object, **k: object) -> object:
        if mod.split(".")[0] == "aspher":
            raise ImportError(f"No module named {mod!r}")
        return real(mod, *a, **k)

    monkeypatch.setattr(_peers.importlib, "import_module", no_aspher)
    ok, why = get_solver(name).availability()
    assert not ok
    assert why.startswith("not installed: pip install contactbench[peers]") and "aspher" in why
    assert "libeigen3-dev" in why


def _traits(**kw: object) -> ProblemTraits:
    base = dict(n=1024, operator="fft", kernel="love", periodic=False, load_control=True)
    return ProblemTraits(**{**base, **kw})  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ASPHER)
def test_what_it_poses_runs_and_the_rest_is_skipped_with_the_reason(name: str) -> None:
    s = get_solver(name)
    assert s.capabilities.load_control and not s.capabilities.bounds
    assert s.skip(_traits()) is None
    periodic = s.skip(_traits(kernel="spectral", periodic=True))
    assert periodic is None if name in EXACT else "free-space" in periodic
    assert "non-periodic 'bcc'" in s.skip(_traits(kernel="bcc"))
    assert "periodic 'love'" in s.skip(_traits(kernel="love", periodic=True))
    assert s.skip(_traits(load_control=False)) is None  # translated: the exact answer's load
    assert "load control only" in s.skip(_traits(load_control=False, n=EXACT_LOAD_MAX_N + 1))
    assert "hardness" in s.skip(_traits(bounded=True))
    assert "layer" in s.skip(_traits(layer=True))
    assert "rectangular" in s.skip(_traits(rectangular=True))  # a rectangular grid or pixels


def test_the_nested_levels_halve_down_to_the_coarsest() -> None:
    assert coarsest_level(4096) == 64 and coarsest_level(64) == 32 and coarsest_level(32) == 16
    assert coarsest_level(96) == 48 and coarsest_level(200) == 50 and coarsest_level(75) == 75
    assert coarsest_level(12) == 12


def _builder(periodic: bool, N: int = 32) -> InstanceBuilder:
    surf = rmd_surface_n(N, 0.7, "periodic" if periodic else "saupe", length=100e-6, seed=55)
    return InstanceBuilder(surf, 1e9, "spectral" if periodic else "love", periodic=periodic, operator="dense")


@pytest.fixture(scope="module", params=[False, True], ids=["love-nonperiodic", "spectral-periodic"])
def loaded(request: pytest.FixtureRequest):
    """A 32^2 load-controlled case (P / (E* A) = LOAD_OVER_EA, a partial contact) and its
    exact answer (p, Delta)."""
    b = _builder(request.param)
    inst = b.build_load(b.load_force(LOAD_OVER_EA))
    ref = constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints)
    assert 0.02 < inst.contact_fraction(ref.p) < 0.5  # a partial contact
    return inst, ref.p, ref.multiplier


@needs_aspher
@pytest.mark.parametrize("name", EXACT)
def test_its_answer_passes_our_judge_and_is_our_exact_answer(loaded, name: str) -> None:
    inst, p_ref, delta_ref = loaded
    res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10))
    v = judge(inst, res.p, res.converged, CHECK_TOL, p_ref=p_ref, p_tol=P_TOL)
    assert v.status == "solved" and v.reading == "pass", (v.kkt_error, v.problems, res.message)
    assert np.max(np.abs(res.p - p_ref)) <= P_TOL * np.max(p_ref)
    assert res.multiplier == pytest.approx(delta_ref, rel=1e-8, abs=1e-8 * np.max(np.abs(inst.qp.ubar)))
    assert res.info["threads"] >= 1 and res.info["peer_status"] == "converged"
    assert res.info["fw_error"] <= 1e-10 and res.matvecs > 0  # its claim, recorded


@needs_aspher
def test_its_single_precision_path_stops_at_its_floor_and_says_so(loaded) -> None:
    """Handed tol 1e-10, its float path stops at its float floor: not a claim of
    convergence, and our judge finds it within the promised floor."""
    inst, p_ref, _ = loaded
    if inst.periodic:
        pytest.skip("aspher-active-f32 is non-periodic only")
    res = get_solver("aspher-active-f32").solve(inst.qp, SolverSettings(tol=1e-10))
    v = judge(inst, res.p, res.converged, ACTIVE_F32_FLOOR)
    assert v.reading == "pass", (v.kkt_error, res.message)
    assert res.info["precision"] == "float" and res.info["active_set"] and res.info["backend"] == "h2"
    assert res.converged == (v.kkt_error <= CHECK_TOL) and res.converged == (res.status == "converged")


@needs_aspher
def test_a_warm_start_is_handed_to_its_cg(loaded) -> None:
    inst, p_ref, _ = loaded
    s = get_solver("aspher-pcg")
    cold = s.solve(inst.qp, SolverSettings(tol=1e-10))
    warm = s.solve(inst.qp, SolverSettings(tol=1e-10), WarmStart(p=p_ref))
    assert warm.warm_started and warm.iterations < cold.iterations


@needs_aspher
@pytest.mark.parametrize("name", EXACT)
def test_displacement_control_is_handed_the_exact_answers_load_and_says_so(name: str) -> None:
    b = _builder(False)
    inst = b.build(0.5 * paper_max_displacement(b.surface))
    res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10))
    v = judge(inst, res.p, res.converged, CHECK_TOL)
    assert v.reading == "pass", (v.kkt_error, res.message)
    assert res.info["posing"].startswith("load control at the load of the exact answer")
    assert res.info["load"] == pytest.approx(float(np.sum(res.p)), rel=1e-8)
    assert abs(res.info["approach_m"]) <= 1e-8 * float(np.max(inst.qp.ubar))  # the QP's own approach


@needs_aspher
@pytest.mark.parametrize("name", ASPHER)
def test_a_problem_it_does_not_pose_is_refused_before_solving(name: str) -> None:
    b = _builder(False)
    bcc = InstanceBuilder(b.surface, 1e9, "bcc", periodic=False).build_load(1e-3)
    with pytest.raises(ProblemInputError, match="'bcc'"):
        get_solver(name).solve(bcc.qp)
    with pytest.raises(ProblemInputError, match="hardness"):
        get_solver(name).solve(b.build_load(1e-3, hardness=1e7).qp)
    s = b.surface
    for rect in (Surface(s.heights[:, :16].copy(), s.delta), Surface(s.heights.copy(), s.delta, delta1=2 * s.delta)):
        with pytest.raises(ProblemInputError, match="N x N grid of square elements"):
            get_solver(name).solve(InstanceBuilder(rect, 1e9, "love", periodic=False).build_load(1e-3).qp)


@pytest.mark.parametrize("case, rectangular", [("love-aniso", True), ("bcc-square-pixels", True)])
def test_the_workers_traits_say_when_a_grid_or_its_pixels_are_rectangular(case: str, rectangular: bool) -> None:
    """The traits the skip policy reads (``harness.run.worker.problem_traits``): the
    battery's 48 x 32 grids, anisotropic pixels or not, are rectangular; a square one is not."""
    assert problem_traits(rectangular_instance(case, 0)).rectangular is rectangular
    square = InstanceBuilder(rmd_surface_n(33, 0.7, seed=1), 1e9, "love", periodic=False).build_load(1e-3)
    assert not problem_traits(square).rectangular


def test_the_active_set_skips_a_side_it_cannot_halve_with_the_reason() -> None:
    """A 33^2 load-controlled Love step was a failed row ("active_set needs a coarse level")."""
    solver = get_solver("aspher-active-f32")
    odd = ProblemTraits(n=500, operator="fft", kernel="love", periodic=False, load_control=True, surface_side=33)
    why = solver.skip(odd)
    assert why is not None and "cannot be halved" in why
    even = ProblemTraits(n=500, operator="fft", kernel="love", periodic=False, load_control=True, surface_side=32)
    assert solver.skip(even) is None or "cannot be halved" not in str(solver.skip(even))
