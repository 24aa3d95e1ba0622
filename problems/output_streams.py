"""Where a block's output goes: file descriptors 1 and 2 and Python's streams pointed at a file.

* ``flush_output`` -- flush Python's stdout and stderr and C's stdio buffers;
* ``output_to_fd`` -- for the span of a block, file descriptors 1 and 2 (stdout and
  stderr, of Python and of C libraries alike) and ``sys.stdout``/``sys.stderr`` write to
  an open file descriptor; then all is put back, whatever happened;
* ``foreign_output_held`` -- a foreign reader's output held off the terminal
  (``output_to_fd`` on a temporary file, its ``logging`` and its Python warnings too), kept
  as a ``ForeignOutput``.

The harness's workers send a solve's output to its log through ``output_to_fd``; map
reading holds its readers' output through ``foreign_output_held``.  Descriptors are the
process's: neither is for a block that runs beside other threads that print.
"""

from __future__ import annotations

import ctypes
import logging
import os
import sys
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator

from .errors import printable_excerpt

#: The most bytes of what a foreign reader wrote while it ran that are kept (``ForeignOutput``).
FOREIGN_OUTPUT_BYTES = 64 * 1024
#: Warnings a foreign reader raises about its own code or installation, not about its
#: input: never passed on (``ForeignOutput``).
FOREIGN_NOISE: tuple[type[Warning], ...] = (DeprecationWarning, PendingDeprecationWarning, ImportWarning,
                                            ResourceWarning)


def flush_output() -> None:
    """Flush Python's stdout and stderr and C's stdio buffers (best effort: a stream may be
    closed or replaced)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # a stream someone replaced or closed
            pass
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library to flush
        pass


@contextmanager
def output_to_fd(fd: int) -> Iterator[None]:
    """File descriptors 1 and 2 and ``sys.stdout``/``sys.stderr`` (whatever they were: a test
    runner's capture) write to the open descriptor ``fd`` for the block; then all is put
    back, whatever happened.  ``fd`` stays open (its owner closes it); any other
    descriptor -- a worker's result pipe -- is untouched."""
    flush_output()
    saved = (os.dup(1), os.dup(2))
    streams = (sys.stdout, sys.stderr)
    text = open(fd, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
    try:
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        sys.stdout = sys.stderr = text
        yield
    finally:
        flush_output()
        sys.stdout, sys.stderr = streams
        text.close()
        for target, saved_fd in ((1, saved[0]), (2, saved[1])):
            os.dup2(saved_fd, target)
            os.close(saved_fd)


@dataclass
class ForeignOutput:
    """What a foreign reader said while it ran (``foreign_output_held``): the messages of
    its Python warnings (``FOREIGN_NOISE`` left out) and what it wrote to stdout and
    stderr -- Python's streams, and file descriptors 1 and 2, so C code's writes and the
    ``logging`` lines of its libraries too (the first ``FOREIGN_OUTPUT_BYTES``)."""

    warnings: list[str] = field(default_factory=list)
    written: str = ""

    def notes(self) -> tuple[str, ...]:
        """Our one-line warnings of a read that succeeded: each warning, then what it
        wrote (``printable_excerpt``s; nothing where it said nothing)."""
        said = [f"its reader warned: {printable_excerpt(w)}" for w in dict.fromkeys(self.warnings)]
        wrote = printable_excerpt(self.written)
        return (*said, *([f"its reader wrote: {wrote}"] if wrote else []))


@contextmanager
def foreign_output_held() -> Iterator[ForeignOutput]:
    """Run the block -- a foreign reader -- with its output held off the terminal
    (``output_to_fd`` on a temporary file, and the root logger's handlers: the ``logging``
    of its libraries) and its Python warnings recorded (under the filters in force), not
    shown.  Whatever happens (an exception, Ctrl-C), all is put back, and the yielded
    ``ForeignOutput`` is filled in before the block's exception passes on."""
    held = ForeignOutput()
    handlers = logging.root.handlers[:]
    with tempfile.TemporaryFile() as sink, warnings.catch_warnings(record=True) as caught:
        log = open(sink.fileno(), "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
        try:
            with output_to_fd(sink.fileno()):
                logging.root.handlers = [logging.StreamHandler(log)]
                try:
                    yield held
                finally:
                    logging.root.handlers = handlers
        finally:
            log.close()
            sink.seek(0)
            held.written = sink.read(FOREIGN_OUTPUT_BYTES).decode("utf-8", errors="replace")
            held.warnings = [str(w.message) for w in caught if not issubclass(w.category, FOREIGN_NOISE)]


__all__ = ["FOREIGN_NOISE", "FOREIGN_OUTPUT_BYTES", "ForeignOutput", "flush_output", "foreign_output_held",
           "output_to_fd"]
