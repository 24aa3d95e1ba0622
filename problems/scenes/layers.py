"""The ``layer-sweep`` scene: the paper's sweep on elastic layers of finite thickness on a
rigid base (problems/layers.py, docs/layers.md), against the half-space.

Each surface (the paper-sweep's RMD surface, or a measured ``--surface`` file) is loaded
by the paper's ramp, Delta_k = (k/K) (z_max - z_mean) / 2, once on the half-space and
once on each layer of thickness T = t L, t in ``LAYER_THICKNESSES`` (L the surface's
shorter side), bonded to its base with nu = 0.3 unless ``cfg.extra`` says otherwise
("nu", "interface", "thicknesses": the t to run).  Every layer shares the ramp of its
surface, so the loads compare at equal approach: a layer is stiffer than the half-space
(more load for the same Delta), by ~1/T when T >> L.  Defaults: 128^2 saupe RMD,
H = 0.7, L = 100 um, BCC, non-periodic, 10 steps (at 128^2, T = 0.1 L spans 12.8 elements:
the real-space kernels' layer correction needs T >= the spacing).  Pure data: which
solvers run and how it is reported is the harness's study design.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import ProblemInputError
from ..layers import DEFAULT_NU, INTERFACES
from ..surfaces import Surface
from . import register_scene
from .base import SCENE_OPTIONS, InstanceSpec, SceneConfig
from .core import PAPER_E, PAPER_SEED, RampScene, layer_suffix, paper_ramp, rough_surface_specs

#: Layer thicknesses in units of the surface's (shorter) side L.
LAYER_THICKNESSES: tuple[float, ...] = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


def thicknesses_of(cfg: SceneConfig) -> tuple[float, ...]:
    """The thicknesses t (units of L) of a run: ``cfg.extra["thicknesses"]``, each finite and > 0."""
    ts = tuple(float(t) for t in cfg.extra.get("thicknesses", LAYER_THICKNESSES))
    if not ts or any(not np.isfinite(t) or t <= 0 for t in ts):
        raise ProblemInputError(f"layer-sweep thicknesses (units of L) must be finite and > 0, got {ts}")
    return ts


@register_scene
class LayerSweep(RampScene):
    """The paper sweep on the half-space and on layers 0.1 L to 10 L thick (module doc)."""

    name = "layer-sweep"
    description = "paper sweep on elastic layers T = 0.1 L .. 10 L on a rigid base (bonded, nu 0.3) and the half-space"
    defaults = SceneConfig(size=128, steps=10, seeds=(PAPER_SEED,), length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft",
                           extra={"thicknesses": LAYER_THICKNESSES, "nu": DEFAULT_NU, "interface": INTERFACES[0]})
    options = SCENE_OPTIONS - {"thickness"}  # the sweep sets the thickness itself

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        # The sweep sets the thickness itself: a single --thickness is not read here.
        base_cfg = replace(cfg, extra={k: v for k, v in cfg.extra.items() if k != "thickness"})
        specs = []
        for spec in rough_surface_specs(self, base_cfg, hurst=float(cfg.extra.get("hurst", 0.7))):
            specs.append(spec)  # the half-space
            for t in thicknesses_of(cfg):
                params = {**spec.params, "thickness_over_L": t, "nu": float(cfg.extra.get("nu", DEFAULT_NU)),
                          "interface": str(cfg.extra.get("interface", INTERFACES[0]))}
                specs.append(InstanceSpec(self.name, spec.instance + layer_suffix(params), params))
        return specs

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        return paper_ramp(spec)
