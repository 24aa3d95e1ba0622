"""A fork that the thread pools of the loaded libraries cannot hang.

ducc0's and pocketfft's thread pools (scipy.fft) stop their threads before every fork, in a
``pthread_atfork`` prepare handler, and start fresh ones after it, in the parent and in the
child alike.  The stop sets a flag and wakes each thread without taking the mutex that thread
waits under: a thread that has checked the flag but is not yet waiting misses the wake-up, and
the fork then waits for it to end -- forever.  A long-idle thread is always already waiting;
the thread at risk is one the latest fork has just started.  A worker's keeper forks the worker
a moment after it was forked itself (``isolation``), and a run may start workers back to back,
so both fork while such threads may still be on their way to their wait.

``settle_after_fork`` closes that window: within ``SETTLE_WAIT_S`` of this process's latest
fork it waits until no other thread of the process is running (``/proc``: every other thread
asleep or stopped), so that each pool thread is inside its wait when the next fork's stop
wakes it.  Later, or where ``/proc`` cannot be read, it returns at once.  ``process_context``'s fork
context forks each of its processes so (a worker's keeper, a ``--jobs`` pool's processes),
and in a worker every fork does (``settle_every_fork``: a solver's own).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
import threading
import time
from multiprocessing.context import BaseContext

#: How long after a fork (seconds) the threads it started may still be on their way to their
#: wait, and so the longest ``settle_after_fork`` waits.  A wait for the scheduler, not a
#: claim on speed: a fresh pool thread reaches its wait within microseconds of running.
SETTLE_WAIT_S = 1.0
#: How often (seconds) the threads' states are read while waiting.
SETTLE_POLL_S = 0.0005
#: The ``/proc/<pid>/task/<tid>/stat`` states of a thread that is not running: asleep (S, D,
#: I), stopped (T, t) or dead (Z, X).
NOT_RUNNING = frozenset("SDITtZX")

_LAST_FORK: list[float] = [-float("inf")]  # time.monotonic() at this process's latest fork


def _note_fork() -> None:
    _LAST_FORK[0] = time.monotonic()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_parent=_note_fork, after_in_child=_note_fork)


def thread_states(pid: int | None = None) -> dict[int, str]:
    """The scheduler state (``/proc``'s one letter: R running, S asleep, ...) of each thread of
    process ``pid`` (default: this one), by thread id; {} where ``/proc`` cannot be read."""
    task = f"/proc/{pid or os.getpid()}/task"
    try:
        tids = os.listdir(task)
    except OSError:
        return {}
    states: dict[int, str] = {}
    for tid in tids:
        try:
            with open(f"{task}/{tid}/stat", "rb") as fh:
                after_name = fh.read().rpartition(b")")[2].split()
        except OSError:  # (the thread ended meanwhile)
            continue
        if after_name and tid.isdigit():
            states[int(tid)] = after_name[0].decode("ascii", errors="replace")
    return states


def others_running(states: dict[int, str], me: int) -> list[int]:
    """The threads of ``states`` (``thread_states``) other than ``me`` that are running or
    runnable."""
    return sorted(tid for tid, state in states.items() if tid != me and state not in NOT_RUNNING)


def settle_after_fork(wait_s: float = SETTLE_WAIT_S) -> bool:
    """Before a fork: wait until no other thread of this process runs, but only while this
    process's latest fork (as parent or child) is less than ``wait_s`` seconds old (module
    doc).  True when it saw every other thread at rest; False when it returned without
    (no recent fork, or the window closed first)."""
    end = _LAST_FORK[0] + wait_s
    me = threading.get_native_id()
    while time.monotonic() < end:
        if not others_running(thread_states(), me):
            return True
        time.sleep(SETTLE_POLL_S)
    return False


_EVERY_FORK = [False]  # whether ``settle_every_fork`` holds in this process (inherited by its children)


def settle_every_fork() -> None:
    """From now on, every fork of this process and of its children -- ``os.fork`` and what
    forks through it, a solver's own included -- first runs ``settle_after_fork``."""
    if not _EVERY_FORK[0] and hasattr(os, "register_at_fork"):
        os.register_at_fork(before=settle_after_fork)
        _EVERY_FORK[0] = True


if sys.platform != "win32":
    from multiprocessing.context import ForkContext, ForkProcess

    class SettledForkProcess(ForkProcess):
        """A process forked once the threads of this process's latest fork are at rest."""

        def start(self) -> None:
            settle_after_fork()
            super().start()

    class SettledForkContext(ForkContext):
        """``multiprocessing``'s fork context whose processes are ``SettledForkProcess``."""

        Process = SettledForkProcess  # type: ignore[assignment]

    _SETTLED_FORK: BaseContext | None = SettledForkContext()
else:  # pragma: no cover - no fork
    _SETTLED_FORK = None


def default_start_method() -> str:
    """How processes are started: fork on Linux (a child inherits what the parent
    registered), spawn elsewhere."""
    return "fork" if sys.platform.startswith("linux") else "spawn"


def process_context(method: str | None = None) -> BaseContext:
    """``multiprocessing``'s context for ``method`` (default ``default_start_method``); its
    fork context forks each process after ``settle_after_fork``."""
    method = method or default_start_method()
    if method == "fork" and _SETTLED_FORK is not None:
        return _SETTLED_FORK
    return mp.get_context(method)
