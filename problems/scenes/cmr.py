"""Scenes of the cascade multi-resolution method (Bemporad & Paggi 2015, section 5.2).

* ``cmr``         -- Fig. 8: RMD surfaces H = 0.3, 0.5, 0.7, L = 100 um, 256^2, cascade
                     16 -> 32 -> 64 -> 128 -> 256, h = 2, 10 displacement steps up to
                     (z_max - z_mean)/2; CMR+NNLS against the direct NNLS.
* ``cmr-h-sweep`` -- Fig. 9: H = 0.7, the top step only, h from 1.25 to 3.0.
* ``cmr-cutoff``  -- the cautionary case of Figs. 10-11: a spectral surface whose PSD has
                     a roll-off plateau at low wave numbers (like the 10x scan) against a
                     pure power law (like the 100x scan); H = 0.6, cascade 64 -> 128 -> 256
                     by block averaging, h = 1.5, one step Delta = (z_max - z_mean)/5.

``warnings(cfg)`` flags every instance whose PSD is not a power law over the scales the
cascade spans (``problems.io.power_law_check``); the CMR solver repeats the check and
puts the warning in its result.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..io import power_law_check
from ..surfaces import Surface, spectral_surface
from . import register_scene
from .base import InstanceSpec, LoadSequence, Scene, SceneConfig, SolverVariant, seeds_of
from .core import PAPER_E, ramp_sequence, rough_surface_specs, surface_from_params

#: h values of the paper's Fig. 9.
H_SWEEP: tuple[float, ...] = (1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0)


def cmr_variants(solvers: list[str], hs: tuple[float, ...], extra: dict[str, Any]) -> list[SolverVariant]:
    """Each non-CMR solver once; each ``cmr+*`` solver once per h (labelled by h when
    there are several)."""
    out: list[SolverVariant] = []
    common = {k: extra[k] for k in ("coarsest", "levels") if extra.get(k) is not None}
    for s in solvers:
        if not s.startswith("cmr+"):
            out.append(SolverVariant(s))
            continue
        for h in hs:
            label = s if len(hs) == 1 else f"{s} h={h:g}"
            out.append(SolverVariant(s, {"h": float(h), **common}, label))
    return out


def psd_warnings(scene: Scene, cfg: SceneConfig, surface_of: Any) -> list[str]:
    """One line per instance whose PSD is not a power law over the cascade's range."""
    out = []
    for spec in scene.instances(cfg):
        check = power_law_check(surface_of(spec.params))
        if not check.power_law:
            out.append(f"{scene.name}/{spec.instance}: CMR asked for, but the {check.message}")
    return out


def top_steps(surface: Surface, steps: int, fraction: float) -> np.ndarray:
    """Delta_k = (k/K) * fraction * (z_max - z_mean)."""
    from ..instances import load_ramp

    return load_ramp(fraction * (surface.z_max - surface.z_mean), steps)


class _RMDCascadeScene(Scene):
    """Shared recipe/build of the RMD scenes (surfaces with their own coarse levels)."""

    hursts: tuple[float, ...] = (0.7,)
    max_fraction = 0.5  # Delta_max = max_fraction * (z_max - z_mean), the paper's top step

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        hursts = tuple(cfg.extra.get("hursts", self.hursts))
        if cfg.surface_path:
            hursts = hursts[:1]
        return [spec for H in hursts for spec in rough_surface_specs(self.name, cfg, float(H))]

    def build(self, spec: InstanceSpec) -> LoadSequence:
        surface = surface_from_params(spec.params)
        return ramp_sequence(spec, surface, top_steps(surface, int(spec.params["steps"]), self.max_fraction))

    def warnings(self, cfg: SceneConfig) -> list[str]:
        return psd_warnings(self, self.config(cfg), surface_from_params)


@register_scene
class CMRScene(_RMDCascadeScene):
    """Paper Fig. 8: CMR+NNLS (h = 2) vs direct NNLS on RMD H = 0.3, 0.5, 0.7."""

    name = "cmr"
    description = "CMR (paper Fig. 8): RMD H=0.3,0.5,0.7, 256^2, cascade 16->256, h=2, vs direct NNLS"
    defaults = SceneConfig(size=256, steps=10, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft",
                           extra={"hursts": (0.3, 0.5, 0.7), "h": (2.0,), "coarsest": 16})
    default_solvers = ("nnls", "cmr+nnls")
    hursts = (0.3, 0.5, 0.7)

    def variants(self, cfg: SceneConfig, solvers: list[str]) -> list[SolverVariant]:
        cfg = self.config(cfg)
        return cmr_variants(solvers, _as_tuple(cfg.extra.get("h", (2.0,))), cfg.extra)


