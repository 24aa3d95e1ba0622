"""The paper's open question, as a scene: is greedy's failure on Example 1 a property of
the BCC half-space, or of greedy?  Bemporad & Paggi warn that greedy's reliability "should
be carefully checked ... for other forms of H".  ``greedy-kernels`` draws Example 1's
ubar (``instances.counterexample``: ubar ~ U(0, 1), delta = 1, E = 0.01) on each operator
of ``KERNEL_VARIANTS``:

* ``bcc``          -- the paper's (non-periodic BCC half-space);
* ``love``         -- Love's rectangle integral, non-periodic;
* ``thin-layer``   -- Love on a bonded layer ``THIN_LAYER_THICKNESS`` elements thick (nu 0.3;
  not BCC, whose self-term makes a layer that thin too stiff: ``layers.BCC_MIN_THICKNESS``);
* ``hardness``     -- BCC with every element's force bounded by ``HARDNESS_OVER_PS`` x p_s.

Periodic kernels are left out on purpose: with every element in the trial set, their
operator has no mean mode (``kernels``: q = 0 removed), so min 1/2 p'Hp - ubar'p over
p >= 0 is unbounded along p = t 1 for ubar > 0 -- no answer to judge.  Recipes carry
``variant``, ``kernel``, ``thickness`` and ``hardness_over_ps`` in their params; the table
carries the variant as a column (no name is parsed).
"""

from __future__ import annotations

from typing import Any

from ..instances import counterexample
from ..layers import Layer
from . import register_scene
from .base import InstanceSpec, LoadSequence, Scene, SceneConfig, seeds_of, validate_each

#: A thin layer: this many elements thick (the non-periodic layer kernel needs >= 1).
THIN_LAYER_THICKNESS = 2.0
#: The hardness variant's bound, as a multiple of the problem's force scale p_s.
HARDNESS_OVER_PS = 0.5
#: name -> (kernel, periodic, layer thickness or None, hardness over p_s or None).
KERNEL_VARIANTS: dict[str, tuple[str, bool, float | None, float | None]] = {
    "bcc": ("bcc", False, None, None),
    "love": ("love", False, None, None),
    "thin-layer": ("love", False, THIN_LAYER_THICKNESS, None),
    "hardness": ("bcc", False, None, HARDNESS_OVER_PS),
}


def variant_params(variant: str) -> dict[str, Any]:
    kernel, periodic, thickness, hardness = KERNEL_VARIANTS[variant]
    return {"variant": variant, "kernel": kernel, "periodic": periodic, "thickness": thickness,
            "hardness_over_ps": hardness}


@register_scene
class GreedyKernels(Scene):
    """Example 1 on each operator of ``KERNEL_VARIANTS`` (module doc)."""

    name = "greedy-kernels"
    description = "Example 1 (greedy counterexample) on BCC, Love, thin-layer (Love) and hardness operators"
    defaults = SceneConfig(seeds=tuple(range(40)), operator="dense", extra={"sizes": (25, 100, 400)})
    options = frozenset({"size", "seeds", "operator"})
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        sizes = (cfg.size * cfg.size,) if cfg.size else tuple(cfg.extra.get("sizes", (25, 100, 400)))
        return [
            InstanceSpec(self.name, f"{variant}-n{n}-s{s}",
                         {"n": int(n), "seed": int(s), "operator": cfg.operator, **variant_params(variant)})
            for variant in KERNEL_VARIANTS
            for n in sizes
            for s in seeds_of(cfg)
        ]

    def validate(self, cfg: SceneConfig) -> None:
        firsts = {(spec.params["variant"], spec.params["n"]): spec for spec in self.instances(cfg)}
        validate_each(list(firsts.values()), lambda spec: build_instance(spec.params, operator="fft"))

    def build(self, spec: InstanceSpec) -> LoadSequence:
        return LoadSequence(spec.instance, [float("nan")], lambda k: build_instance(spec.params))


def build_instance(params: dict[str, Any], operator: str | None = None):
    """The Example 1 instance of one recipe (``operator`` overrides the recipe's)."""
    thickness = params.get("thickness")
    return counterexample(int(params["n"]), int(params["seed"]), operator=operator or params.get("operator") or "dense",
                          kernel=str(params["kernel"]), periodic=bool(params["periodic"]),
                          layer=None if thickness is None else Layer(float(thickness)),
                          hardness_over_ps=params.get("hardness_over_ps"))
