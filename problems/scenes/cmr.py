"""Scenes of the cascade multi-resolution method (Bemporad & Paggi 2015, section 5.2):
data only (the CMR variants, h values and cascade depth are the harness's study design,
``contactbench.harness.studies``).

* ``cmr``         -- Fig. 8: RMD surfaces H = 0.3, 0.5, 0.7, 0.9, L = 100 um, 256^2, 10
                     displacement steps up to (z_max - z_mean)/2, seeds 0-19 (a
                     distribution per H; the surfaces keep their RMD coarse stages
                     16 -> 32 -> ... -> 256, exact sub-samples).
* ``cmr-h-sweep`` -- Fig. 9: H = 0.7, the top step only, seeds 0-19.
* ``cmr-cutoff``  -- the cautionary case of Figs. 10-11: a spectral surface whose PSD has
                     a roll-off plateau at low wave numbers (like the 10x scan) against a
                     pure power law (like the 100x scan); H = 0.6, 256^2, one step
                     Delta = (z_max - z_mean)/5.

``cmr`` and ``cmr-h-sweep`` default to the paper's generator, Saupe's non-periodic
MidPointFM2D (RMD family "saupe"; ``--surface-family periodic`` gives the wrap-around one,
``core.surface_family``).

``warnings(cfg)`` flags every instance whose PSD is not a power law over the scales a
cascade spans (``problems.coarsen.power_law_check``); the CMR solver repeats the check and
puts the warning in its result.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..coarsen import power_law_check
from ..errors import ProblemInputError
from ..surfaces import Surface, spectral_surface
from . import register_scene
from .base import CONTROL_SCENE_OPTIONS, LAYER_SCENE_OPTIONS, SCENE_OPTIONS, InstanceSpec, Scene, SceneConfig, seeds_of
from .core import (PAPER_E, RampScene, check_relief, departure_suffix, grid_suffix, modulus_suffix, recipe_rms_height,
                   rough_surface_specs, square_length, steps_suffix, surface_from_params)


def psd_warnings(scene: Scene, cfg: SceneConfig, surface_of: Any) -> list[str]:
    """One line per instance whose PSD is not a power law over the cascade's range, or
    whose grid is too small to tell (a warning: the solve itself is well posed)."""
    out = []
    for spec in scene.instances(cfg):
        try:
            check = power_law_check(surface_of(spec.params))
        except ProblemInputError as exc:
            out.append(f"{scene.name}/{spec.instance}: a multi-resolution method may be unreliable here: {exc}")
            continue
        if not check.power_law:
            out.append(f"{scene.name}/{spec.instance}: a multi-resolution method is unreliable here: the {check.message}")
    return out


def top_steps(surface: Surface, steps: int, fraction: float) -> np.ndarray:
    """Delta_k = (k/K) * fraction * (z_max - z_mean)."""
    from ..instances import load_ramp

    return load_ramp(fraction * (surface.z_max - surface.z_mean), steps)


#: Hurst exponents of Fig. 8, and the seeds of both CMR scenes (>= 20 per H).
CMR_HURSTS: tuple[float, ...] = (0.3, 0.5, 0.7, 0.9)
CMR_SEEDS: tuple[int, ...] = tuple(range(20))


class _RMDCascadeScene(RampScene):
    """Shared recipe/loads of the RMD scenes (surfaces with their own coarse levels)."""

    hursts: tuple[float, ...] = (0.7,)
    options = SCENE_OPTIONS - LAYER_SCENE_OPTIONS - CONTROL_SCENE_OPTIONS  # CMR poses the plain half-space
    max_fraction = 0.5  # Delta_max = max_fraction * (z_max - z_mean), the paper's top step

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        hursts = tuple(cfg.extra.get("hursts", self.hursts))
        if cfg.surface_path:
            hursts = hursts[:1]
        return [spec for H in hursts for spec in rough_surface_specs(self, cfg, float(H))]

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        surface = check_relief(surface_from_params(spec.params))
        return surface, top_steps(surface, int(spec.params["steps"]), self.max_fraction)

    def warnings(self, cfg: SceneConfig) -> list[str]:
        return psd_warnings(self, self.config(cfg), surface_from_params)


@register_scene
class CMRScene(_RMDCascadeScene):
    """Paper Fig. 8: RMD H = 0.3, 0.5, 0.7, 0.9, 256^2, 10 steps up to (z_max - z_mean)/2,
    seeds 0-19."""

    name = "cmr"
    description = ("CMR problems (paper Fig. 8): RMD (saupe) H=0.3,0.5,0.7,0.9, 256^2, 10 steps up to "
                   "(zmax-zmean)/2, seeds 0-19")
    defaults = SceneConfig(size=256, steps=10, seeds=CMR_SEEDS, length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft", extra={"hursts": CMR_HURSTS})
    hursts = CMR_HURSTS


@register_scene
class CMRHSweep(_RMDCascadeScene):
    """Paper Fig. 9: H = 0.7, the top displacement step (for the sweep over h), seeds 0-19."""

    name = "cmr-h-sweep"
    description = "CMR h-sweep problem (paper Fig. 9): RMD (saupe) H=0.7, 256^2, the top step, seeds 0-19"
    defaults = SceneConfig(size=256, steps=1, seeds=CMR_SEEDS, length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft", extra={"hursts": (0.7,)})
    load_history = False


#: The two spectral surfaces of ``cmr-cutoff`` (their ``params["family"]``, the table's
#: ``surface_family``): C(q) with a roll-off plateau, and a pure power law.
ROLLOFF_FAMILY = "rolloff"
POWER_LAW_FAMILY = "power-law"


@register_scene
class CMRCutoff(RampScene):
    """Paper section 5.2, Figs. 10-11: a spectral surface with a PSD roll-off plateau
    (where CMR fails) and one with a pure power law (where it works); H = 0.6."""

    name = "cmr-cutoff"
    description = "PSD with a roll-off plateau vs a pure power law, H=0.6, 256^2 (paper Figs. 10-11)"
    defaults = SceneConfig(size=256, steps=1, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft",
                           extra={"hurst": 0.6, "rolloff_fraction": 1 / 32, "max_fraction": 0.2})
    # spectral surfaces (no RMD family); a surface file is read in metres, its first channel
    options = SCENE_OPTIONS - {"family", "channel", "height_unit"} - LAYER_SCENE_OPTIONS - CONTROL_SCENE_OPTIONS
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        base = {"size": cfg.size, "length": cfg.length, "E": cfg.E, "kernel": cfg.kernel,
                "periodic": bool(cfg.periodic), "operator": cfg.operator, "steps": cfg.steps,
                "hurst": float(cfg.extra["hurst"]), "max_fraction": float(cfg.extra["max_fraction"])}
        if cfg.surface_path:
            params = {**base, "surface_path": cfg.surface_path, "seed": 0}
            record = surface_from_params(params).preprocessing  # names the map by its base name and content
            name = (f"{record.instance_name}{grid_suffix(str(cfg.kernel), bool(cfg.periodic))}{modulus_suffix(cfg.E)}"
                    f"{steps_suffix(cfg.steps, self.defaults.steps)}")
            return [InstanceSpec(self.name, name,
                                 {**params, "surface_path": record.path, "surface_sha256": record.raw_sha256})]
        square_length(cfg.length)  # (a pair L0,L1 is for a surface file)
        kinds = {ROLLOFF_FAMILY: float(cfg.extra["rolloff_fraction"]), POWER_LAW_FAMILY: None}
        return [InstanceSpec(self.name, f"{kind}-H{base['hurst']:g}-N{cfg.size}-s{s}{departure_suffix(cfg, self.defaults)}",
                             {**base, "family": kind, "rolloff_fraction": frac, "seed": int(s)})
                for kind, frac in kinds.items() for s in seeds_of(cfg)]

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        surface = check_relief(cutoff_surface(spec.params))
        return surface, top_steps(surface, int(spec.params["steps"]), float(spec.params["max_fraction"]))

    def warnings(self, cfg: SceneConfig) -> list[str]:
        return psd_warnings(self, self.config(cfg), cutoff_surface)


def cutoff_surface(params: dict[str, Any]) -> Surface:
    """The spectral surface of a cmr-cutoff recipe (or the measured file it names)."""
    if params.get("surface_path"):
        return surface_from_params(params)
    L = square_length(params["length"])
    frac = params.get("rolloff_fraction")
    return spectral_surface(int(params["size"]), float(params["hurst"]), length=L, seed=int(params["seed"]),
                            rms_height=recipe_rms_height(params),
                            rolloff_wavelength=None if frac is None else float(frac) * L)

