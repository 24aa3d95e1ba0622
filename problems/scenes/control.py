"""Scenes of the paper sweep posed as the field's codes also pose it: under load control
(``load-sweep``) and with hardness-bounded pressures (``plastic-sweep``).

* ``load-sweep``    -- the paper's surface (RMD H = 0.7, L = 100 um, BCC, non-periodic) at
  256^2 under load control: K equal load steps P / (E* A) up to ``LOAD_SWEEP_TOP``
  (``load_sweep_loads``; K = ``--steps``, default 10, or the user's ``--loads``), the
  total force given and the rigid-body approach the answer's multiplier
  (``problems.constraints``).
* ``plastic-sweep`` -- the same surface under the paper's displacement ramp with every
  element's mean pressure bounded by a hardness ``PLASTIC_HARDNESS_OVER_E`` x E*: the
  box 0 <= p_i <= H_A x element area.

Both are data only; ``--control``, ``--loads`` and ``--hardness`` pose the same problems
on every scene that takes them (the "control" records of ``options.OPTIONS``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..constraints import CONTROLS
from ..surfaces import Surface
from . import register_scene
from .base import LAYER_SCENE_OPTIONS, SCENE_OPTIONS, InstanceSpec, SceneConfig
from .core import PAPER_E, PAPER_SEED, RampScene, paper_ramp, rough_surface_specs

#: The top load step of ``load-sweep``, P / (E* A): the range the paper's displacement ramp
#: spans on this surface.
LOAD_SWEEP_TOP = 4e-3
#: The number of load steps of ``load-sweep`` unless ``--steps`` says otherwise.
LOAD_SWEEP_STEPS = 10


def load_sweep_loads(steps: int) -> tuple[float, ...]:
    """``steps`` equal load steps up to ``LOAD_SWEEP_TOP``: (k / K) x top, k = 1..K (12
    significant digits, so that the default's ten steps are 0.0004, 0.0008, ... exactly)."""
    return tuple(float(f"{LOAD_SWEEP_TOP * k / int(steps):.12g}") for k in range(1, int(steps) + 1))


#: The hardness of ``plastic-sweep`` as a multiple of E*.
PLASTIC_HARDNESS_OVER_E = 0.3  # at 256^2: 18-30 % of the contact plastic over the ramp
#: The grid of both scenes (the field's codes are compared at this size).
CONTROL_SCENE_SIZE = 256


class _PaperSurfaceScene(RampScene):
    """The paper's surface and ramp at ``CONTROL_SCENE_SIZE``; subclasses set ``defaults``."""

    options = SCENE_OPTIONS - LAYER_SCENE_OPTIONS

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        return rough_surface_specs(self, cfg, hurst=float(cfg.extra.get("hurst", 0.7)))

    def loads(self, spec: InstanceSpec) -> tuple[Surface, np.ndarray]:
        return paper_ramp(spec)


@register_scene
class LoadSweep(_PaperSurfaceScene):
    """The paper sweep under load control (module doc)."""

    name = "load-sweep"
    description = "paper surface at 256^2 under load control: P/(E* A) = 0.0004 .. 0.004 in 10 steps"
    defaults = SceneConfig(size=CONTROL_SCENE_SIZE, steps=LOAD_SWEEP_STEPS, seeds=(PAPER_SEED,),
                           length=100e-6, E=PAPER_E, kernel="bcc", periodic=False, operator="fft",
                           extra={"control": CONTROLS[1]})

    def config(self, cfg: SceneConfig | None) -> SceneConfig:
        """The merged config; under load control without the user's ``--loads``, the
        ``--steps`` (default ``LOAD_SWEEP_STEPS``) equal steps of ``load_sweep_loads``."""
        merged = super().config(cfg)
        if merged.extra.get("control") == CONTROLS[1] and merged.extra.get("loads") is None:
            merged = replace(merged, extra={**merged.extra, "loads": load_sweep_loads(int(merged.steps or 1))})
        return merged


@register_scene
class PlasticSweep(_PaperSurfaceScene):
    """The paper sweep with a hardness (module doc)."""

    name = "plastic-sweep"
    description = "paper sweep at 256^2 with every pressure bounded by a hardness of 0.3 E* (a mixed LCP)"
    defaults = SceneConfig(size=CONTROL_SCENE_SIZE, steps=10, seeds=(PAPER_SEED,), length=100e-6, E=PAPER_E,
                           kernel="bcc", periodic=False, operator="fft",
                           extra={"hardness": PLASTIC_HARDNESS_OVER_E * PAPER_E})
