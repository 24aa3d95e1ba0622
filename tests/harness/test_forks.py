"""A fork that a library pool's lost wake-up cannot hang (``harness.run.forks``).

The C pool (``lost_wakeup_pool.c``) stops its thread before every fork the way ducc0's and
pocketfft's pools do, with the window in which a fresh thread misses the stop held open: a
worker's keeper that forked at once, a parent that started two workers back to back and a
``--jobs`` pool forking its processes each hung in ``fork`` until killed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from contactbench.harness.run import forks
from tests.helpers import compile_c

HERE = Path(__file__).parent
#: Seconds between two worker starts: within the C pool's window (``SPIN_S``, 0.2 s).
GAP_S = 0.05

#: Runs in a fresh interpreter (the pool's fork handlers stay for the process's life): loads
#: the pool, lets its first thread reach its wait, then starts ``count`` workers, each
#: ``GAP_S`` after the one before (the thread the fork before started is then in its window),
#: and asks each for one reply.
SCRIPT = textwrap.dedent("""
    import ctypes, os, sys, time
    from contactbench.harness.run.isolation import ChildProcess

    ctypes.CDLL(sys.argv[1]).pool_start()
    time.sleep(1.0)  # the pool's first thread is waiting: this process's first fork is safe
    def forks_then_answers(m):
        for _ in range(2):  # a solver's own forks, the second in the window of the thread the first started
            pid = os.fork()
            if pid == 0:
                os._exit(0)
            os.waitpid(pid, 0)
            time.sleep(float(sys.argv[3]))
        return m + 1

    handler = forks_then_answers if sys.argv[4] == "fork" else (lambda m: m + 1)
    children = [ChildProcess(lambda: handler) for _ in range(int(sys.argv[2]))]
    for child in children:
        child.start()
        time.sleep(float(sys.argv[3]))
    replies = [child.call(k, timeout=10.0) for k, child in enumerate(children)]
    for child in children:
        child.close()
    print(" ".join(f"{r.kind}:{r.value}" for r in replies))
""")

#: The same for a ``--jobs`` pool: its processes are forked back to back.
POOL_SCRIPT = textwrap.dedent("""
    import ctypes, sys, time
    from concurrent.futures import ProcessPoolExecutor
    from contactbench.harness.run.forks import process_context

    ctypes.CDLL(sys.argv[1]).pool_start()
    time.sleep(1.0)
    with ProcessPoolExecutor(max_workers=3, mp_context=process_context("fork")) as pool:
        print(" ".join(str(v) for v in pool.map(abs, [-1, -2, -3])))
""")


def run_script(script: str, *args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    """``script`` run by this interpreter in a session of its own; on a hang, that session
    is killed (what a hung fork left) and the hang is the test's failure."""
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"hung for {timeout:g} s (killed): {err[-2000:]}")
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.fixture(scope="module")
def pool_library(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The C pool, built with the system C compiler (skipped without one)."""
    out = tmp_path_factory.mktemp("pool") / "liblost_wakeup_pool.so"
    return compile_c(HERE / "lost_wakeup_pool.c", out, "-shared", "-fPIC", "-lpthread", what="the C pool")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork handlers and /proc: Linux")
@pytest.mark.parametrize("workers, solve", [(1, "plain"), (2, "plain"), (1, "fork")])
def test_workers_start_past_a_pool_that_loses_its_stop(pool_library: Path, workers: int, solve: str) -> None:
    """One worker: its keeper forks the worker while the thread the keeper's own fork started
    is in the window; two: the parent forks the second keeper while the thread its first fork
    started is; a solve that forks twice: the worker forks while the thread its first fork
    started is.  Each worker answers."""
    out = run_script(SCRIPT, str(pool_library), str(workers), str(GAP_S), solve)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == [f"ok:{k + 1}" for k in range(workers)], out.stdout + out.stderr[-2000:]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork handlers and /proc: Linux")
def test_a_jobs_pool_starts_past_a_pool_that_loses_its_stop(pool_library: Path) -> None:
    out = run_script(POOL_SCRIPT, str(pool_library))
    assert out.returncode == 0 and out.stdout.split() == ["1", "2", "3"], out.stdout + out.stderr[-2000:]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc: Linux")
def test_thread_states_tell_a_waiting_thread_from_the_caller() -> None:
    stop = threading.Event()
    waiter = threading.Thread(target=stop.wait, args=(30,), name="forks-waiter", daemon=True)
    waiter.start()
    try:
        end = time.monotonic() + 10
        while forks.thread_states().get(waiter.native_id) not in forks.NOT_RUNNING and time.monotonic() < end:
            time.sleep(0.01)
        states = forks.thread_states()
        me = threading.get_native_id()
        assert states[me] == "R" and states[waiter.native_id] in forks.NOT_RUNNING
        assert waiter.native_id not in forks.others_running(states, me)
    finally:
        stop.set()
        waiter.join()


def test_others_running_reads_each_state() -> None:
    states = {1: "R", 2: "S", 3: "D", 4: "T", 5: "Z", 6: "R", 7: "I"}
    assert forks.others_running(states, me=1) == [6]
    assert forks.others_running(states, me=6) == [1]
    assert forks.others_running({}, me=1) == []


def test_no_wait_long_after_a_fork(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(forks, "_LAST_FORK", [time.monotonic() - 2 * forks.SETTLE_WAIT_S])
    monkeypatch.setattr(forks, "thread_states", lambda pid=None: pytest.fail("read the threads with no recent fork"))
    assert forks.settle_after_fork() is False


def test_a_busy_thread_holds_the_wait_to_its_window(monkeypatch: pytest.MonkeyPatch) -> None:
    """A thread that never rests: the wait ends with the window, False; one that rests: True."""
    monkeypatch.setattr(forks, "_LAST_FORK", [time.monotonic()])
    monkeypatch.setattr(forks, "thread_states", lambda pid=None: {0: "R"})
    assert forks.settle_after_fork(wait_s=0.05) is False
    monkeypatch.setattr(forks, "_LAST_FORK", [time.monotonic()])
    monkeypatch.setattr(forks, "thread_states", lambda pid=None: {0: "S"})
    assert forks.settle_after_fork() is True
