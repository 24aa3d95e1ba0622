"""Study design: how the harness runs each scene.

A scene (``contactbench.problems.scenes``) is pure data: surfaces, kernels, load
sequences.  A ``Study`` says what the harness does with it -- one record per scene name:

* ``solvers``   the registry names run when the user gives no ``--solvers`` (None: every
                available solver);
* ``profiles``  the accuracy profiles run when the user gives no ``--profile``;
* ``reference`` the preferred exact reference solver (before ``REFERENCE_CANDIDATES``);
* ``sweeps``    parameter sweeps: a solver matching a sweep runs once per value of one
                parameter (e.g. ``nnls-gp`` once per K of paper Fig. 6, every ``cmr+*``
                wrapper once per area-of-influence factor h of Fig. 9), and once more per
                entry of the sweep's ``over`` (a second, discrete choice such as the CMR
                coarse reading).  A sweep's values are the study's own, else the solver's
                declared ``grid``.  A solver matching several sweeps gets the variants of
                all of them (each distinct parameter set once).  A solver's whole grid runs
                without a sweep as ``--solvers 'name[grid]'`` (``Study.variants``).

A ``Composite`` (``default``, what ``make bench`` runs) is a mix of studies, each on a
scene with its own options.  A scene with no record here gets ``Study(name)``: every
available solver (or the user's list), profile ``default``, the harness's reference.

The variants built here are named exactly as before this module existed (labels, base
names and parameters feed ``harness.run.plan.make_cell_id``), so stored runs resume -- except
the CMR variants, which were renamed on purpose (both bases, the coarse reading and
the first level are in their parameters and labels).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field, fields, replace
from typing import Any, Sequence

from contactbench.problems.coarsen import COARSE_KINDS
from contactbench.problems.scenes import SceneConfig, all_scenes, get_scene
from contactbench.solvers.cmr import CMRSolver
from contactbench.solvers.admm import PAPER_PARAMS
from contactbench.solvers.registry import SolverSpec, expand_solver_spec, load_solver, split_solver_spec

from contactbench.plugins import did_you_mean

from ..profiles import CLAIMS_DENSE_PROFILE, CLAIMS_FFT_PROFILE
from ..table.files import canonical_json

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


def spec_variant(spec: SolverSpec) -> SolverVariant:
    """The variant of a spec with parameters: its parameters, labelled ``SolverSpec.label``
    (``name[k=v,...]``, keys sorted), the table's ``solver``; ``base_solver`` and
    ``params`` carry the parts."""
    return SolverVariant(spec.name, dict(spec.params), spec.label)


@dataclass(frozen=True)
class Sweep:
    """Run each solver whose name matches ``solvers`` (an fnmatch pattern) once per value
    of parameter ``param``.

    values  : the values (None: the solver's own grid); a run overrides them with
              ``SceneConfig.extra[param]``;
    kind    : the values' type (int or float);
    fixed   : further parameters of every swept variant; ``SceneConfig.extra`` may
              override the keys of ``fixed`` and ``options``;
    over    : parameter sets crossed with the values (each value runs once per entry,
              entry by entry; default one empty set), e.g. ``coarse`` = subsample and
              mean;
    label   : the variant's table name, formatted with solver, param, value and every
              parameter of the variant by name (e.g. "{solver} coarse={coarse} h={h:g}");
    label_single : whether a sweep of one variant is labelled too (else it keeps the
              solver's name)."""

    solvers: str
    param: str
    values: tuple[Any, ...] | None = None
    kind: type = float
    fixed: dict[str, Any] = field(default_factory=dict)
    options: tuple[str, ...] = ()
    label: str = "{solver}[{param}={value}]"
    label_single: bool = True
    over: tuple[dict[str, Any], ...] = ({},)

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
        given = {k: extra[k] for k in (*self.fixed, *self.options) if extra.get(k) is not None}
        labelled = self.label_single or len(values) * len(self.over) > 1
        out = []
        for each in self.over:
            for v in values:
                params = {self.param: v, **self.fixed, **each, **given}
                label = self.label.format(solver=solver, param=self.param, value=v, **params) if labelled else ""
                out.append(SolverVariant(solver, params, label))
        return out


@dataclass(frozen=True)
class Study:
    """How the harness runs one scene (module doc)."""

    scene: str
    solvers: tuple[str, ...] | None = None
    profiles: tuple[str, ...] = ("default",)
    reference: str | None = None
    sweeps: tuple[Sweep, ...] = ()

    def variants(self, solvers: Sequence[str | SolverSpec], extra: dict[str, Any] | None = None) -> list[SolverVariant]:
        """Each solver once, or the variants of every sweep it matches, in the sweeps'
        order (a parameter set two sweeps share runs once, under the first one's label).
        A ``SolverSpec`` (``harness.run.plan.resolve_solver_names``) runs once with exactly
        its parameters, labelled ``SolverSpec.label``, and so does each variant of a name
        with parameters, ``name[k=v]`` or ``name[grid]``
        (``solvers.registry.expand_solver_spec``): no sweep."""
        out: list[SolverVariant] = []
        for s in solvers:
            if isinstance(s, SolverSpec):  # the user's parameters, no sweep
                out.append(spec_variant(s))
                continue
            parts = split_solver_spec(s)
            if parts.raw or parts.grid:  # a study's own name[k=v]
                out += [spec_variant(spec) for spec in expand_solver_spec(s)[0]]
                continue
            sweeps = [w for w in self.sweeps if w.matches(s)]
            if not sweeps:
                out.append(SolverVariant(s))
                continue
            seen: set[str] = set()
            for w in sweeps:
                for v in w.expand(s, dict(extra or {})):
                    key = canonical_json(v.params)
                    if key not in seen:
                        seen.add(key)
                        out.append(v)
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
    every part's own, but a ``--surface`` and its ``--length`` (the map's size) go only to
    the parts whose scene reads a surface file (``for_part``); rows carry the part's scene
    name."""

    name: str
    description: str
    parts: tuple[Part, ...]

    def expand(self, user: SceneConfig | None) -> list[tuple[Study, SceneConfig]]:
        return [(p.study, override(p.cfg, for_part(user, p.study.scene))) for p in self.parts]


def for_part(user: SceneConfig | None, scene: str) -> SceneConfig | None:
    """The user's options as a composite's part on ``scene`` takes them: with a surface file
    (``surface_path``) that the scene does not read, without it and without its length, which
    sizes the map, not the scene's own domain (a Hertz sphere's)."""
    if user is None or not user.surface_path or "surface_path" in get_scene(scene).options:
        return user
    return replace(user, surface_path=None, length=None)


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


# --- Section 5 (CMR) as the paper ran it, as distributions over seeds -------------
#: The direct solvers CMR is compared with, each also CMR's base (``cmr+<base>``): the
#: paper's dense Cholesky + NNLS (``scipy-nnls``: Lawson-Hanson on the dense H; it takes
#: no warm start, so it solves every step of the load history from scratch, as the
#: paper's direct NNLS did) and our matrix-free FFT base ``fast-dual-pccg`` (warm started
#: from its previous step along the history, as every solver that accepts one is).
CMR_DIRECT_BASES: tuple[str, ...] = ("scipy-nnls", "fast-dual-pccg")
#: The CMR wrappers over those bases.
CMR_WRAPPERS: tuple[str, ...] = tuple(f"cmr+{b}" for b in CMR_DIRECT_BASES)
#: The readings of a coarse level (solvers/cmr.py parameter ``coarse``): the exact
#: subsample of the fine grid, or the block mean (a height as a cell average).
CMR_COARSE: tuple[str, ...] = COARSE_KINDS
#: Fig. 8's area-of-influence factor and the paper's first level (16 points per side):
#: the cmr solver's declared defaults (solvers/cmr.py), which the report reads too.
CMR_H: float = next(p.default for p in CMRSolver.params if p.name == "h")
CMR_COARSEST: int = next(p.default for p in CMRSolver.params if p.name == "coarsest")
#: Where the cascade may start (the worst case at H = 0.7 is mostly lost at 16 -> 32).
CMR_COARSEST_SWEEP: tuple[int, ...] = (16, 32, 64)
#: A CMR variant's table name: every choice that varies is in it.
CMR_LABEL = "{solver} coarse={coarse} h={h:g} from {coarsest}"


def cmr_sweep(solvers: str, hs: tuple[float, ...] | None, coarsest: int = CMR_COARSEST,
              coarse: tuple[str, ...] = CMR_COARSE) -> Sweep:
    """The ``cmr+*`` wrappers matching ``solvers`` once per area-of-influence factor h
    (None: the wrapper's own grid, paper Fig. 9) and coarse reading, the cascade
    starting at ``coarsest`` points per side."""
    return Sweep(solvers, "h", values=hs, kind=float, fixed={"coarsest": coarsest}, options=("levels",),
                 label=CMR_LABEL, over=tuple({"coarse": c} for c in coarse))


def coarsest_sweep(solvers: str, values: tuple[int, ...] = CMR_COARSEST_SWEEP, h: float = CMR_H,
                   coarse: tuple[str, ...] = CMR_COARSE) -> Sweep:
    """The ``cmr+*`` wrappers matching ``solvers`` once per first level (points per side)
    at factor ``h``, per coarse reading."""
    return Sweep(solvers, "coarsest", values=values, kind=int, fixed={"h": h}, options=("levels",),
                 label=CMR_LABEL, over=tuple({"coarse": c} for c in coarse))


#: The FFT base and CMR over it; the dense base and CMR over it.
CMR_FAST: tuple[str, ...] = ("fast-dual-pccg", "cmr+fast-dual-pccg")
CMR_DENSE: tuple[str, ...] = ("scipy-nnls", "cmr+scipy-nnls")
#: The grid the dense base runs on in ``cmr-paper``: at the scenes' 256^2 the trial sets
#: reach n ~ 5000 (median, H = 0.7) to 20000 (H = 0.9) and one dense Lawson-Hanson solve
#: costs ~ n^3 (6 s CPU at n = 2913), hours for 20 seeds; at 128^2 n is 4x smaller.
CMR_DENSE_SIZE = 128

#: The sweeps of the CMR scenes (every one names the base it applies to):
#: ``cmr`` (Fig. 8): each base's CMR with both coarse readings at h = 2 from 16.
CMR_SWEEPS: tuple[Sweep, ...] = (cmr_sweep("cmr+*", (CMR_H,)),)
#: ``cmr-h-sweep`` (Fig. 9, the top step of H = 0.7): the FFT base's CMR per h of the
#: paper's grid and per coarse reading, and from 16 / 32 / 64 at h = 2; the dense base's
#: CMR per h with coarse=mean (n_p/n and the error do not depend on the base: the dense
#: base adds the paper's time ratio, at half the cost of both readings).
CMR_H_SWEEPS: tuple[Sweep, ...] = (
    cmr_sweep("cmr+fast-dual-pccg", None),
    cmr_sweep("cmr+scipy-nnls", None, coarse=("mean",)),
    coarsest_sweep("cmr+fast-dual-pccg"),
)
#: cmr and cmr-h-sweep as plain scenes (256^2, within the benchmark budget): the FFT base
#: only -- 3 solves per step (cmr), 22 per seed (cmr-h-sweep).  ``--solvers
#: scipy-nnls,cmr+scipy-nnls`` adds the dense base (its sweeps are declared here).
CMR_STUDY = Study("cmr", solvers=CMR_FAST, sweeps=CMR_SWEEPS)
CMR_H_STUDY = Study("cmr-h-sweep", solvers=CMR_FAST, sweeps=CMR_H_SWEEPS)
#: cmr-cutoff (Figs. 10-11): the incremental NNLS direct and CMR over it, from 64.
CMR_VS_DIRECT: tuple[str, ...] = ("nnls", "cmr+nnls")
CMR_CUTOFF_SWEEP = Sweep("cmr+*", "h", values=(1.5,), kind=float, fixed={"coarsest": 64, "coarse": "mean"}, options=("levels",),
                         label="{solver} {param}={value:g}", label_single=False)
GREEDY_INNER_SOLVES: tuple[str, ...] = ("greedy-cg", "greedy-gs", "greedy-chol")
#: The solvers of the load-controlled and the hardness-bounded sweeps: ours that pose the
#: family, and the field's codes in their native modes (each skipped, with the reason,
#: where it cannot pose the problem or is not installed).
LOAD_CONTROL_SOLVERS: tuple[str, ...] = ("pk", "fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "gp",
                                         "nnls-gp", "cm-pk-ccg", "tamaas-pkr", "tamaas-kato-saturated")
HARDNESS_SOLVERS: tuple[str, ...] = ("pk", "fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "gp", "nnls-gp",
                                     "greedy-cg", "cm-pk-ccg", "tamaas-kato-saturated")

STUDIES: dict[str, Study] = {s.scene: s for s in (
    Study("gp-k-sweep", solvers=("nnls-gp",), sweeps=(GP_K_SWEEP,)),
    Study("greedy-linear-solvers", solvers=GREEDY_INNER_SOLVES),
    CMR_STUDY,
    CMR_H_STUDY,
    Study("cmr-cutoff", solvers=CMR_VS_DIRECT, sweeps=(CMR_CUTOFF_SWEEP,)),
    Study("population", solvers=("fast-ccg",)),
    Study("load-sweep", solvers=LOAD_CONTROL_SOLVERS, reference="pk"),
    Study("plastic-sweep", solvers=HARDNESS_SOLVERS, reference="pk"),
    Study("layer-sweep", solvers=("fast-dual-pccg", "pk", "nnls-gp"), reference="pk"),
    Study("greedy-kernels", solvers=("greedy-cg", "greedy-chol")),
)}

# --- The paper's claims ledger (harness/report/claims.py): two conditions ----------------------
#: Grid sizes of the dense condition: every paper solver at the small ones; at the largest
#: (256^2: n = 8,803 at the top step, a 0.6 GB H; 512^2, the paper's n = 35,555, needs
#: 10 GB) only NNLS+GP and P&K (warm and cold), which fit the benchmark's time.
CLAIMS_DENSE_SIZES: tuple[int, ...] = (64, 128)
CLAIMS_LARGEST = 256
#: The paper's own size: the top step of the 512^2 surface alone (n = 35,218; the paper's
#: 35,555), cold, dense: a 9.2 GiB H, so the run needs ``--memory-budget-gb`` above it
#: (results/claims/README.md gives the command); below that budget these cells are skipped
#: with the reason and their ledger rows are ``unmeasured``.
CLAIMS_PAPER_SIZE = 512
#: P&K as printed (Algorithm 2, pk-printed), P&K 1999 (pk) and NNLS+GP there.  (Greedy
#: Cholesky is not among them: the time model puts its solve at ~2.9e4 s there.)
CLAIMS_PAPER_SOLVERS: tuple[str, ...] = ("pk-printed", "pk", "nnls-gp")
#: Grid sizes of our condition (FFT) for Fig. 4; the greedy solvers run at the first only.
CLAIMS_FFT_SIZES: tuple[int, ...] = (128, 256)
#: The paper-sweep surface (seed) every Fig. 4 / Fig. 5 part runs on, so the parts share instances.
CLAIMS_SEED = 5
#: Example 1's sizes n (100 seeds each) and the larger n (fewer seeds: one dense H of 1600^2).
CLAIMS_EXAMPLE1_SIZES: tuple[int, ...] = (25, 100, 400)
CLAIMS_EXAMPLE1_LARGE = 1600
CLAIMS_EXAMPLE1_LARGE_SEEDS = 20
#: Section 3.1's words around Example 1 (problems/scenes/example1_variants.py): its trial
#: elements 2 delta apart (tex 647-651) and a random SPD Q with positive entries (tex
#: 601-604), greedy CG at n = 25 and 100 over seeds 0-99.
CLAIMS_EXAMPLE1_VARIANTS: tuple[str, ...] = ("counterexample-2delta", "random-positive-h")
CLAIMS_EXAMPLE1_VARIANT_SIZES: tuple[int, ...] = (25, 100)
#: Fig. 6's K values: the paper's minimum (100), what lies beyond it (150, 200) and below.
CLAIMS_K: tuple[int, ...] = (0, 50, 100, 150, 200)
#: The CMR parts (Figs. 8-9) as tex 1200-1220 set them up: 256^2 (the paper's finest), the
#: cascade 16-32-64-128-256, seeds 0-2, the block-mean coarse reading, NNLS warm along the
#: history (the paper's reference) under the paper's condition, each side paying the
#: assembly of its own dense matrices (harness/report/sections/cmr.py); Fig. 9 at the
#: ends of the paper's h range and at Fig. 8's h.
CLAIMS_CMR_SIZE = 256
#: Fig. 6's K sweeps (warm along the history and from p = 0).
CLAIMS_FIG6_SIZE = 128
CLAIMS_CMR_SEEDS: tuple[int, ...] = (0, 1, 2)
CLAIMS_H: tuple[float, ...] = (1.25, CMR_H, 3.0)
#: The real-surface cases (Fig. 11): the paper's real surfaces have 512 points per side.
CLAIMS_CUTOFF_SIZE = 512
#: ADMM as the paper states it (section 4, tex 1027-1029; Algorithm 5, tex 951): rho = 1
#: taken as given, in the table's SI units (m/N, the units of H; the paper does not state
#: its units) and its printed stop ||p - s||_inf <= eps (eps = 1e-8 N), beside the
#: registry's rho relative to mean(diag H) stopped on the scaled KKT error.
CLAIMS_ADMM_PAPER = SolverSpec("admm", {k: PAPER_PARAMS[k] for k in ("rho", "rho_relative", "stop")}).label
#: The solvers of each condition (ADMM is left out of ours: its FFT-matvec CG inner solves
#: took 108 s of the 256^2 sweep, and the claims about it are the paper's, on the dense H).
CLAIMS_DENSE_FIG4: tuple[str, ...] = ("nnls-gp", "nnls", "pk", "admm", CLAIMS_ADMM_PAPER)
#: The independent (cold) solves under the paper's condition: P&K as printed and 1999, NNLS
#: (the warm start's saving), the greedy solvers; pure GP at the smallest size only (it is
#: slow: up to 5e4 iterations a step).
CLAIMS_DENSE_COLD: tuple[str, ...] = ("pk-printed", "pk", "nnls", "greedy-cg", "greedy-chol", "greedy-gs")
CLAIMS_GP_COLD_SIZE = 64
CLAIMS_FFT_FIG4: tuple[str, ...] = ("nnls-gp", "nnls", "pk", "fast-dual-pccg", "fast-ccg")
CLAIMS_FFT_COLD: tuple[str, ...] = ("pk", "greedy-cg", "greedy-gs")
#: CMR's direct base and NNLS+GP beside it (the abstract's "2x faster than NNLS+GP").
CLAIMS_CMR_DENSE: tuple[str, ...] = ("nnls", "cmr+nnls", "nnls-gp")
#: The smooth indenters on which greedy is claimed never to fail (section 3.1).
CLAIMS_SMOOTH_SCENES: tuple[str, ...] = ("hertz", "flat-punch")


def claims_parts() -> tuple[Part, ...]:
    """The parts of ``paper-claims``: each figure's scene under the paper's condition
    (dense, profile ``CLAIMS_DENSE_PROFILE``) and ours (fft, ``CLAIMS_FFT_PROFILE``)."""
    mean_h2 = (cmr_sweep("cmr+*", (CMR_H,), coarse=("mean",)),)
    mean_hs = (cmr_sweep("cmr+*", CLAIMS_H, coarse=("mean",)),)
    k_sweep = (replace(GP_K_SWEEP, values=CLAIMS_K),)
    parts: list[Part] = []
    for op, prof, fig4, cold, cold_sizes, cmr_solvers in (
            ("dense", CLAIMS_DENSE_PROFILE, CLAIMS_DENSE_FIG4, CLAIMS_DENSE_COLD, CLAIMS_DENSE_SIZES, CLAIMS_CMR_DENSE),
            ("fft", CLAIMS_FFT_PROFILE, CLAIMS_FFT_FIG4, CLAIMS_FFT_COLD, CLAIMS_FFT_SIZES[:1], CMR_FAST)):
        ramp = SceneConfig(steps=10, seeds=(CLAIMS_SEED,), operator=op)
        for size in CLAIMS_DENSE_SIZES if op == "dense" else CLAIMS_FFT_SIZES:  # Fig. 4, warm along the history
            parts.append(Part(Study("paper-sweep", solvers=fig4, profiles=(prof,)), replace(ramp, size=size)))
        # Fig. 5 and P&K cold ("P&K1999"): the same surface and steps as independent solves
        parts.append(Part(Study("greedy-linear-solvers", solvers=cold, profiles=(prof,)),
                          replace(ramp, extra={"sizes": cold_sizes})))
        parts.append(Part(Study("greedy-linear-solvers", solvers=("pk",), profiles=(prof,)),
                          replace(ramp, extra={"sizes": (CLAIMS_LARGEST,)})))
        parts.append(Part(Study("gp-k-sweep", solvers=("nnls-gp",), profiles=(prof,), sweeps=k_sweep),
                          replace(ramp, size=CLAIMS_FIG6_SIZE)))
        cmr = SceneConfig(size=CLAIMS_CMR_SIZE, seeds=CLAIMS_CMR_SEEDS, operator=op)
        parts.append(Part(Study("cmr", solvers=cmr_solvers, profiles=(prof,), sweeps=mean_h2), cmr))
        parts.append(Part(Study("cmr-h-sweep", solvers=cmr_solvers, profiles=(prof,), sweeps=mean_hs), cmr))
        parts.append(Part(Study("cmr-cutoff", solvers=cmr_solvers, profiles=(prof,), sweeps=(CMR_CUTOFF_SWEEP,)),
                          SceneConfig(size=CLAIMS_CUTOFF_SIZE, operator=op)))
    dense_ramp = SceneConfig(steps=10, seeds=(CLAIMS_SEED,), operator="dense")
    paper = (CLAIMS_DENSE_PROFILE,)
    # Fig. 6 as the paper ran it: every K from p = 0 (K = 0 is NNLS cold), independent steps
    parts.append(Part(Study("greedy-linear-solvers", solvers=("nnls-gp",), profiles=paper, sweeps=k_sweep),
                      replace(dense_ramp, extra={"sizes": (CLAIMS_FIG6_SIZE,)})))
    parts.append(Part(Study("greedy-linear-solvers", solvers=("gp",), profiles=paper),
                      replace(dense_ramp, extra={"sizes": (CLAIMS_GP_COLD_SIZE,)})))
    parts.append(Part(Study("paper-sweep", solvers=("nnls-gp", "pk"), profiles=paper),
                      replace(dense_ramp, size=CLAIMS_LARGEST)))
    parts.append(Part(Study("greedy-linear-solvers", solvers=CLAIMS_PAPER_SOLVERS, profiles=paper),
                      replace(dense_ramp, steps=1, extra={"sizes": (CLAIMS_PAPER_SIZE,)})))
    for scene in CLAIMS_SMOOTH_SCENES:  # greedy on smooth indenters (section 3.1)
        parts.append(Part(Study(scene, solvers=("greedy-cg",), profiles=paper), SceneConfig(operator="dense")))
    example1 = Study("counterexample", solvers=("greedy-cg",), profiles=paper)
    parts.append(Part(example1, SceneConfig(seeds=tuple(range(100)), extra={"sizes": CLAIMS_EXAMPLE1_SIZES})))
    parts.append(Part(example1, SceneConfig(seeds=tuple(range(CLAIMS_EXAMPLE1_LARGE_SEEDS)),
                                            extra={"sizes": (CLAIMS_EXAMPLE1_LARGE,)})))
    for scene in CLAIMS_EXAMPLE1_VARIANTS:
        parts.append(Part(Study(scene, solvers=("greedy-cg",), profiles=paper),
                          SceneConfig(seeds=tuple(range(100)), extra={"sizes": CLAIMS_EXAMPLE1_VARIANT_SIZES})))
    return tuple(parts)


COMPOSITES: dict[str, Composite] = {c.name: c for c in (
    Composite(
        "cmr-paper",
        "paper section 5 as distributions (results/cmr): cmr and cmr-h-sweep, FFT base at 256^2, dense base at 128^2",
        (  # every part on its scene's seeds (problems/scenes/cmr.py: 20 per H)
            # Fig. 8 and the history: 4 H x 20 seeds, 10 steps, FFT base and CMR over it, 256^2
            Part(CMR_STUDY, SceneConfig(size=256)),
            # Fig. 9 and the first level: H = 0.7 x 20 seeds, the top step, 256^2
            Part(CMR_H_STUDY, SceneConfig(size=256)),
            # the paper's dense base beside the FFT base on the same 128^2 surfaces (Fig. 8 time ratio)
            Part(Study("cmr", solvers=CMR_DENSE + CMR_FAST, sweeps=CMR_SWEEPS),
                 SceneConfig(size=CMR_DENSE_SIZE)),
            # the dense base's time ratio against h (Fig. 9), 128^2
            Part(Study("cmr-h-sweep", solvers=CMR_DENSE, sweeps=CMR_H_SWEEPS),
                 SceneConfig(size=CMR_DENSE_SIZE)),
        ),
    ),
    Composite(
        "paper-claims",
        "the paper's claims ledger (results/claims): each claim under the paper's conditions (dense H, eps 1e-8, "
        "profile paper) and ours (FFT operators, the fast solvers)",
        claims_parts(),
    ),
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


def register_study(study: Study, *, replace: bool = False) -> Study:
    """Record how the harness runs ``study.scene`` (its solvers, profiles, reference and
    sweeps) -- called by the scene's own module, beside ``@register_scene`` and its
    report section, so a scene is declared in one place."""
    old = STUDIES.get(study.scene)
    if old is not None and old != study and not replace:
        raise ValueError(f"a study of scene {study.scene!r} is already registered")
    STUDIES[study.scene] = study
    return study


def study_for(name: str) -> Study:
    """The study of scene ``name`` (``Study(name)`` for a scene with no record).  The
    scenes are discovered first: a scene module registers its study when imported."""
    all_scenes()
    if name in STUDIES:
        return STUDIES[name]
    get_scene(name)
    return Study(name)


def expand(name: str, cfg: SceneConfig | None) -> list[tuple[Study, SceneConfig]]:
    """(study, options) pairs a scene name stands for: one, or a composite's parts."""
    if name in COMPOSITES:
        return COMPOSITES[name].expand(cfg)
    if name not in all_scenes():
        raise KeyError(f"unknown scene {name!r}{did_you_mean(name, catalogue())}; "
                       f"known scenes: {', '.join(sorted(catalogue()))}")
    return [(study_for(name), cfg or SceneConfig())]


def catalogue() -> dict[str, str]:
    """Every runnable name (scenes and composites) with its description, sorted."""
    names = {name: scene.description for name, scene in all_scenes().items()}
    names.update({name: c.description for name, c in COMPOSITES.items()})
    return dict(sorted(names.items()))
