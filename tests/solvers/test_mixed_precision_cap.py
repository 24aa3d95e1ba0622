"""Under mixed precision (float32 rounds under float64 refinement, ``solvers/_refine.py``)
the fast solvers' iterations, the rounds' and the float64 tail's together, never pass the
solve's iteration limit: a tail the rounds left no iteration for does not run."""

from __future__ import annotations

import pytest

from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

FAST = ("fast-ccg", "fast-dual-ccg", "fast-pccg", "fast-dual-pccg", "fast-pdas")


@pytest.fixture(scope="module", params=[False, True], ids=["np", "per"])
def rough_qp(request: pytest.FixtureRequest):  # type: ignore[no-untyped-def]
    s = rmd_surface_n(32, 0.7, length=100e-6, rms_height=1e-6, seed=2)
    return InstanceBuilder(s, 1e9, "bcc", periodic=request.param).build(1.5e-6).qp


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize("max_iter", [1, 3, 5])
def test_the_count_stays_within_max_iter(rough_qp, name: str, max_iter: int) -> None:  # type: ignore[no-untyped-def]
    params = {"precision": "mixed", **({"max_outer": 1} if name == "fast-pdas" else {})}
    res = get_solver(name).solve(rough_qp, SolverSettings(max_iter=max_iter, params=params))
    assert res.iterations <= max_iter, (res.iterations, res.status, res.message)
    assert res.converged or res.status in ("max_iter", "stalled")
