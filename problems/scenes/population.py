"""The ``population`` scene: Monte Carlo populations of seeded RMD surfaces.

The paper (Bemporad & Paggi 2015, section 6) notes that earlier rough-contact studies
were limited to populations of 20 to 50 random surfaces and that faster solvers make
large Monte Carlo studies possible.  This scene generates N_s seeded random-midpoint-
displacement surfaces (paper section 5 generator) per (H, N) and loads each at a few
small loads, so that load, real contact area and solve time can be studied across the
population (harness/report/sections/population.py computes the statistics and the
kappa = A E* h'_rms / P estimate of Hyun & Robbins).

Loads.  A rigid flat is pressed onto the periodic surface until its plane lies
``d * h_rms`` above the mean plane of the surface, i.e. the far-field displacement of
step k is ``Delta_k = (z_max - z_mean) - d_k h_rms`` with separations d_k decreasing
(a load history, so solvers with warm starts start from the previous step).  Measuring
the separation in units of the rms height makes the contact fraction comparable across
seeds (z_max - z_mean itself varies from ~2.5 to ~4.5 h_rms between 64^2 RMD seeds);
d = 2.0, 1.5, 1.0 give A/A0 of roughly 0.5 %, 2 % and 5 %: the small-load regime
where A grows linearly with P.

Defaults: H in (0.5, 0.7, 0.9), N = 64 (periodic RMD, N = 2^k), N_s = 20 seeds,
BCC kernel with periodic images (mean removed), L = 100 um, h_rms = 1 um, E* = 1 GPa.
``cfg.size``, ``cfg.seeds``, ``cfg.steps`` (evenly spaced separations between the first
and last default), ``cfg.extra["hursts"]`` and ``cfg.extra["separations"]`` override.
Every instance is rebuilt from its seed wherever it runs (a Dask worker included).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ProblemInputError
from ..errors import check_hurst
from ..surfaces import Surface
from . import register_scene
from .base import InstanceSpec, LoadSequence, SceneConfig, seeds_of
from .core import (PAPER_E, RampScene, departure_suffix, grid_suffix, ramp_sequence, recipe_rms_height,
                   surface_from_params)

DEFAULT_HURSTS: tuple[float, ...] = (0.5, 0.7, 0.9)
#: Flat-to-mean-plane separations, in units of the rms height (small loads first).
DEFAULT_SEPARATIONS: tuple[float, ...] = (2.0, 1.5, 1.0)
DEFAULT_POPULATION = 20


def separations_for(cfg: SceneConfig) -> tuple[float, ...]:
    """The separations d_k (units of h_rms), one per load step, decreasing."""
    seps = tuple(float(d) for d in cfg.extra.get("separations", DEFAULT_SEPARATIONS))
    if not seps or any(not np.isfinite(d) or d < 0 for d in seps):
        raise ProblemInputError(f"population separations must be finite and >= 0, got {seps}")
    steps = cfg.steps
    if steps is not None and int(steps) != len(seps):
        if int(steps) < 1:
            raise ProblemInputError(f"number of load steps must be >= 1, got {steps}")
        hi, lo = max(seps), min(seps)
        seps = tuple(float(d) for d in np.linspace(hi, lo, int(steps))) if steps > 1 else (hi,)
    return seps


def population_displacements(surface: Surface, separations: tuple[float, ...] | list[float]) -> np.ndarray:
    """Delta_k = (z_max - z_mean) - d_k h_rms: the flat d_k rms heights above the mean
    plane.  A separation the surface's highest summit does not reach is an error."""
    span = surface.z_max - surface.z_mean
    deltas = np.array([span - float(d) * surface.rms_height for d in separations])
    if np.any(deltas <= 0.0):
        bad = [d for d, D in zip(separations, deltas) if D <= 0.0]
        raise ProblemInputError(
            f"separation(s) {bad} x h_rms lie above the highest point of {surface.name} "
            f"(z_max - z_mean = {span / surface.rms_height:.3g} h_rms): no contact; use smaller separations"
        )
    return deltas


def instance_name(hurst: float, size: int, seed: int, cfg: SceneConfig, own: SceneConfig) -> str:
    """"pop-H<H>-N<N>-s<seed>", with the kernel and boundary (``grid_suffix``), the lateral
    size, the modulus and the step count (``departure_suffix``) where ``cfg`` departs from
    the scene's own ``own``: another problem is another instance."""
    grid = (cfg.kernel, bool(cfg.periodic)) != (own.kernel, bool(own.periodic))
    return (f"pop-H{hurst:g}-N{size}-s{seed}{grid_suffix(str(cfg.kernel), bool(cfg.periodic)) if grid else ''}"
            f"{departure_suffix(cfg, own)}")


@register_scene
class Population(RampScene):
    """N_s seeded RMD surfaces per (H, N), each at a few small loads (Monte Carlo)."""

    name = "population"
    description = "Monte Carlo: N_s=20 seeded RMD surfaces per H in (0.5,0.7,0.9), 64^2, 3 small loads (kappa)"
    defaults = SceneConfig(
        size=64,
        steps=len(DEFAULT_SEPARATIONS),
        seeds=tuple(range(DEFAULT_POPULATION)),
        length=100e-6,
        E=PAPER_E,
        kernel="bcc",
        periodic=True,
        operator="fft",
        extra={"hursts": DEFAULT_HURSTS, "separations": DEFAULT_SEPARATIONS},
    )
    # periodic RMD surfaces of the size's own family; no surface file
    options = frozenset({"size", "seeds", "steps", "length", "E", "kernel", "periodic", "operator"})
    load_history = True

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        hursts = tuple(check_hurst(h) for h in cfg.extra.get("hursts", DEFAULT_HURSTS))
        seps = separations_for(cfg)
        size = int(cfg.size)
        if size & (size - 1):
            raise ProblemInputError(f"the population scene uses periodic RMD surfaces: N must be 2^k, got {size}")
        base: dict[str, Any] = {
            "size": size,
            "length": cfg.length,
            "E": cfg.E,
            "kernel": cfg.kernel,
            "periodic": bool(cfg.periodic),
            "operator": cfg.operator,
            "rms_height": recipe_rms_height({"rms_height": cfg.extra.get("rms_height"), "length": cfg.length}),
            "separations": list(seps),
            "steps": len(seps),
        }
        return [
            InstanceSpec(self.name, instance_name(h, size, s, cfg, self.defaults), {**base, "hurst": h, "seed": int(s)})
            for h in hursts
            for s in seeds_of(cfg, tuple(range(DEFAULT_POPULATION)))
        ]

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        surface = population_surface(spec)
        return surface, population_displacements(surface, spec.params["separations"])

    def build(self, spec: InstanceSpec) -> LoadSequence:
        surface, deltas = self.loads(spec)
        seq = ramp_sequence(spec, surface, deltas)
        seq.meta.update(hurst=float(spec.params["hurst"]), seed=int(spec.params["seed"]),
                        rms_slope=surface.rms_slope(), separations=list(spec.params["separations"]))
        return seq


def population_surface(spec: InstanceSpec) -> Surface:
    """The surface of one population recipe, rebuilt from its seed (also used by the
    analysis to recover h'_rms, which the tidy table does not carry)."""
    return surface_from_params(spec.params)