@register_scene
class CMRHSweep(_RMDCascadeScene):
    """Paper Fig. 9: H = 0.7, the top displacement step, h = 1.25 .. 3.0."""

    name = "cmr-h-sweep"
    description = "CMR h sweep (paper Fig. 9): RMD H=0.7, 256^2, top step, h=1.25..3.0, vs direct NNLS"
    defaults = SceneConfig(size=256, steps=1, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft",
                           extra={"hursts": (0.7,), "h": H_SWEEP, "coarsest": 16})
    default_solvers = ("nnls", "cmr+nnls")
    load_history = False

    def variants(self, cfg: SceneConfig, solvers: list[str]) -> list[SolverVariant]:
        cfg = self.config(cfg)
        return cmr_variants(solvers, _as_tuple(cfg.extra.get("h", H_SWEEP)), cfg.extra)


@register_scene
class CMRCutoff(Scene):
    """Paper section 5.2, Figs. 10-11: PSD roll-off plateau (CMR fails) vs pure power law
    (CMR works); spectral surfaces, H = 0.6, cascade 64 -> 128 -> 256, h = 1.5."""

    name = "cmr-cutoff"
    description = "CMR on a PSD with a roll-off plateau (fails) vs a pure power law (works), h=1.5"
    defaults = SceneConfig(size=256, steps=1, seeds=(0,), length=100e-6, E=PAPER_E, kernel="bcc",
                           periodic=False, operator="fft",
                           extra={"hurst": 0.6, "rolloff_fraction": 1 / 32, "h": (1.5,), "coarsest": 64,
                                  "max_fraction": 0.2})
    default_solvers = ("nnls", "cmr+nnls")
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        base = {"size": cfg.size, "length": cfg.length, "E": cfg.E, "kernel": cfg.kernel,
                "periodic": bool(cfg.periodic), "operator": cfg.operator, "steps": cfg.steps,
                "hurst": float(cfg.extra["hurst"]), "max_fraction": float(cfg.extra["max_fraction"])}
        if cfg.surface_path:
            name = str(cfg.surface_path).replace("/", "_")
            return [InstanceSpec(self.name, f"file-{name}", {**base, "surface_path": cfg.surface_path, "seed": 0})]
        kinds = {"rolloff": float(cfg.extra["rolloff_fraction"]), "power-law": None}
        return [InstanceSpec(self.name, f"{kind}-H{base['hurst']:g}-N{cfg.size}-s{s}",
                             {**base, "surface": kind, "rolloff_fraction": frac, "seed": int(s)})
                for kind, frac in kinds.items() for s in seeds_of(cfg)]

    def build(self, spec: InstanceSpec) -> LoadSequence:
        surface = cutoff_surface(spec.params)
        deltas = top_steps(surface, int(spec.params["steps"]), float(spec.params["max_fraction"]))
        return ramp_sequence(spec, surface, deltas)

    def variants(self, cfg: SceneConfig, solvers: list[str]) -> list[SolverVariant]:
        cfg = self.config(cfg)
        return cmr_variants(solvers, _as_tuple(cfg.extra.get("h", (1.5,))), cfg.extra)

    def warnings(self, cfg: SceneConfig) -> list[str]:
        return psd_warnings(self, self.config(cfg), cutoff_surface)


def cutoff_surface(params: dict[str, Any]) -> Surface:
    """The spectral surface of a cmr-cutoff recipe (or the measured file it names)."""
    if params.get("surface_path"):
        return surface_from_params(params)
    L = float(params["length"])
    frac = params.get("rolloff_fraction")
    return spectral_surface(int(params["size"]), float(params["hurst"]), length=L, seed=int(params["seed"]),
                            rolloff_wavelength=None if frac is None else float(frac) * L)


def _as_tuple(v: Any) -> tuple[float, ...]:
    return tuple(float(x) for x in v) if isinstance(v, (list, tuple)) else (float(v),)
