"""pytest-benchmark over every registered solver (parametrized from the registry: a newly
registered solver is benchmarked with no edit here) on two small instances.

    pytest --benchmark-only --benchmark-enable benchmarks/                      # run
    pytest --benchmark-only --benchmark-enable benchmarks/ --benchmark-json=b.json
    CONTACTBENCH_BENCH_ROUNDS=1 pytest --benchmark-only --benchmark-enable benchmarks/ -k "nnls-gp and counterexample"

The settings (profile, time limit, rounds) come from CONTACTBENCH_BENCH_PROFILE,
CONTACTBENCH_BENCH_TIMEOUT and CONTACTBENCH_BENCH_ROUNDS, checked once when pytest
configures (benchmarks/conftest.py).

Every solve of a benchmark -- the untimed warm-up (``pedantic(warmup_rounds=1)``) and each
timed round -- is, outside the clock (``pedantic``'s ``setup`` and ``teardown``):

* handed its own copy of the problem (a deep copy: a new operator with its own arrays, so
  no state carries over and nothing it writes reaches another solve) and of the settings;
* sealed (``ProblemSeal``, with the harness's copy of the instance beside it: a solver
  reaches every object of its process) and watched for the threads it leaves running
  (``threads_left``, the rule of ``contactbench run`` and ``validate``): either makes the
  answer "wrong", naming what it changed or the threads;
* judged by the harness's ``judge`` on the harness's pristine copy, against the exact
  reference (scipy-nnls).

The first solve the judge does not pass decides the test, as in ``contactbench validate``:

* "wrong"       -- a failing answer claimed as converged, a problem written into or
                   threads left running: a test FAILURE whose message carries the KKT
                   figures and says which solve;
* "unconverged" -- the solver honestly reported no convergence: an ``xfail`` with the
                   judge's reason;
* every solve "pass" -- the test passes; the last round's figures go to
  ``benchmark.extra_info`` and so into the JSON output.

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

import contextlib
import copy
import signal
import threading
import time
from dataclasses import dataclass
from functools import lru_cache
from types import FrameType
from typing import Any, Iterator

import numpy as np
import pytest

from contactbench.harness import get_profile
from contactbench.harness.conformance.cases import kill_limit
from contactbench.harness.judging import ProblemSeal, Verdict, judge
from contactbench.harness.pytest_plugin import settle
from contactbench.harness.run.skips import skip_decision
from contactbench.harness.run.worker import problem_traits, running_threads, threads_left
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, ContactInstance, counterexample
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import Solver, SolverSettings, SolveResult
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
    """A deep copy of the instance's problem, with a new operator (matvec counters, caches
    start empty; ``operator`` "dense": H assembled): nothing in it is shared with the
    harness's copy or with another solve."""
    qp = instance(name).qp
    H = DenseOperator(qp.H.to_dense()) if operator == "dense" else qp.H.restrict(np.arange(qp.H.n))
    return copy.deepcopy(QP(H, qp.ubar, qp.geometry, qp.constraints))


class SolveTimeout(BaseException):
    """A solve stopped by the ``Watchdog`` (a ``BaseException``: a solver's ``except
    Exception`` does not swallow it)."""


@dataclass
class Watchdog:
    """A hard limit of ``seconds`` on each solve: ``arm`` before it, ``disarm`` after it,
    inside ``installed`` (module doc: what it cannot stop)."""

    seconds: float
    active: bool = False

    @contextlib.contextmanager
    def installed(self) -> Iterator[Watchdog]:
        """SIGALRM raises ``SolveTimeout`` while armed; the handler and any timer set before
        (another plugin's) are put back after."""
        if not hasattr(signal, "SIGALRM") or threading.current_thread() is not threading.main_thread():
            yield self
            return
        previous = signal.signal(signal.SIGALRM, self.fire)
        held, t0 = signal.setitimer(signal.ITIMER_REAL, 0), time.monotonic()
        self.active = True
        try:
            yield self
        finally:
            self.disarm()
            self.active = False
            signal.signal(signal.SIGALRM, previous)
            if held[0] > 0:
                signal.setitimer(signal.ITIMER_REAL, max(held[0] - (time.monotonic() - t0), 1e-3), held[1])

    def arm(self) -> None:
        if self.active:
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def disarm(self) -> None:
        if self.active:
            signal.setitimer(signal.ITIMER_REAL, 0)

    def fire(self, signum: int, frame: FrameType | None) -> None:
        raise SolveTimeout(f"no answer within the hard limit of {self.seconds:.3g} s")


@dataclass(eq=False)
class Solve:
    """One solve (the ``index``-th of its benchmark, the warm-up 0): its own problem, its
    seal, the threads before it, its result."""

    index: int
    qp: QP
    seal: ProblemSeal
    threads: set[int]
    result: SolveResult | None = None
    judged: bool = False


