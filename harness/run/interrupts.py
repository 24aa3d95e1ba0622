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

from contactbench.stops import USER_STOP_SIGNALS as STOP_SIGNALS, signals_deferred

__all__ = ["STOP_SIGNALS", "signals_deferred"]
