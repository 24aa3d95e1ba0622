"""Under load control a load of 0 leaves p = 0 the only feasible answer: the lifecycle gives
it without calling ``iterate`` (a peer's loop divided by the total force and ran on past
its limit), and the judge reads it solved."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import Outcome, SolveContext, Solver, answered_without_iterate
from contactbench.solvers.registry import get_solver


class NeverIterates(Solver):
    name = "test-never-iterates"
    description = "fails if iterate is called"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise AssertionError("iterate was called on a load of 0")


def zero_load_instance(hardness: float | None = None):  # type: ignore[no-untyped-def]
    s = rmd_surface_n(16, 0.7, length=100e-6, rms_height=1e-6, seed=2)
    return InstanceBuilder(s, 1e9, "bcc", periodic=False).build_load(0.0, hardness=hardness)


def test_a_load_of_0_is_answered_by_the_lifecycle() -> None:
    inst = zero_load_instance()
    assert answered_without_iterate(inst.qp)
    solver = NeverIterates()
    solver.capabilities = type(get_solver("fast-dual-pccg").capabilities)(load_control=True)  # type: ignore[misc]
    res = solver.solve(inst.qp)
    assert res.converged and np.all(res.p == 0.0) and "load 0" in res.message
    assert judge(inst, res.p, True, 1e-8, multiplier=res.multiplier).status == "solved"


@pytest.mark.parametrize("name", ["fast-dual-pccg", "pk", "nnls"])
def test_the_solvers_that_pose_load_control_answer_it(name: str) -> None:
    solver = get_solver(name)
    if not solver.capabilities.load_control:
        pytest.skip(f"{name} does not pose load control")
    inst = zero_load_instance()
    res = solver.solve(inst.qp)
    assert res.iterations == 0 and np.all(res.p == 0.0)
    assert judge(inst, res.p, True, 1e-8, multiplier=res.multiplier).status == "solved"
