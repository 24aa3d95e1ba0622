"""A limit of 0 iterations on the ContactMechanics peers (solvers/peer_cm.py) and on the
screened fast solvers (solvers/_screen.py): 0 iterations reported, not converged, status
max_iter -- never a crash inside the peer, never a round counted past the limit."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.surfaces import Surface
from contactbench.solvers.base import SolverSettings, Status, WarmStart
from contactbench.solvers.registry import get_solver

E = 1e9
DX = 1e-6
CM = ("cm-pk-ccg", "cm-dual-ccg")
FAST = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg")
CM_OK, CM_WHY = get_solver("cm-pk-ccg").availability()


def rough(n: int, seed: int = 0) -> np.ndarray:
    return 1e-6 * np.random.default_rng(seed).standard_normal((n, n))


def builder(h: np.ndarray, periodic: bool) -> InstanceBuilder:
    return InstanceBuilder(Surface(h, DX, periodic=periodic), E, "spectral" if periodic else "bcc",
                           periodic=periodic, operator="fft")


def periodic_step(n: int = 16) -> ContactInstance:
    h = rough(n)
    return builder(h, True).build(0.3 * float(np.ptp(h)))


def loaded_with_a_hardness(n: int = 8) -> ContactInstance:
    hardness = 1e6  # Pa: each element carries at most hardness x its area
    return builder(rough(n), False).build_load(0.9 * n * n * hardness * DX * DX, hardness=hardness)


def assert_zero_limit_outcome(res, name: str) -> None:
    assert res.iterations == 0, f"{name}: {res.iterations} iterations at max_iter 0 ({res.message})"
    assert not res.converged and res.status == Status.MAX_ITER.value, f"{name}: {res.status}"


@pytest.mark.skipif(not CM_OK, reason=CM_WHY)
@pytest.mark.parametrize("name", CM)
@pytest.mark.parametrize("periodic", [False, True])
def test_contactmechanics_at_a_zero_limit_is_not_called(name: str, periodic: bool) -> None:
    h = rough(8)
    inst = builder(h, periodic).build(0.3 * float(np.ptp(h)))
    res = get_solver(name).solve(inst.qp, SolverSettings(max_iter=0, check_tol=1e-6))
    assert_zero_limit_outcome(res, name)
    assert res.info["answered_by_adapter"] and "max_iter 0" in res.message
    np.testing.assert_array_equal(res.p, 0.0)  # the cold start


@pytest.mark.skipif(not CM_OK, reason=CM_WHY)
def test_contactmechanics_at_a_zero_limit_keeps_the_warm_start() -> None:
    h = rough(8)
    inst = builder(h, False).build(0.3 * float(np.ptp(h)))
    p0 = np.full(inst.n, 1e-4)
    res = get_solver("cm-pk-ccg").solve(inst.qp, SolverSettings(max_iter=0), WarmStart(p=p0))
    assert_zero_limit_outcome(res, "cm-pk-ccg")
    np.testing.assert_array_equal(res.p, p0)


@pytest.mark.skipif(not CM_OK, reason=CM_WHY)
def test_contactmechanics_under_a_load_at_a_zero_limit() -> None:
    b = builder(rough(8), False)
    res = get_solver("cm-pk-ccg").solve(b.build_load(b.load_force(1e-3)).qp, SolverSettings(max_iter=0))
    assert_zero_limit_outcome(res, "cm-pk-ccg")


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("case", ["periodic step", "load with a hardness"])
def test_screened_fast_solvers_count_no_iteration_at_a_zero_limit(name: str, case: str) -> None:
    inst = periodic_step() if case == "periodic step" else loaded_with_a_hardness()
    res = get_solver(name).solve(inst.qp, SolverSettings(max_iter=0, check_tol=1e-6))
    assert res.info.get("screened_rounds") == 1  # the screened path, not the whole problem
    assert_zero_limit_outcome(res, name)


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("limit", [1, 2, 5])
def test_screened_fast_solvers_stay_within_a_small_limit(name: str, limit: int) -> None:
    res = get_solver(name).solve(periodic_step().qp, SolverSettings(max_iter=limit, check_tol=1e-12))
    assert res.iterations <= limit
