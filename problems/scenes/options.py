"""The scene options, declared once: one ``OptionRecord`` per option a user may set.

``OPTIONS`` is the one table.  Everything else is derived from it:

* ``SceneConfig``, the options' container (a field per ``CONFIG_FIELDS``, the rest in
  its ``extra``; ``problems.scenes`` re-exports it);
* the command line's flags, types and help (``harness/cli.py``'s ``add_scene_options``);
* which options a ``SceneConfig`` sets (``given_options``), and whether an option is a
  ``SceneConfig`` field or a key of its ``extra`` (``OptionRecord.field``);
* the recipe parameters a rough-surface recipe carries (``recipe_params``) and the
  instance-name suffix of the options that change the problem (``name_suffix``);
* the checks (``config_problems``): every value's rule (``valid``, a hard range) and
  plausibility (``plausible``, overridable with ``allow_implausible``, and for ``E``
  with ``allow_any_E``), and per scene: an option the scene does not read, an option a
  surface file replaces, what an option requires and what it excludes.  The harness's
  planner (``harness.run.plan.plan_run``) runs them, so the command line (exit 2), the
  API (``ProblemInputError``), the pytest plugin and Dask runs refuse the same inputs
  with the same one-line messages.

Adding an option is one record here and its physics in the scenes that read it (their
``Scene.options``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Protocol, Sequence

from contactbench.plugins import did_you_mean

from ..constraints import CONTROLS
from ..errors import ProblemInputError
from ..instances import OPERATOR_KINDS
from ..io import CROP_RULES, DETREND_RULES, NAN_RULES
from ..kernels import KERNELS
from ..layers import DEFAULT_NU, INTERFACES, NU_RANGE
from ..surfaces import RMD_FAMILIES
from ..units import HEIGHT_UNITS, MAX_RMS_SLOPE, MIN_RMS_SLOPE, PLAUSIBLE_MODULUS


class ReadsOptions(Protocol):
    """What the checks read of a scene (``base.Scene``): the options it reads and its
    merged config."""

    options: frozenset[str]

    def config(self, cfg: SceneConfig | None) -> SceneConfig: ...

#: Plausible hardness (Pa): from soft polymers (~10 kPa) to diamond (~100 GPa) and a
#: decade beyond; outside it a value is almost always a unit slip.
PLAUSIBLE_HARDNESS: tuple[float, float] = (1e4, 1e12)
#: Plausible load steps P / (E* A): a mean pressure above E* is beyond the small-slope
#: theory every kernel assumes; below 1e-9 E* not one element of a 8192^2 grid is loaded.
PLAUSIBLE_LOAD: tuple[float, float] = (1e-9, 1.0)
#: Plausible lengths (metres), of a surface's side or a layer's thickness: 1 nm to 1 km.
PLAUSIBLE_LENGTH: tuple[float, float] = (1e-9, 1e3)
#: The largest seed: a seed is stored in the results table's Int64 ``seed`` column.
MAX_SEED = 2**63 - 1
#: The option that lifts every plausibility range (``--allow-implausible``).
ALLOW_IMPLAUSIBLE = "allow_implausible"


@dataclass(frozen=True)
class Range:
    """Numbers from ``lo`` to ``hi`` (ends included unless ``*_open``), always finite."""

    lo: float
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, x: float) -> bool:
        if not math.isfinite(x):
            return False
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return above and below

    def text(self) -> str:
        """"> 0", ">= 1" or "in (-1, 0.5]"."""
        if math.isinf(self.hi):
            return f"{'>' if self.lo_open else '>='} {self.lo:g}"
        return f"in {'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


POSITIVE = Range(0.0, lo_open=True)


@dataclass(frozen=True)
class Requirement:
    """An option needs one of ``keys`` in effect (given, or set by the scene's own
    defaults), with ``value`` when not None; ``when`` restricts the need to one value of
    the option itself (``--control load`` needs ``--loads``)."""

    keys: tuple[str, ...]
    why: str
    value: Any = None
    when: Any = None


@dataclass(frozen=True)
class OptionRecord:
    """One scene option (module doc).

    name      : the ``SceneConfig`` field or ``extra`` key;
    flag      : the command-line flag;
    kind      : "int", "float", "floats" (a comma list), "length" (L0 or L0,L1), "seeds",
                "text", "choice" or "switch";
    help      : the ``--help`` line;
    unit      : the unit of a number ("" when it has none);
    valid     : the hard range of each number (never overridable);
    plausible : the plausible range of each number (``allow_implausible`` lifts it);
    allowed_by: a further switch that lifts ``plausible`` for this option alone;
    choices   : the values of a "choice";
    increasing: a "floats" list must increase strictly;
    group     : "grid", "surface-file", "layer", "control", "material" or "switch";
    requires  : what must be in effect with it (``Requirement``);
    excludes  : options that may not be given with it, and why (``excludes_why``);
    generated_only : a surface file replaces it (the file gives the grid and surface);
    universal : read by every scene (run switches), never "ignored";
    recipe    : carried into a rough-surface recipe's params (it changes the problem);
    suffix    : the instance-name suffix of a recipe's params ("" when at its default);
    what      : what the number is, for messages.
    """

    name: str
    flag: str
    kind: str
    help: str
    unit: str = ""
    valid: Range | None = None
    plausible: Range | None = None
    allowed_by: str | None = None
    choices: tuple[str, ...] = ()
    increasing: bool = False
    group: str = "grid"
    requires: tuple[Requirement, ...] = ()
    excludes: tuple[str, ...] = ()
    excludes_why: str = ""
    generated_only: bool = False
    universal: bool = False
    recipe: bool = False
    suffix: Callable[[dict[str, Any]], str] | None = None
    what: str = ""

    @property
    def field(self) -> bool:
        """Whether the option is a ``SceneConfig`` field (else a key of ``extra``)."""
        return self.name in CONFIG_FIELDS


CONFIG_FIELDS: frozenset[str] = frozenset({"size", "steps", "seeds", "surface_path", "length", "E", "kernel",
                                           "periodic", "operator"})


@dataclass(frozen=True)
class SceneConfig:
    """Options a user may set; None means "the scene's default".  Every option, field or
    ``extra`` key, is a record of ``OPTIONS`` (its flag, unit, ranges and rules);
    ``extra`` may hold a scene's own further keys (sweep values, ``hurst``, ...)."""

    size: int | None = None
    steps: int | None = None
    seeds: tuple[int, ...] | None = None
    surface_path: str | None = None
    length: float | tuple[float, float] | None = None  # L0, or (L0, L1) along axes 0 and 1
    E: float | None = None
    kernel: str | None = None
    periodic: bool | None = None
    operator: str | None = None  # "fft" or "dense"
    extra: dict[str, Any] = field(default_factory=dict)

    def get(self, name: str, default: Any) -> Any:
        v = getattr(self, name)
        return default if v is None else v

    def merged(self, defaults: "SceneConfig") -> "SceneConfig":
        """Fill unset fields from ``defaults``."""
        kw = {f: getattr(defaults, f) for f in CONFIG_FIELDS if getattr(self, f) is None}
        extra = {**defaults.extra, **self.extra}
        return replace(self, extra=extra, **kw)


