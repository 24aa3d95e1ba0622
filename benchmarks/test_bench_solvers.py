"""pytest-benchmark over every registered solver (parametrized from the registry: a newly
registered solver is benchmarked with no edit here).

    pytest --benchmark-only --benchmark-enable benchmarks/                      # run
    pytest --benchmark-only --benchmark-enable benchmarks/ --benchmark-json=b.json

Each round solves a fresh problem (a new operator object, so no state carries over;
``benchmark.pedantic(setup=...)``).  The answer of the last round is judged by the
harness's ``judge`` against the exact reference, and the judge's reading decides the
test, as in ``contactbench validate``:

* "pass"        -- the test passes; the figures go to ``benchmark.extra_info`` and so
                   into the JSON output;
* "wrong"       -- the solver claimed convergence but the answer fails the judge: a test
                   FAILURE whose message carries the KKT figures;
* "unconverged" -- the solver honestly reported no convergence: an ``xfail`` with the
                   judge's reason.

A solver whose method is known to fail on an instance's family (``Solver.refuted_on``:
greedy on the paper's Example 1) is a strict expected failure there: the draw below
(seed 1) is one on which the method claims a wrong answer, and an XPASS fails the test
(the draw no longer shows what it is here to show).

Pairs the harness would skip (``harness.skips``: capabilities, memory or time model,
missing package, the solver's own ``skip``) are skipped with the same reason, and so is a
solver whose declared accuracy floor is above the profile's check (``Profile.floor_skip``).
"""

from __future__ import annotations

import os
from functools import lru_cache
from typing import Any

import numpy as np
import pytest

from contactbench.harness.judging import ProblemSeal, judge
from contactbench.harness import get_profile
from contactbench.harness.pytest_plugin import settle
from contactbench.harness.run.skips import skip_decision
from contactbench.harness.run.worker import problem_traits
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, ContactInstance, counterexample
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import all_solvers, get_solver

PROFILE = os.environ.get("CONTACTBENCH_BENCH_PROFILE", "default")
TIME_LIMIT = float(os.environ.get("CONTACTBENCH_BENCH_TIMEOUT", "30"))
ROUNDS = int(os.environ.get("CONTACTBENCH_BENCH_ROUNDS", "3"))
INSTANCES = ("rmd-32-top", "counterexample-100-s1")


@lru_cache(maxsize=None)
def instance(name: str) -> ContactInstance:
    if name == "counterexample-100-s1":
        return counterexample(100, seed=1)
    if name == "rmd-32-top":
        scene = get_scene("paper-sweep")
        cfg = scene.config(SceneConfig(size=32, steps=3, seeds=(0,)))
        seq = scene.build(scene.instances(cfg)[0])
        return seq.at(len(seq) - 1)
    raise KeyError(name)


@lru_cache(maxsize=None)
def dense_matrix(name: str) -> np.ndarray:
    return instance(name).qp.H.to_dense()


@lru_cache(maxsize=None)
def reference(name: str) -> np.ndarray | None:
    """The exact answer (scipy-nnls on a dense H), or None if that solver is missing."""
    try:
        ref = get_solver("scipy-nnls")
    except KeyError:
        return None
    if not ref.availability()[0]:
        return None
    return ref.solve(fresh_qp(name, "dense"), SolverSettings(tol=1e-9)).p


def fresh_qp(name: str, operator: str) -> QP:
    """A new QP object per round: a new operator (matvec counters, caches start empty)."""
    inst = instance(name)
    ubar = inst.qp.ubar.copy()
    if operator == "dense":
        from contactbench.problems.operators import DenseOperator

        return QP(DenseOperator(dense_matrix(name)), ubar, inst.qp.geometry)
    return QP(inst.qp.H.restrict(np.arange(inst.n)), ubar, inst.qp.geometry)


@pytest.mark.parametrize("name", INSTANCES)
@pytest.mark.parametrize("solver_name", list(all_solvers()))
def test_solver(benchmark: Any, request: pytest.FixtureRequest, solver_name: str, name: str) -> None:
    inst = instance(name)
    decision = skip_decision(solver_name, problem_traits(inst), TIME_LIMIT, float(2**30))
    if decision.skip:
        pytest.skip(decision.reason)
    solver = get_solver(solver_name)
    floor = get_profile(PROFILE).floor_skip(solver)
    if floor:
        pytest.skip(floor)
    family = inst.meta.get("family")
    if family in solver.refuted_on:
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            f"{solver_name} is known to claim a wrong answer on the {family} family (Solver.refuted_on); "
            f"{name} is such a draw")))
    settings = get_profile(PROFILE).solver_settings(TIME_LIMIT)

    handed: list[tuple[QP, ProblemSeal]] = []  # each round's problem, sealed before its solve

    def setup() -> tuple[tuple[Any, ...], dict[str, Any]]:
        qp = fresh_qp(name, decision.operator)
        handed.append((qp, ProblemSeal.of(qp)))
        return (qp, settings, None), {}

    try:  # the warm-up round; a solver that refuses the instance with a clear error is skipped
        solver.solve(fresh_qp(name, decision.operator), settings, None)
    except ProblemInputError as exc:
        pytest.skip(f"{solver_name} refuses this instance: {exc}")
    result = benchmark.pedantic(solver.solve, setup=setup, rounds=ROUNDS, iterations=1, warmup_rounds=0)
    qp, seal = handed[-1]
    verdict = judge(inst, result.p, bool(result.converged), get_profile(PROFILE).check_tol,
                    p_ref=reference(name), tampered=seal.broken(qp))
    info: dict[str, Any] = {
        "solver": solver_name, "instance": name, "n": inst.n, "profile": PROFILE, "operator": decision.operator,
        "iterations": int(result.iterations), "solver_converged": bool(result.converged),
        "solved": verdict.status == "solved", "verdict": verdict.reading, **verdict.figures,
    }
    benchmark.extra_info.update(info)
    settle(verdict, f"{solver_name} on {name} (n = {inst.n}, profile {PROFILE})", result.message)
