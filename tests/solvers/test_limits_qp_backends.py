"""Iteration limits of the generic QP adapters (solvers/qp_backends.py) and the load in
their equilibration (solvers/_scaling.py): a limit bounds what ProxQP runs and what it
reports; a limit of 0 is an honest outcome for every qp-* backend, never a count the
backend did not set; the scaled QP under load control stays order one whatever the
heights' scale."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.kkt import constrained_scales
from contactbench.problems.surfaces import Surface
from contactbench.solvers import _scaling, qp_backends
from contactbench.solvers._scaling import EquilibratedAdapter
from contactbench.solvers.base import SolverSettings, Status, WarmStart
from contactbench.solvers.qp_backends import _status_of, proxqp_options
from contactbench.solvers.registry import all_solvers, get_solver

E = 1e9
DX = 1e-6
QP_ADAPTERS = sorted(n for n in all_solvers() if n.startswith("qp-"))
#: Every adapter over an equilibrated backend: the QP backends, cvxpy and scipy's nnls.
EQUILIBRATED = sorted(n for n, s in all_solvers().items() if isinstance(s, EquilibratedAdapter))


def rough(n: int, scale: float = 1e-6, seed: int = 0) -> np.ndarray:
    return scale * np.random.default_rng(seed).standard_normal((n, n))


def builder(h: np.ndarray, periodic: bool = False) -> InstanceBuilder:
    return InstanceBuilder(Surface(h, DX, periodic=periodic), E, "spectral" if periodic else "bcc",
                           periodic=periodic, operator="fft")


def step(h: np.ndarray, periodic: bool = False) -> ContactInstance:
    return builder(h, periodic).build(0.3 * float(np.ptp(h)))


def loaded(h: np.ndarray, share: float = 1e-3) -> ContactInstance:
    b = builder(h)
    return b.build_load(b.load_force(share))


def require(name: str) -> None:
    ok, why = get_solver(name).availability()
    if not ok:
        pytest.skip(f"{name}: {why}")


# --- ProxQP: the limit bounds both loops, and the count is the outer one -------------


def test_proxqp_options_bound_both_loops() -> None:
    limited = proxqp_options(_scaling.Request(1e-6, 7, None))
    assert limited["max_iter"] == 7 and limited["max_iter_in"] == 7
    harness = proxqp_options(_scaling.Request(1e-6, None, None))  # the harness's call: a check, no limit
    limit = qp_backends.PROXQP_MAX_ITER
    assert harness["max_iter"] == limit and harness["max_iter_in"] == limit
    assert proxqp_options(_scaling.Request(None, None, None)) == {}  # the backend's own defaults


@pytest.mark.parametrize("limit", [1, 4])
def test_proxqp_reports_at_most_its_limit_and_runs_within_it(limit: int) -> None:
    require("qp-proxqp")
    inst = loaded(rough(8))
    # a tolerance no solve reaches: the limit alone ends it
    res = get_solver("qp-proxqp").solve(inst.qp, SolverSettings(1e-300, max_iter=limit))
    assert not res.converged and res.status == Status.MAX_ITER.value
    assert res.iterations <= limit
    assert res.info["options"]["max_iter_in"] == limit
    # ProxQP counts a capped inner loop as max_iter_in + 1 steps
    assert 0 < res.info["inner_iterations"] <= limit * (limit + 1)


@pytest.mark.parametrize("instance", [lambda: step(rough(8)), lambda: loaded(rough(8))], ids=["plain", "load"])
def test_daqp_at_its_limit_says_so_and_keeps_its_iterate(instance: object) -> None:
    """DAQP stopped by its iteration limit reports ``max_iter`` with the count it ran and
    its last (finite) iterate, which the judge reads -- not a NaN answer "failed"."""
    require("qp-daqp")
    inst = instance()  # type: ignore[operator]
    res = get_solver("qp-daqp").solve(inst.qp, SolverSettings(1e-9, max_iter=2))
    assert res.status == Status.MAX_ITER.value and not res.converged, res.message
    assert res.iterations == 2 and res.info["backend_status"] == "iteration limit"
    assert np.all(np.isfinite(res.p))
    full = get_solver("qp-daqp").solve(inst.qp, SolverSettings(1e-9))
    assert full.converged and full.status == Status.CONVERGED.value and full.iterations > 2
    assert judge(inst, full.p, True, 1e-8, multiplier=full.multiplier).status == "solved"


def test_proxqp_solves_with_the_harness_call_and_takes_a_warm_start() -> None:
    require("qp-proxqp")
    inst = step(rough(8))
    solver = get_solver("qp-proxqp")
    cold = solver.solve(inst.qp, SolverSettings(check_tol=1e-9))
    assert cold.converged and judge(inst, cold.p, cold.converged, 1e-9).status == "solved"
    assert cold.iterations <= cold.info["inner_iterations"]
    warm = solver.solve(inst.qp, SolverSettings(check_tol=1e-9), WarmStart(p=cold.p))
    assert warm.converged and warm.warm_started and warm.iterations <= cold.iterations


def test_proxqp_names_an_option_it_does_not_have() -> None:
    require("qp-proxqp")
    res = get_solver("qp-proxqp").solve(step(rough(6)).qp, SolverSettings(
        check_tol=1e-6, params={"backend_options": {"no_such_setting": 1}}))
    assert not res.converged and "no_such_setting" in res.info["backend_status"]


# --- a limit of 0, and counts a backend never set --------------------------------------


@pytest.mark.parametrize("name", EQUILIBRATED)
@pytest.mark.parametrize("periodic", [False, True])
def test_zero_limit_is_an_honest_outcome(name: str, periodic: bool) -> None:
    require(name)
    inst = step(rough(8), periodic)
    res = get_solver(name).solve(inst.qp, SolverSettings(max_iter=0, check_tol=1e-6))
    assert res.iterations == 0 and not res.converged
    assert res.status == Status.MAX_ITER.value and "max_iter 0" in res.message


@pytest.mark.parametrize("limit", [1, 2])
@pytest.mark.parametrize("periodic", [False, True])
def test_scipy_nnls_at_a_small_limit_answers_its_finite_start(limit: int, periodic: bool) -> None:
    """Lawson-Hanson stopped by its limit keeps no iterate: the answer is the start p = 0,
    not converged, status max_iter -- never a non-finite p."""
    inst = step(rough(8), periodic)
    res = get_solver("scipy-nnls").solve(inst.qp, SolverSettings(max_iter=limit))
    assert np.all(np.isfinite(res.p)) and not np.any(res.p)
    assert not res.converged and res.status == Status.MAX_ITER.value and "iteration limit" in res.message


def test_a_warm_start_is_kept_at_a_zero_limit() -> None:
    require("qp-osqp")
    inst = step(rough(8))
    p0 = np.full(inst.n, 1e-3)
    res = get_solver("qp-osqp").solve(inst.qp, SolverSettings(max_iter=0), WarmStart(p=p0))
    np.testing.assert_array_equal(res.p, p0)


def test_a_count_the_backend_never_set_reads_zero() -> None:
    refused = SimpleNamespace(extras={"info": SimpleNamespace(status="Status.PIQP_INVALID_SETTINGS",
                                                              iter=139888739102832)}, found=False)
    assert _status_of(refused) == ("PIQP_INVALID_SETTINGS", 0)
    negative = SimpleNamespace(extras={"info": SimpleNamespace(status="Status.PIQP_UNSOLVED", iter=-7)}, found=False)
    assert _status_of(negative) == ("PIQP_UNSOLVED", 0)
    solved = SimpleNamespace(extras={"info": SimpleNamespace(status="Status.PIQP_SOLVED", iter=9)}, found=True)
    assert _status_of(solved) == ("PIQP_SOLVED", 9)


def test_piqp_refusing_its_settings_records_no_iterations() -> None:
    require("qp-piqp")
    inst = step(rough(8))
    res = get_solver("qp-piqp").solve(inst.qp, SolverSettings(check_tol=1e-6, params={"backend_options": {"max_iter": 0}}))
    assert res.info["backend_status"] == "PIQP_INVALID_SETTINGS"
    assert res.iterations == 0 and not res.converged


# --- the load in the equilibration --------------------------------------------------


@pytest.mark.parametrize("scale", [1e-300, 1e-150, 1e-6])
def test_scaled_load_row_is_order_one(scale: float) -> None:
    inst = loaded(rough(8, scale))
    sqp = _scaling.assemble_scaled(inst.qp)
    assert 1e-3 <= sqp.eq_rhs <= 2 * inst.n
    assert np.all(np.isfinite(sqp.u))
    # the scaled gap is the judge's: w~ = w / u_s (constant diagonal)
    u_s, _ = constrained_scales(inst.qp.ubar, float(np.max(inst.qp.H.diagonal())), inst.qp.constraints)
    assert sqp.eq.s * float(sqp.eq.d[0]) == pytest.approx(u_s * float(sqp.eq.d[0]) ** 2, rel=1e-12)


def test_flat_surface_under_a_load_is_order_one() -> None:
    b = builder(np.zeros((8, 8)))
    sqp = _scaling.assemble_scaled(b.build_load(b.load_force(1e-3)).qp)
    assert 1.0 <= sqp.eq_rhs <= 2 * 64.0


def test_without_a_load_the_scale_is_the_relief() -> None:
    inst = step(rough(8))
    sqp = _scaling.assemble_scaled(inst.qp)
    assert np.max(np.abs(sqp.u)) == pytest.approx(1.0, rel=1e-15)


@pytest.mark.parametrize("name", ["qp-osqp", "qp-proxqp", "qp-piqp", "qp-clarabel"])
def test_tiny_heights_under_a_load_are_solved(name: str) -> None:
    require(name)
    inst = loaded(rough(8, 1e-300))
    res = get_solver(name).solve(inst.qp, SolverSettings(check_tol=1e-6))
    assert res.converged, f"{name}: {res.status} {res.message}"
    assert judge(inst, res.p, res.converged, 1e-6, multiplier=res.multiplier).status == "solved"


@pytest.mark.parametrize("name", ["qp-clarabel+polish", "qp-piqp+polish"])
def test_a_polish_on_a_singular_block_keeps_the_backends_answer(name: str) -> None:
    """A periodic whole grid (H 1 = 0) whose answer is full contact: the polish's block is
    singular, so the backend's own answer stands, unpolished -- no LinAlgError escapes."""
    require(name)
    h = np.zeros((4, 4))
    h[1, 2] = 1.0
    surface = Surface(h, 1.0, periodic=True)
    delta = float(np.nextafter(h.max() - h.mean(), 0.0))  # just below the periodic limit
    inst = InstanceBuilder(surface, 0.01, "love", True, operator="dense").build(delta)
    res = get_solver(name).solve(inst.qp, SolverSettings(check_tol=1e-8))
    assert res.info["polish_improved"] is False and "polish_error" in res.info
    assert judge(inst, res.p, bool(res.converged), 1e-6).status == "solved"
