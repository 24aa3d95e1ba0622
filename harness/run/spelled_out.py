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
  names none (``problems.scenes.core.READ_DEFAULTS``); or
* it is an ``extra`` option that leaving out gives the same recipes
  (``spelled_out_extras``: ``--surface-family saupe`` on a non-periodic scene); or
* it is an option of a ``--surface`` file that only states what the reader takes from the
  file without it (``file_options_spelled_out``: ``--height-unit m`` on a file that states
  no unit, a ``--length`` that agrees with the lateral size the file states).

A ``--length L0,L1`` that reads its file as ``--length L0`` does is written L0
(``one_length_where_it_reads_so``).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, replace
from functools import lru_cache
from typing import Any, Sequence

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.io import unannounced
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.scenes.core import READ_DEFAULTS, SURFACE_FILE_OPTIONS, surface_from_params
from contactbench.problems.scenes.options import BY_NAME

from ..table.files import canonical_json
from .studies import expand

def given_apart(scene_config: Any, scenes: Any) -> Any:
    """A run's scene options (``asdict`` of its ``SceneConfig``, or a folder's record of
    one) with those that only spell out what is in effect without them taken back (module
    doc): a field goes back to None, an ``extra`` key is left out.  Anything that is not
    a record of named scenes is returned as it is."""
    if not isinstance(scene_config, dict) or not isinstance(scenes, list) or not scenes:
        return scene_config
    scene_config = options_given_apart(scene_config, [str(name) for name in scenes])
    try:
        defaults = [asdict(get_scene(str(name)).defaults) for name in scenes]
    except KeyError:
        return scene_config
    return {k: None if k != "extra" and v is not None and all(canonical_json(d.get(k)) == canonical_json(v)
                                                              for d in defaults) else v
            for k, v in scene_config.items()}


def options_given_apart(scene_config: dict[str, Any], scenes: list[str]) -> dict[str, Any]:
    """``scene_config`` less the ``extra`` options and the ``--surface`` file's options that
    only spell out what is in effect without them (``extras_given_apart``,
    ``file_options_given_apart``): what ``given_apart`` and ``left_out`` both take back."""
    return file_options_given_apart(extras_given_apart(scene_config, scenes), scenes)


def extras_given_apart(scene_config: dict[str, Any], scenes: list[str]) -> dict[str, Any]:
    """``scene_config`` less the ``extra`` options that only spell out what is in effect
    without them (``at_read_default``, ``spelled_out_extras``)."""
    extra = scene_config.get("extra")
    if not (isinstance(extra, dict) and extra):
        return scene_config
    dropped = at_read_default(extra, scenes) | spelled_out_extras(scene_config, scenes)
    return {**scene_config, "extra": {k: v for k, v in extra.items() if k not in dropped}}


def left_out(cfg: SceneConfig, scenes: Sequence[str]) -> SceneConfig:
    """``cfg`` less the options that only spell out what is in effect without them
    (``options_given_apart``): the config the plan's recipes
    are built from, so they never carry one.  Other fields are left as given: one at its
    scene's default gives the recipes None gives where the scene fills it in, and is
    needed where it does not (the ``--length`` of a file that states no lateral size)."""
    kept = options_given_apart(asdict(cfg), [str(name) for name in scenes])
    length = kept.get("length")
    return replace(cfg, length=tuple(length) if isinstance(length, (list, tuple)) else length,
                   extra=kept.get("extra", cfg.extra))


def file_options_given_apart(scene_config: dict[str, Any], scenes: list[str]) -> dict[str, Any]:
    """``scene_config`` less the options of its ``--surface`` file that only state what the
    reader takes from the file without them (``file_options_spelled_out``): the length
    goes back to None, an ``extra`` key is left out."""
    dropped = file_options_spelled_out(scene_config, scenes)
    if dropped:
        extra = {k: v for k, v in scene_config["extra"].items() if k not in dropped}
        scene_config = {**scene_config, "extra": extra, **({"length": None} if "length" in dropped else {})}
    return {**scene_config, "length": one_length_where_it_reads_so(scene_config)}


