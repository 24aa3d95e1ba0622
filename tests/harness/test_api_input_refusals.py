"""The public API refuses input it cannot read, in one line naming it: ``judge``'s claim
(a bool only: the text "no" is no claim), reference and its tolerance;
``solve_sequence``'s budget and references (one per step); and ``unregister`` of a
name nobody registered (a ``KeyError``, unless ``missing_ok``)."""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from contactbench.harness import judge, solve_sequence
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import ContactInstance
from contactbench.solvers import available_solvers, unregister
from contactbench.solvers.base import Outcome, SolveContext
from tests.helpers import ExactStub, dense_exact_solution, top_step

TOL = 1e-8


@pytest.fixture(scope="module")
def solved() -> tuple[ContactInstance, np.ndarray]:
    inst = top_step(9)
    return inst, dense_exact_solution(inst.qp)


def refused(call: Any, *words: str) -> str:
    with pytest.raises(ProblemInputError) as info:
        call()
    text = str(info.value)
    assert "\n" not in text and all(w in text for w in words), text
    return text


class CountingExact(ExactStub):
    """The exact stub, counting its solves (never registered: handed in as an instance)."""

    name = "test-counting-exact-api"

    def __init__(self) -> None:
        super().__init__()
        self.solves = 0

    def iterate(self, ctx: SolveContext) -> Outcome:
        self.solves += 1
        return super().iterate(ctx)


# -- judge ------------------------------------------------------------------------------


@pytest.mark.parametrize("claim", ["no", "yes", "", 0, 1, None, 1.0, np.array([True])])
def test_the_judge_takes_a_bool_claim_only(solved: tuple[ContactInstance, np.ndarray], claim: Any) -> None:
    inst, p = solved
    refused(lambda: judge(inst, np.zeros(inst.n), claim, TOL), "claimed", type(claim).__name__)
    for ok in (True, np.True_, np.bool_(True)):
        v = judge(inst, p, ok, TOL)
        assert type(v.claimed) is bool and v.claimed and (v.status, v.reading) == ("solved", "pass")
    v = judge(inst, np.zeros(inst.n), np.False_, TOL)
    assert v.claimed is False and v.reading == "unconverged"


@pytest.mark.parametrize("bad", ["short", "long", "matrix", "nan", "inf", "text", "bool", "ragged"])
def test_the_judge_refuses_a_reference_that_is_no_length_n_vector_of_finite_numbers(
        solved: tuple[ContactInstance, np.ndarray], bad: str) -> None:
    inst, p = solved
    ref = {"short": p[:-1], "long": np.append(p, 0.0), "matrix": p.reshape(1, -1),
           "nan": np.where(np.arange(inst.n) == 0, np.nan, p), "inf": np.where(np.arange(inst.n) == 1, np.inf, p),
           "text": np.array(["1"] * inst.n), "bool": p > 0, "ragged": [[1.0], [1.0, 2.0]]}[bad]
    for p_tol in (1e-6, None):
        refused(lambda: judge(inst, p, True, TOL, p_ref=ref, p_tol=p_tol), "p_ref", f"length-{inst.n}")
    assert judge(inst, p, True, TOL, p_ref=list(p), p_tol=1e-6).reading == "pass"  # a list of numbers is one


@pytest.mark.parametrize("p_tol", [-1, 0.0, -0.0, math.nan, math.inf, "1e-3", True])
def test_the_judge_refuses_a_p_tol_that_is_no_finite_number_above_0(
        solved: tuple[ContactInstance, np.ndarray], p_tol: Any) -> None:
    inst, p = solved
    refused(lambda: judge(inst, p, True, TOL, p_ref=p, p_tol=p_tol), "p_tol")
    assert judge(inst, p, True, TOL, p_ref=p, p_tol=1e-9).reading == "pass"


# -- solve_sequence ---------------------------------------------------------------------


@pytest.mark.parametrize("budget", [-1.0, 0, 0.0, math.nan, "10", True])
def test_solve_sequence_refuses_a_budget_that_is_not_above_0_before_any_solve(
        solved: tuple[ContactInstance, np.ndarray], budget: Any) -> None:
    inst, _ = solved
    solver = CountingExact()
    refused(lambda: solve_sequence(solver, [inst, inst], budget_s=budget, check_tol=TOL), "budget_s")
    assert solver.solves == 0
    assert len(solve_sequence(solver, [inst, inst], budget_s=None, check_tol=TOL)) == 2  # None: no budget


@pytest.mark.parametrize("count", [0, 1, 3])
def test_solve_sequence_refuses_references_that_are_not_one_per_step(
        solved: tuple[ContactInstance, np.ndarray], count: int) -> None:
    inst, p = solved
    solver = CountingExact()
    refused(lambda: solve_sequence(solver, [inst, inst], references=[p] * count, check_tol=TOL),
            f"{count} references for 2 steps")
    assert solver.solves == 0  # steps with a length: refused before any solve

    def steps() -> Iterator[ContactInstance]:
        yield inst
        yield inst

    solver = CountingExact()
    refused(lambda: solve_sequence(solver, steps(), references=[p] * count, check_tol=TOL), f"{count} references")
    assert solver.solves == min(count, 2)  # an iterable: before the step beyond them, or once the steps run out
    out = solve_sequence(solver, steps(), references=[p, None], check_tol=TOL)
    assert "p_rel_error" in out[0].verdict.figures and "p_rel_error" not in out[1].verdict.figures


# -- the registry -----------------------------------------------------------------------


def test_unregister_of_an_unknown_name_is_a_key_error_naming_it_unless_missing_ok() -> None:
    with pytest.raises(KeyError, match="'test-no-such-solver'"):
        unregister("test-no-such-solver")
    assert unregister("test-no-such-solver", missing_ok=True) is None
    for fn in (unregister, available_solvers):
        assert inspect.getdoc(fn), fn.__name__
    assert "KeyError" in (inspect.getdoc(unregister) or "")
    assert "availability" in (inspect.getdoc(available_solvers) or "")
