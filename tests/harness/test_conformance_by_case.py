"""The conformance battery case by case in a user's pytest (``harness.pytest_plugin.case_conforms``
over ``conformance_cases()``): a wrong answer fails with the verdict line first, a case the
solver is not handed is skipped with the reason, and a selection of no case is refused --
never a vacuous pass."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.pytest_plugin import case_conforms
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver

CASE = "counterexample/example1-n400-s0"


class Exact(Solver):
    name = "test-case-exact"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p, 1, True)


class ClaimsZero(Exact):
    name = "test-case-claims-zero"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(np.zeros(ctx.n), 1, True)


def one(pattern: str) -> cf.ConformanceCase:
    (case,) = cf.conformance_cases("fast", pattern=pattern)
    return case


def test_a_wrong_answer_fails_its_case_with_the_verdict_line_first() -> None:
    with pytest.raises(pytest.fail.Exception) as failed:
        case_conforms(ClaimsZero(), one(CASE), isolate=False)
    first = str(failed.value).splitlines()[0]
    assert first.startswith(f"test-case-claims-zero on {CASE}: WRONG"), first
    assert case_conforms(Exact(), one(CASE), isolate=False).ok


@pytest.mark.parametrize("pattern, words", [("edge/delta0*", "the lifecycle"),
                                            ("constrained/load-bcc*", "cannot pose load control")])
def test_a_case_the_solver_is_not_handed_is_a_skip_naming_why(pattern: str, words: str) -> None:
    with pytest.raises(pytest.skip.Exception) as skipped:
        case_conforms(Exact(), one(pattern), isolate=False)
    assert "not handed to test-case-exact" in str(skipped.value) and words in str(skipped.value)


def test_assert_conforms_puts_the_verdict_line_first() -> None:
    with pytest.raises(AssertionError) as failed:
        cf.assert_conforms(ClaimsZero(), [one(CASE)], isolate=False)
    assert str(failed.value).splitlines()[0].startswith("test-case-claims-zero: WRONG"), str(failed.value)


def test_a_selection_of_no_case_or_an_unknown_group_is_refused() -> None:
    with pytest.raises(ProblemInputError, match="no case matches 'edges/\\*' in the groups"):
        cf.conformance_cases("fast", pattern="edges/*")
    with pytest.raises(ProblemInputError, match="unknown battery group.*'nope'.*warm-start"):
        cf.conformance_cases("fast", groups=["nope"])
    assert [str(c) for c in cf.conformance_cases("fast", groups="edge")] == \
        [str(c) for c in cf.conformance_cases("fast", groups=["edge"])]
    assert all(str(c) == c.name for c in cf.conformance_cases("fast", groups="edge"))
