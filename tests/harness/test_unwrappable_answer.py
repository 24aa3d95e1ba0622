"""An answer NumPy cannot even wrap (its ``__array__`` raises, as a device array that refuses
an implicit copy does) is no answer: claimed as converged it is WRONG, the judge naming why,
in-process and in a worker alike -- never a crash of the solve."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.pytest_plugin import case_conforms
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver

CASE = "counterexample/example1-n400-s0"


class RefusesCopy:
    """A device-array stand-in: right values inside, no implicit conversion."""

    def __init__(self, p: np.ndarray) -> None:
        self.p = p

    def __array__(self, *args: Any, **kwargs: Any) -> np.ndarray:
        raise TypeError("Implicit conversion to a NumPy array is not allowed. Please use `.get()`")


class DeviceAnswer(Solver):
    name = "test-device-answer"
    family = "test"
    capabilities = Capabilities(needs_dense=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        H, ubar = ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)
        return Outcome(RefusesCopy(exact_solution(H, ubar).p), 1, True)  # type: ignore[arg-type]


@pytest.mark.parametrize("isolate", [False, True])
def test_a_claimed_answer_numpy_cannot_wrap_is_wrong_and_named(isolate: bool) -> None:
    (case,) = cf.conformance_cases("fast", pattern=CASE)
    with pytest.raises(pytest.fail.Exception) as failed:
        case_conforms(DeviceAnswer(), case, isolate=isolate)
    text = str(failed.value)
    assert text.splitlines()[0].startswith(f"test-device-answer on {CASE}: WRONG"), text
    assert "cannot be read as an array (TypeError)" in text
