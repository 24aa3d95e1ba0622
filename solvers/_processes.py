"""The processes a solve starts, and ending them: what isolates a solve from what it leaves running.

A solver (or an outside program) may start processes, and one of them may leave the process
group it was started in (``setsid``) and so escape a kill of that group.  Three tools keep every
such process within reach:

* ``become_subreaper`` -- Linux (``PR_SET_CHILD_SUBREAPER``): the calling process adopts the
  orphans among its descendants (a child whose parent exited is re-parented to it, not to
  init), so every process a solve started stays its descendant while it lives; a no-op
  elsewhere;
* ``end_descendants(pid)`` -- SIGKILL every descendant of ``pid`` (found by their parent
  links, ``psutil``), round after round until no new one appears (one that forked while the
  others were killed); ``end_own_descendants()`` does so for the calling process and collects
  its dead children, pass after pass until it has no child left (a scan of the process table
  is not atomic: one that missed a process is followed by another);
* ``ends_what_it_starts()`` -- the same for a solve run in the caller's own process (which
  has other children: a test runner's, a pool's): for the block, the caller adopts orphans,
  and after it every process started during it -- each child of the caller that was not
  there before (an orphan it adopted included), with its descendants -- is killed and
  reaped; the caller's other children and theirs are left alone.  A process another thread
  of the caller starts during the block counts as the block's.

Only descendants of the given process are signalled, each checked against its start time
before the signal (a pid reused by another process is left alone): nothing that is not the
solve's is touched.  Where ``PR_SET_CHILD_SUBREAPER`` is missing (``SUBREAPER_MISSING``), a
process that leaves its group and whose parent exits is out of reach.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import time
from typing import Iterator

import psutil

#: ``prctl`` options that set and read whether the caller adopts its descendants' orphans
#: (linux/prctl.h).
PR_SET_CHILD_SUBREAPER = 36
PR_GET_CHILD_SUBREAPER = 37
#: Why a process a solve starts may outlive it where orphans cannot be adopted.
SUBREAPER_MISSING = ("no PR_SET_CHILD_SUBREAPER (a Linux prctl): a process a solve starts that leaves its process "
                     "group (setsid) and whose parent exits is not adopted, and may outlive the solve")
#: At most this many rounds of ``end_descendants`` (each ends everything found then).
KILL_ROUNDS = 50
#: Seconds ``end_own_descendants`` and ``end_started_since`` wait at most for killed children
#: to exit.
REAP_WAIT_S = 5.0
#: Seconds between two scans of the process table while they wait (each pass collects the
#: exited children; one in this many seconds also kills what is left).
RESCAN_S = 0.05


def become_subreaper() -> bool:
    """Make this process adopt its descendants' orphans (module doc); whether it took effect
    (False off Linux, or where the C library or the kernel refuses: ``SUBREAPER_MISSING``).
    A forked child does not inherit it."""
    return _set_subreaper(True)


def _set_subreaper(on: bool) -> bool:
    libc = _libc()
    return libc is not None and int(libc.prctl(PR_SET_CHILD_SUBREAPER, int(on), 0, 0, 0)) == 0


def is_subreaper() -> bool:
    """Whether this process adopts its descendants' orphans (False where it cannot be asked)."""
    libc, flag = _libc(), ctypes.c_int(0)
    return libc is not None and int(libc.prctl(PR_GET_CHILD_SUBREAPER, ctypes.byref(flag), 0, 0, 0)) == 0 \
        and flag.value != 0


def _libc() -> ctypes.CDLL | None:
    """The C library, on Linux (where ``prctl`` is); None elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:  # pragma: no cover - no C library to ask
        return None
    return libc if hasattr(libc, "prctl") else None


def descendants(pid: int) -> list[psutil.Process]:
    """The live (not yet exited) descendants of process ``pid``; none when it is gone."""
    try:
        return live(psutil.Process(pid).children(recursive=True))
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return []


def live(procs: list[psutil.Process]) -> list[psutil.Process]:
    """Those of ``procs`` that have not exited (a zombie, or one gone, is left out)."""
    found = []
    for proc in procs:
        with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
            if proc.status() != psutil.STATUS_ZOMBIE:
                found.append(proc)
    return found


def _in_group(proc: psutil.Process, group: int | None) -> bool:
    try:
        return group is not None and os.getpgid(proc.pid) == group
    except OSError:  # gone
        return False


def end_descendants(pid: int, except_group: int | None = None) -> int:
    """SIGKILL every descendant of process ``pid`` (module doc) -- but those in process group
    ``except_group``, which the caller signals itself; how many were signalled."""
    signalled: set[psutil.Process] = set()
    _end_new_descendants(pid, except_group, signalled)
    return len(signalled)


def _end_new_descendants(pid: int, except_group: int | None, signalled: set[psutil.Process]) -> None:
    """SIGKILL, round after round, every descendant of ``pid`` that is not in ``signalled``
    (nor in group ``except_group``), adding each to ``signalled``."""
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


def has_children() -> bool:
    """Whether this process has a child, running or exited (a dead one is reaped here)."""
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return False
    return True


def _reap_exited() -> bool:
    """Collect every exited child of this process; whether a child is left (still running)."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return False
        if pid == 0:
            return True


