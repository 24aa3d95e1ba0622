"""Reading a NetCDF map warns of the map only: SciPy's note that a netcdf_file opened with
mmap=True cannot be closed while arrays refer to its data (``NETCDF_MMAP_WARNING``) is
about SciPy's buffers, and is never passed on as one of our warnings, during the read or
when the reader is collected afterwards."""

from __future__ import annotations

import gc
import warnings
from pathlib import Path

import numpy as np
import pytest
from contactbench.problems.io import load_surface
from contactbench.problems.map_files import write_topography
from contactbench.problems.map_readers import NETCDF_MMAP_WARNING
from contactbench.problems.surfaces import rmd_surface_n

pytest.importorskip("SurfaceTopography", reason="SurfaceTopography reads NetCDF maps")


def _holed_netcdf(tmp_path: Path) -> Path:
    z = rmd_surface_n(32, hurst=0.7, family="saupe", seed=3).heights.copy()
    z[5:9, 5:9] = np.nan
    return write_topography(tmp_path / "holed.nc", z, 100e-6 / 32, fmt="netcdf")


def test_reading_a_netcdf_map_warns_of_the_map_only(tmp_path: Path) -> None:
    path = _holed_netcdf(tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(2):  # (a run reads its map more than once)
            surface = load_surface(path, length=100e-6)
        del surface
        gc.collect()  # (a reader left to the collector would warn here)
    said = [str(w.message) for w in caught]
    assert not [m for m in said if NETCDF_MMAP_WARNING in m], said
    assert any(m.startswith("holed.nc: 16 missing points") and "filled by rule 'fill-mean'" in m for m in said), said
    assert all(m.startswith("holed.nc: ") and issubclass(w.category, UserWarning) for m, w in zip(said, caught)), said


def test_a_netcdf_map_reads_its_heights_after_its_reader_is_closed(tmp_path: Path) -> None:
    z = rmd_surface_n(32, hurst=0.7, family="saupe", seed=4).heights
    path = write_topography(tmp_path / "whole.nc", z, 100e-6 / 32, fmt="netcdf")
    s = load_surface(path, detrend="none")
    gc.collect()
    assert s.shape == (32, 32) and np.allclose(s.heights - s.heights.mean(), z - z.mean(), rtol=0.0, atol=1e-12 * np.ptp(z))
