"""A measured map under another kernel or boundary is another problem: its instance name
carries them (``scenes.core.grid_suffix``: "-bcc-np", "-bcc-per", "-love-np"), as a
generated surface's does, so a ``--periodic`` run appended to a non-periodic one on the
same map is a second instance with its own rows and its own stored field."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.run.plan import plan_run
from contactbench.problems.scenes import SceneConfig
from contactbench.problems.surfaces import rmd_surface_n
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")

LENGTH = 1e-4


@pytest.fixture
def map_file(in_tmp: Path) -> Path:
    """A 65 x 65 rough map (.npy, metres) of plausible slopes."""
    path = in_tmp / "m.npy"
    np.save(path, rmd_surface_n(65, 0.7, length=LENGTH, rms_height=1e-6, seed=2).heights)
    return path


def planned_instance(scene: str, path: Path, **options: object) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (job,) = plan_run([scene], SceneConfig(surface_path=str(path), length=LENGTH, **options),  # type: ignore[arg-type]
                          ["pk"]).jobs
    return job.spec.instance


@pytest.mark.parametrize("scene", ["paper-sweep", "cmr-cutoff"])
def test_a_map_s_instance_name_carries_its_kernel_and_boundary(scene: str, map_file: Path) -> None:
    plain = planned_instance(scene, map_file)
    wrapped = planned_instance(scene, map_file, periodic=True)
    love = planned_instance(scene, map_file, kernel="love")
    assert plain.startswith("file-m.npy-") and plain.endswith("-bcc-np")
    assert wrapped.endswith("-bcc-per") and love.endswith("-love-np")
    assert len({plain, wrapped, love}) == 3


def test_a_periodic_run_appended_on_the_same_map_is_another_instance(map_file: Path, in_tmp: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = in_tmp / "out"
    base = ["run", "paper-sweep", "--steps", "2", "--solvers", "pk", "--surface", str(map_file), "--length",
            str(LENGTH), "--reference", "none", "--no-progress", "--out", str(out)]
    assert run_cli(base, capsys)[0] == 0
    assert run_cli([*base, "--periodic", "--append"], capsys)[0] == 0
    table = pd.read_parquet(out / "results.parquet")
    by_instance = table.groupby("instance")["periodic"].agg(lambda s: set(s.astype(bool)))
    assert len(by_instance) == 2 and sorted(map(tuple, by_instance)) == [(False,), (True,)], by_instance
    fields = sorted(p.name for p in (out / "arrays").glob("field-*.npz"))
    assert len(fields) == 2 and any("-bcc-per-" in f for f in fields) and any("-bcc-np-" in f for f in fields), fields