def _has_layer(p: dict[str, Any]) -> bool:
    return p.get("thickness") is not None or p.get("thickness_over_L") is not None


def _thickness_suffix(p: dict[str, Any]) -> str:
    if p.get("thickness") is not None:
        return f"-T{float(p['thickness']):g}"
    return f"-T{float(p['thickness_over_L']):g}L" if p.get("thickness_over_L") is not None else ""


def _nu_suffix(p: dict[str, Any]) -> str:
    nu = p.get("nu")
    return f"-nu{float(nu):g}" if _has_layer(p) and nu is not None and float(nu) != DEFAULT_NU else ""


def _interface_suffix(p: dict[str, Any]) -> str:
    return "-frictionless" if _has_layer(p) and p.get("interface") == "frictionless" else ""


def _control_suffix(p: dict[str, Any]) -> str:
    return "-load" if p.get("control") == CONTROLS[1] else ""


def _hardness_suffix(p: dict[str, Any]) -> str:
    return f"-HA{float(p['hardness']):g}" if p.get("hardness") is not None else ""


_SURFACE = Requirement(("surface_path",), "applies to a --surface file; no --surface was given")
_LAYER = Requirement(("thickness", "thicknesses"), "describes an elastic layer; give its --thickness")

#: The scene options, in ``--help`` order (module doc).
OPTIONS: tuple[OptionRecord, ...] = (
    OptionRecord("size", "--size", "int", "grid points per side N (default: the scene's; not with --surface, "
                 "whose grid it is)", unit="points", valid=Range(1.0), generated_only=True),
    OptionRecord("steps", "--steps", "int", "number of load steps K (default: the scene's; under load control "
                 "the --loads set them)", valid=Range(1.0), excludes=("loads",),
                 excludes_why="under load control the loads set the steps; give one or the other"),
    OptionRecord("seeds", "--seeds", "seeds", "e.g. 0-9 or 0,3,5 (default: the scene's; not with --surface)",
                 generated_only=True),
    OptionRecord("surface_path", "--surface", "text", "measured height map: .npy/.csv/.txt or any "
                 "SurfaceTopography format (.x3p, .gwy, .nc, .mat, ...)", group="surface-file"),
    OptionRecord("length", "--length", "length", "L0 or L0,L1: the lateral size in metres along the map's axes 0 "
                 "and 1 (L0 alone: square pixels; optional when the surface file states its size)", unit="m",
                 valid=POSITIVE, plausible=Range(*PLAUSIBLE_LENGTH), what="a surface's side"),
    OptionRecord("E", "--E", "float", "composite modulus E* in Pa (default: the scene's)", unit="Pa",
                 valid=POSITIVE, plausible=Range(*PLAUSIBLE_MODULUS), allowed_by="allow_any_E", group="material",
                 what="a composite modulus"),
    OptionRecord("kernel", "--kernel", "choice", "influence coefficients (default: the scene's; spectral needs a "
                 "periodic domain)", choices=KERNELS),
    OptionRecord("periodic", "--periodic", "switch", "periodic domain"),
    OptionRecord("operator", "--operator", "choice", "operator the instance is built with (gpu: the optional CuPy "
                 "backend, extra `gpu`)", choices=OPERATOR_KINDS),
    OptionRecord("channel", "--channel", "text", "channel (index or name) of a multi-channel --surface file",
                 group="surface-file", requires=(_SURFACE,), recipe=True),
    OptionRecord("height_unit", "--height-unit", "choice", "unit of the heights of a --surface file that states "
                 "none (default: m; refused for a file that states its unit)", choices=tuple(HEIGHT_UNITS),
                 group="surface-file", requires=(_SURFACE,)),
    OptionRecord("allow_steep", "--allow-steep", "switch", "run a --surface whose slope looks implausible (rms "
                 f"slope > {MAX_RMS_SLOPE:g} or < {MIN_RMS_SLOPE:g}, or heights > side length)", group="surface-file",
                 requires=(_SURFACE,)),
    OptionRecord("family", "--surface-family", "choice", "RMD surface family of the generated surfaces: saupe "
                 "(non-periodic MidPointFM2D, the paper's; default of non-periodic scenes) or periodic "
                 "(wrap-around diamond-square)", choices=RMD_FAMILIES, generated_only=True),
    OptionRecord("detrend", "--detrend", "choice", "what is removed from a --surface map before it is solved "
                 "(default: plane, with a warning when the removed tilt exceeds the rms slope)",
                 choices=DETREND_RULES, group="surface-file", requires=(_SURFACE,), recipe=True),
    OptionRecord("nan", "--nan", "choice", "how missing points of a --surface map are filled (default: fill-mean; "
                 "error refuses them)", choices=NAN_RULES, group="surface-file", requires=(_SURFACE,), recipe=True),
    OptionRecord("crop", "--crop", "choice", "crop a rectangular --surface map to a square (square) or pad it "
                 "(pad-square); default: none, the whole map with its own spacing", choices=CROP_RULES,
                 group="surface-file", requires=(_SURFACE,), recipe=True),
    OptionRecord("thickness", "--thickness", "float", "an elastic layer of this thickness in metres on a rigid "
                 "base (default: the half-space)", unit="m", valid=POSITIVE, plausible=Range(*PLAUSIBLE_LENGTH),
                 group="layer", recipe=True, suffix=_thickness_suffix, what="a layer's thickness"),
    OptionRecord("nu", "--nu", "float", f"Poisson's ratio of the layer (default {DEFAULT_NU}; a layer's stiffness "
                 "depends on it)", valid=Range(*NU_RANGE, lo_open=True), group="layer", requires=(_LAYER,),
                 recipe=True, suffix=_nu_suffix, what="Poisson's ratio"),
    OptionRecord("interface", "--interface", "choice", "the layer's contact with its rigid base (default: bonded)",
                 choices=INTERFACES, group="layer", requires=(_LAYER,), recipe=True, suffix=_interface_suffix),
    OptionRecord("control", "--control", "choice", "what is given: the far-field displacement (displacement, the "
                 "default) or the total force (load, with --loads; the approach Delta is then the answer's, "
                 "column delta)", choices=CONTROLS, group="control", recipe=True, suffix=_control_suffix,
                 requires=(Requirement(("loads",), "needs its load steps: --loads L1,L2,... as P/(E* A)",
                                       when=CONTROLS[1]),)),
    OptionRecord("loads", "--loads", "floats", "the load steps of --control load, L1,L2,... as P/(E* A), "
                 "increasing", valid=POSITIVE, plausible=Range(*PLAUSIBLE_LOAD), increasing=True, group="control",
                 recipe=True, what="a load P/(E* A)",
                 requires=(Requirement(("control",), "gives the load steps of --control load; the run is "
                                       "displacement-controlled", value=CONTROLS[1]),)),
    OptionRecord("hardness", "--hardness", "float", "bound every element's mean pressure by this hardness in Pa "
                 "(0 <= p <= H_A x element area; default: none)", unit="Pa", valid=POSITIVE,
                 plausible=Range(*PLAUSIBLE_HARDNESS), group="control", recipe=True, suffix=_hardness_suffix,
                 what="a hardness"),
    OptionRecord("allow_any_E", "--allow-any-E", "switch", "take an --E outside the plausible range",
                 group="switch", universal=True),
    OptionRecord(ALLOW_IMPLAUSIBLE, "--allow-implausible", "switch", "take any value outside its plausible range "
                 "(the options with one: contactbench list options)", group="switch", universal=True),
)

