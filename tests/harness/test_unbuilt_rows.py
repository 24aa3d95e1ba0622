"""A step whose build fails (here: past its build limit) still gets one row per cell, and
each row says what the recipe tells of the step -- N, kernel, E, periodic -- as the rows of
the same recipe built say it (``rows.recipe_columns``); n, the built problem's, stays empty."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from contactbench.harness import run_benchmark
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.run.rows import recipe_columns
from contactbench.problems.scenes import SceneConfig

RUN = RunConfig(reference="none", warmup=False, progress=False)
RECIPE_COLUMNS = ["N", "kernel", "E", "periodic"]


def table(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "results.parquet")


@pytest.mark.parametrize("scene, cfg", [
    ("paper-sweep", SceneConfig(size=16, steps=2, seeds=(0,), periodic=True, kernel="love")),
    ("hertz", SceneConfig(size=16, steps=1, E=2.0e9)),
])
def test_unbuilt_rows_carry_the_recipe_s_columns(tmp_path: Path, scene: str, cfg: SceneConfig) -> None:
    run_benchmark([scene], cfg, ["nnls"], RUN, tmp_path / "built")
    run_benchmark([scene], cfg, ["nnls"], RunConfig(reference="none", warmup=False, progress=False,
                                                    build_timeout=1e-6), tmp_path / "unbuilt")
    built, unbuilt = table(tmp_path / "built"), table(tmp_path / "unbuilt")
    assert (built["status"] == "solved").all() and (unbuilt["status"] == "failed").all()
    assert unbuilt["error"].str.contains("building step").all()
    assert unbuilt["n"].isna().all()
    for col in RECIPE_COLUMNS:
        assert unbuilt[col].notna().all(), col
        assert list(unbuilt[col].astype(object)) == list(built[col].astype(object)), col


def test_a_measured_map_s_side_is_not_guessed_from_the_recipe() -> None:
    cols = recipe_columns({"size": 64, "surface_path": "map.npy", "E": 1.0, "kernel": "bcc", "periodic": False})
    assert "N" not in cols and cols == {"E": 1.0, "kernel": "bcc", "periodic": False}
    assert recipe_columns({"size": True, "E": "x", "kernel": 3}) == {}
