"""What solvers print during a run: kept in OUT/solver-output.log, off the terminal.

A solver's output (file descriptors 1 and 2, so a C extension's and a program's it runs
too) goes, one worker message at a time, to a file of the job's own
(``SolverOutput.worker_file``: the isolated worker's handler writes there,
``harness.run.worker.SolveServer``); after each message the job's driver
(``harness.run.job.JobDriver``) moves its head into the run's log
(``OutputLog.append``) and empties it.  The solver code the driver runs in its own
process -- a solver's skip check and time, memory and capability models -- is captured
the same way (``SolverOutput.captured``).  The terminal keeps the progress bar and the
harness's own messages.

A message the run is stopped in (Ctrl-C, SIGTERM) gets no reply; what it printed so far
joins the log all the same, its entry's title ending "(interrupted)", with a further
Ctrl-C held back until it is written (``harness.run.interrupts.signals_deferred``):
``SolverOutput.collect_stopped`` under the message's own title, else -- what is left when
the driver ends -- under ``STOPPED_TITLE`` (``SolverOutput.close``).

The log is bounded: each entry keeps the first ``ENTRY_HEAD_BYTES`` bytes of one
message's output and says how many it dropped; once the log holds ``LOG_CAP_BYTES`` it
takes no more entries and its last line counts what was dropped since
(``dropped_line``, rewritten in place).  Pool processes append to one log under an
exclusive ``flock``.  The log is never written through a link: it is opened with
``O_NOFOLLOW``, and a run whose log is a link or a folder is refused before anything runs
(the rule of every entry of a results folder, ``harness.table.store.check_run_entries``).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from .interrupts import signals_deferred
from .isolation import KEPT_HEAD_BYTES, SCRATCH_PREFIX, output_to

#: The run folder's file of what the solvers printed (meta.json ``solver_output`` names it).
OUTPUT_LOG = "solver-output.log"
#: The bytes of one message's output an entry keeps (its head: what a waiting parent keeps
#: of a message's output file, ``isolation.bound_output``).
ENTRY_HEAD_BYTES = KEPT_HEAD_BYTES
#: The size past which the log takes no more entries (its last line then counts them).
LOG_CAP_BYTES = 16 * 1024 * 1024

#: How an entry's title ends when the run was stopped in its message (Ctrl-C, SIGTERM).
STOPPED = "(interrupted)"
#: The title of what is left in the driver's files when it ends: the output of the message
#: the run was stopped in, not collected under that message's own title.
STOPPED_TITLE = "the message in progress when the run was stopped"

#: How the log's own last line begins once it is full (``dropped_line``); printed by a solver,
#: it is written as ``FORGED_FULL`` instead, so no output can make the log look full.
FULL_MARK = b"[the log is full ("
FORGED_FULL = b"[printed: " + FULL_MARK[1:]
_DROPPED = re.compile(re.escape(FULL_MARK) + rb"(\d+) bytes\): +(\d+) bytes of +(\d+) more outputs dropped\]\n\Z")


def dropped_line(cap: int, dropped_bytes: int, outputs: int) -> bytes:
    """The log's last line once it is full: fixed width, so it is rewritten in place."""
    return FULL_MARK + f"{cap} bytes): {dropped_bytes:20d} bytes of {outputs:12d} more outputs dropped]\n" \
        .encode("ascii")


def entry(title: str, head: bytes, size: int) -> bytes:
    """One entry: a title line, the output's head (a line that reads as the log's own
    "full" line changed, ``FORGED_FULL``), and what was dropped of it."""
    kept = len(head)
    head = head.replace(FULL_MARK, FORGED_FULL)
    body = head if head.endswith(b"\n") else head + b"\n"
    cut = f"[... {size - kept} more bytes dropped: an entry keeps the first {kept}]\n" if size > kept else ""
    return f"==> {title} ({size} bytes) <==\n".encode("utf-8", "replace") + body + cut.encode("ascii")


@dataclass(frozen=True)
class OutputLog:
    """OUT/solver-output.log (module doc)."""

    path: Path
    entry_head: int = ENTRY_HEAD_BYTES
    cap: int = LOG_CAP_BYTES

    def append(self, title: str, source: Path) -> None:
        """Add the head of ``source`` (one message's output) under ``title``; nothing when it
        is empty or unreadable."""
        try:
            with open(source, "rb") as fh:
                size = os.fstat(fh.fileno()).st_size
                head = fh.read(self.entry_head) if size else b""
        except OSError:
            return
        if not size:
            return
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)  # (never through a link)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            self._write(fd, entry(title, head, size), size)
        finally:
            os.close(fd)  # (closing releases the lock)

    def _write(self, fd: int, text: bytes, size: int) -> None:
        end = os.fstat(fd).st_size
        width = len(dropped_line(self.cap, 0, 0))
        last = os.pread(fd, width, end - width) if end >= width else b""
        full = _DROPPED.search(last)
        if full:
            os.pwrite(fd, dropped_line(self.cap, int(full[2]) + size, int(full[3]) + 1), end - width)
        elif end + len(text) <= self.cap:
            os.pwrite(fd, text, end)
        else:
            os.pwrite(fd, dropped_line(self.cap, size, 1), end)


class SolverOutput:
    """The files that take a job's solver output before it joins the run's ``log``: a
    temporary folder of the driver's (named as a worker's, so one left by a killed run is
    removed as theirs: ``isolation.remove_orphan_scratch``)."""

    def __init__(self, log: OutputLog) -> None:
        self.log = log
        self.folder = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-output-"))
        self.worker_file = self.folder / "worker.txt"
        self.own_file = self.folder / "driver.txt"

    def collect(self, title: str, source: Path | None = None) -> None:
        """Move what ``source`` (default: the worker's file) holds into the log, and empty it."""
        path = source or self.worker_file
        self.log.append(title, path)
        with contextlib.suppress(OSError):
            os.truncate(path, 0)

    def collect_stopped(self, title: str, source: Path | None = None) -> None:
        """``collect`` the output of a message the run was stopped in, its title marked
        ``STOPPED``; a further Ctrl-C or SIGTERM meanwhile waits for it (module doc)."""
        with signals_deferred():
            self.collect(f"{title} {STOPPED}", source)

    @contextlib.contextmanager
    def captured(self, title: str) -> Iterator[None]:
        """The block's output (this process's descriptors 1 and 2) into the log under ``title``
        (marked ``STOPPED`` where the run is stopped in the block)."""
        stopped = False
        try:
            with output_to(str(self.own_file)):
                yield
        except KeyboardInterrupt:  # (Ctrl-C, and SIGTERM's ``Terminated``)
            stopped = True
            raise
        finally:
            (self.collect_stopped if stopped else self.collect)(title, self.own_file)

    def close(self) -> None:
        """Remove the files.  What they still hold -- the output of a message the run was
        stopped in, its worker killed -- joins the log first, under ``STOPPED_TITLE``: each
        reply's output is collected when it comes."""
        with signals_deferred():
            for source in (self.worker_file, self.own_file):
                self.collect(f"{STOPPED_TITLE} {STOPPED}", source)
            shutil.rmtree(self.folder, ignore_errors=True)
