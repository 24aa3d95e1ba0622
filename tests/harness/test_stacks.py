"""A worker that gives no answer in time is asked where it was before it is killed: the
timeout's detail names the frames its main thread was in -- a Python loop, a lock waited on
in C, with or without a keeper -- and a worker that cannot answer (stopped) costs at most
the dump's wait and names nothing (``harness.run.stacks``)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

import pytest

from contactbench.harness.run import isolation, stacks
from contactbench.harness.run.isolation import ChildProcess

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork, and faulthandler's signals")


def _spins_in_python(message: object) -> None:
    while True:
        sum(range(1000))


def _waits_on_a_lock(message: object) -> None:
    lock = threading.Lock()
    lock.acquire()
    lock.acquire()  # (waited on in C, the GIL released)


def _stops_itself(message: object) -> None:
    os.kill(os.getpid(), signal.SIGSTOP)


def timeout_detail(handler: object) -> str:
    child = ChildProcess(lambda: handler)
    try:
        out = child.call("go", 0.5)
    finally:
        child.close()
    assert out.kind == "timeout", out
    return out.detail


@pytest.mark.parametrize(("handler", "where"), [(_spins_in_python, "in _spins_in_python"),
                                                 (_waits_on_a_lock, "in _waits_on_a_lock")])
def test_a_timeout_names_where_the_worker_was(handler: object, where: str) -> None:
    detail = timeout_detail(handler)
    assert "; it was at harness/test_stacks.py:" in detail and where in detail, detail
    assert "in serve" in detail.split("; it was at ", 1)[1], detail  # (the worker's loop, below the handler)


def test_a_worker_without_a_keeper_names_where_it_was_too(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(isolation, "become_subreaper", lambda: False)  # (read by the forked child)
    assert "in _spins_in_python" in timeout_detail(_spins_in_python)


def test_a_worker_that_cannot_answer_names_nothing_and_is_still_killed() -> None:
    t0 = time.monotonic()
    detail = timeout_detail(_stops_itself)
    assert detail.startswith("no answer within the hard limit") and "it was at" not in detail, detail
    assert time.monotonic() - t0 < 30  # (bounded: the dump's wait, not forever)


def test_the_current_thread_is_named_and_a_dump_without_frames_names_nothing() -> None:
    dump = ('Thread 0x00007f0000000001 (most recent call first):\n'
            '  File "/x/lib/python3.11/threading.py", line 320 in wait\n'
            'Current thread 0x00007f0000000002 (most recent call first):\n'
            '  File "/repo/solvers/_ccg.py", line 12 in step\n'
            '  File "/v/lib/site-packages/scipy/fft/_basic.py", line 7 in rfft\n')
    assert stacks.innermost_frames(dump) == ["solvers/_ccg.py:12 in step", "scipy/fft/_basic.py:7 in rfft"]
    assert stacks.innermost_frames(dump, 1) == ["solvers/_ccg.py:12 in step"]
    assert stacks.innermost_frames(dump.split("Current")[0]) == ["python3.11/threading.py:320 in wait"]
    assert stacks.innermost_frames("") == [] and stacks.innermost_frames("garbage\n\x00") == []


def _stops_its_keeper(runner: object) -> str:
    if os.getppid() == runner:  # no keeper here: the worker's parent is the runner itself
        return "no keeper"
    os.kill(os.getppid(), signal.SIGSTOP)
    return "answered"


def test_a_worker_whose_solve_stopped_its_keeper_still_ends_on_its_own_at_close() -> None:
    child = ChildProcess(lambda: _stops_its_keeper)
    out = child.call(os.getpid(), 30.0)
    keeper = child.proc
    child.close()
    if out.value == "no keeper":
        pytest.skip("this platform runs the worker without a keeper (solvers._processes.SUBREAPER_MISSING)")
    assert out.kind == "ok" and out.value == "answered", out
    assert keeper is not None and keeper.exitcode == 0, keeper  # (-9: killed after the wait)