#: The records by name.
BY_NAME: dict[str, OptionRecord] = {r.name: r for r in OPTIONS}
#: Every option name (``Scene.options`` is a subset).
SCENE_OPTIONS: frozenset[str] = frozenset(BY_NAME)


def names_in(*groups: str) -> frozenset[str]:
    """The options of ``groups`` (e.g. "layer", "control")."""
    return frozenset(r.name for r in OPTIONS if r.group in groups)


# ---------------------------------------------------------------------------
# Derived: what a config sets, recipe parameters, name suffixes
# ---------------------------------------------------------------------------


def value_of(cfg: SceneConfig, name: str) -> Any:
    """The value ``cfg`` holds for option ``name`` (a field, or a key of ``extra``)."""
    return getattr(cfg, name) if BY_NAME[name].field else cfg.extra.get(name)


def given_options(cfg: SceneConfig) -> set[str]:
    """The options a (user's, unmerged) config sets: fields not None, ``extra`` keys
    not None or False."""
    return {r.name for r in OPTIONS if value_of(cfg, r.name) is not None and value_of(cfg, r.name) is not False}


def recipe_params(extra: dict[str, Any], *groups: str) -> dict[str, Any]:
    """The ``extra`` options of ``groups`` a recipe carries (those set)."""
    return {r.name: extra[r.name] for r in OPTIONS
            if r.recipe and r.group in groups and extra.get(r.name) is not None}


