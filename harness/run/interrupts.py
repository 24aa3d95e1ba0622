"""Steps of a run's shutdown that a further Ctrl-C must not cut short.

After Ctrl-C (or SIGTERM) a run stops its workers and writes its table from the journal
(``harness.run.runner.execute_plan``).  A second signal in the middle would leave the
folder without its table until the next run.  ``signals_deferred`` holds SIGINT and
SIGTERM back for such a step: a signal that arrives meanwhile is acted on once the step
is done -- the handler in force before it then runs (``KeyboardInterrupt``, the
command's ``Terminated``) -- unless the step ends by an exception already (the command
is then stopping anyway, and the signal has nothing more to stop).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Any, Iterator

#: The signals that stop a run (Ctrl-C, a batch scheduler's or ``kill``'s SIGTERM).
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """``STOP_SIGNALS`` held back for the block (module doc); in a thread other than the
    main one (which cannot set handlers) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        pending.append(signum)

    before = {sig: signal.signal(sig, hold) for sig in STOP_SIGNALS}
    failed = True
    try:
        yield
        failed = False
    finally:
        for sig, handler in before.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        if pending and not failed:
            signal.raise_signal(pending[0])
