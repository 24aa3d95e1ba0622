"""One function called in a forked child process, its plain result brought back: how the
harness loads user code it must not run in its own process.

``in_a_child`` runs ``fn(*args)`` in a child forked from the caller's process
(``isolation.ChildProcess``) and returns what it returned.  A one-line refusal ``fn``
raises there (``CARRIED_ERRORS``, any ``OneLine``) is carried back by its text and raised
again in the caller's process as its own kind; a child that ends before it answers
(``os._exit``, a signal, a segfault) is a ``ChildEnded`` that says how it ended
(``isolation.how_it_ended``); one that hangs past ``LOAD_LIMIT_S`` or raises anything else
is a ``LoadFailed``.  ``validate`` loads a solver named by import path only this way
(``harness.conformance.declared``); ``run`` imports such a solver's module this way once
before it imports it in its own process (``harness.run.plan.probe_import``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

from contactbench.problems.errors import ProblemInputError
from contactbench.solvers.base import ParamError
from contactbench.solvers.registry import SolverDeclarationError, SolverLoadError, SolverSpecError

from .isolation import ChildProcess, how_it_ended

#: Seconds a child may take to load the solvers named and read their declarations.
LOAD_LIMIT_S = 120.0


class OneLine(ValueError):
    """A refusal whose text is all the user is told (one line): carried out of a child as
    its text (``CARRIED_ERRORS``)."""


class LoadFailed(OneLine):
    """A child could not load a solver or read its declaration: what it said, in one line."""


class ChildEnded(LoadFailed):
    """The child ended before it answered (it exited, or a signal killed it); ``how``: how
    it ended, in the words of ``isolation.how_it_ended`` ('exited with code 3')."""

    def __init__(self, text: str, how: str) -> None:
        super().__init__(text)
        self.how = how


#: The one-line errors a loading child sends back by kind, raised again in the harness's
#: process as that kind (a ``OneLine`` of the caller's own kind as a ``LoadFailed``); the
#: first kind an error is an instance of is its kind (a ``SolverLoadError`` before the
#: ``ProblemInputError`` it is).
CARRIED_ERRORS: dict[str, type[Exception]] = {
    "load": SolverLoadError, "param": ParamError, "input": ProblemInputError, "spec": SolverSpecError,
    "declaration": SolverDeclarationError,
    "line": LoadFailed,
}


@dataclass(frozen=True)
class Carried:
    """An error of a kind ``CARRIED_ERRORS`` names, carried out of the child by its text."""

    kind: str
    text: str


def _carrying(fn: Callable[..., Any], args: tuple[Any, ...]) -> Any:
    """``fn(*args)`` in the child; an error of a kind ``CARRIED_ERRORS`` names, or any
    ``OneLine``, comes back as a ``Carried``."""
    try:
        return fn(*args)
    except OneLine as exc:
        return Carried("line", str(exc))
    except tuple(CARRIED_ERRORS.values()) as exc:
        kind = next(k for k, cls in CARRIED_ERRORS.items() if isinstance(exc, cls))
        return Carried(kind, str(exc))


class _Once:
    """The child's handler: each message is the argument tuple of ``fn``."""

    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn

    def __call__(self, args: tuple[Any, ...]) -> Any:
        return _carrying(self.fn, args)


def in_a_child(fn: Callable[..., Any], *args: Any, what: str = "loading the solver") -> Any:
    """``fn(*args)`` run in a forked child and its result brought back (it must pickle):
    the caller's process runs none of the code ``fn`` loads.  An error ``fn`` raises of a
    kind ``CARRIED_ERRORS`` names is raised again here as that kind, any other ``OneLine`` as
    a ``LoadFailed`` with its text; a child that ended before it answered is a ``ChildEnded``,
    one that hung past ``LOAD_LIMIT_S`` or raised anything else a ``LoadFailed``, each
    naming ``what``."""
    child = ChildProcess(partial(_Once, fn))
    try:
        out = child.call(args, LOAD_LIMIT_S)
    finally:
        child.close()
    if not out.ok:
        first = (str(out.detail).strip().splitlines() or [out.kind])[0]
        text = f"{what} failed ({out.kind}): {first}"
        if out.kind == "crashed":
            raise ChildEnded(text, how_it_ended(out.exitcode))
        raise LoadFailed(text)
    value = out.value
    if isinstance(value, Carried):
        raise CARRIED_ERRORS[value.kind](value.text)
    return value
