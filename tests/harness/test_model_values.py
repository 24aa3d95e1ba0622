"""A solver's time and memory models are read as estimates only when they are ones
(``harness.run.skips.model_value``): a real number >= 0 (infinity: never within a limit).
NaN, a negative number or a non-number is a bug of the solver's declaration: its rows fail
naming it, as a model that raises does, instead of the NaN comparing false and the solve
running as if predicted to fit (or a text "12" read as 12 s)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from contactbench.harness.run.skips import ModelValueError, capability_decision, model_value, time_decision
from contactbench.solvers.base import ProblemTraits
from contactbench.solvers.registry import get_solver

TRAITS = ProblemTraits(n=1_000, operator="fft", has_surface=True, surface_side=64)
GiB = float(2**30)


class Modelled(type(get_solver("pk"))):  # type: ignore[misc]
    """pk with the time and memory models a test gives it."""

    def __init__(self, seconds: Any = 1.0, nbytes: Any = 1.0) -> None:
        self.seconds, self.nbytes = seconds, nbytes

    def time_estimate(self, n: int, operator_kind: str) -> Any:
        return self.seconds

    def memory_estimate(self, n: int) -> Any:
        return self.nbytes


@pytest.mark.parametrize("value", [float("nan"), -1.0, -1e-300, "12", None, True, [3.0], complex(1, 0)])
def test_what_no_estimate_is_fails_the_model_naming_it(value: Any) -> None:
    with pytest.raises(ModelValueError, match="time_estimate returned"):
        model_value(value, "time_estimate")
    if value is not None:  # (None is "no time model", read before model_value)
        decision = time_decision(Modelled(seconds=value), TRAITS, "fft", 60.0, None)
        assert decision.skip and decision.failed and "time model failed: ModelValueError" in decision.reason
    decision = capability_decision(Modelled(nbytes=value), TRAITS, 8 * GiB)
    assert decision.skip and decision.failed and "memory_estimate returned" in decision.reason


@pytest.mark.parametrize("value", [0, 0.0, 2.5, np.float32(2.5), np.int64(3), math.inf])
def test_a_number_at_or_above_zero_is_an_estimate(value: Any) -> None:
    assert model_value(value, "time_estimate") == float(value)
    decision = time_decision(Modelled(seconds=value), TRAITS, "fft", 60.0, None)
    assert not decision.failed and decision.skip == (float(value) > 60.0)


def test_no_time_model_is_no_prediction() -> None:
    assert not time_decision(Modelled(seconds=None), TRAITS, "fft", 60.0, None).skip


def test_a_solve_without_a_time_model_keeps_its_warm_up_to_512_and_drops_it_from_1024() -> None:
    """The warm-up rule's floor for a solver that declares no time model (the field's
    codes): on the paper's top-step trial sets (n = 35,218 at 512^2, about 140,000 at
    1024^2) its prediction is under the warm-up limit at 512^2 and over it from 1024^2."""
    from contactbench.harness.run.job import MIN_PREDICTED_MATVECS
    from contactbench.harness.run.plan import RunConfig
    from contactbench.solvers._kit import matvec_seconds

    limit = RunConfig().warmup_limit
    assert MIN_PREDICTED_MATVECS * matvec_seconds(35_218, "fft") < limit
    assert MIN_PREDICTED_MATVECS * matvec_seconds(140_000, "fft") > limit