def name_suffix(params: dict[str, Any], *groups: str) -> str:
    """The instance-name suffix of a recipe's options of ``groups``, in table order."""
    return "".join(r.suffix(params) for r in OPTIONS if r.suffix is not None and r.group in groups)


# ---------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------


def _numbers(rec: OptionRecord, value: Any) -> list[float]:
    """The numbers of ``value`` (one, or a list for "floats" / "length")."""
    many = rec.kind == "floats" or (rec.kind == "length" and isinstance(value, (list, tuple)))
    items = list(value) if many else [value]
    if rec.kind == "length" and not 1 <= len(items) <= 2:
        raise ProblemInputError(f"{rec.flag} takes L0 or L0,L1 (metres), got {value!r}")
    if rec.kind == "floats" and not items:
        raise ProblemInputError(f"{rec.flag} takes L1,L2,... (numbers), got none")
    out = []
    for x in items:
        if isinstance(x, bool) or not isinstance(x, (int, float)) and not hasattr(x, "__float__"):
            raise ProblemInputError(f"{rec.flag} takes {'an integer' if rec.kind == 'int' else 'a number'}, "
                                    f"got {x!r}")
        v = float(x)
        if rec.kind == "int" and v != int(v):
            raise ProblemInputError(f"{rec.flag} takes an integer, got {x!r}")
        out.append(v)
    return out


