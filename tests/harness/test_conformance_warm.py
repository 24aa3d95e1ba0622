"""The battery's warm-started cases (``warm-start``): a solver that takes a warm start is
handed one that is not the case's answer, and its answer is judged like any other; a
solver that returns its warm start unchanged, claiming convergence, is WRONG; a solver
that takes none skips them as a capability it declares."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.cases import WARM_CASES, WARM_GROUP, warm_cases, warm_start_of
from contactbench.harness.conformance.command import main as validate_main
from contactbench.harness.profiles import get_profile
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.scenes.stress import build_battery_spec
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver


def exact_p(ctx: SolveContext) -> np.ndarray:
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


class ReturnsItsWarmStart(Solver):
    """Right from a cold start; from a warm start, the warm start itself, claimed."""

    name = "test-warm-returns-its-warm-start"
    family = "test"
    capabilities = Capabilities(warm_start="primal")

    def iterate(self, ctx: SolveContext) -> Outcome:
        if ctx.p0 is not None:
            return Outcome(ctx.p0, 0, True)
        return Outcome(exact_p(ctx), 1, True)


class ChecksItsWarmStart(Solver):
    """Primal-dual: asserts it is handed a warm p and w of length n, then answers exactly."""

    name = "test-warm-checks-its-warm-start"
    family = "test"
    capabilities = Capabilities(warm_start="primal-dual")

    def iterate(self, ctx: SolveContext) -> Outcome:
        assert ctx.warm is not None and ctx.warm.p is not None and ctx.warm.w is not None
        assert ctx.p0 is not None and ctx.p0.shape == ctx.warm.w.shape == (ctx.n,)
        return Outcome(exact_p(ctx), 1, True)


class Cold(Solver):
    name = "test-warm-cold-only"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        assert ctx.p0 is None
        return Outcome(exact_p(ctx), 1, True)


def test_the_warm_group_is_a_group_of_the_battery_in_every_mode() -> None:
    for mode in ("fast", "full"):
        warm = cf.conformance_cases(mode, groups=[WARM_GROUP])
        assert [c.name for c in warm] == [f"{WARM_GROUP}/{name}" for name, _ in WARM_CASES]
        assert {c.group for c in warm} == {WARM_GROUP}
        assert [c.name for c in cf.conformance_cases(mode)][-len(WARM_CASES):] == [c.name for c in warm]


@pytest.mark.parametrize("case", warm_cases(), ids=str)
def test_each_warm_start_is_far_from_the_answer_of_its_case(case: cf.ConformanceCase) -> None:
    inst = build_battery_spec(case.spec).at(0)
    warm = warm_start_of(case, 0, inst)
    assert warm is not None and warm.p is not None and warm.p.shape == (inst.n,)
    assert kkt_check(inst, warm.p).kkt_error > 1e4 * get_profile(case.profile).check_tol
    assert np.any(warm.p > 0)  # not a cold start in disguise


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solver_that_returns_its_warm_start_is_wrong(isolate: bool) -> None:
    table = cf.validate(ReturnsItsWarmStart(), warm_cases(), isolate=isolate)
    assert [r.status for r in table.rows] == ["WRONG"] * len(WARM_CASES), table.format()
    assert table.exit_code() == 1
    cold = cf.validate(ReturnsItsWarmStart(), [c.spec for c in warm_cases()], isolate=False)
    assert cold.exit_code() == 0, cold.format()  # the same problems from a cold start: right


def test_the_command_line_runs_the_warm_group() -> None:
    assert validate_main([f"{__name__}:ReturnsItsWarmStart", "--group", WARM_GROUP, "--quiet", "--no-isolate"]) == 1


def test_a_primal_dual_solver_is_handed_a_warm_p_and_w() -> None:
    table = cf.validate(ChecksItsWarmStart(), warm_cases(), isolate=False)
    assert table.outcome() == "conforms" and table.count("pass") == len(WARM_CASES), table.format()


def test_a_solver_that_takes_no_warm_start_skips_the_warm_cases_as_a_declared_capability() -> None:
    table = cf.validate(Cold(), warm_cases(), isolate=False)
    assert table.count("skipped") == len(WARM_CASES) and not any(r.own_skip for r in table.rows), table.format()
    assert "takes no warm start" in table.rows[0].message
    assert table.outcome() == "untested" and "no answer of the solver's own" in table.summary()
    both = cf.validate(Cold(), [*warm_cases(), warm_cases()[0].spec], isolate=False)
    assert both.outcome() == "conforms", both.format()


@pytest.mark.parametrize("name", ["pk", "nnls", "fast-dual-pccg", "admm"])
def test_registered_solvers_that_take_a_warm_start_conform_from_it(name: str) -> None:
    table = cf.validate(name, warm_cases(), isolate=False)
    assert table.outcome() == "conforms" and table.count("pass") == len(WARM_CASES), table.format()
