"""One small plug-in registry, shared by solvers, scenes and report sections.

A ``PluginRegistry`` maps names to objects.  Objects are added with ``add`` (usually
from a decorator the owning module exposes, e.g. ``@register`` for solvers).  On first
read the registry *discovers* its plug-ins once:

* every module of ``package`` whose short name passes ``include`` (modules whose name
  starts with ``_`` are always skipped; ``recursive`` walks sub-packages too);
* every entry point of ``entry_point_group`` (each names a module or an object to load).

A module that fails to import does not take the registry down: its traceback is kept
in ``import_errors()``.  ``get`` of an unknown name raises ``error`` (a ``KeyError``)
with a message that lists the known names, led by the closest ones (``did_you_mean``).
"""

from __future__ import annotations

import difflib
import importlib
import pkgutil
import traceback
from importlib import metadata
from typing import Callable, Generic, Iterable, Iterator, TypeVar

from contactbench.stops import raise_noted, signals_noted

T = TypeVar("T")


class UnknownPluginError(KeyError):
    """An unknown name; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """" (did you mean 'a' or 'b'?)" for the known names closest to ``name`` (difflib),
    or "" when none is close: the one spelling-suggestion rule of the command line."""
    close = difflib.get_close_matches(name, list(known), n=3, cutoff=0.6)
    if not close:
        return ""
    return f" (did you mean {' or '.join(repr(c) for c in close)}?)"


def _always(_short: str) -> bool:
    return True


def _identical(old: object, new: object) -> bool:
    return old is new


class PluginRegistry(Generic[T]):
    """Named plug-ins of one ``kind`` ("solver", "scene", "report section").

    ``same(old, new)`` says when adding a name that exists is a harmless repeat (for
    instance the same class registered again); otherwise ``add`` refuses it unless
    ``replace=True``."""

    def __init__(self, kind: str, *, package: str | None = None, entry_point_group: str | None = None,
                 include: Callable[[str], bool] = _always, recursive: bool = False,
                 same: Callable[[T, T], bool] = _identical,
                 error: type[UnknownPluginError] = UnknownPluginError) -> None:
        self.kind = kind
        self.package = package
        self.entry_point_group = entry_point_group
        self.include = include
        self.recursive = recursive
        self.same = same
        self.error = error
        self._items: dict[str, T] = {}
        self._errors: dict[str, str] = {}
        self._discovered = False

    # -- writing ---------------------------------------------------------------

    def add(self, name: str, obj: T, *, replace: bool = False) -> T:
        """Register ``obj`` under ``name``; a clash with another object is an error."""
        if not name:
            raise ValueError(f"a {self.kind} needs a non-empty name: {obj!r}")
        old = self._items.get(name)
        if old is not None and not replace and not self.same(old, obj):
            raise ValueError(f"{self.kind} name {name!r} is already registered")
        self._items[name] = obj
        return obj

    def remove(self, name: str) -> None:
        self._items.pop(name, None)

    # -- discovery -------------------------------------------------------------

    def discover(self) -> None:
        """Import the package's plug-in modules and the entry points, once.  A user's stop
        (Ctrl-C, SIGTERM) that an import swallowed -- a ``KeyboardInterrupt`` caught inside
        a third-party module's import -- is raised once the imports are done
        (``stops.raise_noted``)."""
        if self._discovered:
            return
        self._discovered = True  # set first: a plug-in module may read the registry
        with signals_noted() as arrived:
            for module in self._plugin_modules():
                try:
                    importlib.import_module(module)
                except Exception:  # a broken module must not take the registry down
                    self._errors[module] = traceback.format_exc(limit=-4)
            for ep in self._entry_points():
                try:
                    ep.load()
                except Exception:
                    self._errors[f"entry point {ep.name}"] = traceback.format_exc(limit=-4)
        raise_noted(arrived)

    def _plugin_modules(self) -> Iterator[str]:
        if self.package is None:
            return
        pkg = importlib.import_module(self.package)
        walk = pkgutil.walk_packages if self.recursive else pkgutil.iter_modules
        names = sorted(m.name for m in walk(pkg.__path__, prefix=f"{self.package}."))
        for name in names:
            short = name.rsplit(".", 1)[-1]
            if not short.startswith("_") and self.include(short):
                yield name

    def _entry_points(self) -> list[metadata.EntryPoint]:
        if self.entry_point_group is None:
            return []
        return sorted(metadata.entry_points(group=self.entry_point_group), key=lambda ep: ep.name)

    # -- reading ---------------------------------------------------------------

    def all(self) -> dict[str, T]:
        """Every plug-in by name (sorted), after discovery."""
        self.discover()
        return dict(sorted(self._items.items()))

    def get(self, name: str) -> T:
        """The plug-in called ``name``, or ``error`` naming the known ones."""
        items = self.all()
        if name not in items:
            known = ", ".join(items) or "(none)"
            raise self.error(f"unknown {self.kind} {name!r}{did_you_mean(name, items)}; known {self.kind}s: {known}")
        return items[name]

    def import_errors(self) -> dict[str, str]:
        """Module (or ``entry point NAME``) -> traceback of each plug-in that failed to load."""
        self.discover()
        return dict(self._errors)

    def __contains__(self, name: object) -> bool:
        return name in self.all()
