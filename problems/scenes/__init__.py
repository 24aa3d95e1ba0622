"""Scenes: named families of contact problems (the benchopt "Dataset" extension point).

A scene turns a ``SceneConfig`` (CLI options) into picklable ``InstanceSpec`` recipes;
each recipe builds a ``LoadSequence`` (one instance per load step) wherever it runs,
so workers rebuild instances from seeds instead of receiving them.

Adding a scene = one module in ``problems/scenes/`` with a ``Scene`` subclass decorated
by ``@register_scene``.  Modules are discovered automatically, and so are the modules
named by entry points of group ``contactbench.scenes`` (a scene shipped by another
package).  The registry lives in ``base.py``; this package re-exports it.
"""

from __future__ import annotations

from .base import (
    InstanceSpec,
    LoadSequence,
    Scene,
    SceneConfig,
    all_scenes,
    get_scene,
    register_scene,
    scene_import_errors,
)

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
