"""The plane that detrend "plane" removes (problems/io.py ``bulk_plane_fit``) is the plane of
the map's bulk (the points ``units.bulk_figures`` keeps): one tall spike does not tilt the
whole map, so a map too smooth but for one outlier is still refused through the default
detrend; a map without outliers keeps its plain least-squares plane."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.problems.io import bulk_plane_fit, load_surface, plane_fit
from tests.helpers import run_cli

N = 32
SIDE = 32e-6
D = SIDE / N
SPIKE = (5, 7)


def smooth(rms: float = 1e-13) -> np.ndarray:
    """A very smooth map (rms slope ~3e-7 at spacing D): one gentle wave and white noise."""
    x = np.arange(N) * D
    wave = 1e-12 * np.sin(2 * np.pi * x / SIDE)[:, None] * np.cos(2 * np.pi * x / SIDE)[None, :]
    return wave + np.random.default_rng(3).normal(0.0, rms, (N, N))


def tilt(s0: float, s1: float) -> np.ndarray:
    """The plane of slopes s0 (along axis 0) and s1 (axis 1), rise per length."""
    return s0 * D * np.arange(N)[:, None] + s1 * D * np.arange(N)[None, :]


def test_one_spike_does_not_tilt_the_removed_plane(tmp_path: Path) -> None:
    z = smooth()
    z[SPIKE] += 5e-6
    np.save(tmp_path / "m.npy", z)
    s = load_surface(tmp_path / "m.npy", length=SIDE)
    assert s.preprocessing is not None and s.preprocessing.removed_slope is not None
    s0, s1 = s.preprocessing.removed_slope
    assert abs(s0) < 1e-8 and abs(s1) < 1e-8  # (the plane through the spike: ~1e-4)


def test_the_cli_refuses_a_smooth_map_with_one_spike_under_the_default_detrend(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    z = smooth()
    z[SPIKE] += 5e-6
    np.save("m.npy", z)
    rc, _, err = run_cli(["run", "paper-sweep", "--surface", "m.npy", "--length", f"{SIDE!r}", "--steps", "1",
                          "--solvers", "pk", "--out", "o"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, lines
    assert "only through 1 outlier point" in lines[0] and "at index (5, 7)" in lines[0]
    assert not (tmp_path / "o").exists()


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("nan", [False, True])
def test_a_tilted_map_with_a_spike_loses_the_bulk_tilt(tmp_path: Path, nan: bool) -> None:
    z = smooth(rms=1e-9) + tilt(2e-3, -1e-3)
    z[SPIKE] += 5e-6
    if nan:  # (the fill keeps working, along the bulk's plane)
        z[20:23, 10:12] = np.nan
    np.save(tmp_path / "t.npy", z)
    s = load_surface(tmp_path / "t.npy", length=SIDE)
    assert s.preprocessing is not None and s.preprocessing.removed_slope is not None
    keep = ~np.isnan(z)
    keep[SPIKE] = False
    _, c, b = plane_fit(z, keep)  # (the bulk leaves out the spike and a few of the noise's extremes)
    assert np.allclose(s.preprocessing.removed_slope, (c / D, b / D), rtol=0.0, atol=2e-6)
    assert np.allclose(s.preprocessing.removed_slope, (2e-3, -1e-3), rtol=1e-3, atol=0.0)
    assert np.isfinite(s.heights).all()
    if nan:  # filled at the bulk's plane: no filled point stands out of the map
        assert abs(float(s.heights[21, 11])) < 1e-8


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("nan", [False, True])
def test_a_map_without_outliers_keeps_its_least_squares_plane(tmp_path: Path, nan: bool) -> None:
    z = np.random.default_rng(8).normal(0.0, 1e-7, (N, N + 8)) + np.pad(tilt(1e-3, 4e-3), ((0, 0), (0, 8)), "edge")
    measured = None
    if nan:
        z[3:6, 30:33] = np.nan
        measured = ~np.isnan(z)
    plain = plane_fit(z, measured)
    assert np.allclose(bulk_plane_fit(z, measured), plain, rtol=1e-12, atol=0.0)
    np.save(tmp_path / "c.npy", z)
    s = load_surface(tmp_path / "c.npy", length=(SIDE, (N + 8) * D))
    assert s.preprocessing is not None and s.preprocessing.removed_slope is not None
    assert np.allclose(s.preprocessing.removed_slope, (plain[1] / D, plain[2] / D), rtol=1e-12, atol=0.0)
