"""Where a worker that gave no answer in time was: its stack, read before it is killed.

A worker dumps the Python stack of each of its threads to ``STACKS_NAME`` in its temporary
folder on ``STACK_SIGNAL`` (``faulthandler``: written from the signal handler itself, so a
thread stuck in C code or in a lock is read too).  Where a keeper holds the worker's tree
(``isolation``), the keeper passes the signal on to the worker; until it has forked the
worker, it dumps its own stack.  ``where_it_was`` sends the signal, waits at most
``DUMP_WAIT_S`` for the dump and names the signalled thread's innermost frames in one line --
Linux gives a signal sent to a process to its main thread where that thread takes it, and
the thread that took it is the one faulthandler marks current.  A worker that is stopped,
that replaced the signal's handler or that exited answers nothing, and so does its line.
"""

from __future__ import annotations

import contextlib
import faulthandler
import os
import re
import signal
import time
from typing import IO, Any

#: The file, in a worker's temporary folder, that its stack dumps go to.
STACKS_NAME = "stacks.txt"
#: The signal on which a worker dumps its stacks there.
STACK_SIGNAL = signal.SIGUSR1
#: The longest wait for a dump (seconds).
DUMP_WAIT_S = 1.0
#: How many of the signalled thread's innermost frames ``where_it_was`` names.
FRAMES_NAMED = 3

_DUMP_FILE: list[IO[str]] = []  # the open file faulthandler writes to (held for the process lifetime)
_FRAME = re.compile(r'^\s*File "(?P<path>[^"]*)", line (?P<line>\d+) in (?P<name>.*)$')


def short_path(path: str) -> str:
    """A source file's path as a row names it: cut below ``site-packages`` (a peer's own
    module), else its last two parts (``solvers/_ccg.py``)."""
    head, sep, tail = path.rpartition("site-packages" + os.sep)
    if sep:
        return tail
    return os.sep.join(path.split(os.sep)[-2:])


def dump_stacks_on_signal(folder: str) -> None:
    """From now on this process (and a child it forks, until that child replaces the handler)
    appends its threads' stacks to ``folder``/``STACKS_NAME`` on ``STACK_SIGNAL``."""
    with contextlib.suppress(OSError, ValueError, RuntimeError):
        fh = open(os.path.join(folder, STACKS_NAME), "a", encoding="utf-8")
        faulthandler.register(STACK_SIGNAL, file=fh, all_threads=True, chain=False)
        _DUMP_FILE[:] = [fh]


def pass_stack_signal_to(pid: int) -> None:
    """In a keeper: ``STACK_SIGNAL`` goes on to process ``pid`` (the worker) instead of
    dumping the keeper's own stack."""

    def forward(signum: int, frame: Any) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, signum)

    with contextlib.suppress(ValueError, OSError):
        signal.signal(STACK_SIGNAL, forward)


def where_it_was(pid: int, folder: str) -> str:
    """Ask process ``pid`` (a live worker, or its keeper) for its stacks, and give its
    signalled thread's innermost ``FRAMES_NAMED`` frames as ``; it was at file:line in
    name <- ...`` ("" when no dump came within ``DUMP_WAIT_S``)."""
    path = os.path.join(folder, STACKS_NAME)
    start = _size(path)
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.kill(pid, STACK_SIGNAL)
        text = _dump_after(path, start)
        frames = innermost_frames(text)
        return f"; it was at {' <- '.join(frames)}" if frames else ""
    return ""


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def _dump_after(path: str, start: int) -> str:
    """What was appended to ``path`` past ``start`` once it stops growing (a dump is
    written at once), or after ``DUMP_WAIT_S``."""
    end, seen = time.monotonic() + DUMP_WAIT_S, start
    while time.monotonic() < end:
        time.sleep(0.02)
        size = _size(path)
        if size > start and size == seen:
            break
        seen = size
    try:
        with open(path, "rb") as fh:
            fh.seek(start)
            return fh.read().decode("utf-8", errors="replace")
    except OSError:
        return ""


def innermost_frames(dump: str, count: int = FRAMES_NAMED) -> list[str]:
    """The first ``count`` frames (``file:line in name``, the file as ``short_path``) of the
    thread faulthandler's ``dump`` marks current -- of its first thread where none is."""
    blocks: list[tuple[bool, list[str]]] = []
    for line in dump.splitlines():
        if line.startswith(("Current thread", "Thread", "Stack (most recent call first)")):
            blocks.append((line.startswith("Current thread"), []))
        elif blocks and (m := _FRAME.match(line)):
            blocks[-1][1].append(f"{short_path(m['path'])}:{m['line']} in {m['name'].strip()}")
    chosen = next((frames for current, frames in blocks if current), blocks[0][1] if blocks else [])
    return chosen[:count]
