"""Judged pytest-benchmark timings: a solver's timing counts only when the harness's judge
passes every answer it timed.

pytest-benchmark times whatever its ``benchmark`` fixture is handed and keeps the row --
in the timing table, the ``--benchmark-json`` file and saved runs -- unless the fixture's
``has_error`` is set; a wrong answer judged after the timed call, or a test failed after
it, leaves the row in.  This module is the one home of the rule that keeps such timings
out, for the benchmark suite (``benchmarks/``) and for a user's own benchmark through the
``contactbench`` pytest plugin:

``JudgedBenchmark(benchmark)``  wraps the fixture: ``has_error`` is set (and
    ``extra_info[PASSED_KEY]`` False) until ``passed()``; ``run(solver, inst, ...)`` times
    a solver's solves with ``benchmark.pedantic`` and judges each, outside the clock:

    * every solve -- the untimed warm-up and each timed round -- is handed a problem no
      earlier solve saw: the instance scaled by its own factor (``round_factor``: ubar,
      the upper bounds and the load times c; the answer is then c times the instance's,
      the approach Delta too), a deep copy with its own operator, so no state carries
      over and a solver that memoises answers across solves misses every time;
    * sealed (``ProblemSeal``, with the harness's copies beside it) and watched for the
      threads it leaves running (``threads_left``); the processes it starts end with it
      and the working folder, the environment and NumPy's error handling are put back
      after it, outside the clock (``Rounds.keep``: ``ends_what_it_starts``,
      ``process_state_kept``);
    * judged on a copy of its answer, taken when judged (``kept_answer``): a solver that
      hands back a buffer it writes again in a later solve changes no verdict;
    * judged by ``judge`` on the harness's scaled copy (the reference scaled alike);
    * the first solve the judge does not pass settles the test (``settle``): "wrong"
      fails it, "unconverged" is an xfail; a solve past the hard limit (``Watchdog``)
      fails it as a timeout, one that raises fails it (``ProblemInputError`` in the first
      solve: a skip, the solver refuses the instance);
    * timed rounds whose fastest is more than ``WARMUP_SPEEDUP`` times faster than the
      untimed warm-up solve are checked: untimed solves of perturbed problems (each entry of
      ubar times 1 + random noise of ``PROBE_NOISE``: its sign and its zeros kept, so the
      problem is no harder than the timed one) after them, up to ``PROBES``; when the fastest of them too is
      that much slower than the fastest timed round, the solver carried work across solves (a
      cache) and the test fails naming the three times.  A one-off cost of the first
      call (compiling, a device context) is not flagged: the solve after it is fast.

``keep_judged(groups)``  pytest-benchmark's groups less the rows that must not count (a
    ``has_error`` row, or one of a ``JudgedBenchmark`` not passed): for a
    ``pytest_benchmark_group_stats`` hook wrapper.
``exclude_unpassed(item, report)``  sets ``has_error`` on the ``benchmark`` fixture of a
    test whose report is not a pass (a wrong answer settled after a plain
    ``benchmark(...)``, an xfail, an error in teardown): for a
    ``pytest_runtest_makereport`` hook wrapper.

Importing this module imports pytest only; the harness, numpy and the problem classes
are imported on use.
"""

from __future__ import annotations

import contextlib
import copy
import math
import signal
import threading
import time
from dataclasses import dataclass, field
from types import FrameType
from typing import TYPE_CHECKING, Any, Iterator

import pytest

from .outcomes import settle

if TYPE_CHECKING:
    import numpy as np

    from contactbench.harness.judging import ProblemSeal, Verdict
    from contactbench.problems.instances import QP, ContactInstance
    from contactbench.solvers.base import Solver, SolverSettings, SolveResult

#: ``extra_info`` key of a ``JudgedBenchmark``: True once every solve passed the judge.
PASSED_KEY = "every_solve_passed"
#: Timed rounds this many times faster than the warm-up solve are checked for a cache.
WARMUP_SPEEDUP = 10.0
#: The relative size of the noise on each entry of ubar of the cache check's problems.
PROBE_NOISE = 1e-6
#: The cache check's solves at most (each of a problem of its own; the fastest counts).
PROBES = 2


