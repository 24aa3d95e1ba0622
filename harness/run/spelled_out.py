"""Scene options that only spell out what is in effect without them: the one rule.

A run that writes an option out at the value it has anyway (``--kernel bcc`` on a scene
whose kernel is bcc, ``--control displacement``, ``--nu 0.3`` on a layer,
``--detrend plane`` on a measured map) is the run without it: the same recipes, so the
same cells (``plan.make_cell_id``), and the same configuration of a results folder.
``given_apart`` takes such options back from each configuration a folder records
(``runner.run_identity``: a folder written with or without them is one configuration);
the planner takes back its ``extra`` ones from the user's options once they are checked
(``left_out``, in ``plan.plan_run``: the recipes then never carry them).  An option is
taken back when

* it is a ``SceneConfig`` field equal to the default of every scene the run names;
* it is an ``extra`` option at the value a recipe's reader applies where the recipe
  names none (``READ_DEFAULTS``); or
* it is an ``extra`` option that leaving out gives the same recipes
  (``spelled_out_extras``: ``--surface-family saupe`` on a non-periodic scene).
"""

from __future__ import annotations

import inspect
from dataclasses import asdict, replace
from typing import Any, Sequence

from contactbench.problems.constraints import CONTROLS
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.io import load_surface
from contactbench.problems.layers import DEFAULT_NU, INTERFACES
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.scenes.core import SURFACE_FILE_OPTIONS
from contactbench.problems.scenes.options import BY_NAME

from ..table.files import canonical_json
from .studies import expand

#: The value of an ``extra`` option that a recipe's reader applies where the recipe does
#: not name it (``problems.scenes.core``: displacement control, the layer's Poisson's
#: ratio and bonded interface, and ``problems.io.load_surface``'s cleaning of a map).
READ_DEFAULTS: dict[str, Any] = {
    "control": CONTROLS[0],
    "nu": DEFAULT_NU,
    "interface": INTERFACES[0],
    **{name: inspect.signature(load_surface).parameters[name].default for name in SURFACE_FILE_OPTIONS},
}


def given_apart(scene_config: Any, scenes: Any) -> Any:
    """A run's scene options (``asdict`` of its ``SceneConfig``, or a folder's record of
    one) with those that only spell out what is in effect without them taken back (module
    doc): a field goes back to None, an ``extra`` key is left out.  Anything that is not
    a record of named scenes is returned as it is."""
    if not isinstance(scene_config, dict) or not isinstance(scenes, list) or not scenes:
        return scene_config
    scene_config = extras_given_apart(scene_config, [str(name) for name in scenes])
    try:
        defaults = [asdict(get_scene(str(name)).defaults) for name in scenes]
    except KeyError:
        return scene_config
    return {k: None if k != "extra" and v is not None and all(canonical_json(d.get(k)) == canonical_json(v)
                                                              for d in defaults) else v
            for k, v in scene_config.items()}


def extras_given_apart(scene_config: dict[str, Any], scenes: list[str]) -> dict[str, Any]:
    """``scene_config`` less the ``extra`` options that only spell out what is in effect
    without them (``at_read_default``, ``spelled_out_extras``)."""
    extra = scene_config.get("extra")
    if not (isinstance(extra, dict) and extra):
        return scene_config
    dropped = at_read_default(extra, scenes) | spelled_out_extras(scene_config, scenes)
    return {**scene_config, "extra": {k: v for k, v in extra.items() if k not in dropped}}


def left_out(cfg: SceneConfig, scenes: Sequence[str]) -> SceneConfig:
    """``cfg`` less the ``extra`` options that only spell out what is in effect without
    them (``extras_given_apart``): the config the plan's recipes are built from, so they
    never carry one.  Fields are left as given: one at its scene's default gives the
    recipes None gives where the scene fills it in, and is needed where it does not (the
    ``--length`` of a surface file)."""
    kept = extras_given_apart(asdict(cfg), [str(name) for name in scenes])
    return replace(cfg, extra=kept.get("extra", cfg.extra))


def at_read_default(extra: dict[str, Any], scenes: list[str]) -> set[str]:
    """The ``extra`` options at the value a recipe's reader applies without them
    (``READ_DEFAULTS``), where no scene the run names (a composite's parts included) sets
    another in its own defaults: ``--control displacement`` is taken back on the paper
    sweep, never on the load sweep, whose default it overrides."""
    return {k for k, v in extra.items()
            if k in READ_DEFAULTS and canonical_json(v) == canonical_json(READ_DEFAULTS[k])
            and all(canonical_json(d.get(k, v)) == canonical_json(v) for d in scene_default_extras(scenes))}


def scene_default_extras(scenes: Sequence[str]) -> list[dict[str, Any]]:
    """The ``extra`` defaults of every scene ``scenes`` runs (a composite's parts each);
    unknown names give none (the plan refuses them)."""
    out: list[dict[str, Any]] = []
    for name in scenes:
        try:
            out += [dict(get_scene(study.scene).config(part).extra) for study, part in expand(name, SceneConfig())]
        except (ProblemInputError, KeyError, TypeError, ValueError):
            continue
    return out


def spelled_out_extras(scene_config: dict[str, Any], scenes: list[str]) -> set[str]:
    """The ``extra`` scene options (records of ``problems.scenes.options.OPTIONS``) of a
    run's ``scene_config`` (``asdict`` of its ``SceneConfig``) whose value is the one in
    effect without them: leaving one out gives every scene the run names (a composite's
    parts included) the same recipes, so the same cells (``make_cell_id``), and so does
    leaving them all out.  None of them where the config reads a surface file (its recipes
    read the file; its options are recorded in them) or cannot be planned.  The first seed
    stands for all (an option's effect on a recipe is the same for every seed)."""
    try:
        cfg = SceneConfig(**scene_config)
    except TypeError:
        return set()
    if cfg.surface_path:
        return set()
    if cfg.seeds:
        cfg = replace(cfg, seeds=tuple(cfg.seeds[:1]))
    try:
        given = recipes(scenes, cfg)
    except (ProblemInputError, KeyError, TypeError, ValueError):
        return set()
    dropped: set[str] = set()
    for key in [k for k in cfg.extra if k in BY_NAME]:
        without = replace(cfg, extra={k: v for k, v in cfg.extra.items() if k != key and k not in dropped})
        try:
            if recipes(scenes, without) == given:
                dropped.add(key)
        except (ProblemInputError, KeyError, TypeError, ValueError):
            continue
    return dropped


def recipes(scenes: Sequence[str], cfg: SceneConfig) -> list[tuple[str, str, str]]:
    """(scene, instance, ``InstanceSpec.params_json``) of every recipe the plan builds for
    ``scenes`` under ``cfg`` (``plan.scene_jobs``: each part's merged config)."""
    out: list[tuple[str, str, str]] = []
    for name in scenes:
        for study, part in expand(name, cfg):
            scene = get_scene(study.scene)
            out += [(spec.scene, spec.instance, spec.params_json()) for spec in scene.instances(scene.config(part))]
    return out
