"""How the ``contactbench`` command ends when it is stopped (docs/harness.md, "Exit
status"): the statuses a shell reports for the signal, and what a command stopped before
it ran anything says, read by the entry point (``contactbench.command``) before anything
else is loaded, and by ``harness.cli``; and which stop signals arrived while a block ran
(``signals_noted``), so that a stop the code it interrupted swallowed still stops the
command (``raise_noted``: plug-in discovery, a user's solver module); and the holding back
of those signals for a step that a stop must not cut short (``signals_deferred``: a run's
shutdown, harness/run/interrupts.py; taking and letting go a folder's lock,
harness/table/store.py).  Nothing here imports beyond the standard library."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from types import FrameType
from typing import Any, Callable, Iterator

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130
#: ... and by SIGTERM (128 + SIGTERM).
EXIT_TERMINATED = 143
#: What a command stopped before it ran anything was doing (after "interrupted: ").
STARTING_TEXT = "contactbench was starting; nothing was run"

#: The signals whose arrival makes a ``KeyboardInterrupt`` the user's (Ctrl-C; SIGTERM,
#: which the command line raises as one: harness/cli.py ``Terminated``).
USER_STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)


def _noting(arrived: set[int], handler: Callable[[int, FrameType | None], Any]) -> Callable[..., Any]:
    """A signal handler that records its signal in ``arrived``, then runs ``handler``."""

    def note(signum: int, frame: FrameType | None) -> Any:
        arrived.add(signum)
        return handler(signum, frame)

    return note


@contextmanager
def signals_noted() -> Iterator[set[int]]:
    """The set of ``USER_STOP_SIGNALS`` that arrive while the block runs, each still
    handled by the handler it had.  Only the main thread's Python handlers raise
    ``KeyboardInterrupt``; elsewhere (another thread, a signal ignored or left to its
    default) nothing is watched, and none of them can raise one."""
    arrived: set[int] = set()
    before: dict[int, tuple[Any, Any]] = {}
    if threading.current_thread() is threading.main_thread():
        for signum in USER_STOP_SIGNALS:
            handler = signal.getsignal(signum)
            if callable(handler):
                before[signum] = (handler, _noting(arrived, handler))
                signal.signal(signum, before[signum][1])
    try:
        yield arrived
    finally:
        for signum, (handler, noting) in before.items():
            if signal.getsignal(signum) is noting:  # (a handler the block set is left as it is)
                signal.signal(signum, handler)


def raise_noted(arrived: set[int]) -> None:
    """Raise what each signal in ``arrived`` raises (its handler, called again): for a stop
    that code it interrupted swallowed -- a ``KeyboardInterrupt`` caught inside an import --
    so that the user's stop still stops the command."""
    for signum in sorted(arrived):
        handler = signal.getsignal(signum)
        if callable(handler):
            handler(signum, None)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """``USER_STOP_SIGNALS`` held back for the block: a signal that arrives meanwhile is
    acted on once the block is done -- the handler in force before it then runs -- unless
    the block ends by an exception already (the command is then stopping anyway).  In a
    thread other than the main one (which cannot set handlers) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        pending.append(signum)

    before = {sig: signal.signal(sig, hold) for sig in USER_STOP_SIGNALS}
    failed = True
    try:
        yield
        failed = False
    finally:
        for sig, handler in before.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        if pending and not failed:
            signal.raise_signal(pending[0])
