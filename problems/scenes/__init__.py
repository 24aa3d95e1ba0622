"""Scenes: named families of contact problems (the benchopt "Dataset" extension point).

A scene turns a ``SceneConfig`` (CLI options) into picklable ``InstanceSpec`` recipes;
each recipe builds a ``LoadSequence`` (one instance per load step) wherever it runs,
so workers rebuild instances from seeds instead of receiving them.

Adding a scene = one module in ``problems/scenes/`` with a ``Scene`` subclass decorated
by ``@register_scene``.  Modules are discovered automatically.
"""

from __future__ import annotations

from contactbench.plugins import PluginRegistry

from .base import InstanceSpec, LoadSequence, Scene, SceneConfig


def _same_class(old: Scene, new: Scene) -> bool:
    return type(old) is type(new)


_SCENES: PluginRegistry[Scene] = PluginRegistry(
    "scene", package=__name__, include=lambda short: short != "base", same=_same_class)


def register_scene(cls: type[Scene]) -> type[Scene]:
    """Class decorator: register one instance of the scene under its ``name``."""
    inst = cls()
    if not inst.name:
        raise ValueError(f"{cls!r} has no name")
    _SCENES.add(inst.name, inst)
    return cls


def all_scenes() -> dict[str, Scene]:
    return _SCENES.all()


def scene_import_errors() -> dict[str, str]:
    return _SCENES.import_errors()


def get_scene(name: str) -> Scene:
    """The scene called ``name``, or a ``KeyError`` listing the known ones."""
    return _SCENES.get(name)


__all__ = [
    "InstanceSpec",
    "LoadSequence",
    "Scene",
    "SceneConfig",
    "all_scenes",
    "get_scene",
    "register_scene",
    "scene_import_errors",
]