def counts(bench: Any) -> bool:
    """Whether a benchmark row (pytest-benchmark's flat record) goes into the table: not
    one with ``has_error`` set, nor one whose ``extra_info[PASSED_KEY]`` is False (a
    ``JudgedBenchmark`` not passed, a test ``exclude_unpassed`` marked)."""
    if bench.get("has_error"):
        return False
    return (bench.get("extra_info") or {}).get(PASSED_KEY) is not False


def keep_judged(groups: list[tuple[Any, list[dict[str, Any]]]]) -> list[tuple[Any, list[dict[str, Any]]]]:
    """``groups`` (what ``pytest_benchmark_group_stats`` returns: (group name, rows)) less
    the rows that do not count (``counts``) and the groups left empty.  Use::

        @pytest.hookimpl(wrapper=True)
        def pytest_benchmark_group_stats(config, benchmarks, group_by):
            return keep_judged((yield))
    """
    kept = [(name, [b for b in group if counts(b)]) for name, group in groups]
    return [(name, group) for name, group in kept if group]


def exclude_unpassed(item: Any, report: Any) -> None:
    """Set ``has_error`` on the ``benchmark`` fixture of ``item`` (when it has one) when
    ``report`` (its ``pytest_runtest_makereport`` report of any phase) is not a plain
    pass: a failure, a skip or an xfail after the timed call, or an error in teardown;
    ``extra_info[PASSED_KEY]`` is set False too.  pytest-benchmark then leaves its row out
    of the JSON and saved runs, and ``keep_judged`` out of the table.  Use in a hook wrapper::

        @pytest.hookimpl(wrapper=True)
        def pytest_runtest_makereport(item, call):
            report = yield
            exclude_unpassed(item, report)
            return report
    """
    fixture = (getattr(item, "funcargs", None) or {}).get("benchmark")
    if fixture is None or not hasattr(fixture, "has_error"):
        return
    if report.when == "setup" and report.passed:
        return
    if not report.passed or hasattr(report, "wasxfail"):
        fixture.has_error = True
        extra = getattr(fixture, "extra_info", None)
        if isinstance(extra, dict):
            extra[PASSED_KEY] = False  # (the table's records carry extra_info, not has_error)


class SolveTimeout(BaseException):
    """A solve stopped by the ``Watchdog`` (a ``BaseException``: a solver's ``except
    Exception`` does not swallow it)."""


@dataclass
class Watchdog:
    """A hard limit of ``seconds`` on each solve (None: none): ``arm`` before it,
    ``disarm`` after it, inside ``installed``.  SIGALRM raises in the solver's Python
    code: it cannot stop a C loop that never returns to Python nor a solver that catches
    ``BaseException``; without SIGALRM (Windows) or outside the main thread it is off."""

    seconds: float | None
    active: bool = False

    @contextlib.contextmanager
    def installed(self) -> Iterator[Watchdog]:
        """SIGALRM raises ``SolveTimeout`` while armed; the handler and any timer set before
        (another plugin's) are put back after."""
        if (self.seconds is None or not hasattr(signal, "SIGALRM")
                or threading.current_thread() is not threading.main_thread()):
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
        if self.active and self.seconds is not None:
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def disarm(self) -> None:
        if self.active:
            signal.setitimer(signal.ITIMER_REAL, 0)

    def fire(self, signum: int, frame: FrameType | None) -> None:
        raise SolveTimeout(f"no answer within the hard limit of {self.seconds:.3g} s")


def round_factor(index: int, solves: int) -> float:
    """The factor of solve ``index`` (0: the warm-up) of ``solves``: distinct, in (1, 2),
    never 1 (a problem posed elsewhere in the process is never handed as it is)."""
    return 1.0 + (index + 1) / (solves + 1)


