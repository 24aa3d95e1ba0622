"""Solver registry (in the manner of qpsolvers: it knows what is importable).

Every module in the ``solvers`` package (and every module under ``solvers/``
sub-packages; modules named ``_*`` are helpers, not solvers) is imported once on first
use; modules register their solvers with the ``@register`` decorator.  External
packages can add solvers through the entry-point group ``contactbench.solvers`` (each
entry point names a module to import), and tests may register throw-away solvers with
``register(..., replace=True)`` / ``unregister``.  The registry itself is a
``contactbench.plugins.PluginRegistry``.
"""

from __future__ import annotations

import importlib
from typing import Callable, TypeVar

from contactbench.plugins import PluginRegistry, UnknownPluginError

from .base import Solver

S = TypeVar("S")


class UnknownSolverError(UnknownPluginError):
    """``get_solver`` of a name nobody registered (a ``KeyError``)."""


def _same_class(old: Solver, new: Solver) -> bool:
    return type(old) is type(new)


_SOLVERS: PluginRegistry[Solver] = PluginRegistry(
    "solver", package="contactbench.solvers", entry_point_group="contactbench.solvers", recursive=True,
    include=lambda short: short not in ("base", "registry"), same=_same_class, error=UnknownSolverError)


def register(obj: S | None = None, *, replace: bool = False) -> S | Callable[[S], S]:
    """Register a Solver subclass (instantiated with no arguments) or instance.

    Usable as ``@register`` on a class or ``register(instance)``.
    """

    def _do(o: S) -> S:
        inst = o() if isinstance(o, type) else o
        if not isinstance(inst, Solver):
            raise TypeError(f"{o!r} is not a Solver")
        if not inst.name:
            raise ValueError(f"{o!r} has no name")
        _SOLVERS.add(inst.name, inst, replace=replace)
        return o

    if obj is None:
        return _do
    return _do(obj)


def unregister(name: str) -> None:
    _SOLVERS.remove(name)


def all_solvers() -> dict[str, Solver]:
    """Every registered solver, available or not, by name (sorted)."""
    return _SOLVERS.all()


def available_solvers() -> dict[str, Solver]:
    return {k: s for k, s in all_solvers().items() if s.availability()[0]}


def import_errors() -> dict[str, str]:
    """Module -> traceback of every solver module that failed to import."""
    return _SOLVERS.import_errors()


def get_solver(name: str) -> Solver:
    """The solver called ``name``, or ``UnknownSolverError`` listing the known ones."""
    return _SOLVERS.get(name)


def load_solver(spec: str) -> Solver:
    """A solver by registry name or by import path ``module:NAME`` (a Solver subclass,
    instance or factory)."""
    if ":" not in spec:
        return get_solver(spec)
    mod_name, attr = spec.split(":", 1)
    obj = getattr(importlib.import_module(mod_name), attr)
    if isinstance(obj, type) and issubclass(obj, Solver):
        return obj()
    if isinstance(obj, Solver):
        return obj
    if callable(obj):
        out = obj()
        if isinstance(out, Solver):
            return out
    raise TypeError(f"{spec} is not a Solver subclass, instance or factory")
