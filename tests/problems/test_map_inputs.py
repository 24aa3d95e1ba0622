"""Map inputs that are no height map of a rough surface, each refused in one line naming
the file and what it holds: numbers that are not written plainly, true/false and complex
values, maps of fewer than ``MIN_MAP_SIDE`` points along a side, and zip archives that are
no map."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from contactbench.problems.io import SurfaceFileError, load_surface, read_height_map, write_x3p
from contactbench.problems.map_readers import MIN_MAP_SIDE


def random_map(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 1e-6, shape)


def test_a_number_in_a_text_map_is_written_plainly(tmp_path: Path) -> None:
    """Python's float reads "1_0e-7" as 1e-6; a map's numbers are plain decimals, so such a
    cell is refused in one line naming it."""
    z = random_map((8, 8))
    lines = [",".join(repr(float(v)) for v in row) for row in z]
    lines[5] = lines[5].replace(lines[5].split(",")[2], "1_0e-7", 1)
    (tmp_path / "u.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(SurfaceFileError, match=r"'1_0e-7' on line 6 is not a plainly written number"):
        read_height_map(tmp_path / "u.csv")


@pytest.mark.parametrize("values", [np.ones((16, 16), dtype=bool), np.ones((16, 16), dtype=complex)],
                         ids=["bool", "complex"])
def test_true_false_and_complex_values_are_no_heights(tmp_path: Path, values: np.ndarray) -> None:
    np.save(tmp_path / "v.npy", values)
    with pytest.raises(SurfaceFileError, match="(true/false values|complex numbers) .*not heights"):
        load_surface(tmp_path / "v.npy", length=1e-4)


@pytest.mark.parametrize("shape", [(2, 2), (2, 64), (64, 7)])
def test_a_map_needs_the_least_number_of_points_along_each_side(tmp_path: Path, shape: tuple[int, int]) -> None:
    np.save(tmp_path / "small.npy", random_map(shape))
    with pytest.raises(SurfaceFileError, match=f"a map needs at least {MIN_MAP_SIDE} points along each side"):
        load_surface(tmp_path / "small.npy", length=1e-4)
    np.save(tmp_path / "least.npy", random_map((MIN_MAP_SIDE, MIN_MAP_SIDE)))
    assert read_height_map(tmp_path / "least.npy").z.shape == (MIN_MAP_SIDE, MIN_MAP_SIDE)


def test_a_zip_archive_that_is_no_map_says_what_it_holds(tmp_path: Path) -> None:
    """Two .x3p zipped, one, none, and an .x3p under the extension .zip: each refused in one
    line that says what the archive holds (the reader SurfaceTopography picks for .zip fails on
    each with a bare KeyError)."""
    write_x3p(tmp_path / "a.x3p", random_map((8, 8)), 1e-6)
    write_x3p(tmp_path / "b.x3p", random_map((8, 8), seed=1), 1e-6)
    cases = {"two.zip": (["a.x3p", "b.x3p"], r"a zip archive of 2 map files \(a.x3p, b.x3p\), not one map"),
             "one.zip": (["a.x3p"], r"a zip archive of one map file \(a.x3p\): unzip it"),
             "none.zip": ([], r"a zip archive with no map file in it .* \(readme.txt\); give the map file")}
    for name, (members, phrase) in cases.items():
        with zipfile.ZipFile(tmp_path / name, "w") as zf:
            for m in members:
                zf.write(tmp_path / m, m)
            if not members:
                zf.writestr("readme.txt", "hello")
        with pytest.raises(SurfaceFileError, match=phrase) as e:
            load_surface(tmp_path / name, detrend="none")
        assert "KeyError" not in str(e.value) and "\n" not in str(e.value)
    (tmp_path / "x3p.zip").write_bytes((tmp_path / "a.x3p").read_bytes())
    with pytest.raises(SurfaceFileError, match=r"an ISO 25178 .x3p archive under the extension '.zip': rename it"):
        load_surface(tmp_path / "x3p.zip", detrend="none")