def value_problem(rec: OptionRecord, value: Any, allow: set[str]) -> str | None:
    """The one-line problem with ``value`` for option ``rec``, None when it passes:
    its type, choices, hard range, order and (unless allowed) plausible range; a text
    option that is empty or blank."""
    try:
        if rec.kind == "choice":
            if value not in rec.choices:
                return (f"{rec.flag} {value!r} is not one of {', '.join(rec.choices)}"
                        f"{did_you_mean(str(value), rec.choices)}")
            return None
        if rec.kind == "seeds":
            given = (f"{value.start}" + (f"-{value.stop - 1}" if value.stop - value.start > 1 else "")
                     if isinstance(value, range) else value)
            wrong = f"{rec.flag} takes integers from 0 to {MAX_SEED} (2^63 - 1), got {given}"
            if isinstance(value, range):  # (a lazy range stays lazy: the plan bounds its size)
                ok = value.start < value.stop and value.start >= 0 and value.step > 0 and value.stop - 1 <= MAX_SEED
                return None if ok else wrong
            seeds = list(value)
            if not seeds or any(isinstance(s, bool) or int(s) != s or not 0 <= s <= MAX_SEED for s in seeds):
                return wrong
            return None
        if rec.kind == "text":
            return f"{rec.flag} is empty (a script's unset variable?)" if not str(value).strip() else None
        if rec.kind == "switch":
            return None
        xs = _numbers(rec, value)
    except (ProblemInputError, TypeError, ValueError) as exc:
        return str(exc) if isinstance(exc, ProblemInputError) else f"{rec.flag} takes a number, got {value!r}"
    unit = f" {rec.unit}" if rec.unit else ""
    what = f" ({rec.what})" if rec.what else ""
    for x in xs:
        if rec.valid is not None and not rec.valid.contains(x):
            finite = "" if math.isfinite(x) else "finite and "
            return f"{rec.flag} must be {finite}{rec.valid.text()}{what}, got {x:g}"
    if rec.increasing and any(b <= a for a, b in zip(xs, xs[1:])):
        return f"{rec.flag} must be increasing, got {','.join(repr(x) for x in xs)}"
    if rec.plausible is not None and not ({ALLOW_IMPLAUSIBLE, rec.allowed_by} & allow):
        for x in xs:
            if not rec.plausible.contains(x):
                side = "below" if x < rec.plausible.lo else "above"
                flags = " or ".join(BY_NAME[n].flag for n in (rec.allowed_by, ALLOW_IMPLAUSIBLE) if n)
                slip = f" (a unit slip? it is in {rec.unit})" if rec.unit else ""
                return (f"{rec.flag} {x:g}{unit} is {side} the plausible range {rec.plausible.text()[3:]}{unit} of "
                        f"{rec.what or rec.name}{slip}; pass {flags} to run it anyway")
    return None


