"""The pytest plugin refuses what the command line refuses, and touches nothing it refuses.

* ``run_harness`` into a folder that is not a run folder leaves the user's own run.lock
  (and everything else) as it is;
* a solver list that names no solver ("", ",", " , ", []) is the plan's refusal, so
  ``plan_run``, ``run_benchmark`` and ``run_harness`` give the same line;
* ``contact_instance`` names a keyword its kind does not take, and refuses a step outside
  the sequence instead of wrapping it around."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import pytest

from contactbench.harness.run.plan import PlanError, RunConfig, plan_run
from contactbench.harness.table.store import LOCK_FILE, RunFolderError
from contactbench.problems.errors import ProblemInputError
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
