"""The pytest plugin's solves hold against a solver that attacks the route it is timed or
judged by.

* ``contactbench_benchmark.run`` judges at ``settings.check_tol`` and stops a solve past
  the hard limit of ``settings.time_limit`` (a keyword that differs from the settings' is
  refused), and the solver is handed the limits it is judged and stopped by;
* ``contactbench_solve`` stops a solve past its hard limit (``settings.time_limit``, else
  ``SOLVE_TIME_LIMIT``);
* a benchmark's figures are those of the answer the judge read, not of a buffer the
  solver wrote again later; a read-back that does not pass fails the item;
* both put back the working folder, the environment and NumPy's error handling after
  each solve, and end the processes it started -- the cache check's solves included;
* ``contactbench_settle`` fails a hand judge on a ``contact_instance`` problem whose
  operator a solver replaced a product of;
* ``settle`` words an unclaimed "wrong" by the verdict's own reason."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness import judged_benchmark as jb
from contactbench.harness import pytest_plugin
from contactbench.harness.judged_benchmark import PASSED_KEY, JudgedBenchmark
from contactbench.harness.judging import judge
from contactbench.harness.outcomes import settle
from contactbench.harness.pytest_plugin import judged_solve
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import ContactInstance, counterexample
from contactbench.solvers import Capabilities, Outcome, Solver, SolverSettings
from contactbench.solvers.base import SolveContext
from tests.helpers import dense_exact_solution


@dataclass
class FakeBenchmark:
    """What ``JudgedBenchmark`` uses of pytest-benchmark's fixture: ``pedantic`` runs the
    warm-up and the rounds as pytest-benchmark does (setup, the call, teardown)."""

    has_error: bool = False
    extra_info: dict[str, Any] = field(default_factory=dict)

    def pedantic(self, target: Callable[..., Any], setup: Callable[[], Any], teardown: Callable[..., None],
                 rounds: int, iterations: int, warmup_rounds: int) -> Any:
        try:
            for _ in range(warmup_rounds + rounds):
                args, kwargs = setup()
                result = target(*args, **kwargs)
                teardown(*args, **kwargs)
            return result
        except Exception:
            self.has_error = True
            raise


class Exact(Solver):
    """The exact answer; records the settings each solve is handed."""

    name = "test-attack-exact"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True, input_format="dense")

    def __init__(self) -> None:
        super().__init__()
        self.handed: list[tuple[float | None, float | None]] = []

    def solve(self, qp: Any, settings: Any = None, warm: Any = None) -> Any:
        self.handed.append((settings.check_tol, settings.time_limit) if settings is not None else (None, None))
        return super().solve(qp, settings, warm)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(dense_exact_solution(ctx.qp), 1, True)


class Rounded(Exact):
    """The exact answer rounded to float32 (handed back as float64): kkt about 1e-8."""

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(dense_exact_solution(ctx.qp).astype(np.float32).astype(np.float64), 1, True)


class Stalls(Exact):
    """Ignores its time limit: runs 4 s in Python before its exact answer."""

    def iterate(self, ctx: SolveContext) -> Outcome:
        end = time.monotonic() + 4.0
        while time.monotonic() < end:
            time.sleep(0.02)
        return super().iterate(ctx)


class OneBuffer(Exact):
    """A slow first call (a one-off cost: the cache check runs), then fast; every answer
    is written into the one buffer it hands back."""

    def __init__(self) -> None:
        super().__init__()
        self.buffer: np.ndarray | None = None

    def iterate(self, ctx: SolveContext) -> Outcome:
        if self.buffer is None:
            time.sleep(0.3)
            self.buffer = np.empty(ctx.n)
        self.buffer[:] = dense_exact_solution(ctx.qp)
        return Outcome(self.buffer, 1, True)


VARIABLE = "CONTACTBENCH_TEST_PLUGIN_ATTACK"


class Meddler(Exact):
    """The exact answer; from call ``first`` on, it also changes the working folder, the
    environment and NumPy's error handling, and starts a process that outlives it.  A slow
    first call (``slow``) makes a benchmark's cache check run."""

    def __init__(self, first: int = 1, slow: bool = False) -> None:
        super().__init__()
        self.first, self.slow, self.calls = first, slow, 0
        self.children: list[subprocess.Popen[bytes]] = []

    def iterate(self, ctx: SolveContext) -> Outcome:
        self.calls += 1
        if self.slow and self.calls == 1:
            time.sleep(0.3)
        if self.calls >= self.first:
            os.chdir("/")
            os.environ[VARIABLE] = "1"
            np.seterr(all="raise")
            self.children.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"]))
        return super().iterate(ctx)


