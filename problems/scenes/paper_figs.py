"""Scenes for the paper's timing figures (data only; the solvers, K grid and profiles
each figure runs are the harness's study design, ``contactbench.harness.studies``).

* ``gp-k-sweep``            paper Fig. 6's problem: the Fig. 4 problem (RMD H = 0.7,
                            L = 100 um, 512^2, 10 steps), on which the study runs NNLS
                            warm-started by K gradient-projection steps for each K.
* ``greedy-linear-solvers`` paper Fig. 5's problems: RMD surfaces of several sizes, each at
                            several displacements, so the trial-set size n spans about two
                            decades.

Both use the paper's generator, RMD family "saupe" (``core.surface_family``), unless the
run asks for another.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..surfaces import Surface
from . import register_scene
from .base import InstanceSpec, SceneConfig
from .core import PAPER_E, PaperSweep, RampScene, paper_ramp, rough_surface_specs


@register_scene
class GpKSweep(PaperSweep):
    """Paper Fig. 6: the Fig. 4 problem, for the sweep over the number K of
    gradient-projection steps before NNLS (the study's K grid)."""

    name = "gp-k-sweep"
    description = "the Fig. 4 problem (RMD H=0.7, 512^2, 10 steps) for NNLS+GP over K (paper Fig. 6)"


@register_scene
class GreedyLinearSolvers(RampScene):
    """Paper Fig. 5: one RMD surface per size, each loaded in ``steps`` displacement
    steps up to the paper's (z_max - z_mean)/2, so n spans about two decades.  Steps are
    independent solves (no load history)."""

    name = "greedy-linear-solvers"
    description = "RMD surfaces 64^2-256^2 at 5 displacements each: solve time vs trial-set size n (paper Fig. 5)"
    defaults = SceneConfig(steps=5, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc", periodic=False,
                           operator="fft", extra={"sizes": (64, 128, 256)})
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        """One recipe per size and seed; a measured map (``--surface``) is one recipe, at
        its own grid (the sizes are the generated surfaces')."""
        if cfg.surface_path:
            return rough_surface_specs(self, cfg, hurst=float(cfg.extra.get("hurst", 0.7)))
        sizes = (cfg.size,) if cfg.size else tuple(int(s) for s in cfg.extra["sizes"])
        hurst = float(cfg.extra.get("hurst", 0.7))
        specs: list[InstanceSpec] = []
        for N in sizes:
            specs += rough_surface_specs(self, replace(cfg, size=int(N)), hurst=hurst)
        return specs

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        return paper_ramp(spec)
