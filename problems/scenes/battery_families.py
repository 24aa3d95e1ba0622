"""The stress battery's recipes for the problem families beyond the square, unbounded,
displacement-controlled half-space (``stress.battery_specs`` groups):

constrained
    One rough RMD surface (16^2, BCC, non-periodic) under load control (the whole grid in
    the trial set, P / (E* A) = ``LOAD_OVER_EA``), with a hardness bound
    (``HARDNESS_OVER_PS`` x the problem's force scale p_s per element), and with both.
rectangular
    A 48 x 32 RMD map (cut from a 64^2 one) with square pixels (BCC), and the same map
    with pixels 1.5 times longer along axis 1 (Love's rectangle integral).

Each recipe's params name its ``group``, verdict ``profile`` and ``compare`` as the other
groups' do; the exact reference of a constrained recipe is the dense certified solve of
``problems.mixed_lcp``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..constraints import CONTROLS
from ..instances import ContactInstance, InstanceBuilder, paper_max_displacement
from ..surfaces import Surface, rmd_surface_n
from .base import InstanceSpec, LoadSequence

#: The load of the load-controlled recipes, P / (E* A).
LOAD_OVER_EA = 1e-3
#: The hardness of the bounded recipes: the bound per element as a multiple of p_s.
HARDNESS_OVER_PS = 0.5
#: The E* of these recipes (Pa) and the size of the constrained surface.
FAMILY_E = 1e9
CONSTRAINED_N = 16
RECT_SHAPE = (48, 32)
RECT_SOURCE_N = 64  # the RMD grid the rectangle is cut from (RMD sizes are powers of two)
#: constrained case -> (load control, hardness).
CONSTRAINED_CASES: dict[str, tuple[bool, bool]] = {
    "load": (True, False), "hardness": (False, True), "load-hardness": (True, True)}
#: rectangular case -> (kernel, pixel aspect d1 / d0).
RECTANGULAR_CASES: dict[str, tuple[str, float]] = {"bcc-square-pixels": ("bcc", 1.0), "love-aniso": ("love", 1.5)}


def _spec(scene: str, group: str, instance: str, **params: Any) -> InstanceSpec:
    return InstanceSpec(scene, f"{group}/{instance}", {"group": group, "profile": "mid", "compare": "none",
                                                       **params})


def constrained_specs(scene: str, seed: int = 0) -> list[InstanceSpec]:
    """The constrained recipes; their params tell the planner each case's control and bound
    (``control``, ``hardness_over_ps``, as the scenes' own recipes do), from ``CONSTRAINED_CASES``."""
    return [_spec(scene, "constrained", f"{case}-bcc-N{CONSTRAINED_N}", case=case, seed=seed, n=CONSTRAINED_N ** 2,
                  control=CONTROLS[int(load)], hardness_over_ps=HARDNESS_OVER_PS if bounded else None)
            for case, (load, bounded) in CONSTRAINED_CASES.items()]


def rectangular_specs(scene: str, seed: int = 0) -> list[InstanceSpec]:
    n0, n1 = RECT_SHAPE
    return [_spec(scene, "rectangular", f"{case}-{n0}x{n1}", case=case, seed=seed, n=n0 * n1)
            for case in RECTANGULAR_CASES]


def constrained_instance(case: str, seed: int) -> ContactInstance:
    load_control, bounded = CONSTRAINED_CASES[case]
    surface = rmd_surface_n(CONSTRAINED_N, 0.7, length=100e-6, rms_height=1e-6, seed=seed)
    builder = InstanceBuilder(surface, FAMILY_E, "bcc", periodic=False)
    plain = builder.build(paper_max_displacement(surface))
    hardness = None
    if bounded:  # the bound per element HARDNESS_OVER_PS x p_s, as a pressure
        hardness = HARDNESS_OVER_PS * plain.force_scale() / float(np.prod(surface.spacing))
    if load_control:
        return builder.build_load(builder.load_force(LOAD_OVER_EA), hardness=hardness)
    return builder.build(paper_max_displacement(surface), hardness=hardness)


def rectangular_instance(case: str, seed: int) -> ContactInstance:
    kernel, aspect = RECTANGULAR_CASES[case]
    n0, n1 = RECT_SHAPE
    square = rmd_surface_n(RECT_SOURCE_N, 0.7, length=100e-6, rms_height=1e-6, seed=seed)
    surface = Surface(np.array(square.heights[:n0, :n1]), square.delta,
                      delta1=None if aspect == 1.0 else aspect * square.delta, name=f"rect-{case}")
    return InstanceBuilder(surface, FAMILY_E, kernel, periodic=False).build(paper_max_displacement(surface))


def build_constrained(spec: InstanceSpec) -> LoadSequence:
    p = spec.params
    return LoadSequence(spec.instance, [float("nan")], lambda k: constrained_instance(str(p["case"]), int(p["seed"])))


def build_rectangular(spec: InstanceSpec) -> LoadSequence:
    p = spec.params
    return LoadSequence(spec.instance, [float("nan")], lambda k: rectangular_instance(str(p["case"]), int(p["seed"])))