def scaled_instance(inst: ContactInstance, factor: float, noise: np.ndarray | None = None) -> ContactInstance:
    """``inst`` with ubar, the upper bounds and the load times ``factor`` (the same
    operator, geometry and physical context), each entry of ubar also times (1 + its
    ``noise``) when given -- every sign and every exact zero kept, so a problem does not
    turn harder than the one timed (a plateau at zero gap stays p = 0): for a factor c and
    no noise its answer is c times ``inst``'s (Delta too)."""
    from dataclasses import replace

    from contactbench.problems.constraints import Constraints
    from contactbench.problems.instances import QP

    qp, c = inst.qp, inst.qp.constraints
    ubar = qp.ubar * factor * (1.0 if noise is None else 1.0 + noise)
    constraints = Constraints(None if c.upper is None else c.upper * factor,
                              None if c.load is None else c.load * factor)
    return replace(inst, qp=QP(qp.H, ubar, qp.geometry, constraints), meta=dict(inst.meta))


def handed_copy(qp: QP, operator: str | None = None) -> QP:
    """A deep copy of ``qp`` with a new operator (matvec counters, caches start empty;
    ``operator`` "dense": H assembled): nothing in it is shared with ``qp``."""
    import numpy as np

    from contactbench.problems.instances import QP
    from contactbench.problems.operators import DenseOperator

    H = DenseOperator(qp.H.to_dense()) if operator == "dense" else qp.H.restrict(np.arange(qp.H.n))
    return copy.deepcopy(QP(H, qp.ubar, qp.geometry, qp.constraints))


@dataclass(eq=False)
class Solve:
    """One solve (the ``index``-th of its benchmark, the warm-up 0; -1, -2 the cache check's):
    the harness's copy of its problem (``inst``, scaled by ``factor``), the copy handed to
    the solver, its seal, the threads before it, its result and time, and the copy of its
    answer the judge read (``answer``, once ``judged``)."""

    index: int
    factor: float
    inst: ContactInstance
    qp: QP
    seal: ProblemSeal
    threads: set[int]
    result: SolveResult | None = None
    seconds: float = math.nan
    judged: bool = False
    answer: Any = None


