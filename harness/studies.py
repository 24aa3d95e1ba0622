"""Study design: how the harness runs each scene.

A scene (``contactbench.problems.scenes``) is pure data: surfaces, kernels, load
sequences.  A ``Study`` says what the harness does with it -- one record per scene name:

* ``solvers``   the registry names run when the user gives no ``--solvers`` (None: every
                available solver);
* ``profiles``  the accuracy profiles run when the user gives no ``--profile``;
* ``reference`` the preferred exact reference solver (before ``REFERENCE_CANDIDATES``);
* ``sweeps``    parameter sweeps: a solver matching a sweep runs once per value of one
                parameter (e.g. ``nnls-gp`` once per K of paper Fig. 6, every ``cmr+*``
                wrapper once per area-of-influence factor h of Fig. 9).  A sweep's values
                are the study's own, else the solver's declared ``grid``.

A ``Composite`` (``default``, what ``make bench`` runs) is a mix of studies, each on a
scene with its own options.  A scene with no record here gets ``Study(name)``: every
available solver (or the user's list), profile ``default``, the harness's reference.

The variants built here are named exactly as before this module existed (labels, base
names and parameters feed ``harness.plan.make_cell_id``), so stored runs resume.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field, fields, replace
from typing import Any, Sequence

from contactbench.problems.scenes import SceneConfig, all_scenes, get_scene
from contactbench.solvers.registry import load_solver

#: Exact solvers tried, in order, for the reference solution of a step (after the
#: study's own ``reference``): the dense Lawson-Hanson NNLS where H fits, else the
#: matrix-free NNLS, else Polonsky-Keer.
REFERENCE_CANDIDATES: tuple[str, ...] = ("scipy-nnls", "nnls", "pk")
#: The profile a reference is solved at.
REFERENCE_PROFILE = "high"


@dataclass(frozen=True)
class SolverVariant:
    """A solver with fixed parameters, e.g. NNLS+GP with K = 50.  ``label`` is what the
    tidy table calls it (column ``solver``); ``base`` is the registry name."""

    base: str
    params: dict[str, Any] = field(default_factory=dict)
    label: str = ""

    @property
    def name(self) -> str:
        return self.label or self.base


def solver_grid(solver: str, param: str) -> tuple[Any, ...]:
    """The values of ``param`` that ``solver`` declares for sweeps (``Solver.grid``)."""
    values = dict(load_solver(solver).grid).get(param)
    if not values:
        raise KeyError(f"solver {solver!r} declares no grid for parameter {param!r}")
    return tuple(values)


@dataclass(frozen=True)
class Sweep:
    """Run each solver whose name matches ``solvers`` (an fnmatch pattern) once per value
    of parameter ``param``.

    values  : the values (None: the solver's own grid); a run overrides them with
              ``SceneConfig.extra[param]``;
    kind    : the values' type (int or float);
    fixed   : further parameters of every swept variant; ``SceneConfig.extra`` may
              override the keys of ``fixed`` and ``options``;
    label   : the variant's table name, formatted with solver, param and value;
    label_single : whether a sweep of one value is labelled too (else it keeps the
              solver's name)."""

    solvers: str
    param: str
    values: tuple[Any, ...] | None = None
    kind: type = float
    fixed: dict[str, Any] = field(default_factory=dict)
    options: tuple[str, ...] = ()
    label: str = "{solver}[{param}={value}]"
    label_single: bool = True

    def matches(self, solver: str) -> bool:
        return fnmatch.fnmatchcase(solver, self.solvers)

    def grid(self, solver: str, extra: dict[str, Any]) -> tuple[Any, ...]:
        given = extra.get(self.param, self.values)
        if given is None:
            given = solver_grid(solver, self.param)
        given = given if isinstance(given, (list, tuple)) else (given,)
        return tuple(self.kind(v) for v in given)

    def expand(self, solver: str, extra: dict[str, Any]) -> list[SolverVariant]:
        values = self.grid(solver, extra)
        common = {**self.fixed, **{k: extra[k] for k in (*self.fixed, *self.options) if extra.get(k) is not None}}
        labelled = self.label_single or len(values) > 1
        return [SolverVariant(solver, {self.param: v, **common},
                              self.label.format(solver=solver, param=self.param, value=v) if labelled else "")
                for v in values]


@dataclass(frozen=True)
class Study:
    """How the harness runs one scene (module doc)."""

    scene: str
    solvers: tuple[str, ...] | None = None
    profiles: tuple[str, ...] = ("default",)
    reference: str | None = None
    sweeps: tuple[Sweep, ...] = ()

    def variants(self, solvers: Sequence[str], extra: dict[str, Any] | None = None) -> list[SolverVariant]:
        """Each solver once, or once per value of the first sweep it matches."""
        out: list[SolverVariant] = []
        for s in solvers:
            sweep = next((w for w in self.sweeps if w.matches(s)), None)
            out += sweep.expand(s, dict(extra or {})) if sweep else [SolverVariant(s)]
        return out

    def reference_candidates(self, reference: str) -> tuple[str, ...]:
        """Reference solvers to try: none ("none"), the one asked for, or ("auto") the
        study's own then ``REFERENCE_CANDIDATES``."""
        if reference == "none":
            return ()
        if reference != "auto":
            return (reference,)
        return tuple(dict.fromkeys(([self.reference] if self.reference else []) + list(REFERENCE_CANDIDATES)))


@dataclass(frozen=True)
class Part:
    """One part of a composite: a study on its scene with these options."""

    study: Study
    cfg: SceneConfig


@dataclass(frozen=True)
class Composite:
    """A named mix of studies run as one (``default``).  Options the user sets override
    every part's own; rows carry the part's scene name."""

    name: str
    description: str
    parts: tuple[Part, ...]

    def expand(self, user: SceneConfig | None) -> list[tuple[Study, SceneConfig]]:
        return [(p.study, override(p.cfg, user)) for p in self.parts]


def override(base: SceneConfig, user: SceneConfig | None) -> SceneConfig:
    """``base`` with every field the user set (not None) replaced by the user's value."""
    if user is None:
        return base
    kw: dict[str, Any] = {f.name: getattr(user, f.name) for f in fields(SceneConfig)
                          if f.name != "extra" and getattr(user, f.name) is not None}
    return replace(base, extra={**base.extra, **user.extra}, **kw)


# ---------------------------------------------------------------------------
# The studies
# ---------------------------------------------------------------------------

#: The paper's own algorithms (section 3) and the dense reference.
PAPER_SOLVERS: tuple[str, ...] = ("greedy-cg", "greedy-gs", "greedy-chol", "pk", "nnls", "gp", "nnls-gp", "admm",
                                  "scipy-nnls")
#: Paper Fig. 6: NNLS warm-started by K accelerated gradient-projection steps, per K.
GP_K_SWEEP = Sweep("nnls-gp", "K", kind=int)


def cmr_sweep(hs: tuple[float, ...] | None, coarsest: int) -> Sweep:
    """Every ``cmr+*`` wrapper once per area-of-influence factor h (None: the wrapper's
    own grid, paper Fig. 9; labelled by h when there are several), with the cascade
    starting at ``coarsest`` points per side."""
    return Sweep("cmr+*", "h", values=hs, kind=float, fixed={"coarsest": coarsest}, options=("levels",),
                 label="{solver} {param}={value:g}", label_single=False)


CMR_VS_DIRECT: tuple[str, ...] = ("nnls", "cmr+nnls")
GREEDY_INNER_SOLVES: tuple[str, ...] = ("greedy-cg", "greedy-gs", "greedy-chol")

STUDIES: dict[str, Study] = {s.scene: s for s in (
    Study("gp-k-sweep", solvers=("nnls-gp",), sweeps=(GP_K_SWEEP,)),
    Study("greedy-linear-solvers", solvers=GREEDY_INNER_SOLVES),
    Study("cmr", solvers=CMR_VS_DIRECT, sweeps=(cmr_sweep((2.0,), 16),)),
    Study("cmr-h-sweep", solvers=CMR_VS_DIRECT, sweeps=(cmr_sweep(None, 16),)),
    Study("cmr-cutoff", solvers=CMR_VS_DIRECT, sweeps=(cmr_sweep((1.5,), 64),)),
    Study("population", solvers=("fast-ccg",)),
)}

COMPOSITES: dict[str, Composite] = {c.name: c for c in (
    Composite(
        "default",
        "make bench: small paper-sweep, counterexample, hertz, gp-k-sweep, greedy-linear-solvers",
        (
            # paper-sweep 64^2, 3 steps, every available solver at low and high (Fig. 4, work-precision)
            Part(Study("paper-sweep", profiles=("low", "high")), SceneConfig(size=64, steps=3, seeds=(0,))),
            # the counterexample (Example 1) at n = 100 on seeds 0-9 with the paper's solvers
            Part(Study("counterexample", solvers=PAPER_SOLVERS),
                 SceneConfig(seeds=tuple(range(10)), extra={"sizes": (100,)})),
            # hertz 16^2-64^2: convergence to the closed form
            Part(Study("hertz", solvers=("nnls", "pk", "scipy-nnls", "fast-ccg")),
                 SceneConfig(extra={"sizes": (16, 32, 64)})),
            Part(STUDIES["gp-k-sweep"], SceneConfig(size=64, steps=3, seeds=(0,))),  # Fig. 6
            Part(STUDIES["greedy-linear-solvers"],  # Fig. 5
                 SceneConfig(steps=4, seeds=(0,), extra={"sizes": (32, 64)})),
        ),
    ),
)}


def study_for(name: str) -> Study:
    """The study of scene ``name`` (``Study(name)`` for a scene with no record)."""
    if name in STUDIES:
        return STUDIES[name]
    get_scene(name)
    return Study(name)


def expand(name: str, cfg: SceneConfig | None) -> list[tuple[Study, SceneConfig]]:
    """(study, options) pairs a scene name stands for: one, or a composite's parts."""
    if name in COMPOSITES:
        return COMPOSITES[name].expand(cfg)
    if name not in all_scenes():
        raise KeyError(f"unknown scene {name!r}; known scenes: {', '.join(sorted(catalogue()))}")
    return [(study_for(name), cfg or SceneConfig())]


def catalogue() -> dict[str, str]:
    """Every runnable name (scenes and composites) with its description, sorted."""
    names = {name: scene.description for name, scene in all_scenes().items()}
    names.update({name: c.description for name, c in COMPOSITES.items()})
    return dict(sorted(names.items()))
