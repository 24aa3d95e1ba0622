"""The pytest plugin refuses what the command line refuses, and touches nothing it refuses.

* ``run_harness`` into a folder that is not a run folder leaves the user's own run.lock
  (and everything else) as it is;
* a solver list that names no solver ("", ",", " , ", []) is the plan's refusal, so
  ``plan_run``, ``run_benchmark`` and ``run_harness`` give the same line;
* ``contact_instance`` names a keyword its kind does not take, and refuses a step outside
  the sequence instead of wrapping it around, an integer keyword that is not an int
  (never rounded or parsed) and an instance over the memory budget (before building it),
  each in one ``ProblemInputError`` line; the problem it hands out is read-only;
* ``contactbench_solve`` judges a solver's answer on a sealed copy: a solver that writes
  into its problem (in place, or by replacing ubar) fails the test;
* ``run_harness`` names an unknown keyword and an ``extra`` key no scene reads;
* ``case_conforms`` and ``contactbench_conformance`` take a case by its name, and refuse
  what is not a case in one line."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.pytest_plugin import case_conforms, extra_keys
from tests.helpers import ExactStub as Exact
from contactbench.solvers import Outcome, SolveContext, Solver

from contactbench.harness.run.plan import PlanError, RunConfig, plan_run
from contactbench.harness.table.store import LOCK_FILE, RunFolderError
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.operators import memory_budget_scope
from contactbench.problems.scenes import SceneConfig


@pytest.mark.parametrize("text", ["", "my notes\n"])
def test_run_harness_leaves_a_refused_folder_and_its_run_lock(run_harness: Callable[..., Any], tmp_path: Path,
                                                              text: str) -> None:
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "data.txt").write_text("mine\n")
    (theirs / LOCK_FILE).write_text(text)
    with pytest.raises(RunFolderError, match="not a contactbench run folder"):
        run_harness(["counterexample"], solvers=["test-exact"], out=theirs, size=3, seeds=(0,), reference="none")
    assert sorted(p.name for p in theirs.iterdir()) == ["data.txt", LOCK_FILE]
    assert (theirs / LOCK_FILE).read_text() == text and (theirs / "data.txt").read_text() == "mine\n"


@pytest.mark.parametrize("solvers", ["", ",", " , ", []])
def test_a_solver_list_naming_no_solver_is_the_plans_refusal(solvers: Any) -> None:
    # (max_cells=1: a plan that took it for every solver stops at its size, not at running)
    with pytest.raises(PlanError, match="names no solver") as info:
        plan_run(["counterexample"], SceneConfig(size=3, seeds=(0,)), solvers, RunConfig(max_cells=1))
    assert len(info.value.problems) == 1


def test_run_harness_refuses_an_empty_solver_string(run_harness: Callable[..., Any], tmp_path: Path) -> None:
    out = tmp_path / "run"
    with pytest.raises(PlanError, match="names no solver"):
        run_harness(["counterexample"], solvers="", out=out, size=3, seeds=(0,), max_cells=1)
    assert not out.exists()


@pytest.mark.parametrize(("kind", "kw", "named"), [
    ("rmd", {"n": 100}, "n"),
    ("counterexample", {"N": 25}, "N"),
    ("counterexample", {"n": 4, "sede": 5}, "sede"),
])
def test_contact_instance_names_a_keyword_it_does_not_take(contact_instance: Callable[..., Any], kind: str,
                                                           kw: dict[str, Any], named: str) -> None:
    with pytest.raises(ProblemInputError, match=rf"unknown keyword\(s\) {named}\b") as info:
        contact_instance(kind, **kw)
    assert "\n" not in str(info.value)


def test_contact_instance_refuses_a_step_outside_the_sequence(contact_instance: Callable[..., Any]) -> None:
    for step in (3, 7, -4, -99):
        with pytest.raises(ProblemInputError, match=f"step {step} is outside the 3 load step"):
            contact_instance("rmd", N=16, steps=3, step=step)
    first, last = contact_instance("rmd", N=16, steps=3, step=-3), contact_instance("rmd", N=16, steps=3, step=2)
    assert first.meta["step"] == 0 and last.meta["step"] == 2


class ZeroWriter(Exact):
    """Makes p = 0 the answer by writing ubar <= 0 into its problem, in place where it can."""

    name = "test-guard-zero-writer"

    def iterate(self, ctx: SolveContext) -> Outcome:
        try:
            ctx.qp.ubar[...] = -1.0
        except ValueError:
            object.__setattr__(ctx.qp, "ubar", -np.ones(ctx.n))
        return Outcome(np.zeros(ctx.n), 1, True)


class Replacer(Exact):
    """The same, replacing ubar on the problem it is handed."""

    name = "test-guard-replacer"

    def iterate(self, ctx: SolveContext) -> Outcome:
        object.__setattr__(ctx.qp, "ubar", -np.ones(ctx.n))
        return Outcome(np.zeros(ctx.n), 1, True)


@pytest.mark.parametrize(("kind", "kw"), [("counterexample", {"n": 16, "seed": 1}), ("rmd", {"N": 17, "steps": 2})])
def test_contact_instance_hands_out_a_read_only_problem(contact_instance: Callable[..., Any], kind: str,
                                                        kw: dict[str, Any]) -> None:
    inst = contact_instance(kind, **kw)
    ubar = inst.qp.ubar
    with pytest.raises(ValueError, match="read-only"):
        ubar[...] = -1.0
    with pytest.raises(ValueError):
        ubar.setflags(write=True)
    if kind == "counterexample":
        with pytest.raises(ValueError, match="read-only"):
            inst.qp.H.H[0, 0] = 0.0
    assert bool(np.all(inst.qp.ubar == ubar)) and inst.qp.ubar is ubar


@pytest.mark.parametrize("solver", [ZeroWriter(), Replacer()], ids=lambda s: s.name)
def test_contactbench_solve_fails_a_solver_that_writes_into_its_problem(
        contact_instance: Callable[..., Any], contactbench_solve: Callable[..., Any], solver: Solver) -> None:
    inst = contact_instance("counterexample", n=16, seed=1)
    ubar = np.array(inst.qp.ubar)
    with pytest.raises(pytest.fail.Exception, match="wrote into the problem it was handed") as failed:
        contactbench_solve(solver, inst)
    assert "\n" not in str(failed.value)
    assert np.array_equal(inst.qp.ubar, ubar)  # (the judge's copy is untouched)
    done = contactbench_solve(Exact(), inst)
    assert done.verdict.reading == "pass" and done.result.converged


def test_contactbench_solve_refuses_what_is_not_an_instance(contactbench_solve: Callable[..., Any]) -> None:
    with pytest.raises(ProblemInputError, match="inst must be a ContactInstance"):
        contactbench_solve(Exact(), "counterexample")


def test_contact_instance_refuses_an_instance_over_the_memory_budget(contact_instance: Callable[..., Any]) -> None:
    with pytest.raises(ProblemInputError, match=r"n = 1000000\) needs at least .* over the memory budget of 8 GiB"):
        contact_instance("counterexample", n=10**6)
    with memory_budget_scope(2.0**20), pytest.raises(
            ProblemInputError, match=r"contact_instance\('rmd'\): its largest instance \(N = 257\) needs at least .* "
                                     r"over the memory budget of 0.000977 GiB \(CONTACTBENCH_MEMORY_BUDGET_GB\)"):
        contact_instance("rmd", N=257, steps=1)


@pytest.mark.parametrize(("kind", "kw", "named"), [
    ("rmd", {"N": 17.9}, "N"), ("rmd", {"N": "17"}, "N"), ("rmd", {"N": "abc"}, "N"), ("rmd", {"seed": 0.7}, "seed"),
    ("rmd", {"steps": 2.0}, "steps"), ("rmd", {"step": True}, "step"), ("rmd", {"N": np.float64(17)}, "N"),
    ("counterexample", {"n": 16.5}, "n"), ("counterexample", {"seed": 1.2}, "seed"),
    ("counterexample", {"seed": np.True_}, "seed"),
])
def test_contact_instance_refuses_an_integer_keyword_that_is_no_int(contact_instance: Callable[..., Any], kind: str,
                                                                   kw: dict[str, Any], named: str) -> None:
    with pytest.raises(ProblemInputError, match=rf"{named} must be an integer, got") as info:
        contact_instance(kind, **kw)
    assert repr(kw[named]) in str(info.value) and "\n" not in str(info.value)


def test_contact_instance_takes_numpy_integers(contact_instance: Callable[..., Any]) -> None:
    a = contact_instance("counterexample", n=np.int64(16), seed=np.int32(1))
    b = contact_instance("counterexample", n=16, seed=1)
    assert np.array_equal(a.qp.ubar, b.qp.ubar)


def test_contact_instance_refuses_an_unknown_kind_in_one_line(contact_instance: Callable[..., Any]) -> None:
    with pytest.raises(ProblemInputError, match="unknown instance kind 'nope'"):
        contact_instance("nope")


SMALL = {"solvers": ["test-exact"], "size": 3, "seeds": (0,), "reference": "none"}


@pytest.mark.parametrize(("options", "named"), [
    ({"extra": {"bogus": 1}}, "'bogus'"), ({"extra": {"heigth_unit": "um"}}, "'heigth_unit'"),
    ({"extra": {"hurts": 0.5}}, "'hurts'"), ({"bogus": 1}, "bogus"),
    ({"height_unit": "um"}, "height_unit"), ({"timeout": "abc"}, "timeout"),
])
def test_run_harness_names_an_option_it_does_not_know(run_harness: Callable[..., Any], tmp_path: Path,
                                                       options: dict[str, Any], named: str) -> None:
    out = tmp_path / "run"
    with pytest.raises(ProblemInputError, match=named) as info:
        run_harness(["counterexample"], out=out, **{**SMALL, **options})
    assert "\n" not in str(info.value)
    assert not out.exists()


def test_the_extra_keys_a_scene_reads_are_taken() -> None:
    assert {"sizes"} <= extra_keys(["counterexample"])
    assert {"hurst", "height_unit"} - extra_keys(["paper-sweep"]) == {"height_unit"}  # (an option, not a scene's)
    assert {"hursts"} <= extra_keys(["cmr"])


CASE = "counterexample/example1-n400-s0"


def test_a_case_may_be_given_by_its_name(contactbench_conformance: Callable[..., Any]) -> None:
    assert case_conforms(Exact(), CASE, isolate=False).ok
    assert contactbench_conformance(Exact(), [CASE], isolate=False).ok
    assert [r.case for r in cf.validate(Exact(), CASE, isolate=False).rows] == [CASE]


@pytest.mark.parametrize(("case", "words"), [
    ("counterexample/no-such-case", "no conformance case is named 'counterexample/no-such-case'"),
    (5, "a conformance case is a ConformanceCase .* got int 5"),
])
def test_what_is_not_a_case_is_refused_in_one_line(contactbench_conformance: Callable[..., Any], case: Any,
                                                   words: str) -> None:
    with pytest.raises(ProblemInputError, match=words):
        case_conforms(Exact(), case, isolate=False)
    with pytest.raises(ProblemInputError, match=words):
        contactbench_conformance(Exact(), [case], isolate=False)
