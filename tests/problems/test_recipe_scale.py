"""A generated rough surface's rms height is ``scenes.core.RECIPE_RMS_SHARE`` of its side, so
``--length L`` poses the recipe's surface at another scale: the same slopes, contact share and
P/(E* A) -- not the same heights on another side (at L = 1 nm, 1 um heights made slopes of
4e4 and P/(E* A) = 300, with no refusal)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.scenes.core import PAPER_LENGTH, RECIPE_RMS_SHARE, recipe_rms_height

SCALE = 1e-5


def first_surface(scene_name: str, length: float | None):
    scene = get_scene(scene_name)
    cfg = scene.config(SceneConfig(size=32, steps=2, seeds=(0,)))
    if length is not None:
        cfg = dataclasses.replace(cfg, length=length)
    spec = scene.instances(cfg)[0]
    return scene.loads(spec)


@pytest.mark.parametrize("scene_name", ["paper-sweep", "cmr-cutoff", "cmr-h-sweep", "population"])
def test_another_length_scales_the_whole_surface(scene_name: str) -> None:
    base, base_steps = first_surface(scene_name, None)
    small, small_steps = first_surface(scene_name, base.lengths[0] * SCALE)
    assert small.rms_height == pytest.approx(base.rms_height * SCALE, rel=1e-9)
    assert small.rms_slope() == pytest.approx(base.rms_slope(), rel=1e-9)
    np.testing.assert_allclose(small.heights, base.heights * SCALE, rtol=1e-9, atol=1e-12 * SCALE * base.rms_height)
    np.testing.assert_allclose(small_steps, np.asarray(base_steps) * SCALE, rtol=1e-9)


def test_the_recipe_height_is_its_share_of_the_side_unless_named() -> None:
    assert recipe_rms_height({}) == pytest.approx(RECIPE_RMS_SHARE * PAPER_LENGTH)
    assert recipe_rms_height({"length": 2e-3}) == pytest.approx(RECIPE_RMS_SHARE * 2e-3)
    assert recipe_rms_height({"length": 2e-3, "rms_height": 5e-9}) == 5e-9