def end_own_descendants(wait_s: float = REAP_WAIT_S) -> int:
    """SIGKILL every descendant of this process and collect its exited children until it has
    no child left, waiting at most ``wait_s`` seconds for them to exit: what a solve left
    running ends with it.  While it waits it scans the process table afresh every
    ``RESCAN_S``, so a descendant one scan missed (read while a process of its chain was
    exiting) is killed by a later one, not waited for.  How many were signalled.  Cheap when
    there is nothing (no child: no scan of the process table)."""
    if not has_children():
        return 0
    me, end, scan_at = os.getpid(), time.monotonic() + wait_s, 0.0
    signalled: set[psutil.Process] = set()
    while True:
        if time.monotonic() >= scan_at:
            _end_new_descendants(me, None, signalled)
            scan_at = time.monotonic() + RESCAN_S
        if not _reap_exited() or time.monotonic() > end:
            return len(signalled)
        time.sleep(0.005)


def snapshot(pid: int) -> frozenset[psutil.Process]:
    """Every descendant of process ``pid`` now, exited ones not yet reaped included (each
    known by its pid and start time)."""
    with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
        return frozenset(psutil.Process(pid).children(recursive=True))
    return frozenset()


def started_since(pid: int, before: frozenset[psutil.Process]) -> list[psutil.Process]:
    """The processes of ``pid``'s tree started since ``before`` (its ``snapshot``): each child
    of ``pid`` not in it -- started by ``pid``, or an orphan it adopted -- with its
    descendants; not a new process under one that was there before (another's)."""
    try:
        children = psutil.Process(pid).children()
    except (psutil.NoSuchProcess, psutil.AccessDenied):
        return []
    found = []
    for child in children:
        if child in before:
            continue
        found.append(child)
        with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
            found.extend(p for p in child.children(recursive=True) if p not in before)
    return found


def end_started_since(before: frozenset[psutil.Process], wait_s: float = REAP_WAIT_S) -> int:
    """SIGKILL every process of this process's tree started since ``before`` (its
    ``snapshot``: ``started_since``), round after round, and reap those that are its
    children (by their pids: no other child's exit is collected) until none is left, waiting
    at most ``wait_s`` seconds; while it waits it scans afresh every ``RESCAN_S`` and kills
    what an earlier scan missed.  How many were signalled."""
    me = os.getpid()
    found = started_since(me, before)
    if not found:  # (nothing to kill or reap: no second look at the process table)
        return 0
    signalled: set[psutil.Process] = set()
    end, scan_at = time.monotonic() + wait_s, time.monotonic() + RESCAN_S
    _end_started(me, before, found, signalled)
    while not _reaped_started(me, before) and time.monotonic() <= end:
        time.sleep(0.005)
        if time.monotonic() >= scan_at:
            _end_started(me, before, started_since(me, before), signalled)
            scan_at = time.monotonic() + RESCAN_S
    return len(signalled)


def _end_started(me: int, before: frozenset[psutil.Process], found: list[psutil.Process],
                 signalled: set[psutil.Process]) -> None:
    """SIGKILL, round after round, the live processes of ``found`` (and of each fresh
    ``started_since`` scan) that are not in ``signalled``, adding each to it."""
    for _ in range(KILL_ROUNDS):
        new = [p for p in live(found) if p not in signalled]
        if not new:
            return
        for proc in new:
            with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
                proc.kill()  # (psutil checks the start time first: a reused pid is not signalled)
            signalled.add(proc)
        found = started_since(me, before)


def _reaped_started(me: int, before: frozenset[psutil.Process]) -> bool:
    """Whether this process (``me``) has no child left that is not in ``before``; each
    exited one is collected here, and then False: one that exited may have left an orphan
    adopted after the list was read, which the next call lists."""
    try:
        waiting = [c.pid for c in psutil.Process(me).children() if c not in before]
    except (psutil.NoSuchProcess, psutil.AccessDenied):  # pragma: no cover - this process is there
        return True
    for pid in waiting:
        _reaped(pid)
    return not waiting


def _reaped(pid: int) -> bool:
    """Whether child ``pid`` has exited and is collected now (or is no child to collect)."""
    try:
        return os.waitpid(pid, os.WNOHANG)[0] != 0
    except ChildProcessError:
        return True


@contextlib.contextmanager
def ends_what_it_starts() -> Iterator[None]:
    """Every process the block starts in this process -- one that leaves its group
    (``setsid``) and whose parent exits included, where orphans can be adopted -- ends with
    the block, however the block ends (module doc); this process adopts orphans for the
    block only, unless it did before."""
    before = snapshot(os.getpid())
    adopting = is_subreaper()
    took = not adopting and become_subreaper()
    try:
        yield
    finally:
        try:
            end_started_since(before)
        finally:
            if took:
                _set_subreaper(False)
