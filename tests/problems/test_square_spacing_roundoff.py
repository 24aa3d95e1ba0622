"""Square elements to round-off: spacings that differ by a few ulps (L0 / N0 against
L1 / N1 for equal pixels) are one spacing for the 'bcc' kernel and for a map read with
(L0, L1); spacings that really differ are still rectangular, and 'bcc' refuses them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.io import load_surface
from contactbench.problems.kernels import SQUARE_SPACING_RTOL, check_element_shape, kernel_table, square_spacing
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.surfaces import Surface, rmd_surface_n

E = 2.0e9
SHAPE = (48, 32)
#: 150e-6 / 48 = 3.1249999999999997e-06 and 100e-6 / 32 = 3.125e-06: one ulp apart.
ROUNDED = (150e-6 / 48, 100e-6 / 32)


def test_the_two_spacings_differ_by_round_off_only() -> None:
    assert ROUNDED[0] != ROUNDED[1]
    assert abs(ROUNDED[0] - ROUNDED[1]) <= SQUARE_SPACING_RTOL * max(ROUNDED)
    assert SQUARE_SPACING_RTOL < 1e-14  # a few ulps, not a tolerance that would take a real rectangle


def test_bcc_takes_spacings_equal_to_round_off_and_uses_the_axis_0_spacing() -> None:
    assert square_spacing(ROUNDED) == ROUNDED[0]
    assert check_element_shape("bcc", ROUNDED) == (ROUNDED[0], ROUNDED[0])
    for periodic in (False, True):
        table = kernel_table("bcc", SHAPE, ROUNDED, E, periodic=periodic)
        square = kernel_table("bcc", SHAPE, ROUNDED[0], E, periodic=periodic)
        assert np.allclose(table, square, rtol=1e-12, atol=0.0)
    assert np.array_equal(kernel_table("bcc", SHAPE, ROUNDED, E, periodic=False),
                          kernel_table("bcc", SHAPE, ROUNDED[0], E, periodic=False))


@pytest.mark.parametrize("d2", [3.125e-6 * (1 + 1e-7), 3.125e-6 * (1 + 64 * np.finfo(np.float64).eps), 4.6875e-6])
def test_bcc_refuses_spacings_that_really_differ(d2: float) -> None:
    assert square_spacing((3.125e-6, d2)) is None
    with pytest.raises(ProblemInputError, match="'bcc' kernel needs square elements") as caught:
        kernel_table("bcc", SHAPE, (3.125e-6, d2), E, periodic=False)
    assert repr(float(d2)) in str(caught.value)  # the two spacings read apart, however close
    assert check_element_shape("love", (3.125e-6, d2)) == (3.125e-6, d2)


def _rect_map(tmp_path: Path) -> Path:
    path = tmp_path / "rect.npy"
    np.save(path, rmd_surface_n(64, hurst=0.7, family="saupe", seed=2).heights[:48, :32])
    return path


def test_a_map_read_with_lengths_of_equal_pixels_has_square_pixels(tmp_path: Path) -> None:
    s = load_surface(_rect_map(tmp_path), length=(150e-6, 100e-6))
    assert s.spacing == (ROUNDED[0], ROUNDED[0]) and s.delta1 is None and s.square_pixels
    assert s.preprocessing is not None and s.preprocessing.spacing == s.spacing
    r = load_surface(_rect_map(tmp_path), length=(150e-6, 150e-6))
    assert r.spacing == (150e-6 / 48, 150e-6 / 32) and not r.square_pixels


def test_paper_sweep_takes_the_map_with_lengths_of_equal_pixels(tmp_path: Path) -> None:
    path = str(_rect_map(tmp_path))
    scene = get_scene("paper-sweep")
    cfg = scene.config(SceneConfig(surface_path=path, length=(150e-6, 100e-6), steps=2))
    scene.validate(cfg)
    assert len(scene.instances(cfg)) == 1
    with pytest.raises(ProblemInputError, match="'bcc' kernel needs square elements"):
        scene.validate(scene.config(SceneConfig(surface_path=path, length=(150e-6, 150e-6), steps=2)))


def test_a_surface_built_with_spacings_equal_to_round_off_has_square_pixels() -> None:
    s = Surface(np.zeros((48, 32)), 150e-6 / 48, delta1=100e-6 / 32)
    assert s.delta1 is None and s.square_pixels and s.spacing == (150e-6 / 48, 150e-6 / 48)
    assert Surface(np.zeros((4, 4)), 1.0, delta1=1.0 + 1e-7).delta1 == 1.0 + 1e-7