@dataclass
class Rounds:
    """The solves of one benchmark (module doc): ``setup`` hands each its problem, ``solve``
    is the timed call, ``teardown`` judges it; a solve the judge does not pass settles the
    test there (``settle``)."""

    solver: Solver
    inst: ContactInstance
    operator: str | None
    settings: SolverSettings
    check_tol: float
    reference: np.ndarray | None
    watchdog: Watchdog
    what: str
    count: int  # the solves pedantic runs: the warm-up and the timed rounds
    first_timed: int  # the index of the first timed solve (0 when pytest-benchmark is disabled)
    solves: list[Solve] = field(default_factory=list)
    verdict: Verdict | None = None
    problem_written: bool = False
    kept: contextlib.ExitStack | None = None  # (``keep``: open from a solve's setup to its teardown)

    def keep(self) -> None:
        """From now until ``release``: the processes started end and the process state
        (working folder, environment, NumPy's error handling) is put back
        (``ends_what_it_starts``, ``process_state_kept``, as ``run`` and ``validate`` do)."""
        from contactbench.harness.run.worker import process_state_kept
        from contactbench.solvers._processes import ends_what_it_starts

        self.release()
        stack = contextlib.ExitStack()
        stack.enter_context(ends_what_it_starts())
        stack.enter_context(process_state_kept())
        self.kept = stack

    def release(self) -> None:
        """End what ``keep`` started (the watchdog disarmed first: a stop never lands in it)."""
        self.watchdog.disarm()
        stack, self.kept = self.kept, None
        if stack is not None:
            stack.close()

    def prepare(self, index: int, factor: float, noise: np.ndarray | None = None) -> Solve:
        """Solve ``index``: the harness's scaled copy, a copy of it handed, the seal."""
        from contactbench.harness.judging import ProblemSeal
        from contactbench.harness.run.worker import running_threads

        inst = scaled_instance(self.inst, factor, noise)
        qp = handed_copy(inst.qp, self.operator)
        return Solve(index, factor, inst, qp, ProblemSeal.of(qp, [self.inst.qp, inst.qp]), running_threads())

    def setup(self) -> tuple[tuple[Solve, SolverSettings], dict[str, Any]]:
        index = len(self.solves)
        solve = self.prepare(index, round_factor(index, self.count))
        self.solves.append(solve)
        self.keep()
        self.watchdog.arm()
        return (solve, copy.deepcopy(self.settings)), {}

    def solve(self, solve: Solve, settings: SolverSettings) -> SolveResult:
        t0 = time.perf_counter()
        solve.result = self.solver.solve(solve.qp, settings, None)
        solve.seconds = time.perf_counter() - t0
        return solve.result

    def teardown(self, solve: Solve, settings: SolverSettings) -> None:
        self.release()
        self.judge(solve)

    def label(self, index: int) -> str:
        if index < 0:
            return "in its untimed check solve after the timed rounds"
        if self.first_timed == 0:
            return "in its one solve (pytest-benchmark disabled)"
        if index < self.first_timed:
            return "in its untimed warm-up solve"
        return f"in timed round {index - self.first_timed + 1}"

    def fault(self, solve: Solve) -> str:
        """What ``solve`` changed in the problems (handed or the harness's), else the threads
        it left running; "" neither (``problem_written`` set when it wrote)."""
        from contactbench.harness.run.worker import threads_left

        solve.judged = True
        left = threads_left(solve.threads)
        broken = solve.seal.broken(solve.qp)
        solve.seal.mend(solve.qp)
        if broken:
            self.problem_written = True
        return broken or left

    def judge(self, solve: Solve) -> None:
        from contactbench.harness.judging import judge

        assert solve.result is not None
        fault, res = self.fault(solve), solve.result
        solve.answer = kept_answer(res.p)
        ref = None if self.reference is None or solve.index < 0 else self.reference * solve.factor
        self.verdict = judge(solve.inst, solve.answer, bool(res.converged), self.check_tol, p_ref=ref,
                             tampered=fault, multiplier=res.multiplier)
        settle(self.verdict, f"{self.what} {self.label(solve.index)}", res.message)

    def judge_pending(self) -> None:
        """Judge the solves ``teardown`` did not (pytest-benchmark disabled runs none)."""
        self.release()
        for solve in self.solves:
            if not solve.judged:
                self.judge(solve)

    def unfinished(self) -> tuple[str, str]:
        """(label, fault) of the solve that raised or was stopped (``fault``)."""
        self.release()
        solve = self.solves[-1]
        return self.label(solve.index), self.fault(solve)

    def timed_min(self) -> float:
        """The fastest timed solve's seconds (measured around the solver's call)."""
        return min((s.seconds for s in self.solves[self.first_timed:]), default=math.nan)

    def cache_check(self, limit: float) -> str:
        """"" unless the fastest timed round is over ``limit`` times faster than the warm-up
        and than the fastest of ``PROBES`` untimed solves of perturbed problems after the
        rounds (each judged too): then the reason the timing is not a solve's (module doc)."""
        if self.first_timed < 1 or len(self.solves) <= self.first_timed:
            return ""
        fastest, warm = self.timed_min(), self.solves[0].seconds
        if not fastest * limit < warm:
            return ""
        import numpy as np

        shape = np.shape(self.inst.qp.ubar)
        rng = np.random.default_rng()
        probe = math.inf
        for k in range(PROBES):  # (the least of PROBES: a pause of the machine in one is not a cache)
            noise = PROBE_NOISE * rng.standard_normal(shape)
            solve = self.prepare(-1 - k, round_factor(self.count + k, self.count + PROBES), noise)
            self.solves.append(solve)
            self.keep()
            self.watchdog.arm()
            self.solve(solve, copy.deepcopy(self.settings))
            self.release()
            self.judge(solve)
            probe = min(probe, solve.seconds)
            if not fastest * limit < probe:
                return ""
        return (f"{self.what}: its fastest timed round ({fastest:.3g} s) is over {limit:g}x faster than its "
                f"untimed warm-up solve ({warm:.3g} s) and than untimed solves of slightly perturbed problems "
                f"after the rounds ({probe:.3g} s): it carries work across solves (a cache), so the "
                f"timing is not a solve's and is left out")