def value_problems(cfg: SceneConfig) -> list[str]:
    """The problems of every value ``cfg`` gives (``value_problem``), in table order."""
    allow = {r.name for r in OPTIONS if r.kind == "switch" and value_of(cfg, r.name)}
    out = []
    for name in sorted(given_options(cfg), key=list(BY_NAME).index):
        problem = value_problem(BY_NAME[name], value_of(cfg, name), allow)
        if problem:
            out.append(problem)
    return out


def in_effect(name: str, value: Any, given: SceneConfig, merged: Sequence[SceneConfig]) -> bool:
    """Whether config key ``name`` is set (to ``value`` when not None) by the user or by a
    scene's merged config (any of ``merged``: a composite's parts)."""
    for cfg in (given, *merged):
        v = getattr(cfg, name) if name in CONFIG_FIELDS else cfg.extra.get(name)
        if v is not None and v is not False and (value is None or v == value):
            return True
    return False


def taken_flags(options: Sequence[frozenset[str]]) -> list[str]:
    """The flags of the options any of ``options`` holds (scenes' ``options``), in table order."""
    return [r.flag for r in OPTIONS if not r.universal and any(r.name in o for o in options)]


def scene_problems(name: str, options: Sequence[frozenset[str]], given: SceneConfig,
                   merged: Sequence[SceneConfig]) -> list[str]:
    """The problems of the options ``given`` (the user's config) on scene or composite
    ``name``, whose scenes read ``options`` and merge the config into ``merged``: an
    option none of them reads, one a surface file replaces, an unmet requirement, two
    options that exclude each other."""
    opts = sorted(given_options(given), key=list(BY_NAME).index)
    file = "surface_path" in opts and any("surface_path" in o for o in options)
    out: list[str] = []
    read = [opt for opt in opts if BY_NAME[opt].universal or any(opt in o for o in options)]
    for opt in opts:
        rec = BY_NAME[opt]
        if opt not in read:
            taken = ", ".join(taken_flags(options)) or "no scene option"
            out.append(f"scene {name!r} does not take {rec.flag} (it would be ignored); it takes {taken}")
        elif file and rec.generated_only:
            out.append(f"{rec.flag} does not apply with --surface: the file gives the grid and the one surface; "
                       "leave it out")
    for opt in read:  # (what an unread option would need is beside the point)
        rec = BY_NAME[opt]
        for req in rec.requires:
            if req.when is not None and value_of(given, opt) != req.when:
                continue
            if not any(in_effect(k, req.value, given, merged) for k in req.keys):
                shown = f"{rec.flag} {req.when}" if req.when is not None else rec.flag
                out.append(f"{shown} {req.why}")
        out += [f"{rec.flag} and {BY_NAME[other].flag} exclude each other: {rec.excludes_why}"
                for other in rec.excludes if other in opts]
    return list(dict.fromkeys(out))


def config_problems(name: str, scenes: Sequence[ReadsOptions], cfgs: Sequence[SceneConfig],
                    given: SceneConfig | None) -> list[str]:
    """Every problem with the user's options ``given`` on scene or composite ``name``,
    whose scenes are ``scenes`` under configs ``cfgs`` (the user's, or a composite
    part's with the user's on top): the values first (``value_problems``), and only when
    they pass, the options against the scenes (``scene_problems``)."""
    if given is None:
        return []
    problems = value_problems(given)
    if problems:
        return problems
    merged = []
    for scene, cfg in zip(scenes, cfgs):
        try:
            merged.append(scene.config(cfg))
        except ProblemInputError:  # (e.g. a kernel the domain cannot take: the scene's validate says so)
            continue
    return scene_problems(name, [scene.options for scene in scenes], given, merged)


def check_config(name: str, scenes: Sequence[ReadsOptions], cfgs: Sequence[SceneConfig],
                 given: SceneConfig | None) -> None:
    """``config_problems`` as one ``ProblemInputError``, one line per problem."""
    problems = config_problems(name, scenes, cfgs, given)
    if problems:
        raise ProblemInputError("\n".join(problems))
