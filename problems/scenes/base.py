"""Scene interfaces."""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Any, Callable, ClassVar, NamedTuple, Sequence

import numpy as np

from contactbench.plugins import PluginRegistry

from ..errors import ProblemInputError
from ..instances import ContactInstance
from ..kernels import check_kernel
from ..surfaces import Surface
from .options import SCENE_OPTIONS, SceneConfig, names_in


#: The options of an elastic layer on a rigid base (scenes that pose only the half-space
#: leave them out of their ``options``); the table of every option is ``options.OPTIONS``.
LAYER_SCENE_OPTIONS: frozenset[str] = names_in("layer")
#: The options of load control and hardness (scenes that pose only the displacement-
#: controlled, unbounded problem leave them out of their ``options``).
CONTROL_SCENE_OPTIONS: frozenset[str] = names_in("control")


#: Recipe params that say where an input was read from, not what it is (``InstanceSpec.params_json``).
LOCATION_PARAMS: frozenset[str] = frozenset({"surface_path"})


@dataclass(frozen=True)
class InstanceSpec:
    """A picklable recipe for one instance (a surface with its load sequence).

    ``params`` hold everything needed to rebuild it (seed, size, kernel, ...), are
    JSON-serialisable, and are recorded with every row.
    """

    scene: str
    instance: str
    params: dict[str, Any]

    def build(self) -> "LoadSequence":
        return get_scene(self.scene).build(self)

    def params_json(self) -> str:
        """The recipe's identity (cell ids, job keys): its params less ``LOCATION_PARAMS``,
        which say where an input was read from, not what it is -- a map's content is named
        by its key in the instance name, so one map given by two paths is one cell."""
        return json.dumps({k: v for k, v in self.params.items() if k not in LOCATION_PARAMS},
                          sort_keys=True, default=str)


@dataclass(frozen=True)
class StepSizes:
    """What the planner may know of a recipe's steps before any is built: the trial-set
    size n of each step, and the side of its grid where the grid is square with square
    pixels (0 otherwise: the worker's ``ProblemTraits.surface_side``)."""

    n: tuple[int, ...]
    side: int


@dataclass
class LoadSequence:
    """The steps of one instance.  ``factory(k)`` builds the QP instance of step k
    (0-based); ``deltas[k]`` is its far-field displacement (NaN where the scene has
    none); ``analytic(k)`` returns closed-form values for the step, if any."""

    instance: str
    deltas: Sequence[float]
    factory: Callable[[int], ContactInstance]
    surface: Surface | None = None
    analytic: Callable[[int], dict[str, float]] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.deltas)

    def at(self, k: int) -> ContactInstance:
        inst = self.factory(k)
        inst.meta.setdefault("step", k)
        return inst


