"""The filled points a crop leaves out are not in the problem: the map's record counts the
points filled in the map as read (``filled``) and in the map as solved (``filled_solved``),
the table's ``nan_filled`` is the latter, and the report's "Problem changes" says how many
of the filled points the solved map keeps."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.report.core import map_changes
from contactbench.problems.io import load_surface
from contactbench.problems.preprocessing import MapPreprocessing
from contactbench.problems.surfaces import rmd_surface_n

N0, N1, D = 33, 20, 5e-6


def rect_map(path: Path, holes: list[tuple[int, int]]) -> Path:
    """A 33 x 20 rough map (.npy, metres) with NaN at ``holes``."""
    z = rmd_surface_n(33, 0.7, length=N0 * D, rms_height=1e-7, seed=1).heights[:, :N1].copy()
    for h in holes:
        z[h] = np.nan
    np.save(path, z)
    return path


def record(path: Path, crop: str) -> MapPreprocessing:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load_surface(path, N0 * D, crop=crop).preprocessing  # type: ignore[arg-type]
    assert rec is not None
    return rec


CORNER = [(i, j) for i in range(3) for j in range(3)]  # rows 0:3, outside the central rows 6:26
CENTRE = [(16, 5), (17, 5)]


@pytest.mark.parametrize(("holes", "crop", "solved"), [
    (CORNER, "square", 0), (CORNER + CENTRE, "square", 2), (CORNER, "none", 9), (CORNER, "pad-square", 9)])
def test_the_record_counts_the_filled_points_the_solved_map_keeps(tmp_path: Path, holes: list[tuple[int, int]],
                                                                   crop: str, solved: int) -> None:
    rec = record(rect_map(tmp_path / "m.npy", holes), crop)
    assert rec.filled == len(holes) and rec.filled_solved == solved
    assert rec.columns()["nan_filled"] == solved


def test_the_report_says_the_crop_left_the_filled_points_out(tmp_path: Path) -> None:
    rec = record(rect_map(tmp_path / "m.npy", CORNER), "square")
    row = pd.Series({"scene": "paper-sweep", "instance": rec.instance_name, "N0": 20, "N1": 20, **rec.columns()})
    text = map_changes(row, rec.as_dict())
    assert "9 missing points filled" in text and "none of them in the map as solved (the crop left 9 out)" in text
    kept = record(rect_map(tmp_path / "k.npy", CORNER), "none")
    row = pd.Series({"scene": "paper-sweep", "instance": kept.instance_name, "N0": N0, "N1": N1, **kept.columns()})
    text = map_changes(row, kept.as_dict())
    assert "9 missing points filled" in text and "in the map as solved" not in text
