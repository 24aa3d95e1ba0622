"""``validate`` flags a right answer whose iteration count is below its own trace (a solver
that reports 0 iterations after recording 50): the count is a column the report compares
solvers by.  An honest count passes."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.pytest_plugin import case_conforms
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver

CASE = "counterexample/example1-n400-s0"


class Counted(Solver):
    name = "test-counted"
    family = "test"
    capabilities = Capabilities(needs_dense=True)
    said = 5

    def iterate(self, ctx: SolveContext) -> Outcome:
        H, ubar = ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)
        for k in range(1, 6):
            ctx.record(k, 10.0 ** -k)
        return Outcome(exact_solution(H, ubar).p, self.said, True)


class Undercounts(Counted):
    name = "test-undercounts"
    said = 0


def one() -> cf.ConformanceCase:
    (case,) = cf.conformance_cases("fast", pattern=CASE)
    return case


def test_a_count_below_the_solver_s_own_trace_is_flagged_and_named() -> None:
    table = case_conforms(Undercounts(), one(), isolate=False)  # the answer is right: it conforms
    assert "an iteration count below its own trace" in table.headline(False)
    (row,) = [r for r in table.rows if r.step >= 0]
    assert row.status == "flagged" and row.flags == "count"
    assert "reports 0 iterations where its own trace reaches iteration 5" in row.message
    with pytest.raises(pytest.fail.Exception, match="flagged"):
        case_conforms(Undercounts(), one(), isolate=False, strict=True)


def test_an_honest_count_passes() -> None:
    table = case_conforms(Counted(), one(), isolate=False, strict=True)
    assert all(r.status == "pass" for r in table.rows if r.step >= 0)