@dataclass
class JudgedBenchmark:
    """pytest-benchmark's ``benchmark`` fixture, whose row counts only once ``passed`` is
    called (module doc); constructing one sets ``has_error`` until then."""

    benchmark: Any
    #: Whether a solve of the last ``run`` wrote into a problem (a harness copy included):
    #: a caller that caches the instance should rebuild it.
    problem_written: bool = False

    def __post_init__(self) -> None:
        self.benchmark.has_error = True
        self.benchmark.extra_info[PASSED_KEY] = False

    def passed(self) -> None:
        """Every solve passed the judge: the timing goes into the table and the JSON."""
        self.benchmark.has_error = False
        self.benchmark.extra_info[PASSED_KEY] = True

    def run(self, solver: Solver | str, inst: ContactInstance, settings: SolverSettings | None = None, *,
            rounds: int = 3, check_tol: float | None = None, reference: np.ndarray | None = None,
            operator: str | None = None, time_limit: float | None = None, what: str = "",
            warmup_speedup: float | None = WARMUP_SPEEDUP) -> Verdict:
        """Time ``solver`` (an instance or a registry name) on ``inst`` (the caller's copy:
        never handed to the solver) with ``benchmark.pedantic`` -- one untimed warm-up and
        ``rounds`` timed rounds (>= 1), each solve on its own scaled copy, judged outside
        the clock (module doc) -- and return the verdict of the last timed round's answer
        read back on ``inst`` (``read_back``; one that does not pass settles the test too).
        ``settings``: the solver's settings (None: ``SolverSettings()``); ``check_tol``:
        the judge's (None: ``settings.check_tol``, else the default profile's);
        ``reference``: the exact answer of ``inst`` (its errors in the figures);
        ``operator`` "dense" hands H assembled; ``time_limit``: seconds (None:
        ``settings.time_limit``, else none), the hard limit is ``kill_limit`` of it;
        ``what``: the name in messages (default: the solver's and n); ``warmup_speedup``:
        the cache check's ratio (None: no check).  The solver is handed ``settings`` with
        the check_tol judged at and the time limit the hard limit is of
        (``resolved_settings``); a keyword that differs from a value ``settings`` gives,
        ``settings`` that is not a ``SolverSettings`` or ``rounds`` that is not a whole
        number >= 1 is refused (one-line ``ProblemInputError``; ``ValueError`` for rounds).
        Every solve passed: ``passed()`` is called and the figures go to ``extra_info``.
        Otherwise the test is settled: a failure, an xfail or a skip (module doc), and the
        row does not count."""
        from contactbench.problems.errors import ProblemInputError
        from contactbench.solvers.registry import get_solver

        if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
            raise ValueError(f"rounds must be a whole number >= 1, got {rounds!r}")
        settings = resolved_settings("contactbench_benchmark.run", settings, check_tol, time_limit)
        check_tol, time_limit = settings.check_tol, settings.time_limit
        assert check_tol is not None
        solver = get_solver(solver) if isinstance(solver, str) else solver
        what = what or f"{solver.name or type(solver).__name__} (n = {inst.n})"
        watchdog = Watchdog(None if time_limit is None else kill_time(time_limit))
        disabled = bool(getattr(self.benchmark, "disabled", False))
        run = Rounds(solver, inst, operator, settings, check_tol, reference, watchdog, what,
                     count=1 if disabled else rounds + 1, first_timed=0 if disabled else 1)
        failure = refusal = ""  # (settled after the except blocks: a message without their traceback)
        last: Solve | None = None
        try:
            with watchdog.installed():
                try:
                    self.benchmark.pedantic(run.solve, setup=run.setup, teardown=run.teardown, rounds=rounds,
                                            iterations=1, warmup_rounds=1)
                    run.judge_pending()
                    last = [s for s in run.solves if s.index >= 0][-1]
                    assert last.result is not None and last.judged
                    verdict = read_back(inst, last, check_tol, reference)  # (before the check's solves)
                    if verdict.reading != "pass":
                        settle(verdict, f"{what} {run.label(last.index)}, read back on the instance as given",
                               str(last.result.message))
                    if warmup_speedup is not None:
                        failure = run.cache_check(warmup_speedup)
                except SolveTimeout as exc:
                    where, fault = run.unfinished()
                    failure = (f"{what} {where}: timeout: {exc}" + (f" (the time limit {time_limit:g} s plus the "
                               "grace)" if time_limit is not None else "") + "; the solve was stopped"
                               + (f"; {fault}" if fault else ""))
                except ProblemInputError as exc:
                    where, fault = run.unfinished()
                    if fault or len(run.solves) > 1:
                        failure = f"{what} {where}: raised ProblemInputError: {exc}" + (f"; {fault}" if fault else "")
                    else:
                        refusal = f"{solver.name} refuses this instance: {exc}"
                except Exception:
                    where, fault = run.unfinished()
                    if fault:
                        pytest.fail(f"{what} {where}: raised, and {fault}")
                    raise
        finally:
            run.release()
            self.problem_written = run.problem_written
        if failure:
            pytest.fail(failure, pytrace=False)
        if refusal:
            pytest.skip(refusal)
        assert last is not None and last.result is not None
        self.benchmark.extra_info.update({
            "iterations": int(last.result.iterations), "solver_converged": bool(last.result.converged),
            "solves_judged": len(run.solves), "solved": verdict.status == "solved", "verdict": verdict.reading,
            **verdict.figures,
        })
        self.passed()
        return verdict


