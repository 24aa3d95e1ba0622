"""Scenes for the paper's timing figures, and ``default`` (what ``make bench`` runs).

* ``gp-k-sweep``            paper Fig. 6: NNLS warm-started by K accelerated gradient-projection
                            steps (Algorithm 4 then Algorithm 3), K = 0, 10, 25, 50, 100, 150, 200,
                            on the Fig. 4 problem (RMD H = 0.7, L = 100 um, 512^2, 10 steps).
* ``greedy-linear-solvers`` paper Fig. 5: the greedy method (Algorithm 1) with CG, Gauss-Seidel
                            and Cholesky inner solves against the trial-set size n, over RMD
                            surfaces of several sizes and displacements.
* ``default``               a mix of small instances of the paper scenes that runs in a few
                            minutes on 2 cores and gives the report every figure type.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any

from . import get_scene, register_scene
from .base import InstanceSpec, LoadSequence, Scene, SceneConfig, SolverVariant
from .core import PAPER_E, PaperSweep, rough_surface_specs

#: Paper Fig. 6: the numbers K of gradient-projection steps before NNLS.
GP_K_VALUES: tuple[int, ...] = (0, 10, 25, 50, 100, 150, 200)


@register_scene
class GpKSweep(PaperSweep):
    """Paper Fig. 6: total NNLS+GP time over the 10-step sweep against K.  The solver
    ``nnls-gp`` is run once per K (labels ``nnls-gp[K=..]``); other solvers given with
    --solvers run once, unlabelled."""

    name = "gp-k-sweep"
    description = "NNLS+GP with K = 0..200 GP steps on the Fig. 4 problem (paper Fig. 6)"
    default_solvers = ("nnls-gp",)
    defaults = replace(PaperSweep.defaults, extra={"K": GP_K_VALUES})

    def variants(self, cfg: SceneConfig, solvers: list[str]) -> list[SolverVariant]:
        ks = tuple(int(k) for k in cfg.extra.get("K", GP_K_VALUES))
        out: list[SolverVariant] = []
        for s in solvers:
            if s == "nnls-gp":
                out += [SolverVariant("nnls-gp", {"K": k}, f"nnls-gp[K={k}]") for k in ks]
            else:
                out.append(SolverVariant(s))
        return out


@register_scene
class GreedyLinearSolvers(Scene):
    """Paper Fig. 5: greedy with CG, Gauss-Seidel and Cholesky (``mldivide``) inner
    solves against the trial-set size n.  Each RMD surface (one per size) is loaded in
    ``steps`` displacement steps up to the paper's (z_max - z_mean)/2, so n spans about
    two decades.  Steps are independent solves (greedy has no warm start)."""

    name = "greedy-linear-solvers"
    description = "greedy-CG vs Gauss-Seidel vs Cholesky against trial-set size n (paper Fig. 5)"
    defaults = SceneConfig(steps=5, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc", periodic=False,
                           operator="fft", extra={"sizes": (64, 128, 256)})
    default_solvers = ("greedy-cg", "greedy-gs", "greedy-chol")
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        sizes = (cfg.size,) if cfg.size else tuple(int(s) for s in cfg.extra["sizes"])
        hurst = float(cfg.extra.get("hurst", 0.7))
        specs: list[InstanceSpec] = []
        for N in sizes:
            specs += rough_surface_specs(self.name, replace(cfg, size=int(N)), hurst=hurst)
        return specs

    def build(self, spec: InstanceSpec) -> LoadSequence:
        return get_scene("paper-sweep").build(spec)


#: (scene, options, default solvers or None for every available one, profiles)
DefaultPart = tuple[str, SceneConfig, tuple[str, ...] | None, tuple[str, ...]]

PAPER_SOLVERS: tuple[str, ...] = ("greedy-cg", "greedy-gs", "greedy-chol", "pk", "nnls", "gp", "nnls-gp", "admm",
                                  "scipy-nnls")


@register_scene
class Default(Scene):
    """What ``make bench`` runs: small instances of every paper scene, so the report
    has every figure type, in a few minutes on 2 cores.

    * paper-sweep at 64^2, 3 steps, every available solver at profiles low and high
      (Fig. 4 and work-precision);
    * the counterexample at n = 100 on seeds 0-9 with the paper's solvers;
    * hertz at 16^2-64^2 (convergence to the closed form);
    * gp-k-sweep at 64^2, 3 steps (Fig. 6);
    * greedy-linear-solvers at 32^2 and 64^2, 4 steps (Fig. 5).

    Options given on the command line (--size, --steps, ...) override every part.
    Rows carry the part's own scene name."""

    name = "default"
    description = "make bench: small paper-sweep, counterexample, hertz, gp-k-sweep, greedy-linear-solvers"
    load_history = False

    def parts(self, cfg: SceneConfig | None = None) -> list[DefaultPart]:
        parts: list[DefaultPart] = [
            ("paper-sweep", SceneConfig(size=64, steps=3, seeds=(0,)), None, ("low", "high")),
            ("counterexample", SceneConfig(seeds=tuple(range(10)), extra={"sizes": (100,)}), PAPER_SOLVERS,
             ("default",)),
            ("hertz", SceneConfig(extra={"sizes": (16, 32, 64)}), ("nnls", "pk", "scipy-nnls", "fast-ccg"),
             ("default",)),
            ("gp-k-sweep", SceneConfig(size=64, steps=3, seeds=(0,)), ("nnls-gp",), ("default",)),
            ("greedy-linear-solvers", SceneConfig(steps=4, seeds=(0,), extra={"sizes": (32, 64)}),
             ("greedy-cg", "greedy-gs", "greedy-chol"), ("default",)),
        ]
        return [(name, override(part_cfg, cfg), solvers, profiles) for name, part_cfg, solvers, profiles in parts]

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        specs: list[InstanceSpec] = []
        for name, part_cfg, _, _ in self.parts(cfg):
            scene = get_scene(name)
            specs += scene.instances(scene.config(part_cfg))
        return specs

    def build(self, spec: InstanceSpec) -> LoadSequence:
        return get_scene(spec.scene).build(spec)


def override(base: SceneConfig, user: SceneConfig | None) -> SceneConfig:
    """``base`` with every field the user set (not None) replaced by the user's value."""
    if user is None:
        return base
    kw: dict[str, Any] = {f.name: getattr(user, f.name) for f in fields(SceneConfig)
                          if f.name != "extra" and getattr(user, f.name) is not None}
    return replace(base, extra={**base.extra, **user.extra}, **kw)
