"""The ``contactbench`` command's entry point: imports nothing until it runs, so that a
Ctrl-C (or SIGTERM's default) while the command is still loading its modules ends it
quietly, as a Ctrl-C later does (``harness.cli``: exit 130, one line), not in a traceback
through the imports."""

from __future__ import annotations

import sys

#: Exit status of a command stopped by Ctrl-C (128 + SIGINT), as ``harness.cli`` ends one.
EXIT_INTERRUPTED = 130
#: What a command stopped before it ran anything was doing (``harness.cli`` says it too, while
#: it reads its arguments).
STARTING_TEXT = "contactbench was starting; nothing was run"


def main() -> int:
    """``harness.cli.main``, loaded here."""
    try:
        from contactbench.harness.cli import main as command
    except KeyboardInterrupt:
        print(f"interrupted: {STARTING_TEXT}", file=sys.stderr)
        return EXIT_INTERRUPTED
    return command()