def one_length_where_it_reads_so(scene_config: dict[str, Any]) -> Any:
    """The ``length`` of ``scene_config``, written L0 where it is a pair L0,L1 that reads its
    ``--surface`` file as L0 alone does (``map_key``: the same spacing per axis, so L1 is
    what L0 implies): ``--length L`` and ``--length L,L`` on a square map are one
    configuration.  Anything else is returned as it is."""
    length, path, extra = scene_config.get("length"), scene_config.get("surface_path"), scene_config.get("extra")
    if not (isinstance(length, (list, tuple)) and len(length) == 2 and isinstance(path, str) and path
            and isinstance(extra, dict)):
        return length
    unit = extra.get("height_unit")
    as_pair = map_key(path, extra, list(length), unit)
    return length[0] if as_pair is not None and map_key(path, extra, length[0], unit) == as_pair else length


def file_options_spelled_out(scene_config: dict[str, Any], scenes: list[str]) -> set[str]:
    """The options of a run's ``--surface`` file (``scene_config``: ``asdict`` of its
    ``SceneConfig``, or a folder's record of one) that only state what the recipe's reader
    (``core.surface_from_params``: ``io.load_surface``) takes from the file without them:

    * ``height_unit``, where leaving it out gives the same map (``map_key``): a file that
      states no unit is read in metres, so ``--height-unit m`` on it;
    * ``length``, where the file states a lateral size, the given one agrees with it (the
      reader takes the map both with and without it: ``io.map_spacing``, within its
      ``LENGTH_RTOL``) and every scene the run names reads the file's own size where it
      is left out (``reads_file_length``).  The run then reads the file's spacing, which
      the given length matches within that tolerance.

    None where the config names no file, or the reader refuses the map as given (the plan
    says why): the options are checked as given."""
    path, extra = scene_config.get("surface_path"), scene_config.get("extra")
    if not (isinstance(path, str) and path and isinstance(extra, dict)):
        return set()
    length, unit = scene_config.get("length"), extra.get("height_unit")
    if (length is None and unit is None) or map_key(path, extra, length, unit) is None:
        return set()
    dropped: set[str] = set()
    if unit is not None and map_key(path, extra, length, None) == map_key(path, extra, length, unit):
        dropped.add("height_unit")
    if length is not None and map_key(path, extra, None, unit) is not None \
            and reads_file_length(scene_config, scenes):
        dropped.add("length")
    return dropped


def map_key(path: str, extra: dict[str, Any], length: Any, height_unit: Any) -> str | None:
    """The ``MapPreprocessing.key`` of the map at ``path`` as a recipe's reader reads it
    (``core.surface_from_params``) with ``length``, ``height_unit`` and the run's channel
    and cleaning (``extra``); None where the reader refuses it.  Read once per file state
    and options (``read_map_key``)."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    real = os.path.realpath(path)
    params = {"surface_path": real, "length": length, "height_unit": height_unit,
              **{k: extra.get(k) for k in ("channel", *SURFACE_FILE_OPTIONS)}}
    return read_map_key(real, stat.st_mtime_ns, stat.st_size, canonical_json(params))


@lru_cache(maxsize=32)
def read_map_key(path: str, mtime_ns: int, size: int, params_json: str) -> str | None:
    """``map_key`` of the recipe parameters ``params_json`` of the file ``path`` in the state
    (``mtime_ns``, ``size``) it is read in.  The read warns of nothing (``io.unannounced``):
    it asks what the map would be under these options, which need not be the run's."""
    try:
        with unannounced():
            record = surface_from_params(json.loads(params_json)).preprocessing
    except (ProblemInputError, OSError, KeyError, TypeError, ValueError):
        return None
    return None if record is None else str(record.key)


def reads_file_length(scene_config: dict[str, Any], scenes: list[str]) -> bool:
    """Whether every scene ``scenes`` runs (a composite's parts each) reads its ``--surface``
    file's own lateral size when ``--length`` is left out (its merged config keeps none:
    ``PaperSweep.config``; the CMR scenes fill in their own)."""
    try:
        cfg = SceneConfig(**{**scene_config, "length": None})
        parts = [part for name in scenes for part in expand(name, cfg)]
        return bool(parts) and all(get_scene(study.scene).config(part).length is None for study, part in parts)
    except (ProblemInputError, KeyError, TypeError, ValueError):
        return False


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
