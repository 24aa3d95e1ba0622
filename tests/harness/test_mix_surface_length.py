"""In the ``default`` mix a ``--surface`` and its ``--length`` (the map's size) go to the
scenes that read a surface file only: the Hertz scene keeps its own 2 mm domain rather than
taking the map's 0.1 mm."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactbench.harness.run.plan import plan_run
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.surfaces import rmd_surface_n


def test_the_map_s_length_does_not_resize_the_hertz_scene(tmp_path: Path) -> None:
    path = tmp_path / "m.npy"
    np.save(path, rmd_surface_n(65, 0.7, length=1e-4, rms_height=1e-6, seed=1).heights)
    plan = plan_run(["default"], SceneConfig(surface_path=str(path), length=1e-4), ["pk"])
    hertz = [j.spec for j in plan.jobs if j.spec.scene == "hertz"]
    assert hertz and all(s.params["length"] == get_scene("hertz").defaults.length for s in hertz)
    maps = [j.spec for j in plan.jobs if j.spec.params.get("surface_path")]
    assert {s.scene for s in maps} >= {"paper-sweep", "greedy-linear-solvers"}


def test_a_length_without_a_surface_still_reaches_every_part() -> None:
    plan = plan_run(["default"], SceneConfig(length=2e-3), ["pk"])
    assert all(j.spec.params.get("length") == 2e-3 for j in plan.jobs if j.spec.scene in ("hertz", "paper-sweep"))
