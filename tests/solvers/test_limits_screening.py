"""A small iteration limit on the screened fast solvers (solvers/_screen.py): never a round
counted past the limit (a limit of 0, for every solver: tests/solvers/test_iteration_limits.py)."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.surfaces import Surface
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

E = 1e9
DX = 1e-6
FAST = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg")


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


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("limit", [1, 2, 5])
@pytest.mark.parametrize("case", ["periodic step", "load with a hardness"])
def test_screened_fast_solvers_stay_within_a_small_limit(name: str, limit: int, case: str) -> None:
    inst = periodic_step() if case == "periodic step" else loaded_with_a_hardness()
    res = get_solver(name).solve(inst.qp, SolverSettings(max_iter=limit, check_tol=1e-12))
    assert res.info.get("screened_rounds", 0) >= 1  # the screened path, not the whole problem
    assert res.iterations <= limit
