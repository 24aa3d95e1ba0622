"""Generic QP adapters (qpsolvers backends, cvxpy, scipy-nnls reference): accuracy at the
``high`` profile against the reference, equilibration, raw mode, missing packages,
capabilities, the memory model that skips 512^2 instances, and the solve lifecycle
(statuses, declared parameters, backend defaults, build vs solve time)."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.kkt import kkt_check, relative_error, relative_load_error
from contactbench.problems.instances import ContactInstance, InstanceBuilder, counterexample, paper_max_displacement, trial_set
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET, DenseOperator
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _scaling
from contactbench.solvers.base import ParamError, SolverSettings, Status, WarmStart
from contactbench.solvers.qp_backends import BackendSpec, QPSolversAdapter, no_options
from contactbench.solvers.registry import all_solvers, get_solver

ADAPTERS = sorted(n for n, s in all_solvers().items() if n.startswith("qp-") or n == "cvxpy")
COUNTEREXAMPLE_SEEDS = (0, 1, 2, 3, 4)


def _instances() -> dict[str, ContactInstance]:
    surf = rmd_surface_n(32, 0.7, seed=1)
    out = {"rmd32": InstanceBuilder(surf, 1e9, operator="dense").build(paper_max_displacement(surf))}
    for seed in COUNTEREXAMPLE_SEEDS:
        out[f"counterexample-{seed}"] = counterexample(100, seed)
    return out


@pytest.fixture(scope="module")
def cases() -> dict[str, tuple[ContactInstance, np.ndarray]]:
    ref = get_solver("scipy-nnls")
    out = {}
    for key, inst in _instances().items():
        res = ref.solve(inst.qp, SolverSettings(1e-9))
        out[key] = (inst, res.p)
    return out


def _require(name: str) -> None:
    ok, why = get_solver(name).availability()
    if not ok:
        pytest.skip(f"{name}: {why}")


def test_reference_is_exact(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    for key, (inst, p) in cases.items():
        assert kkt_check(inst, p).kkt_error < 1e-12, key
        assert np.count_nonzero(p > 0) > 0, key


@pytest.mark.parametrize("name", ADAPTERS)
def test_high_profile_agrees_with_reference(name: str, cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require(name)
    solver = get_solver(name)
    # a backend that cannot reach the high profile says so (ECOS); it is held to its floor
    floor = getattr(solver, "accuracy_floor", None) or 1e-8
    for key, (inst, p_ref) in cases.items():
        res = solver.solve(inst.qp, SolverSettings(1e-9))
        rep = kkt_check(inst, res.p)
        assert rep.kkt_error <= floor, f"{name} on {key}: kkt {rep.kkt_error:.2e}, status {res.status}"
        assert relative_error(res.p, p_ref) <= 100 * floor, f"{name} on {key}"
        assert relative_load_error(inst.load(res.p), inst.load(p_ref)) <= floor, f"{name} on {key}"
        assert res.status == Status.CONVERGED.value and res.converged, f"{name} on {key}"
        assert res.info["backend_status"] and res.info["backend_status"] != res.status
        # build (assembly, scaling, conversion, CVXPY's compilation) is setup, inside solve time
        assert 0.0 < res.info["build_time"] <= res.setup_time <= res.solve_time


def test_equilibration_gives_order_one_problem() -> None:
    rng = np.random.default_rng(3)
    M = rng.random((6, 6))
    H = 4e-6 * (M @ M.T + 6 * np.eye(6))
    ubar = 1e-6 * rng.random(6)
    eq = _scaling.equilibration_for(np.diag(H), ubar)
    Hs, us = eq.scale_matrix(H), eq.scale_rhs(ubar)
    np.testing.assert_allclose(np.diag(Hs), 1.0)
    assert np.max(np.abs(us)) == pytest.approx(1.0)
    p = rng.random(6)
    np.testing.assert_allclose(eq.to_original(eq.to_scaled(p)), p)
    # objective divided by s^2, gap mapped back exactly
    ps = eq.to_scaled(p)
    obj = 0.5 * p @ H @ p - ubar @ p
    obj_s = 0.5 * ps @ Hs @ ps - us @ ps
    assert obj_s * eq.s**2 == pytest.approx(obj, rel=1e-12)
    np.testing.assert_allclose(eq.gap_to_original(Hs @ ps - us), H @ p - ubar, rtol=1e-12, atol=1e-20)
    raw = _scaling.equilibration_for(np.diag(H), ubar, enabled=False)
    assert raw.scale_matrix(H) is H and raw.s == 1.0


def test_shared_dense_matrix_is_not_copied(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    inst, _ = cases["rmd32"]
    assert isinstance(inst.qp.H, DenseOperator)
    assert _scaling.dense_matrix(inst.qp) is inst.qp.H.H


def test_raw_mode_can_be_selected(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-osqp")
    inst, p_ref = cases["rmd32"]
    solver = get_solver("qp-osqp")
    raw = solver.solve(inst.qp, SolverSettings(None, params={"scaling": False}))
    scaled = solver.solve(inst.qp, SolverSettings(None))
    assert raw.info["scaling"] == "raw" and raw.info["scale_s"] == 1.0
    assert scaled.info["scaling"] == "jacobi+rhs"
    # the documented hazard: OSQP's defaults on SI-unit data stop far from the answer
    assert kkt_check(inst, raw.p).kkt_error > 1e3 * kkt_check(inst, scaled.p).kkt_error


def test_missing_backend_gives_clear_message(tmp_path, monkeypatch) -> None:
    missing = QPSolversAdapter(BackendSpec("nosuchqp", "contactbench_no_such_pkg", "none", "dense", "none",
                                           no_options, 4.0, 1e-9))
    ok, why = missing.availability()
    assert not ok and "not installed" in why and "contactbench_no_such_pkg" in why
    inst = counterexample(4, 0)
    with pytest.raises(RuntimeError, match="not installed"):
        missing.solve(inst.qp, SolverSettings(1e-9))
    (tmp_path / "contactbench_broken_pkg.py").write_text("import contactbench_absent_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    broken = QPSolversAdapter(BackendSpec("brokenqp", "contactbench_broken_pkg", "none", "dense", "none",
                                          no_options, 4.0, 1e-9))
    ok, why = broken.availability()
    assert not ok and why.startswith("failed to import")


def test_every_adapter_declares_capabilities() -> None:
    solvers = all_solvers()
    for name in ADAPTERS + ["scipy-nnls"]:
        cap = solvers[name].capabilities
        assert cap.needs_dense and cap.input_format in ("dense", "sparse"), name
    assert solvers["scipy-nnls"].capabilities.exact
    assert solvers["qp-osqp"].capabilities.warm_start == "primal"
    assert solvers["qp-proxqp"].capabilities.warm_start == "primal"
    assert solvers["qp-clarabel"].capabilities.warm_start == "none"
    assert solvers["qp-piqp"].capabilities.warm_start == "none"
    assert solvers["qp-piqp"].capabilities.input_format == "dense"
    assert solvers["qp-osqp"].capabilities.input_format == "sparse"


def test_memory_model_skips_512_top_step() -> None:
    surf = rmd_surface_n(512, 0.7, seed=2)
    n = int(trial_set(surf.heights, paper_max_displacement(surf)).size)
    assert n > 15_000
    for name in ADAPTERS + ["scipy-nnls"]:
        solver = get_solver(name)
        assert solver.memory_estimate(n) > DEFAULT_MEMORY_BUDGET, name
        assert solver.memory_estimate(33) < DEFAULT_MEMORY_BUDGET, name
        assert solver.time_estimate(n, "fft") > solver.time_estimate(33, "fft"), name


def test_polish_is_a_separate_labelled_variant(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-clarabel")
    inst, p_ref = cases["counterexample-0"]
    plain = get_solver("qp-clarabel").solve(inst.qp, SolverSettings(None))
    pol = get_solver("qp-clarabel+polish").solve(inst.qp, SolverSettings(None))
    assert "polish_rounds" not in plain.info and pol.info["polish_converged"]
    assert kkt_check(inst, pol.p).kkt_error < 1e-12
    assert kkt_check(inst, pol.p).kkt_error <= kkt_check(inst, plain.p).kkt_error


def test_polish_variant_repairs_a_cut_short_backend(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-clarabel")
    inst, p_ref = cases["counterexample-1"]
    short = SolverSettings(1e-9, max_iter=2)  # two interior-point steps: far from the answer
    plain = get_solver("qp-clarabel").solve(inst.qp, short)
    pol = get_solver("qp-clarabel+polish").solve(inst.qp, short)
    assert plain.status == pol.status == Status.MAX_ITER.value and not pol.converged
    assert kkt_check(inst, plain.p).kkt_error > 1e-3
    assert pol.info["polish_converged"] and pol.info["polish_rounds"] > 1  # the guessed set was repaired
    assert kkt_check(inst, pol.p).kkt_error < 1e-12
    assert relative_error(pol.p, p_ref) < 1e-10


def test_warm_start_is_forwarded_where_supported(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-osqp")
    inst, p_ref = cases["counterexample-2"]
    res = get_solver("qp-osqp").solve(inst.qp, SolverSettings(1e-6), WarmStart(p=p_ref))
    assert res.warm_started
    if get_solver("qp-clarabel").availability()[0]:
        res = get_solver("qp-clarabel").solve(inst.qp, SolverSettings(1e-6), WarmStart(p=p_ref))
        assert not res.warm_started


def test_backend_limits_and_failures_map_to_the_status_enum(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    inst, _ = cases["counterexample-0"]
    _require("qp-osqp")
    res = get_solver("qp-osqp").solve(inst.qp, SolverSettings(1e-9, max_iter=5))
    assert res.status == Status.MAX_ITER.value and not res.converged
    assert "iterations" in res.info["backend_status"] and res.info["options"]["max_iter"] == 5
    res = get_solver("scipy-nnls").solve(inst.qp, SolverSettings(max_iter=2))  # Lawson-Hanson cut short: its start
    assert res.status == Status.MAX_ITER.value and not res.converged
    assert res.info["backend_status"].startswith("iteration limit") and np.array_equal(res.p, np.zeros(inst.n))


def test_no_tolerance_means_the_backends_own_defaults(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-osqp")
    inst, _ = cases["counterexample-0"]
    solver = get_solver("qp-osqp")
    assert solver.default_tol is None
    assert solver.solve(inst.qp, SolverSettings(None)).info["options"] == {}  # nothing set, no limit of ours
    asked = solver.solve(inst.qp, SolverSettings(1e-6, time_limit=30.0)).info["options"]
    assert asked["eps_abs"] == 1e-6 and asked["eps_rel"] == 0.0 and 0.0 < asked["time_limit"] <= 30.0


def test_parameters_are_declared_and_checked(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    inst, _ = cases["counterexample-0"]
    for name in ADAPTERS + ["scipy-nnls"]:
        declared = {p.name for p in get_solver(name).params}
        assert "scaling" in declared, name
    assert {p.name for p in get_solver("scipy-nnls").params} == {"scaling"}
    assert {p.name for p in get_solver("cvxpy").params} == {"scaling", "solver", "form", "backend_options"}
    with pytest.raises(ParamError, match="allowed: backend_options, input_format, scaling"):
        get_solver("qp-osqp").solve(inst.qp, SolverSettings(params={"scalling": False}))
    with pytest.raises(ParamError, match="input_format"):
        get_solver("qp-osqp").solve(inst.qp, SolverSettings(params={"input_format": "csr"}))
    with pytest.raises(ParamError, match="form"):
        get_solver("cvxpy").solve(inst.qp, SolverSettings(params={"form": "qaud_form"}))
    with pytest.raises(ParamError, match="scaling"):
        get_solver("scipy-nnls").solve(inst.qp, SolverSettings(params={"scaling": "no"}))


def test_input_format_parameter_reaches_the_backend(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    _require("qp-osqp")
    inst, p_ref = cases["counterexample-3"]
    solver = get_solver("qp-osqp")
    assert solver.solve(inst.qp, SolverSettings(1e-9)).info["input_format"] == "sparse"
    dense = solver.solve(inst.qp, SolverSettings(1e-9, params={"input_format": "dense"}))
    assert dense.info["input_format"] == "dense" and dense.converged
    assert relative_error(dense.p, p_ref) < 1e-6


@pytest.mark.parametrize("name", ADAPTERS)
def test_the_default_profile_derives_the_backends_tolerances_from_its_check(
        name: str, cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    """Under a profile that asks no tolerance (``default``) a backend is handed the
    profile's check, so what it claims meets the check; a claim it cannot back is not made."""
    from contactbench.harness.profiles import get_profile

    _require(name)
    profile = get_profile("default")
    assert profile.tol is None  # the premise: no tolerance asked, only the check
    for key in ("rmd32", "counterexample-1"):
        inst, _ = cases[key]
        res = get_solver(name).solve(inst.qp, profile.solver_settings(30.0))
        kkt = kkt_check(inst, res.p).kkt_error
        assert not res.converged or kkt <= profile.check_tol, (name, key, kkt, res.message)
        assert res.converged or res.status == Status.STALLED.value or "limit" in res.status, (name, key, res.status)


