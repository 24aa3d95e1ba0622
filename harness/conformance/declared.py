"""What ``validate`` knows of a solver whose code it never runs: the declaration, read in a
child process.

``validate`` judges in its own process, so that what a new solver's code does -- in its
solve, or when its module is imported -- cannot reach the judge, the verdict table or the
exit status.  A solver named by import path (``module:NAME``, ``names_user_code``) is
therefore loaded only in child processes forked from ``validate``'s
(``harness.run.isolation.ChildProcess``):
``in_a_child`` runs one function there (loading, checking the parameters, availability) and
brings back its plain result; the solves run in another such child
(``cases.CaseRunner``), which loads the solver afresh.  A registry name is the project's own
solver or an installed plugin's, loaded where ``run`` loads it; a ``Solver`` object handed to
the API, and every solver under ``--no-isolate``, is already in the harness's process: their
code is trusted as any code that process imported (docs/verdicts.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

from contactbench.problems.errors import ProblemInputError
from contactbench.solvers.base import ParamError, Solver
from contactbench.solvers.registry import (SolverDeclarationError, SolverLoadError, SolverSpecError, is_import_path,
                                           load_named_solver)

from ..run.isolation import SOLVER_FAULTS, ChildProcess, exception_text

#: Seconds a child may take to load the solvers named and read their declarations.
LOAD_LIMIT_S = 120.0


def names_user_code(spec: str) -> bool:
    """Whether the solver spec ``spec`` (``NAME``, ``module:NAME``, either with ``[...]``)
    names its solver by import path: code ``validate`` loads in a child only."""
    return is_import_path(spec.split("[", 1)[0])


@dataclass(frozen=True)
class Declaration:
    """A solver as ``validate`` reports it: its ``name``, the ``promise`` its capabilities
    make, and whether it is ``available`` here (``why`` not)."""

    name: str
    promise: str
    available: bool
    why: str = ""


def declaration_of(solver: Solver | str, params: dict[str, Any] | None = None) -> Declaration:
    """The declaration of ``solver`` (a ``Solver``, or the text ``load_named_solver`` reads:
    a module that does not load is one ``SolverLoadError`` line); where it is available,
    its parameters ``params`` checked (``Solver.resolve_params``: a ``ParamError``)."""
    s = load_named_solver(solver)
    try:
        available, why = s.availability()
    except SOLVER_FAULTS as exc:
        available, why = False, f"its availability() failed: {exception_text(exc)}"
    if available:
        s.resolve_params(params)
    return Declaration(s.name, str(s.capabilities.promise), bool(available), str(why))


class OneLine(ValueError):
    """A refusal whose text is all the user is told (one line): carried out of a child as
    its text (``CARRIED_ERRORS``)."""


class LoadFailed(OneLine):
    """A child could not load a solver or read its declaration: what it said, in one line."""


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
    the harness's process runs none of the code ``fn`` loads.  An error ``fn`` raises of a
    kind ``CARRIED_ERRORS`` names is raised again here as that kind, any other ``OneLine`` as
    a ``LoadFailed`` with its text; a child that crashed, hung past ``LOAD_LIMIT_S`` or raised anything else is a
    ``LoadFailed`` naming ``what``."""
    child = ChildProcess(partial(_Once, fn))
    try:
        out = child.call(args, LOAD_LIMIT_S)
    finally:
        child.close()
    if not out.ok:
        first = (str(out.detail).strip().splitlines() or [out.kind])[0]
        raise LoadFailed(f"{what} failed ({out.kind}): {first}")
    value = out.value
    if isinstance(value, Carried):
        raise CARRIED_ERRORS[value.kind](value.text)
    return value
