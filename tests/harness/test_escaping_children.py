"""A process a solve starts ends with the solve, even one that leaves its process group
(``setsid``) and whose parent exits: the isolated worker adopts it
(``PR_SET_CHILD_SUBREAPER``) and kills every descendant left after each message, and the
parent kills the worker's descendants before the worker at a time limit; a worker that
dies on its own (``os._exit``, a signal) leaves its orphans to its keeper, which kills
them (``harness.run.isolation``, ``contactbench.solvers._processes``); ``validate`` and
``run`` share that worker, and ``validate --no-isolate`` ends what a solve started in its
own process, leaving the process's other children alone.  An outside program's
descendants that left its group are killed with it at its time limit
(``solvers.external.run_program``)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np
import psutil
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.run import isolation
from contactbench.harness.run.isolation import ChildProcess
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Outcome, SolveContext, Solver
from contactbench.solvers import _processes
from contactbench.solvers._processes import REAP_WAIT_S, SUBREAPER_MISSING, is_subreaper
from contactbench.solvers.external import run_program
from tests.helpers import process_gone

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason=f"/proc, and {SUBREAPER_MISSING}")

#: How long a test waits at most for a killed process to be gone: a wait for the kernel, not
#: a claim on speed (it returns as soon as the process is gone), generous for a loaded machine.
GONE_WAIT_S = 30.0
#: How long an escaped process lives at most: well past ``GONE_WAIT_S``, so that one that was
#: not killed is still there when the wait ends (and a test that waits for it can fail).
LIFETIME_S = 4 * GONE_WAIT_S
T = TypeVar("T")

#: The environment variable that tells ``EscapingSolver`` where to write its grandchild's pid.
PID_FILE_VAR = "CONTACTBENCH_TEST_ESCAPE_PID_FILE"


def within_growing_limits(attempt: Callable[[float], T], started: Path) -> T:
    """``attempt(limit)`` -- a message or program that starts a process, writes its pid into
    ``started`` and hangs past ``limit`` seconds -- with a limit of 1 s, doubled (up to
    ``GONE_WAIT_S``) until ``started`` holds a pid when it returns: a loaded machine, slower
    to start what the attempt starts, costs time, not the test.  The last attempt's value."""
    limit = 1.0
    while True:
        value = attempt(limit)
        if (started.exists() and started.read_text()) or limit >= GONE_WAIT_S:
            return value
        limit *= 2


