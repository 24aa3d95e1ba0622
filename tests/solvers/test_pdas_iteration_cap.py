"""fast-pdas counts its Newton steps and its CCG safeguard's iterations as one total, and that
total never passes the solve's iteration limit (``SolverSettings.max_iter``): the Newton steps
stop at ``min(max_outer, max_iter)`` and the CCG gets what is left."""

from __future__ import annotations

import pytest

from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.fast_pdas import iteration_limits
from contactbench.solvers.registry import get_solver


def rough_qp(periodic: bool):  # type: ignore[no-untyped-def]
    s = rmd_surface_n(32, 0.7, length=100e-6, rms_height=1e-6, seed=2)
    return InstanceBuilder(s, 1e9, "bcc", periodic=periodic).build(1.5e-6).qp


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("max_outer", [1, 2, 50])
@pytest.mark.parametrize("max_iter", [1, 2, 5, 20])
def test_the_count_stays_within_max_iter(periodic: bool, max_outer: int, max_iter: int) -> None:
    res = get_solver("fast-pdas").solve(rough_qp(periodic), SolverSettings(max_iter=max_iter,
                                                                            params={"max_outer": max_outer}))
    assert res.iterations <= max_iter
    if not periodic:  # one round on the whole problem (a whole grid's screening rounds sum their infos)
        newton = int(res.info["outer_iterations"])
        assert newton <= min(max_outer, max_iter)
        assert res.iterations == newton + int(res.info.get("ccg_iterations", 0))
    if not res.converged:
        assert res.status in ("max_iter", "stalled")


def test_the_ccg_gets_what_the_newton_steps_left() -> None:
    assert iteration_limits(50, 8) == (8, 8)
    assert iteration_limits(50, 8, outer=3) == (8, 5)
    assert iteration_limits(2, 8, outer=2) == (2, 6)
    assert iteration_limits(50, 8, outer=8) == (8, 0)
    assert iteration_limits(50, None, outer=8) == (50, None)
