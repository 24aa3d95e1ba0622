"""What ``validate`` knows of a solver whose code it never runs: the declaration, read in a
child process.

``validate`` judges in its own process, so that what a new solver's code does -- in its
solve, or when its module is imported -- cannot reach the judge, the verdict table or the
exit status.  A solver named by import path (``module:NAME``, ``names_user_code``) is
therefore loaded only in child processes forked from ``validate``'s
(``harness.run.isolation.ChildProcess``):
``in_a_child`` (``harness.run.child_call``) runs one function there (loading, checking the
parameters, availability) and brings back its plain result; the solves run in another such child
(``cases.CaseRunner``), which loads the solver afresh.  A registry name is the project's own
solver or an installed plugin's, loaded where ``run`` loads it; a ``Solver`` object handed to
the API, and every solver under ``--no-isolate``, is already in the harness's process: their
code is trusted as any code that process imported (docs/verdicts.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from contactbench.solvers.base import Promise, Solver
from contactbench.solvers.registry import is_import_path, load_named_solver

from ..run.child_call import LoadFailed as LoadFailed
from ..run.child_call import OneLine as OneLine
from ..run.child_call import in_a_child as in_a_child
from ..run.skips import checked_availability


def names_user_code(spec: str) -> bool:
    """Whether the solver spec ``spec`` (``NAME``, ``module:NAME``, either with ``[...]``)
    names its solver by import path: code ``validate`` loads in a child only."""
    return is_import_path(spec.split("[", 1)[0])


@dataclass(frozen=True)
class Declaration:
    """A solver as ``validate`` reports it: its ``name``, the ``promise`` its capabilities
    make, and whether it is ``available`` here (``why`` not)."""

    name: str
    promise: Promise
    available: bool
    why: str = ""


def declaration_of(solver: Solver | str, params: dict[str, Any] | None = None) -> Declaration:
    """The declaration of ``solver`` (a ``Solver``, or the text ``load_named_solver`` reads:
    a module that does not load is one ``SolverLoadError`` line); where it is available,
    its parameters ``params`` checked (``Solver.resolve_params``: a ``ParamError``)."""
    s = load_named_solver(solver)
    available, why, _ = checked_availability(s)
    if available:
        s.resolve_params(params)
    promise = s.capabilities.promise
    return Declaration(s.name, promise if promise == "exact" else float(promise), bool(available), str(why))
