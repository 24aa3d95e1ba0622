"""One problem, one instance name: a measured map in ``greedy-linear-solvers`` is one recipe
(the scene's sizes are its generated surfaces'), and a scene that names two recipes alike is
refused at planning, before anything runs (the report would fold two problems' rows into one
cell's repeats)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.harness.run.plan import PlanError, plan_run
from contactbench.problems.scenes import SceneConfig, register_scene
from contactbench.problems.scenes.base import InstanceSpec, _SCENES
from contactbench.problems.scenes.core import Counterexample
from contactbench.problems.surfaces import rmd_surface_n


def test_a_measured_map_in_the_greedy_sizes_scene_is_one_instance(tmp_path: Path) -> None:
    path = tmp_path / "m.npy"
    np.save(path, rmd_surface_n(33, 0.7, length=1e-4, rms_height=1e-6, seed=1).heights)
    plan = plan_run(["greedy-linear-solvers"], SceneConfig(surface_path=str(path), length=1e-4), ["pk"])
    assert len(plan.jobs) == 1 and plan.jobs[0].spec.params["surface_path"]


def test_a_scene_naming_two_recipes_alike_is_refused_before_anything_runs() -> None:
    @register_scene
    class Twice(Counterexample):
        name = "test-twice-named"

        def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
            (one,) = super().instances(cfg)[:1]
            return [one, InstanceSpec(self.name, one.instance, {**one.params, "other": 1})]

    try:
        with pytest.raises(PlanError, match="one instance name"):
            plan_run(["test-twice-named"], SceneConfig(size=6, seeds=(0,)), ["pk"])
    finally:
        _SCENES.remove("test-twice-named")
