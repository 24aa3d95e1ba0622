"""A map implausible only because of a few outliers (problems/units.py ``outlier_account``):
the refusal names them -- how many, the farthest from the median and its index, in metres --
and suggests no height unit, which would shrink the whole map with the spike; a map whose
every height is in another unit still gets the unit advice."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.problems.surfaces import Surface
from contactbench.problems.units import ImplausibleUnitsError, check_plausible_units
from tests.helpers import run_cli

SIDE = 32e-6


def spiky(spikes: dict[tuple[int, int], float], N: int = 32, rms: float = 1e-7) -> np.ndarray:
    """White heights of rms ``rms`` (rms slope ~0.14 at spacing SIDE/N) with the given spikes."""
    h = np.random.default_rng(5).normal(0.0, rms, (N, N))
    for ij, z in spikes.items():
        h[ij] = z
    return h


def refusal(h: np.ndarray, unit: str | None = "m") -> ImplausibleUnitsError:
    with pytest.raises(ImplausibleUnitsError) as exc:
        check_plausible_units(Surface(h, SIDE / h.shape[0]), unit, "map.npy")
    return exc.value


def test_one_spike_is_named_and_no_unit_is_suggested() -> None:
    err = refusal(spiky({(3, 4): 1e-3}))
    line = str(err)
    assert err.suggestion is None and "--height-unit" not in line and "\n" not in line
    assert "1 outlier point alone makes it so" in line and "0.001 m at index (3, 4)" in line
    assert "without it the map is plausible" in line


def test_a_few_spikes_are_counted() -> None:
    line = str(refusal(spiky({(3, 4): 1e-3, (40, 2): -2e-3, (60, 61): 5e-4}, N=64), None))
    assert "3 outlier points alone make it so" in line and "-0.002 m at index (40, 2)" in line


def test_a_whole_map_in_millimetres_still_gets_the_unit_advice() -> None:
    err = refusal(spiky({}) * 1e3)
    assert err.suggestion == "mm" and "outlier" not in str(err)


def test_the_cli_refuses_a_spiky_map_in_one_line_without_unit_advice(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    np.save("spike.npy", spiky({(3, 4): 1e-3}))
    rc, _, err = run_cli(["run", "paper-sweep", "--surface", "spike.npy", "--length", f"{SIDE!r}", "--steps", "2",
                          "--solvers", "pk", "--out", "o"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "1 outlier point" in lines[0] and "--height-unit" not in lines[0]
    assert not (tmp_path / "o").exists()


def rough(N: int = 256, rms: float = 1e-6) -> np.ndarray:
    """A smooth random map of rms ``rms`` (rms slope ~0.28 on a side of 100 um at N = 256)."""
    h = np.cumsum(np.cumsum(np.random.default_rng(1).standard_normal((N, N)), 0), 1)
    return (h - h.mean()) / h.std() * rms


def rough_refusal(h: np.ndarray, unit: str | None = "m") -> ImplausibleUnitsError:
    with pytest.raises(ImplausibleUnitsError) as exc:
        check_plausible_units(Surface(h, 1e-4 / h.shape[0]), unit)
    return exc.value


@pytest.mark.parametrize("count", [65, 70, 300])
def test_spikes_beyond_a_thousandth_of_the_map_get_no_unit_advice(count: int) -> None:
    h = rough()
    h.flat[np.random.default_rng(1).choice(h.size, count, replace=False)] = 1e-2
    err = rough_refusal(h)
    line = str(err)
    assert err.suggestion is None and "--height-unit" not in line and "\n" not in line
    assert f"{count} outlier points alone make it so" in line and "0.01 m at index" in line


def test_a_ridge_column_gets_no_unit_advice() -> None:
    h = rough()
    h[:, 100] += 5e-3
    err = rough_refusal(h)
    assert err.suggestion is None and "--height-unit" not in str(err)
    assert "256 outlier points alone make it so" in str(err) and "without them the map is plausible" in str(err)


@pytest.mark.parametrize("unit", ["m", "um", None])
def test_a_map_too_smooth_is_not_made_plausible_by_one_spike(unit: str | None) -> None:
    h = rough(rms=1e-12)  # rms slope ~2.8e-7: refused alone
    h[7, 7] = 5e-6  # rms slope 0.1 with the spike
    err = rough_refusal(h, unit)
    line = str(err)
    assert err.suggestion is None and "--height-unit" not in line and "\n" not in line
    assert "rms slope 0.1 only through 1 outlier point" in line and "5e-06 m at index (7, 7)" in line
    assert "without it the rms slope is 2.8e-07" in line


def test_a_map_in_micrometres_with_a_spike_is_advised_micrometres_and_the_spike_named() -> None:
    h = rough() * 1e6  # micrometres read as metres
    h[3, 3] = 1e3
    err = rough_refusal(h)
    assert err.suggestion == "um" and "--height-unit um" in str(err) and "\n" not in str(err)
    assert "in micrometres 1 outlier point" in str(err) and "1e+03 m at index (3, 3)" in str(err)


def test_the_cli_refuses_a_smooth_map_with_one_spike_in_one_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    h = rough(32, rms=1e-13)
    h[3, 4] = 5e-7
    np.save("smooth.npy", h)
    rc, _, err = run_cli(["run", "paper-sweep", "--surface", "smooth.npy", "--length", f"{SIDE!r}", "--steps", "2",
                          "--solvers", "pk", "--detrend", "mean", "--out", "o"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "only through 1 outlier point" in lines[0]
    assert "--height-unit" not in lines[0] and not (tmp_path / "o").exists()
