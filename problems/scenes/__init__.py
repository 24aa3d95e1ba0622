"""Scenes: named families of contact problems (the benchopt "Dataset" extension point).

A scene turns a ``SceneConfig`` (CLI options) into picklable ``InstanceSpec`` recipes;
each recipe builds a ``LoadSequence`` (one instance per load step) wherever it runs,
so workers rebuild instances from seeds instead of receiving them.

Adding a scene = one module in ``problems/scenes/`` with a ``Scene`` subclass decorated
by ``@register_scene``.  Modules are discovered automatically.
"""

from __future__ import annotations

import importlib
import pkgutil
import traceback

from .base import InstanceSpec, LoadSequence, Scene, SceneConfig, SolverVariant

_SCENES: dict[str, Scene] = {}
_ERRORS: dict[str, str] = {}
_DISCOVERED = False


def register_scene(cls: type[Scene]) -> type[Scene]:
    inst = cls()
    if not inst.name:
        raise ValueError(f"{cls!r} has no name")
    _SCENES[inst.name] = inst
    return cls


def _discover() -> None:
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    for mod in pkgutil.iter_modules(__path__, prefix=__name__ + "."):
        short = mod.name.rsplit(".", 1)[-1]
        if short == "base" or short.startswith("_"):
            continue
        try:
            importlib.import_module(mod.name)
        except Exception:
            _ERRORS[mod.name] = traceback.format_exc(limit=3)


def all_scenes() -> dict[str, Scene]:
    _discover()
    return dict(sorted(_SCENES.items()))


def scene_import_errors() -> dict[str, str]:
    _discover()
    return dict(_ERRORS)


def get_scene(name: str) -> Scene:
    scenes = all_scenes()
    if name not in scenes:
        raise KeyError(f"unknown scene {name!r}; known scenes: {', '.join(scenes)}")
    return scenes[name]


__all__ = [
    "InstanceSpec",
    "LoadSequence",
    "Scene",
    "SceneConfig",
    "SolverVariant",
    "all_scenes",
    "get_scene",
    "register_scene",
]
