"""Solver registry (in the manner of qpsolvers: it knows what is importable).

Every module in the ``solvers`` package (and every module under ``solvers/``
sub-packages) is imported once on first use; modules register their solvers with the
``@register`` decorator.  External packages can add solvers through the entry-point
group ``contactbench.solvers`` (each entry point names a module to import), and tests
may register throw-away solvers with ``register(..., replace=True)`` /
``unregister``.
"""

from __future__ import annotations

import importlib
import pkgutil
import traceback
from importlib import metadata
from typing import Callable, TypeVar

from .base import Solver

_REGISTRY: dict[str, Solver] = {}
_IMPORT_ERRORS: dict[str, str] = {}
_DISCOVERED = False
_SKIP_MODULES = {"base", "registry"}

S = TypeVar("S")


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
        if inst.name in _REGISTRY and not replace and type(_REGISTRY[inst.name]) is not type(inst):
            raise ValueError(f"solver name {inst.name!r} is already registered")
        _REGISTRY[inst.name] = inst
        return o

    if obj is None:
        return _do
    return _do(obj)


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def _discover() -> None:
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    import contactbench.solvers as pkg

    for mod in pkgutil.walk_packages(pkg.__path__, prefix="contactbench.solvers."):
        short = mod.name.rsplit(".", 1)[-1]
        if short in _SKIP_MODULES or short.startswith("_"):
            continue
        try:
            importlib.import_module(mod.name)
        except Exception:  # a broken module must not take the registry down
            _IMPORT_ERRORS[mod.name] = traceback.format_exc(limit=3)
    try:
        eps = metadata.entry_points(group="contactbench.solvers")
    except TypeError:  # pragma: no cover - very old importlib.metadata
        eps = []
    for ep in eps:
        try:
            ep.load()
        except Exception:
            _IMPORT_ERRORS[f"entry point {ep.name}"] = traceback.format_exc(limit=3)


def all_solvers() -> dict[str, Solver]:
    """Every registered solver, available or not, by name (sorted)."""
    _discover()
    return dict(sorted(_REGISTRY.items()))


def available_solvers() -> dict[str, Solver]:
    return {k: s for k, s in all_solvers().items() if s.availability()[0]}


def import_errors() -> dict[str, str]:
    _discover()
    return dict(_IMPORT_ERRORS)


class UnknownSolverError(KeyError):
    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


def get_solver(name: str) -> Solver:
    """The solver called ``name``, or a clear error saying what exists or why not."""
    solvers = all_solvers()
    if name not in solvers:
        known = ", ".join(solvers) or "(none)"
        raise UnknownSolverError(f"unknown solver {name!r}; registered solvers: {known}")
    return solvers[name]


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