def test_a_claim_above_the_check_is_withdrawn(cases: dict[str, tuple[ContactInstance, np.ndarray]]) -> None:
    """OSQP cut loose (eps 1e-2, no polishing) says "solved"; with a check of 1e-8 the
    adapter does not claim it (stalled, the backend's word kept); without a check it does."""
    _require("qp-osqp")
    inst, _ = cases["rmd32"]
    loose = {"backend_options": {"eps_abs": 1e-2, "eps_rel": 1e-2, "polishing": False}}
    solver = get_solver("qp-osqp")
    free = solver.solve(inst.qp, SolverSettings(1e-2, params=loose))
    assert free.converged and kkt_check(inst, free.p).kkt_error > 1e-8  # the premise: a loose claim
    checked = solver.solve(inst.qp, SolverSettings(1e-2, params=loose, check_tol=1e-8))
    assert not checked.converged and checked.status == Status.STALLED.value
    assert checked.info["backend_status"] == free.info["backend_status"]
    assert checked.info["claim_kkt"] > 1e-8 and "not claimed" in checked.message
    np.testing.assert_allclose(checked.p, free.p)


def test_ecos_options_follow_the_requested_tolerance() -> None:
    from contactbench.solvers.qp_backends import ECOS_TIGHTEST, ecos_options
    from contactbench.solvers._scaling import Request

    assert ecos_options(Request(None, None, None)) == {}
    tols = [ecos_options(Request(t, None, None))["abstol"] for t in (1e-2, 1e-3, 1e-6, 1e-9)]
    assert tols == sorted(tols, reverse=True) and tols[-1] == ECOS_TIGHTEST and tols[0] <= 1e-8


def test_a_profile_tighter_than_a_declared_floor_is_skipped_with_the_reason() -> None:
    """ECOS declares a floor of 1e-7: the default profile's check (1e-6) is within reach,
    the high profile's (1e-8) is not, and the reason names both numbers."""
    from contactbench.harness.profiles import get_profile

    _require("qp-ecos")
    ecos = get_solver("qp-ecos")
    assert ecos.capabilities.accuracy_floor == 1e-7
    assert get_profile("default").floor_skip(ecos) is None
    why = get_profile("high").floor_skip(ecos)
    assert why is not None and "1e-07" in why and "1e-08" in why
    assert get_profile("high").floor_skip(get_solver("qp-clarabel")) is None  # no floor declared
