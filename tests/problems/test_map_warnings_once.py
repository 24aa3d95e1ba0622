"""A map's cleaning warnings are the run's reads' alone: the plan's reads that only ask
what the map would be under other options (``harness.run.spelled_out``: without the given
``--height-unit``, in metres) warn of nothing (``io.unannounced``), so a tilted map in nm
warns once, in the unit it is read in, not a second time with its numbers read as metres."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from contactbench.problems.io import load_surface, unannounced
from contactbench.problems.surfaces import rmd_surface_n, with_rms_slope
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")

N, LENGTH, TILT = 33, 1e-4, 0.5


def tilted_nm_map(path: Path) -> Path:
    """A rough map (rms slope 0.2) on a plane of slope ``TILT``, its numbers in nm."""
    rough = with_rms_slope(rmd_surface_n(N, 0.7, length=LENGTH, seed=4), 0.2)
    i = np.arange(N)[:, None] * np.ones(N)[None, :]
    np.save(path, (rough.heights + TILT * rough.delta * i) * 1e9)
    return path


def test_a_tilted_map_in_nm_warns_once_in_its_own_unit(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tilted_nm_map(in_tmp / "tilt_nm.npy")
    rc, _, err = run_cli(["run", "paper-sweep", "--steps", "2", "--solvers", "pk", "--surface", str(path),
                          "--length", str(LENGTH), "--height-unit", "nm", "--reference", "none", "--no-progress",
                          "--out", str(in_tmp / "B")], capsys)
    assert rc == 0, err
    tilts = [line for line in err.splitlines() if "tilted by" in line]
    assert len(tilts) == 1, tilts
    assert "tilted by 0.5" in tilts[0], tilts


def test_a_read_inside_unannounced_keeps_its_warnings_in_its_record_only(in_tmp: Path) -> None:
    path = tilted_nm_map(in_tmp / "quiet_nm.npy")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with unannounced():
            quiet = load_surface(path, LENGTH, height_unit="nm")
        assert not caught
        loud = load_surface(path, LENGTH, height_unit="nm")  # (the quiet read did not use up its warning)
    assert quiet.preprocessing is not None and any("tilted by" in w for w in quiet.preprocessing.warnings)
    assert loud.preprocessing is not None and [str(w.message) for w in caught] == list(loud.preprocessing.warnings)