@dataclass
class Rounds:
    """The solves of one benchmark (module doc): ``setup`` hands each its problem, ``solve``
    is the timed call, ``teardown`` judges it; a solve the judge does not pass settles the
    test there (``settle``)."""

    solver: Solver
    name: str
    operator: str
    settings: SolverSettings
    check_tol: float
    watchdog: Watchdog
    what: str
    first_timed: int  # the index of the first timed solve (0 when pytest-benchmark is disabled)

    def __post_init__(self) -> None:
        self.solves: list[Solve] = []
        self.verdict: Verdict | None = None

    def setup(self) -> tuple[tuple[Solve, SolverSettings], dict[str, Any]]:
        qp = fresh_qp(self.name, self.operator)
        solve = Solve(len(self.solves), qp, ProblemSeal.of(qp, [instance(self.name).qp]), running_threads())
        self.solves.append(solve)
        self.watchdog.arm()
        return (solve, copy.deepcopy(self.settings)), {}

    def solve(self, solve: Solve, settings: SolverSettings) -> SolveResult:
        solve.result = self.solver.solve(solve.qp, settings, None)
        return solve.result

    def teardown(self, solve: Solve, settings: SolverSettings) -> None:
        self.watchdog.disarm()
        self.judge(solve)

    def label(self, index: int) -> str:
        if self.first_timed == 0:
            return "in its one solve (pytest-benchmark disabled)"
        if index < self.first_timed:
            return "in its untimed warm-up solve"
        return f"in timed round {index - self.first_timed + 1}"

    def fault(self, solve: Solve) -> str:
        """What ``solve`` changed in the problems (handed or the harness's), else the threads
        it left running; "" neither.  A problem written into is rebuilt for the next test."""
        solve.judged = True
        left = threads_left(solve.threads)
        broken = solve.seal.broken(solve.qp)
        solve.seal.mend(solve.qp)
        if broken:
            instance.cache_clear()
        return broken or left

    def judge(self, solve: Solve) -> None:
        assert solve.result is not None
        fault, res = self.fault(solve), solve.result
        self.verdict = judge(instance(self.name), res.p, bool(res.converged), self.check_tol,
                             p_ref=reference(self.name), tampered=fault, multiplier=res.multiplier)
        settle(self.verdict, f"{self.what} {self.label(solve.index)}", res.message)

    def judge_pending(self) -> None:
        """Judge the solves ``teardown`` did not (pytest-benchmark disabled runs none)."""
        for solve in self.solves:
            if not solve.judged:
                self.judge(solve)

    def unfinished(self) -> tuple[str, str]:
        """(label, fault) of the solve that raised or was stopped (``fault``)."""
        self.watchdog.disarm()
        solve = self.solves[-1]
        return self.label(solve.index), self.fault(solve)


@pytest.mark.parametrize("name", INSTANCES)
@pytest.mark.parametrize("solver_name", list(all_solvers()))
def test_solver(judged_benchmark: Any, bench_settings: Any, request: pytest.FixtureRequest, solver_name: str,
                name: str) -> None:
    benchmark = judged_benchmark.benchmark
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
    reference(name)  # (solved before any solve of the solver's)
    what = f"{solver_name} on {name} (n = {inst.n}, profile {profile.name})"
    watchdog = Watchdog(kill_limit(bench_settings.time_limit))
    rounds = Rounds(solver, name, decision.operator, profile.solver_settings(bench_settings.time_limit),
                    profile.check_tol, watchdog, what, first_timed=0 if getattr(benchmark, "disabled", False) else 1)
    failure = refusal = ""  # (settled after the except blocks: a message without their traceback)
    with watchdog.installed():
        try:
            benchmark.pedantic(rounds.solve, setup=rounds.setup, teardown=rounds.teardown,
                               rounds=bench_settings.rounds, iterations=1, warmup_rounds=1)
        except SolveTimeout as exc:
            where, fault = rounds.unfinished()
            failure = (f"{what} {where}: timeout: {exc} (the time limit {bench_settings.time_limit:g} s plus the "
                       f"grace); the solve was stopped" + (f"; {fault}" if fault else ""))
        except ProblemInputError as exc:
            where, fault = rounds.unfinished()
            if fault or len(rounds.solves) > 1:
                failure = f"{what} {where}: raised ProblemInputError: {exc}" + (f"; {fault}" if fault else "")
            else:
                refusal = f"{solver_name} refuses this instance: {exc}"
        except Exception:
            where, fault = rounds.unfinished()
            if fault:
                pytest.fail(f"{what} {where}: raised, and {fault}")
            raise
        if not (failure or refusal):
            rounds.judge_pending()
    if failure:
        pytest.fail(failure, pytrace=False)
    if refusal:
        pytest.skip(refusal)
    assert rounds.verdict is not None and rounds.solves[-1].result is not None
    result, verdict = rounds.solves[-1].result, rounds.verdict
    benchmark.extra_info.update({
        "solver": solver_name, "instance": name, "n": inst.n, "profile": profile.name, "operator": decision.operator,
        "iterations": int(result.iterations), "solver_converged": bool(result.converged),
        "solves_judged": len(rounds.solves), "solved": verdict.status == "solved", "verdict": verdict.reading,
        **verdict.figures,
    })
    judged_benchmark.passed()


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