def resolved_settings(what: str, settings: SolverSettings | None, check_tol: float | None,
                      time_limit: float | None) -> SolverSettings:
    """A copy of ``settings`` (None: ``SolverSettings()``) whose check_tol is ``check_tol``
    (None: ``settings.check_tol``, else the default profile's) and whose time_limit is
    ``time_limit`` (None: ``settings.time_limit``, else None): what the solver is handed,
    judged at and stopped by.  A one-line ``ProblemInputError`` naming ``what``: ``settings``
    not a ``SolverSettings``, a keyword that differs from the value ``settings`` gives, or a
    value ``SolverSettings`` refuses."""
    from dataclasses import replace

    from contactbench.harness.profiles import get_profile
    from contactbench.problems.errors import ProblemInputError
    from contactbench.solvers.base import SolverSettings as _Settings

    if settings is None:
        settings = _Settings()
    elif not isinstance(settings, _Settings):
        raise ProblemInputError(f"{what}: settings must be a SolverSettings or None, got {type(settings).__name__}")
    given = {"check_tol": check_tol, "time_limit": time_limit}
    for name, value in given.items():
        held = getattr(settings, name)
        if value is not None and held is not None and value != held:
            raise ProblemInputError(f"{what}: {name}={value!r} differs from the settings' {name} {held!r}; "
                                    f"give it once")
    tol = check_tol if check_tol is not None else settings.check_tol
    limit = time_limit if time_limit is not None else settings.time_limit
    tol = get_profile("default").check_tol if tol is None else tol
    return replace(settings, params=dict(settings.params), check_tol=tol, time_limit=limit)


def kept_answer(p: Any) -> Any:
    """A copy of answer ``p`` that the solver holds no reference to (an array copied, any
    other object deep-copied; as given where it cannot be copied: the judge reads it)."""
    import numpy as np

    if isinstance(p, np.ndarray):
        return np.array(p, copy=True)
    try:
        return copy.deepcopy(p)
    except Exception:  # (an object that refuses a copy: the judge says what it is)
        return p


def kill_time(time_limit: float) -> float:
    """Seconds a solve with ``time_limit`` may run before it is stopped (``kill_limit``)."""
    from contactbench.harness.conformance.cases import kill_limit

    return kill_limit(time_limit)


def read_back(inst: ContactInstance, solve: Solve, check_tol: float, reference: np.ndarray | None) -> Verdict:
    """The verdict of ``solve``'s answer (one the judge passed: the copy it read,
    ``Solve.answer``) read back on ``inst``: the answer and its Delta divided by the solve's
    factor (the figures of the instance as given: its load, its objective); equal to the
    scaled problem's up to rounding."""
    from contactbench.harness.judging import judge, read_answer

    res = solve.result
    assert res is not None and solve.judged
    p, _ = read_answer(solve.answer, inst.n)
    assert p is not None
    try:
        multiplier = None if res.multiplier is None else float(res.multiplier) / solve.factor
    except (TypeError, ValueError):
        multiplier = None
    return judge(inst, p / solve.factor, bool(res.converged), check_tol, p_ref=reference, multiplier=multiplier)
