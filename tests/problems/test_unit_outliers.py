"""A map implausible only because of a few outliers (problems/units.py ``outlier_account``):
the refusal names them -- how many, the farthest from the median and its index, in metres --
and suggests no height unit, which would shrink the whole map with the spike; a map whose
every height is in another unit still gets the unit advice."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.harness.cli import main
from contactbench.problems.surfaces import Surface
from contactbench.problems.units import ImplausibleUnitsError, check_plausible_units

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
    try:
        rc = main(["run", "paper-sweep", "--surface", "spike.npy", "--length", f"{SIDE!r}", "--steps", "2",
                   "--solvers", "pk", "--out", "o"])
    except SystemExit as exc:
        rc = int(exc.code or 0)
    lines = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "1 outlier point" in lines[0] and "--height-unit" not in lines[0]
    assert not (tmp_path / "o").exists()