class Poison(Exact):
    """Answers p = 0 claimed as converged and replaces the product of the operator it is
    handed so that H p - ubar reads 0 there."""

    def iterate(self, ctx: SolveContext) -> Outcome:
        ubar = np.array(ctx.qp.ubar, dtype=np.float64)
        ctx.qp.H.matvec = lambda x: ubar.copy()
        return Outcome(np.zeros(ctx.n), 1, True)


@pytest.fixture(scope="module")
def inst() -> ContactInstance:
    return counterexample(49, seed=1)


# -- the settings' check_tol and time_limit -----------------------------------------------


def test_a_benchmark_is_judged_at_the_settings_check_tol(inst: ContactInstance) -> None:
    assert JudgedBenchmark(FakeBenchmark()).run(Rounded(), inst, rounds=1).reading == "pass"  # (1e-6)
    bench = FakeBenchmark()
    with pytest.raises(pytest.fail.Exception, match="kkt_error .* > check_tol 1e-10"):
        JudgedBenchmark(bench).run(Rounded(), inst, SolverSettings(check_tol=1e-10), rounds=1)
    assert bench.has_error and bench.extra_info[PASSED_KEY] is False


@pytest.mark.parametrize(("field", "given", "keyword"), [("check_tol", 1e-10, 1e-6), ("time_limit", 1.0, 5.0)])
def test_a_keyword_that_differs_from_the_settings_is_refused(inst: ContactInstance, field: str, given: float,
                                                             keyword: float) -> None:
    solver = Exact()
    with pytest.raises(ProblemInputError, match=f"{field}={keyword!r} differs from the settings' {field}") as info:
        JudgedBenchmark(FakeBenchmark()).run(solver, inst, SolverSettings(**{field: given}), rounds=1,
                                             **{field: keyword})
    assert "\n" not in str(info.value) and solver.handed == []


def test_the_solver_is_handed_the_limits_it_is_judged_and_stopped_by(inst: ContactInstance) -> None:
    solver = Exact()
    JudgedBenchmark(FakeBenchmark()).run(solver, inst, SolverSettings(tol=1e-9), rounds=1, check_tol=1e-7,
                                         time_limit=5.0, warmup_speedup=None)
    assert solver.handed == [(1e-7, 5.0)] * 2
    other = Exact()
    JudgedBenchmark(FakeBenchmark()).run(other, inst, SolverSettings(check_tol=1e-7, time_limit=5.0), rounds=1,
                                         check_tol=1e-7, time_limit=5.0, warmup_speedup=None)
    assert other.handed == [(1e-7, 5.0)] * 2


def test_a_benchmark_stops_a_solve_past_the_settings_time_limit(inst: ContactInstance) -> None:
    bench, t0 = FakeBenchmark(), time.monotonic()
    with pytest.raises(pytest.fail.Exception, match=r"untimed warm-up solve: timeout: .*time limit 0\.1 s"):
        JudgedBenchmark(bench).run(Stalls(), inst, SolverSettings(time_limit=0.1), rounds=1)
    assert time.monotonic() - t0 < 3.5 and bench.has_error


