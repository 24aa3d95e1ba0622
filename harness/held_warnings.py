"""What a command refuses bad input with, and the warnings it holds while it checks its input.

``harness.cli`` refuses an ``INPUT_ERRORS`` (or an ``OSError``: a path that cannot be read
or written) in one line with exit status 2; the warnings its checks raised are then not
shown (``HeldWarnings``, ``held_warnings``).
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Iterator

from contactbench.problems.errors import ProblemInputError


#: What a command refuses bad input with (``harness.cli``: one line, its problems joined by "; ", exit 2; an
#: ``OSError``: a path that cannot be read or written); the warnings its checks raised are
#: then not shown (``HeldWarnings``).
INPUT_ERRORS: tuple[type[Exception], ...] = (ProblemInputError, KeyError, ValueError)
BAD_INPUT_ERRORS: tuple[type[Exception], ...] = (*INPUT_ERRORS, OSError)


@dataclass
class HeldWarnings:
    """A ``warnings.showwarning`` that holds the warnings a command raises while it checks
    its input, so that bad input is refused in its one line with nothing before it: once
    every check has passed the command calls ``release`` (the warnings held are shown, in
    order, and any later one at once); warnings still held when the command refuses its
    input are dropped (``held_warnings``)."""

    show: Any
    held: list[tuple[Any, ...]] = field(default_factory=list)
    released: bool = False

    def __call__(self, message: Warning | str, category: type[Warning], filename: str, lineno: int,
                 file: Any = None, line: str | None = None) -> None:
        if self.released:
            self.show(message, category, filename, lineno, file, line)
        else:
            self.held.append((message, category, filename, lineno, file, line))

    def release(self) -> None:
        """Show the warnings held, and from now on each warning at once."""
        self.released = True
        held, self.held = self.held, []
        for args in held:
            self.show(*args)


@contextmanager
def held_warnings() -> Iterator[HeldWarnings]:
    """Hold the warnings shown in the block (``HeldWarnings``); at its end those still held
    are shown, unless it ended by refusing bad input (``BAD_INPUT_ERRORS``)."""
    holder = HeldWarnings(warnings.showwarning)
    warnings.showwarning = holder
    try:
        yield holder
    except BAD_INPUT_ERRORS:
        holder.held.clear()
        raise
    finally:
        warnings.showwarning = holder.show
        holder.release()
