"""How the ``contactbench`` command ends when it is stopped (docs/harness.md, "Exit
status"): the statuses a shell reports for the signal, and what a command stopped before
it ran anything says.  Read by the entry point (``contactbench.command``) before anything
else is loaded, and by ``harness.cli``."""

from __future__ import annotations

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130
#: ... and by SIGTERM (128 + SIGTERM).
EXIT_TERMINATED = 143
#: What a command stopped before it ran anything was doing (after "interrupted: ").
STARTING_TEXT = "contactbench was starting; nothing was run"
