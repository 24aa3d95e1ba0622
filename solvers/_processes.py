"""The processes a solve starts, and ending them: what isolates a solve from what it leaves running.

A solver (or an outside program) may start processes, and one of them may leave the process
group it was started in (``setsid``) and so escape a kill of that group.  Two tools keep every
such process within reach:

* ``become_subreaper`` -- Linux (``PR_SET_CHILD_SUBREAPER``): the calling process adopts the
  orphans among its descendants (a child whose parent exited is re-parented to it, not to
  init), so every process a solve started stays its descendant while it lives; a no-op
  elsewhere;
* ``end_descendants(pid)`` -- SIGKILL every descendant of ``pid`` (found by their parent
  links, ``psutil``), round after round until no new one appears (one that forked while the
  others were killed), and ``reap_children`` collects the calling process's dead children.

Only descendants of the given process are signalled, each checked against its start time
before the signal (a pid reused by another process is left alone): nothing that is not the
solve's is touched.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time

import psutil

#: ``prctl`` option that makes the caller adopt its descendants' orphans (linux/prctl.h).
PR_SET_CHILD_SUBREAPER = 36
#: At most this many rounds of ``end_descendants`` (each ends everything found then).
KILL_ROUNDS = 50
#: Seconds ``reap_children`` waits at most for killed children to exit.
REAP_WAIT_S = 5.0


def become_subreaper() -> bool:
    """Make this process adopt its descendants' orphans (module doc); whether it took effect
    (False off Linux, or where the C library or the kernel refuses)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)) == 0
    except (OSError, AttributeError):  # pragma: no cover - no C library to ask
        return False


def descendants(pid: int) -> list[psutil.Process]:
    """The live (not yet exited) descendants of process ``pid``; none when it is gone."""
    try:
        found = psutil.Process(pid).children(recursive=True)
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return []
    live = []
    for proc in found:
        try:
            if proc.status() != psutil.STATUS_ZOMBIE:
                live.append(proc)
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
    return live


def _in_group(proc: psutil.Process, group: int | None) -> bool:
    try:
        return group is not None and os.getpgid(proc.pid) == group
    except OSError:  # gone
        return False


def end_descendants(pid: int, except_group: int | None = None) -> int:
    """SIGKILL every descendant of process ``pid`` (module doc) -- but those in process group
    ``except_group``, which the caller signals itself; how many were signalled."""
    signalled: set[psutil.Process] = set()
    for _ in range(KILL_ROUNDS):
        new = [p for p in descendants(pid) if p not in signalled and not _in_group(p, except_group)]
        if not new:
            break
        for proc in new:
            try:
                proc.kill()  # psutil checks the start time first: a reused pid is not signalled
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                pass
            signalled.add(proc)
    return len(signalled)


def has_children() -> bool:
    """Whether this process has a child, running or exited (a dead one is reaped here)."""
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return False
    return True


def reap_children(wait_s: float = REAP_WAIT_S) -> None:
    """Collect this process's exited children, waiting at most ``wait_s`` seconds for those
    still exiting (after ``end_descendants``)."""
    end = time.monotonic() + wait_s
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            if time.monotonic() > end:
                return
            time.sleep(0.005)


def end_own_descendants() -> int:
    """``end_descendants`` of this process, then ``reap_children``: what a solve left running
    ends with it.  Cheap when there is nothing (no child: no scan of the process table)."""
    if not has_children():
        return 0
    count = end_descendants(os.getpid())
    reap_children()
    return count
