"""A promise as ``validate`` reads it from a solver's declaration (``declared.declaration_of``,
the CLI's and the worker's path) keeps its type, so its words say "held to" only where the
floor is looser than the loosest threshold a run calls solved (docs/verdicts.md)."""

from __future__ import annotations

from contactbench.harness.conformance.battery import PROMISE_BOUND, promise_text
from contactbench.harness.conformance.declared import declaration_of
from contactbench.solvers.registry import get_solver


def test_a_floor_under_the_bound_is_stated_as_it_is() -> None:
    declared = declaration_of("admm")
    floor = get_solver("admm").capabilities.promise
    assert floor != "exact" and float(floor) < PROMISE_BOUND
    assert declared.promise == float(floor) and isinstance(declared.promise, float)
    assert promise_text(declared.promise) == f"scaled KKT floor {float(floor):g}"


def test_a_floor_over_the_bound_says_what_it_is_held_to() -> None:
    words = promise_text(0.5)
    assert words == f"scaled KKT floor 0.5, held to {PROMISE_BOUND:g}, the loosest threshold run calls solved"


def test_exact_stays_exact() -> None:
    assert declaration_of("nnls").promise == "exact" and promise_text("exact") == "exact"