def ended_in_time(pid: int, wait_s: float = GONE_WAIT_S) -> bool:
    """Whether ``pid`` ends within ``wait_s`` (a bounded wait for the kernel, not a claim on
    speed); a survivor is killed here, so that a failing test leaves nothing behind."""
    deadline = time.monotonic() + wait_s
    while not process_gone(pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    if process_gone(pid):
        return True
    os.kill(pid, 9)
    return False


def fork_sleeper() -> int:
    """Fork a process that runs a program sleeping ``LIFETIME_S`` (holding none of this
    process's pipes); its pid, in this process."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the forked child
        try:
            os.execv(sys.executable, [sys.executable, "-c", f"import time; time.sleep({LIFETIME_S:g})"])
        finally:
            os._exit(1)
    return pid


def start_escaped_grandchild(pid_file: str) -> int:
    """Fork a child that leaves the process group (``setsid``), forks a grandchild that
    runs a program that sleeps (holding none of the worker's pipes), and exits at once: the
    grandchild is an orphan outside the group.  Its pid is written into ``pid_file`` and
    returned."""
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover - runs in the forked child
        try:
            os.setsid()
            grandchild = fork_sleeper()
            os.write(write, str(grandchild).encode())
        finally:
            os._exit(0)
    os.close(write)
    text = os.read(read, 32).decode()
    os.close(read)
    os.waitpid(child, 0)
    Path(pid_file).write_text(text)
    return int(text)


def escape_then(msg: tuple[str, str]) -> int:
    """A worker's handler: start an escaped grandchild, then answer ("return") or hang."""
    pid = start_escaped_grandchild(msg[1])
    if msg[0] == "hang":
        time.sleep(600)
    return pid


def test_an_escaped_grandchild_ends_with_the_message_that_started_it(tmp_path: Path) -> None:
    with ChildProcess(lambda: escape_then) as child:
        reply = child.call(("return", str(tmp_path / "pid")), timeout=None)
        assert reply.kind == "ok", reply
        assert ended_in_time(int(reply.value)), "the grandchild outlived its message"
        assert child.alive  # the worker itself goes on


def test_an_escaped_grandchild_of_a_worker_killed_at_its_limit_is_killed_too(tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    with ChildProcess(lambda: escape_then) as child:
        assert child.call(("return", str(tmp_path / "first")), timeout=None).kind == "ok"  # the worker is up
        hang = ("hang", str(pid_file))
        assert within_growing_limits(lambda limit: child.call(hang, timeout=limit), pid_file).kind == "timeout"
        assert ended_in_time(int(pid_file.read_text())), "the grandchild outlived the killed worker"


def escape_then_die(msg: tuple[str, str]) -> int:
    """A worker's handler: start an escaped grandchild, then end the worker itself --
    ``os._exit(3)`` ("exit") or the signal named."""
    pid = start_escaped_grandchild(msg[1])
    if msg[0] == "exit":
        os._exit(3)
    os.kill(os.getpid(), signal.Signals[msg[0]])
    time.sleep(600)
    return pid


@pytest.mark.parametrize("how, said", [("exit", "worker exited with code 3"),
                                       ("SIGSEGV", "worker killed by signal SIGSEGV"),
                                       ("SIGKILL", "worker killed by signal SIGKILL")])
def test_an_escaped_grandchild_of_a_worker_that_died_on_its_own_is_killed(tmp_path: Path, how: str,
                                                                         said: str) -> None:
    """The worker's death is reported as its own (exit code, signal), and the process it
    started that left its group ends with it."""
    pid_file = tmp_path / "pid"
    with ChildProcess(lambda: escape_then_die) as child:
        reply = child.call((how, str(pid_file)), timeout=30.0)
    survived = pid_file.exists() and not ended_in_time(int(pid_file.read_text()))
    assert reply.kind == "crashed" and said in reply.detail, reply
    assert pid_file.exists() and not survived, "the grandchild outlived the worker that died"


def test_a_grandchild_one_scan_of_the_keeper_missed_is_killed_by_the_next(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """A scan of the process table is not atomic (a chain read while a process in it exits):
    the first scan of each process here -- the keeper's, after its worker died -- misses
    every descendant, and the keeper's next pass still finds the grandchild and kills it,
    rather than waiting for it to exit and leaving it behind."""
    scanned: set[int] = set()
    real = _processes.descendants

    def first_misses(pid: int) -> list[psutil.Process]:
        if os.getpid() in scanned:
            return real(pid)
        scanned.add(os.getpid())
        return []

    monkeypatch.setattr(_processes, "descendants", first_misses)  # (inherited by the forked keeper)
    pid_file = tmp_path / "pid"
    with ChildProcess(lambda: escape_then_die) as child:
        reply = child.call(("SIGKILL", str(pid_file)), timeout=30.0)
    survived = pid_file.exists() and not ended_in_time(int(pid_file.read_text()))
    assert reply.kind == "crashed" and "worker killed by signal SIGKILL" in reply.detail, reply
    assert pid_file.exists() and not survived, "the grandchild outlived the worker that died"


def test_a_keeper_slow_to_end_is_still_read_as_the_worker_s_own_death(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """On a loaded machine the keeper may take all of ``REAP_WAIT_S`` and more to end what
    it keeps: the parent waits for it, and says how the worker ended, not that it did not."""
    real = isolation.end_own_descendants

    def slow(wait_s: float = REAP_WAIT_S) -> int:
        time.sleep(REAP_WAIT_S + 1.0)
        return real(wait_s)

    monkeypatch.setattr(isolation, "end_own_descendants", slow)  # (inherited by the forked keeper)
    with ChildProcess(lambda: escape_then_die) as child:
        reply = child.call(("SIGKILL", str(tmp_path / "pid")), timeout=30.0)
    assert reply.kind == "crashed" and "worker killed by signal SIGKILL" in reply.detail, reply
    assert ended_in_time(int((tmp_path / "pid").read_text())), "the grandchild outlived the worker that died"


#: A runner in its own process: a worker whose message starts an escaped grandchild (its pid
#: into the file ``argv[1]``) and hangs; the test kills the runner with SIGKILL.
RUNNER = """
import sys
from contactbench.harness.run import isolation
from contactbench.harness.run.isolation import ChildProcess
from tests.harness.test_escaping_children import escape_then
ChildProcess(lambda: escape_then).call(("hang", sys.argv[1]), timeout=None)
"""


def test_a_kill_9_of_the_runner_ends_what_its_worker_s_solve_started(tmp_path: Path) -> None:
    """The keeper's death signal is one it catches: it kills what it keeps, the grandchild
    that left its group included, when the runner is killed outright."""
    pid_file = tmp_path / "pid"
    runner = subprocess.Popen([sys.executable, "-c", RUNNER, str(pid_file)], cwd=Path(__file__).parents[2])
    try:
        deadline = time.monotonic() + 60.0
        while not (pid_file.exists() and pid_file.read_text()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pid_file.exists(), "the runner's worker never started its grandchild"
    finally:
        runner.kill()
        runner.wait()
    assert ended_in_time(int(pid_file.read_text())), "the grandchild outlived the killed runner"


def leave_and_kill_the_keeper(pid_file: str) -> int:
    """A worker's handler: drop its death signal, leave its group, kill its keeper (its pid
    into ``pid_file``), then go on "solving" past its time limit."""
    import ctypes

    ctypes.CDLL(None).prctl(1, 0, 0, 0, 0)  # PR_SET_PDEATHSIG: none
    os.setsid()
    Path(pid_file).write_text(str(os.getpid()))
    os.kill(os.getppid(), signal.SIGKILL)
    time.sleep(2.0)
    return os.getpid()


def test_a_worker_that_left_its_keeper_ends_when_the_runner_lets_it_go(tmp_path: Path) -> None:
    """Out of reach of the runner's kill, the worker holds no copy of the runner's end of its
    pipe: once the runner has closed it, the worker's reply finds no reader and its wait for
    the next message ends, and so does the worker."""
    pid_file = tmp_path / "pid"
    with ChildProcess(lambda: leave_and_kill_the_keeper) as child:
        reply = child.call(str(pid_file), timeout=1.0)
    assert reply.kind in ("timeout", "crashed"), reply
    assert ended_in_time(int(pid_file.read_text())), "the worker outlived the runner's end of its pipe"


def hold_the_pipe_then_kill_the_keeper(pid_file: str) -> int:
    """A worker's handler: leave behind a process outside the group that holds every file
    of the worker's, its pipe among them, for ``LIFETIME_S`` (its pid into ``pid_file``),
    then kill the keeper and go on "solving"."""
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover - runs in the forked child
        os.setsid()
        holder = os.fork()
        if holder == 0:
            time.sleep(LIFETIME_S)
        else:
            os.write(write, str(holder).encode())
        os._exit(0)
    os.close(write)
    Path(pid_file).write_text(os.read(read, 32).decode())
    os.waitpid(child, 0)
    os.kill(os.getppid(), signal.SIGKILL)
    time.sleep(LIFETIME_S)
    return 0


def test_a_keeper_killed_while_its_pipe_is_held_open_is_a_crash_not_a_timeout(tmp_path: Path) -> None:
    """No end of file comes while what the solver left running holds the pipe: the parent
    reads the keeper's death itself, "crashed" with how it ended, not a hang to the limit."""
    pid_file = tmp_path / "pid"
    try:
        with ChildProcess(lambda: hold_the_pipe_then_kill_the_keeper) as child:
            reply = child.call(str(pid_file), timeout=LIFETIME_S / 2)
        assert reply.kind == "crashed" and "SIGKILL" in reply.detail, reply
    finally:
        if pid_file.exists() and pid_file.read_text():
            ended_in_time(int(pid_file.read_text()), wait_s=0.0)


class EscapingSolver(Solver):
    """Starts a grandchild that leaves its group and outlives its parent, then answers."""

    name = "test-escaping-solver"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        start_escaped_grandchild(os.environ[PID_FILE_VAR])
        return Outcome(exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p, 1, True)


def test_validate_leaves_no_escaped_grandchild_behind(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pid_file = tmp_path / "pid"
    monkeypatch.setenv(PID_FILE_VAR, str(pid_file))
    table = cf.validate(EscapingSolver(), cf.conformance_cases("fast", pattern="random/spd-n30-s0"))
    assert table.exit_code() == 0, table.format()
    assert ended_in_time(int(pid_file.read_text())), "the solver's grandchild outlived validate"


def test_validate_in_process_ends_what_a_solve_started_and_leaves_the_process_s_other_children(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``validate --no-isolate``: the solver's grandchild that left its group is killed with
    its solve; a child this process started before is left running, and this process does
    not adopt orphans after the solve."""
    pid_file = tmp_path / "pid"
    monkeypatch.setenv(PID_FILE_VAR, str(pid_file))
    own = subprocess.Popen([sys.executable, "-c", f"import time; time.sleep({LIFETIME_S:g})"])
    try:
        table = cf.validate(EscapingSolver(), cf.conformance_cases("fast", pattern="random/spd-n30-s0"),
                            isolate=False)
        survived = pid_file.exists() and not ended_in_time(int(pid_file.read_text()))
        assert table.exit_code() == 0, table.format()
        assert pid_file.exists() and not survived, "the solver's grandchild outlived validate"
        assert own.poll() is None, "a child of the process that is not the solve's was ended"
        assert not is_subreaper()
    finally:
        own.kill()
        own.wait()


def start_child_and_grandchild() -> int:
    """Fork a child that forks a grandchild running a program that sleeps, then sleeps
    itself: the grandchild's pid (its parent is alive, in this process's group)."""
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # pragma: no cover - runs in the forked child
        try:
            grandchild = fork_sleeper()
            os.write(write, str(grandchild).encode())
            time.sleep(LIFETIME_S)
        finally:
            os._exit(0)
    os.close(write)
    text = os.read(read, 32).decode()
    os.close(read)
    return int(text)


def test_a_process_the_scans_at_an_in_process_solve_s_end_missed_is_killed_by_a_later_one(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``ends_what_it_starts``: the scans of its kill rounds miss the grandchild (as a scan
    read while a process of its chain exits may); once its parent is killed it is this
    process's orphan, and a later scan, while the block's end waits for its children, kills
    it rather than waiting for it to exit."""
    real = _processes.started_since
    scans: list[int] = []
    with _processes.ends_what_it_starts():
        hidden = start_child_and_grandchild()

        def hiding_it_twice(pid: int, before: frozenset[psutil.Process]) -> list[psutil.Process]:
            scans.append(pid)
            found = real(pid, before)
            return found if len(scans) > 2 else [p for p in found if p.pid != hidden]

        monkeypatch.setattr(_processes, "started_since", hiding_it_twice)
    assert ended_in_time(hidden), "a process the solve started outlived it"


def test_an_outside_programs_child_that_left_its_group_is_killed_at_the_time_limit(tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    program = ("import os, sys, time\n"
               "pid = os.fork()\n"
               "if pid == 0:\n"
               "    os.setsid(); time.sleep(%g); os._exit(0)\n"
               "open(sys.argv[1], 'w').write(str(pid))\n"
               "time.sleep(600)\n") % LIFETIME_S
    argv = [sys.executable, "-c", program, str(pid_file)]
    result = within_growing_limits(lambda limit: run_program(argv, None, limit, tmp_path), pid_file)
    assert result.timed_out and pid_file.exists(), result
    assert ended_in_time(int(pid_file.read_text())), "the program's child outlived its time limit"
