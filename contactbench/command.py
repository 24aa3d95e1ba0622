"""The ``contactbench`` command's entry point: imports nothing until it runs, so that a
Ctrl-C (or SIGTERM's default) while the command is still loading its modules ends it
quietly, as a Ctrl-C later does (``harness.cli``: exit 130, one line), not in a traceback
through the imports."""

from __future__ import annotations

import sys

from contactbench.stops import EXIT_INTERRUPTED, STARTING_TEXT


def main() -> int:
    """``harness.cli.main``, loaded here."""
    try:
        from contactbench.harness.cli import main as command
    except KeyboardInterrupt:
        print(f"interrupted: {STARTING_TEXT}", file=sys.stderr)
        return EXIT_INTERRUPTED
    return command()
