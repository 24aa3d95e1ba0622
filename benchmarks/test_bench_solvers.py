"""pytest-benchmark over every registered solver (parametrized from the registry: a newly
registered solver is benchmarked with no edit here) on two small instances.

    pytest --benchmark-only --benchmark-enable benchmarks/                      # run
    pytest --benchmark-only --benchmark-enable benchmarks/ --benchmark-json=b.json
    CONTACTBENCH_BENCH_ROUNDS=1 pytest --benchmark-only --benchmark-enable benchmarks/ -k "nnls-gp and counterexample"

The settings (profile, time limit, rounds) come from CONTACTBENCH_BENCH_PROFILE,
CONTACTBENCH_BENCH_TIMEOUT and CONTACTBENCH_BENCH_ROUNDS, checked once when pytest
configures (benchmarks/conftest.py).

Each benchmark is ``JudgedBenchmark.run`` (``harness.judged_benchmark``, the rule a user's
own benchmark gets through the pytest plugin): every solve -- the untimed warm-up
(``pedantic(warmup_rounds=1)``) and each timed round -- is, outside the clock
(``pedantic``'s ``setup`` and ``teardown``):

* handed a problem no earlier solve saw: the instance scaled by a factor of its own
  (ubar, the bounds and the load; its answer scales alike), a deep copy with a new
  operator, so no state carries over, nothing it writes reaches another solve and a
  solver that memoises answers across solves gains nothing; and a copy of the settings;
* sealed (``ProblemSeal``, with the harness's copies of the instance beside it: a solver
  reaches every object of its process) and watched for the threads it leaves running
  (``threads_left``, the rule of ``contactbench run`` and ``validate``): either makes the
  answer "wrong", naming what it changed or the threads;
* judged by the harness's ``judge`` on the harness's scaled copy, against the exact
  reference (scipy-nnls) scaled alike.

The first solve the judge does not pass decides the test, as in ``contactbench validate``:

* "wrong"       -- a failing answer claimed as converged, a problem written into or
                   threads left running: a test FAILURE whose message carries the KKT
                   figures and says which solve;
* "unconverged" -- the solver honestly reported no convergence: an ``xfail`` with the
                   judge's reason;
* every solve "pass" -- the test passes; the last round's figures (read back on the
  instance as built) go to ``benchmark.extra_info`` and so into the JSON output.

Timed rounds over 10 times faster than the untimed warm-up are checked with one more
untimed solve, of a perturbed problem: when it too is that slow, the solver carried work
across solves (a cache) and the test fails naming the times.

A timing counts only when every solve passed: any other benchmark (failed, xfailed, timed
out, crashed) is left out of the timing table and the JSON (benchmarks/conftest.py).

A solve still running beyond ``kill_limit`` of the time limit (``Watchdog``: SIGALRM, in the
main thread on POSIX) is stopped and the test fails as a timeout.  The watchdog raises in
the solver's Python code: it cannot stop a C loop that never returns to Python, nor a
solver that catches ``BaseException``; where SIGALRM is missing (Windows) or pytest runs
the test outside the main thread there is no hard limit.  Threads a solve leaves running
cannot be stopped either: the test fails naming them, and Python waits for the
non-daemon ones when pytest exits.

A solver module that fails to import (an entry point whose module raises, an external
solver manifest that cannot be read) is a failing ``test_solver_module_imports`` item
naming the module and its error (``registry.import_errors``), as ``contactbench list
solvers`` reports it.

A solver whose method is known to fail on an instance's family (``Solver.refuted_on``:
greedy on the paper's Example 1) is a strict expected failure there: the draw below
(seed 1) is one on which the method claims a wrong answer, and an XPASS fails the test
(the draw no longer shows what it is here to show).

Pairs the harness would skip (``harness.skips``: capabilities, memory or time model,
missing package, the solver's own ``skip``) are skipped with the same reason, and so is a
solver whose declared accuracy floor is above the profile's check (``Profile.floor_skip``)
or that refuses the instance in its first solve with a ``ProblemInputError``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
import pytest

from contactbench.harness import get_profile
from contactbench.harness.judged_benchmark import JudgedBenchmark, handed_copy
from contactbench.harness.run.skips import skip_decision
from contactbench.harness.run.worker import problem_traits
from contactbench.problems.instances import QP, ContactInstance, counterexample
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import all_solvers, get_solver, import_errors

INSTANCES = ("rmd-32-top", "counterexample-100-s1")


@lru_cache(maxsize=None)
def instance(name: str) -> ContactInstance:
    """The harness's copy of instance ``name``: solvers get deep copies (``fresh_qp``)."""
    if name == "counterexample-100-s1":
        return counterexample(100, seed=1)
    if name == "rmd-32-top":
        scene = get_scene("paper-sweep")
        cfg = scene.config(SceneConfig(size=32, steps=3, seeds=(0,)))
        seq = scene.build(scene.instances(cfg)[0])
        return seq.at(len(seq) - 1)
    raise KeyError(name)


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
    """A deep copy of the instance's problem, with a new operator (``handed_copy``)."""
    return handed_copy(instance(name).qp, operator)


@pytest.mark.parametrize("name", INSTANCES)
@pytest.mark.parametrize("solver_name", list(all_solvers()))
def test_solver(contactbench_benchmark: JudgedBenchmark, bench_settings: Any, request: pytest.FixtureRequest,
                solver_name: str, name: str) -> None:
    inst = instance(name)
    decision = skip_decision(solver_name, problem_traits(inst), bench_settings.time_limit, float(2**30))
    if decision.skip:
        pytest.skip(decision.reason)
    solver = get_solver(solver_name)
    profile = get_profile(bench_settings.profile)
    floor = profile.floor_skip(solver)
    if floor:
        pytest.skip(floor)
    family = inst.meta.get("family")
    if family in solver.refuted_on:
        request.applymarker(pytest.mark.xfail(strict=True, reason=(
            f"{solver_name} is known to claim a wrong answer on the {family} family (Solver.refuted_on); "
            f"{name} is such a draw")))
    ref = reference(name)  # (solved before any solve of the solver's)
    what = f"{solver_name} on {name} (n = {inst.n}, profile {profile.name})"
    try:
        contactbench_benchmark.run(solver, inst, profile.solver_settings(bench_settings.time_limit),
                             rounds=bench_settings.rounds, check_tol=profile.check_tol, reference=ref,
                             operator=decision.operator, time_limit=bench_settings.time_limit, what=what)
    finally:
        if contactbench_benchmark.problem_written:
            instance.cache_clear()  # (a write may have reached the harness's copy: built again for the next test)
    contactbench_benchmark.benchmark.extra_info.update({
        "solver": solver_name, "instance": name, "n": inst.n, "profile": profile.name, "operator": decision.operator,
    })


@pytest.mark.filterwarnings("ignore:Benchmark fixture was not used")
@pytest.mark.parametrize("module", sorted(import_errors()) or [
    pytest.param("", id="none", marks=pytest.mark.skip(reason="every solver source loaded"))])
def test_solver_module_imports(benchmark: Any, module: str) -> None:
    """A solver module that failed to import fails here, naming its error: its solvers are
    missing from ``test_solver`` (``benchmark`` is requested so that ``--benchmark-only``
    runs this test)."""
    error = import_errors()[module].strip().splitlines() or ["(no message)"]
    pytest.fail(f"solver source {module} failed to load, so its solvers are not benchmarked: {error[-1]}",
                pytrace=False)
