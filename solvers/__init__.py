"""The public API for solver authors: ``from contactbench.solvers import ...``.

Solver, SolveResult, SolverSettings, WarmStart, Capabilities, Param, Status, Outcome,
SolveContext and ProblemTraits are the records of the solve lifecycle
(``contactbench.solvers.base``); ``register`` adds a solver to the registry, and
``get_solver``/``all_solvers`` read it.
"""

from __future__ import annotations

from .base import (
    Capabilities,
    Outcome,
    Param,
    ParamError,
    ProblemTraits,
    SolveAborted,
    SolveContext,
    SolveResult,
    Solver,
    SolverSettings,
    Status,
    WarmStart,
)
from .registry import all_solvers, available_solvers, get_solver, register, unregister

__all__ = [
    "Capabilities",
    "Outcome",
    "Param",
    "ParamError",
    "ProblemTraits",
    "SolveAborted",
    "SolveContext",
    "SolveResult",
    "Solver",
    "SolverSettings",
    "Status",
    "WarmStart",
    "all_solvers",
    "available_solvers",
    "get_solver",
    "register",
    "unregister",
]