class Scene(ABC):
    """A named family of instances (benchopt's Dataset): pure data -- surfaces, kernels,
    load sequences.  Which solvers run on it, at which profiles, with which parameter
    grids and against which reference is the harness's study design
    (``contactbench.harness.run.studies``)."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    defaults: ClassVar[SceneConfig] = SceneConfig()
    #: Whether consecutive steps form a load history (warm starts across steps).
    load_history: ClassVar[bool] = True

    #: The options the scene reads (``options.SCENE_OPTIONS`` names); the planner refuses
    #: any other it is given (``options.scene_problems``) instead of silently dropping it.
    options: ClassVar[frozenset[str]] = SCENE_OPTIONS

    def config(self, cfg: SceneConfig | None) -> SceneConfig:
        """``cfg`` with the scene's defaults filled in; a kernel the (merged) periodicity
        cannot take is a ``ProblemInputError`` (``kernels.check_kernel``: ``spectral``
        is periodic only)."""
        merged = (cfg or SceneConfig()).merged(self.defaults)
        if merged.kernel is not None and "kernel" in self.options:
            check_kernel(str(merged.kernel), bool(merged.periodic) and "periodic" in self.options)
        return merged

    @abstractmethod
    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        """Recipes for every instance of the scene under ``cfg`` (already merged)."""

    @abstractmethod
    def build(self, spec: InstanceSpec) -> LoadSequence:
        """Build the load sequence of one recipe."""

    def validate(self, cfg: SceneConfig) -> None:
        """Refuse a bad configuration before anything runs: raise ``ProblemInputError``
        naming the bad input (``cfg`` is already merged).  Called by the harness's
        planner; it must be cheap (build surfaces and loads, not operators).  The default
        checks nothing beyond what ``instances`` itself refuses."""

    def validate_sizes(self, cfg: SceneConfig) -> dict[str, StepSizes]:
        """``validate``, and the ``StepSizes`` of each recipe (by instance name) where the
        scene can tell them as cheaply (surfaces and loads, no operators); the planner
        asks the solvers' time and memory models with them.  The default validates and
        tells none."""
        self.validate(cfg)
        return {}

    def warnings(self, cfg: SceneConfig) -> list[str]:
        """Things the user should know before trusting the run (e.g. a surface whose
        PSD is not a power law, where a multi-resolution method is unreliable)."""
        return []


def validate_each(specs: list[InstanceSpec], check: Callable[[InstanceSpec], Any]) -> None:
    """Run ``check`` on every recipe; raise one ``ProblemInputError`` with one line per
    distinct problem found (ten seeds of a bad size are one problem, not ten)."""
    problems: list[str] = []
    for spec in specs:
        try:
            check(spec)
        except ProblemInputError as exc:
            msg = str(exc)
            if msg not in problems:
                problems.append(msg)
    if problems:
        raise ProblemInputError("\n".join(problems))


def seeds_of(cfg: SceneConfig, default: tuple[int, ...] = (0,)) -> tuple[int, ...]:
    return tuple(cfg.seeds) if cfg.seeds else default


def nan() -> float:
    return float(np.nan)


# ---------------------------------------------------------------------------
# The scene registry (problems/scenes/__init__.py re-exports it)
# ---------------------------------------------------------------------------


def _same_class(old: Scene, new: Scene) -> bool:
    return type(old) is type(new)


_SCENES: PluginRegistry[Scene] = PluginRegistry(
    "scene", package="contactbench.problems.scenes", entry_point_group="contactbench.scenes",
    include=lambda short: short != "base", same=_same_class)


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


#: Lower bound of an instance's memory on an N x N grid (``instance_nbytes``): float64 or
#: int64 arrays per grid point (heights, gap, pressure, grid index), and complex128
#: half-spectra of the (padded) grid (the kernel's and one work buffer).
GRID_ARRAYS = 4
SPECTRA = 2


def instance_nbytes(params: dict[str, Any]) -> float:
    """At least the bytes one instance of recipe ``params`` needs: on an N x N grid
    (``size``) ``GRID_ARRAYS`` arrays of N^2 eight-byte numbers and ``SPECTRA``
    complex128 half-spectra of the grid (padded to 2N x 2N unless periodic); for a
    problem given by its size n (``n``), the dense H (8 n^2 bytes) where the operator is
    dense."""
    size, n = params.get("size"), params.get("n")
    if isinstance(size, (int, float)) and size > 0:
        N = int(size)
        P = N if params.get("periodic") else 2 * N
        return float(8 * GRID_ARRAYS * N * N + SPECTRA * 16 * P * (P // 2 + 1))
    if isinstance(n, (int, float)) and n > 0:
        return float(8 * int(n) * int(n) if params.get("operator") == "dense" else 8 * GRID_ARRAYS * int(n))
    return 0.0


def largest_recipe(specs: Sequence[InstanceSpec]) -> tuple[str, float]:
    """(what names it, its bytes by ``instance_nbytes``) of the recipe of ``specs`` that
    needs the most memory: "N = <size>", "n = <n>" or its instance name; ("", 0.0) for none."""
    largest = max(specs, key=lambda s: instance_nbytes(s.params), default=None)
    if largest is None:
        return "", 0.0
    p = largest.params
    what = f"N = {p['size']}" if p.get("size") else (f"n = {p['n']}" if p.get("n") else largest.instance)
    return what, instance_nbytes(p)


def check_instance_memory(specs: Sequence[InstanceSpec], budget: float, what: str, subject: str) -> None:
    """A one-line ``ProblemInputError`` where the largest recipe of ``specs`` needs more
    than ``budget`` bytes by ``instance_nbytes`` (before anything is built; ``what``: the
    budget's name for the user, e.g. an option; ``subject``: what the recipes are of)."""
    largest, nbytes = largest_recipe(specs)
    if nbytes > budget:
        raise ProblemInputError(f"{subject}: its largest instance ({largest}) needs at least {nbytes / 2**30:.3g} GiB, "
                                f"over the memory budget of {budget / 2**30:.3g} GiB ({what})")


class SceneCount(NamedTuple):
    """The size of a scene under one configuration, counted from its recipes alone."""

    instances: int
    steps: int  # instance steps: the QPs of an export
    specs: list[Any]  # the recipes the count was read from (all of them, or the probes)


def seed_count(seeds: Sequence[int]) -> int:
    """How many seeds ``seeds`` holds; a ``range`` is counted from its ends, whatever its
    size (``len`` of a range of 2^63 or more seeds, ``--seeds 0-9223372036854775807``,
    overflows)."""
    if isinstance(seeds, range):
        return max(0, -((seeds.start - seeds.stop) // seeds.step))
    return len(seeds)


def scene_counts(scene: Any, cfg: SceneConfig) -> SceneCount:
    """The instances and instance steps of ``scene`` under ``cfg`` (merged), from the
    recipes (``params["steps"]``, 1 where absent) and nothing built.  With more than
    three steps or two seeds they are counted from the recipes at 2 and 3 steps and 1 and
    2 seeds (both counts are bilinear in steps and seeds: every scene's recipes are one
    per seed, each with ``steps`` load steps or a fixed number), so a huge ``--steps`` or
    ``--seeds`` is never expanded."""
    steps, seeds = cfg.steps, cfg.seeds
    big_steps = steps is not None and int(steps) > 3
    big_seeds = seeds is not None and seed_count(seeds) > 2

    def count(specs: list[Any]) -> tuple[int, int]:
        return len(specs), sum(int(s.params.get("steps") or 1) for s in specs)

    if not (big_steps or big_seeds):
        specs = list(scene.instances(cfg))
        return SceneCount(*count(specs), specs)
    s_pts = (2, 3) if big_steps else (steps,)
    k_pts = ((seeds[0],), (seeds[0], seeds[1])) if big_seeds else (seeds,)
    probes = {(i, j): list(scene.instances(replace(cfg, steps=s, seeds=None if k is None else tuple(k))))
              for i, s in enumerate(s_pts) for j, k in enumerate(k_pts)}
    ds = int(steps) - 2 if big_steps else 0
    dk = seed_count(seeds) - 1 if big_seeds else 0

    def bilinear(what: int) -> int:
        c = {ij: count(probes[(min(ij[0], len(s_pts) - 1), min(ij[1], len(k_pts) - 1))])[what]
             for ij in ((0, 0), (1, 0), (0, 1), (1, 1))}
        return (c[0, 0] + (c[1, 0] - c[0, 0]) * ds + (c[0, 1] - c[0, 0]) * dk
                + (c[1, 1] - c[1, 0] - c[0, 1] + c[0, 0]) * ds * dk)

    return SceneCount(bilinear(0), bilinear(1), [s for v in probes.values() for s in v])
