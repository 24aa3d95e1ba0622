"""The battery's iteration-limit cases (``iteration-limit``): a few small cases solved under
``ITERATION_LIMIT``; a solver that reports more iterations than its limit -- times the
stages it lists where it declares ``limit_per_stage`` -- is flagged (``--strict`` fails
it), one that honours the limit is not, and an answer stopped at the limit is not left
unsolved."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.cases import ITERATION_LIMIT, LIMIT_CASES, LIMIT_GROUP, limit_cases
from contactbench.harness.conformance.command import main as validate_main
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver


def exact_p(ctx: SolveContext) -> np.ndarray:
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


class IgnoresTheLimit(Solver):
    """Exact, and reports 5000 iterations whatever ``max_iter`` it is given."""

    name = "test-limit-ignores-the-limit"
    family = "test"
    capabilities = Capabilities(exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 5000, True, "done")


class HonoursTheLimit(Solver):
    """Exact in one iteration, never more than ``max_iter``."""

    name = "test-limit-honours-the-limit"
    family = "test"
    capabilities = Capabilities(exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), min(1, ctx.max_iter), True, "done")


class StopsAtTheLimit(Solver):
    """Stops at ``max_iter`` unconverged (p = 0) below 3 iterations; exact above."""

    name = "test-limit-stops-at-the-limit"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        if ctx.max_iter < 3:
            return Outcome(np.zeros(ctx.n), ctx.max_iter, False, "stopped at max_iter")
        return Outcome(exact_p(ctx), 3, True, "done")


class StagedLimit(Solver):
    """A limit that bounds each of its two stages: reports twice the limit, stages listed."""

    name = "test-limit-two-stages"
    family = "test"
    capabilities = Capabilities(exact=True)
    limit_per_stage = True

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 2 * ctx.max_iter, True, "done", info={"stages": "coarse fine"})


class StagedPastTheLimit(StagedLimit):
    """Two stages listed, one iteration more than twice the limit reported."""

    name = "test-limit-two-stages-past"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 2 * ctx.max_iter + 1, True, "done", info={"stages": "coarse fine"})


def test_the_limit_group_is_a_group_of_the_battery_in_every_mode() -> None:
    assert LIMIT_GROUP in cf.BATTERY_GROUPS and ITERATION_LIMIT >= 1
    for mode in ("fast", "full"):
        limited = cf.conformance_cases(mode, groups=[LIMIT_GROUP])
        assert [c.name for c in limited] == [f"{LIMIT_GROUP}/{name}" for name in LIMIT_CASES]
        assert {c.group for c in limited} == {LIMIT_GROUP}
        assert all(c.max_iter == ITERATION_LIMIT and c.compare == "none" for c in limited)
        assert [c.name for c in cf.conformance_cases(mode) if c.group == LIMIT_GROUP] == [c.name for c in limited]


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solver_that_ignores_the_limit_is_flagged(isolate: bool) -> None:
    table = cf.validate(IgnoresTheLimit(), limit_cases(), isolate=isolate)
    assert [r.status for r in table.rows] == ["flagged"] * len(LIMIT_CASES), table.format()
    assert all(r.flags == "limit" and "5000 iterations under max_iter" in r.message for r in table.rows)
    assert table.outcome() == "conforms" and table.exit_code(strict=True) == 1
    assert "more iterations than its iteration limit" in table.headline()


def test_strict_validate_fails_a_solver_that_ignores_the_limit(capsys: pytest.CaptureFixture[str]) -> None:
    argv = [f"{__name__}:IgnoresTheLimit", "--group", LIMIT_GROUP, "--strict", "--no-isolate"]
    assert validate_main(argv) == 1
    assert "FAILS (--strict)" in capsys.readouterr().out


def test_a_solver_that_honours_the_limit_is_not_flagged() -> None:
    table = cf.validate(HonoursTheLimit(), limit_cases(), isolate=False)
    assert [r.status for r in table.rows] == ["pass"] * len(LIMIT_CASES), table.format()
    assert table.exit_code(strict=True) == 0


def test_stopping_at_the_limit_is_not_left_unsolved() -> None:
    table = cf.validate(StopsAtTheLimit(), limit_cases(), isolate=False)
    assert [r.status for r in table.rows] == ["unconverged"] * len(LIMIT_CASES), table.format()
    assert [r.iterations for r in table.rows] == [ITERATION_LIMIT] * len(LIMIT_CASES)
    assert not table.unsolved and table.outcome(strict=True) == "conforms"  # the answer the group asks for
    assert table.headline().startswith(f"CONFORMS: every solve stopped at the iteration limit of {LIMIT_GROUP} as asked")


def test_a_group_of_the_limit_alone_judges_the_limit(capsys: pytest.CaptureFixture[str]) -> None:
    """``--group iteration-limit`` alone: a solver that stops at the limit conforms (exit 0),
    one that reports more iterations is flagged -- not "untested" for reasons none of which
    held (no case skipped, refused or answered without it) -- and fails ``--strict``."""
    assert validate_main(["nnls", "--group", LIMIT_GROUP, "--quiet", "--no-isolate"]) == 0
    assert "stopped at the iteration limit" in capsys.readouterr().out
    argv = [f"{__name__}:IgnoresTheLimit", "--group", LIMIT_GROUP, "--quiet", "--no-isolate"]
    assert validate_main(argv) == 0
    out = capsys.readouterr().out
    assert "rows flagged" in out and "more iterations than its iteration limit" in out and "UNTESTED" not in out
    assert validate_main([*argv, "--strict"]) == 1


def test_flagged_rows_not_accepted_are_not_called_accepted() -> None:
    """A limit row whose answer the KKT test does not accept is flagged for the limit, and
    the headline does not say it was accepted."""
    table = cf.validate(IgnoresTheLimit(), limit_cases(), isolate=False)
    for row in table.rows:
        row.kkt_error = 10 * row.check_tol
    assert table.headline().startswith("CONFORMS to its promise (exact): 2 of 2 rows flagged -- more iterations")


def test_a_limit_per_stage_allows_the_limit_times_its_stages() -> None:
    table = cf.validate(StagedLimit(), limit_cases(), isolate=True)
    assert [r.status for r in table.rows] == ["pass"] * len(LIMIT_CASES), table.format()
    assert [r.iterations for r in table.rows] == [2 * ITERATION_LIMIT] * len(LIMIT_CASES)
    past = cf.validate(StagedPastTheLimit(), limit_cases(), isolate=False)
    assert [r.status for r in past.rows] == ["flagged"] * len(LIMIT_CASES), past.format()
    assert all("x 2 stages" in r.message for r in past.rows)


def test_an_unconverged_answer_past_the_limit_is_flagged_and_not_accepted() -> None:
    class PastAndUnconverged(Solver):
        name = "test-limit-past-and-unconverged"
        family = "test"

        def iterate(self, ctx: SolveContext) -> Outcome:
            return Outcome(np.zeros(ctx.n), ctx.max_iter + 1, False, "stopped")

    table = cf.validate(PastAndUnconverged(), limit_cases(), isolate=False)
    assert [r.status for r in table.rows] == ["flagged"] * len(LIMIT_CASES), table.format()
    assert all(r.message.startswith("not converged, and ") for r in table.rows)
    assert not table.judged and table.exit_code(strict=True) == 1


class HalfPastTheLimit(Solver):
    """Half the exact answer, not claimed, reporting more iterations than its limit."""

    name = "test-limit-half-past"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(0.5 * exact_p(ctx), ctx.max_iter + 7, False, "stopped")


def test_an_answer_not_accepted_is_flagged_for_its_count_alone() -> None:
    """Off the reference, as an answer stopped short is: that is no flag of its; the limit
    it ignored is."""
    table = cf.validate(HalfPastTheLimit(), limit_cases(), isolate=False)
    assert [(r.status, r.flags) for r in table.rows] == [("flagged", "limit")] * len(LIMIT_CASES), table.format()
    assert table.headline().endswith("rows flagged -- more iterations than its iteration limit")