def test_contactbench_solve_stops_a_solve_past_its_time_limit(inst: ContactInstance,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    t0 = time.monotonic()
    with pytest.raises(pytest.fail.Exception, match=r"timeout: .*time limit 0\.1 s"):
        judged_solve(Stalls(), inst, SolverSettings(time_limit=0.1))
    monkeypatch.setattr(pytest_plugin, "SOLVE_TIME_LIMIT", 0.1)  # (no limit named: the default one)
    with pytest.raises(pytest.fail.Exception, match=r"timeout: .*time limit 0\.1 s"):
        judged_solve(Stalls(), inst)
    assert time.monotonic() - t0 < 7.0
    solver = Exact()
    assert judged_solve(solver, inst).verdict.reading == "pass" and solver.handed == [(1e-6, 0.1)]


# -- the answer read back is the one judged ------------------------------------------------


def test_a_benchmark_reads_back_the_answer_it_judged(inst: ContactInstance) -> None:
    """The cache check's solves write the solver's one buffer again after the last timed
    round was judged: its figures are still that round's answer's."""
    bench = FakeBenchmark()
    verdict = JudgedBenchmark(bench).run(OneBuffer(), inst, rounds=2)
    assert bench.extra_info["solves_judged"] > 3  # (the cache check ran)
    assert verdict.reading == "pass" and bench.extra_info["verdict"] == "pass" and bench.extra_info["solved"]


def test_a_read_back_that_does_not_pass_fails_the_item(inst: ContactInstance, monkeypatch: pytest.MonkeyPatch) -> None:
    def wrong_read_back(inst: ContactInstance, *args: Any) -> Any:
        return judge(inst, np.zeros(inst.n), True, 1e-6)

    monkeypatch.setattr(jb, "read_back", wrong_read_back)
    bench = FakeBenchmark()
    with pytest.raises(pytest.fail.Exception, match="read back on the instance as given"):
        JudgedBenchmark(bench).run(Exact(), inst, rounds=1, warmup_speedup=None)
    assert bench.has_error and bench.extra_info[PASSED_KEY] is False


# -- the process's state and processes after each solve ------------------------------------


@pytest.fixture
def meddled(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Any:
    """The test runs in ``tmp_path`` without ``VARIABLE``; NumPy's error handling and any
    process a ``Meddler`` left are put back and ended after it."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(VARIABLE, raising=False)
    errors, solvers = np.geterr(), []
    yield solvers.append
    np.seterr(**errors)
    for solver in solvers:
        for child in solver.children:
            if child.poll() is None:
                child.kill()
                child.wait()


def assert_put_back(solver: Meddler, where: Path, errors: dict[str, str]) -> None:
    assert solver.children, "the solver meddled in no solve"
    assert Path.cwd() == where and VARIABLE not in os.environ and np.geterr() == errors
    assert [c.pid for c in solver.children if c.poll() is None] == []


@pytest.mark.parametrize("which", ["every-solve", "cache-check"])
def test_a_benchmark_puts_back_what_a_solve_changed(inst: ContactInstance, meddled: Callable[[Meddler], None],
                                                    tmp_path: Path, which: str) -> None:
    """Every solve, or only the cache check's (after the warm-up and 2 rounds)."""
    solver = Meddler() if which == "every-solve" else Meddler(first=4, slow=True)
    meddled(solver)
    errors = np.geterr()
    JudgedBenchmark(FakeBenchmark()).run(solver, inst, rounds=2)
    assert_put_back(solver, tmp_path, errors)


def test_contactbench_solve_puts_back_what_a_solve_changed(inst: ContactInstance, meddled: Callable[[Meddler], None],
                                                           tmp_path: Path) -> None:
    solver = Meddler()
    meddled(solver)
    errors = np.geterr()
    assert judged_solve(solver, inst).verdict.reading == "pass"
    assert_put_back(solver, tmp_path, errors)


# -- a hand judge on a contact_instance problem -----------------------------------------------


def test_contactbench_settle_fails_a_hand_judge_on_a_poisoned_operator(
        contact_instance: Callable[..., Any], contactbench_settle: Callable[..., None]) -> None:
    honest = contact_instance("rmd", N=16, steps=1)  # (an FFT operator: the judge's products build its caches)
    res = Exact().solve(honest.qp, SolverSettings())
    contactbench_settle(judge(honest, res.p, bool(res.converged), 1e-8), "honest", res.message)
    inst = contact_instance("counterexample", n=16, seed=1)
    res = Poison().solve(inst.qp, SolverSettings())
    verdict = judge(inst, res.p, bool(res.converged), 1e-8)
    assert verdict.reading == "pass"  # (judged with the replaced product)
    with pytest.raises(pytest.fail.Exception, match=r"wrote into the problem it was handed \(.*matvec") as failed:
        contactbench_settle(verdict, "poison", res.message)
    assert "\n" not in str(failed.value)
    assert judge(inst, res.p, bool(res.converged), 1e-8).reading == "wrong"  # (put back)


# -- settle's words ---------------------------------------------------------------------------


def test_settle_words_an_unclaimed_wrong_by_the_verdict_s_reason(inst: ContactInstance) -> None:
    left = "the solver left 1 thread running after its solve ('x'), which could write into the problem"
    verdict = judge(inst, dense_exact_solution(inst.qp), False, 1e-6, tampered=left)
    with pytest.raises(pytest.fail.Exception) as failed:
        settle(verdict, "threads")
    assert str(failed.value).startswith(f"threads: the judge reads the answer as wrong: {left}")
    assert "wrote into" not in str(failed.value).replace(left, "")
