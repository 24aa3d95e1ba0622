"""The plausible slope range of a measured map (problems/units.py): a map too smooth
(rms slope below MIN_RMS_SLOPE: a height unit or a side length off by 1e3 or 1e6) is
refused before anything runs, as a map too steep is, in one line naming the height unit or
the length probably meant; ``--allow-steep`` runs either."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.harness.run.plan import PlanError, plan_run
from contactbench.problems.scenes import SceneConfig
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.problems.units import MAX_RMS_SLOPE, MIN_RMS_SLOPE, UnitFigures, probable_unit

SIDE = 1e-4  # metres: the map's own side


def metre_map(path: Path) -> Path:
    """An RMD surface (rms 1 um on a 100 um side, rms slope ~0.3) saved in metres."""
    np.save(path, rmd_surface_n(33, 0.7, length=SIDE, rms_height=1e-6, seed=3).heights)
    return path


def test_a_side_length_off_by_a_million_is_refused_as_too_smooth_naming_the_length(tmp_path: Path) -> None:
    surface = metre_map(tmp_path / "m.npy")
    cfg = SceneConfig(surface_path=str(surface), length=SIDE * 1e6, steps=1)
    with pytest.raises(PlanError, match=rf"rms slope .* \(below {MIN_RMS_SLOPE:g}.*check --length"):
        plan_run(["paper-sweep"], cfg, ["fast-dual-pccg"])
    allowed = SceneConfig(surface_path=str(surface), length=SIDE * 1e6, steps=1, extra={"allow_steep": True})
    assert len(plan_run(["paper-sweep"], allowed, ["fast-dual-pccg"]).jobs) == 1


def test_metres_read_as_micrometres_are_refused_naming_the_metre(tmp_path: Path) -> None:
    surface = metre_map(tmp_path / "m.npy")
    cfg = SceneConfig(surface_path=str(surface), length=SIDE, steps=1, extra={"height_unit": "um"})
    with pytest.raises(PlanError, match="heights look like metres given as micrometres; pass --height-unit m"):
        plan_run(["paper-sweep"], cfg, ["fast-dual-pccg"])


def test_the_probable_unit_of_a_smooth_map_is_the_largest_that_makes_it_plausible() -> None:
    assert UnitFigures(MIN_RMS_SLOPE, 0.0, 1.0).plausible and UnitFigures(MAX_RMS_SLOPE, 0.0, 1.0).plausible
    assert not UnitFigures(MIN_RMS_SLOPE / 2, 0.0, 1.0).plausible
    assert probable_unit(UnitFigures(1.3e-7, 1e-11, 1e-4), "um") == "m"  # m as um
    assert probable_unit(UnitFigures(5e-6, 1e-11, 1e-4), "mm") == "m"  # m as mm
    assert probable_unit(UnitFigures(2e-7, 1e-12, 1e-4), "nm") == "mm"  # um would do too (2e-4): mm is larger
    assert probable_unit(UnitFigures(1e-9, 1e-13, 1e-4), "m") is None  # no unit helps: the length is wrong
