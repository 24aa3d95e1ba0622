"""Surfaces: RMD and spectral generators, the Hurst fit, coarse levels, bad heights."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.surfaces import (
    RMD_MAX_LEVEL,
    Surface,
    check_grid_size,
    check_not_flat,
    check_rmd_family,
    check_rmd_size,
    fit_hurst,
    radial_psd,
    rmd_surface,
    rmd_surface_n,
    spectral_surface,
)

HURSTS = (0.3, 0.5, 0.7)


@pytest.mark.parametrize("hurst", HURSTS)
@pytest.mark.parametrize("seed", [0, 1])
def test_hurst_fit_recovers_H_for_spectral_surfaces(hurst: float, seed: int) -> None:
    s = spectral_surface(256, hurst, seed=seed)
    assert abs(fit_hurst(s).hurst - hurst) <= 0.05


@pytest.mark.parametrize("hurst", HURSTS)
@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("seed", [0, 1])
def test_hurst_fit_recovers_H_for_rmd_surfaces(hurst: float, periodic: bool, seed: int) -> None:
    s = rmd_surface(8, hurst, seed=seed, periodic=periodic)
    assert s.N == (256 if periodic else 257)
    assert abs(fit_hurst(s).hurst - hurst) <= 0.1


def test_binned_fit_agrees_with_whittle_on_a_spectral_surface() -> None:
    s = spectral_surface(256, 0.6, seed=4)
    binned = fit_hurst(s, psd=radial_psd(s))
    assert binned.method == "binned"
    assert abs(binned.hurst - fit_hurst(s).hurst) < 0.03
    assert binned.r2 > 0.95


def test_radial_psd_integrates_to_the_variance() -> None:
    """Parseval: sum over modes of C(q) dq^2 = rms^2 (periodic, no window)."""
    s = spectral_surface(64, 0.5, rms_height=2e-6, seed=0)
    psd = radial_psd(s)
    dq2 = (2 * np.pi / s.length) ** 2
    assert np.sum(psd.C * psd.counts) * dq2 == pytest.approx(s.rms_height**2, rel=1e-10)


@pytest.mark.parametrize("periodic", [True, False])
def test_rmd_coarse_levels_are_exact_sub_samples(periodic: bool) -> None:
    s = rmd_surface(6, 0.7, seed=3, periodic=periodic)
    assert [lev.N for lev in s.levels] == ([4, 8, 16, 32] if periodic else [5, 9, 17, 33])
    for lev in s.levels:
        stride = lev.meta["stride"]
        assert np.array_equal(lev.heights, s.heights[::stride, ::stride])
        assert lev.delta == pytest.approx(s.delta * stride, rel=1e-15)
        assert lev.periodic == periodic


@pytest.mark.parametrize("N, size_of_levels", [(64, [4, 8, 16, 32]), (65, [5, 9, 17, 33])])
def test_saupe_coarse_stages_equal_the_fine_grid_subsampled(N: int, size_of_levels: list[int]) -> None:
    """The paper's generator (non-periodic MidPointFM2D): for N = 2^k the (2^k + 1)^2 grid
    loses its last row and column, and so does every stage -- each stage is still exactly
    z[::s, ::s]; N = 2^k + 1 keeps the whole grid."""
    s = rmd_surface_n(N, 0.7, family="saupe", seed=7, length=100e-6)
    assert s.N == N and not s.periodic and s.meta["family"] == "saupe" and s.name.startswith("saupe-H0.7-")
    assert s.delta == pytest.approx(100e-6 / 64, rel=1e-15)  # L / 2^k either way
    assert s.rms_height == pytest.approx(1e-6, rel=1e-12) and abs(s.z_mean) < 1e-18
    assert [lev.N for lev in s.levels] == size_of_levels
    for lev in s.levels:
        stride = lev.meta["stride"]
        assert np.array_equal(lev.heights, s.heights[::stride, ::stride])
        assert lev.delta == pytest.approx(s.delta * stride, rel=1e-15) and lev.meta["family"] == "saupe"
    whole = rmd_surface_n(65, 0.7, family="saupe", seed=7)
    cropped_raw = rmd_surface_n(64, 0.7, family="saupe", seed=7)
    # the same construction: the cropped grid is the whole one without its last row/column (up to scaling)
    a, b = whole.heights[:-1, :-1], cropped_raw.heights
    np.testing.assert_allclose((a - a.mean()) / a.std(), (b - b.mean()) / b.std(), rtol=0, atol=1e-12)


def test_rmd_families_choose_the_grid_and_refuse_what_they_cannot_give() -> None:
    per = rmd_surface_n(32, 0.7, family="periodic", seed=1)
    assert per.periodic and per.N == 32 and per.meta["family"] == "periodic" and per.name.startswith("periodic-")
    assert np.array_equal(per.heights, rmd_surface_n(32, 0.7, seed=1).heights)  # no family: N = 2^k is periodic
    assert rmd_surface_n(33, 0.7).meta["family"] == "saupe"
    assert not np.array_equal(rmd_surface_n(32, 0.7, family="saupe", seed=1).heights, per.heights)
    with pytest.raises(ProblemInputError, match="'periodic' RMD family needs N = 2\\^k .* got N = 33"):
        rmd_surface_n(33, 0.7, family="periodic")
    with pytest.raises(ProblemInputError, match="unknown RMD surface family 'voss': choose one of 'saupe', 'periodic'"):
        check_rmd_family("voss")
    with pytest.raises(ProblemInputError, match="RMD surface needs N = 2\\^k"):
        rmd_surface_n(30, 0.7, family="saupe")
    with pytest.raises(ProblemInputError, match="crop applies to the non-periodic"):
        rmd_surface(5, 0.7, periodic=True, crop=True)


def test_rmd_with_additions_stores_the_construction_states() -> None:
    plain = rmd_surface(6, 0.7, seed=3)
    sra = rmd_surface(6, 0.7, seed=3, additions=True)
    assert [lev.N for lev in sra.levels] == [lev.N for lev in plain.levels]
    stride = sra.levels[-1].meta["stride"]
    moved = sra.levels[-1].heights - sra.heights[::stride, ::stride]
    assert np.abs(moved).max() > 0  # later stages displaced the old points ...
    assert np.std(moved) < 0.5 * sra.rms_height  # ... by the small, fine-scale additions only


def test_rmd_is_seeded_and_scaled() -> None:
    a = rmd_surface(5, 0.5, seed=9, rms_height=3e-6, length=50e-6)
    b = rmd_surface(5, 0.5, seed=9, rms_height=3e-6, length=50e-6)
    assert np.array_equal(a.heights, b.heights)
    assert a.rms_height == pytest.approx(3e-6, rel=1e-12)
    assert abs(a.z_mean) < 1e-18 and a.length == pytest.approx(50e-6)
    assert not np.array_equal(a.heights, rmd_surface(5, 0.5, seed=10).heights)


def test_rmd_surface_n_chooses_the_grid_and_refuses_other_sizes() -> None:
    assert rmd_surface_n(32, 0.7).periodic and rmd_surface_n(32, 0.7).N == 32
    assert not rmd_surface_n(33, 0.7).periodic and rmd_surface_n(33, 0.7).N == 33
    with pytest.raises(ProblemInputError, match="N = 2\\^k \\(periodic\\) or 2\\^k \\+ 1 .* N = 30"):
        rmd_surface_n(30, 0.7)
    with pytest.raises(ProblemInputError, match="Hurst exponent must lie in \\(0, 1\\), got 1.2"):
        rmd_surface(5, 1.2)


def test_surface_scaled_scales_every_length() -> None:
    s = rmd_surface(5, 0.7, seed=2)
    t = s.scaled(1e-6)
    assert np.allclose(t.heights, s.heights * 1e-6, rtol=1e-15, atol=0)
    assert t.delta == pytest.approx(s.delta * 1e-6, rel=1e-15)
    assert t.rms_slope() == pytest.approx(s.rms_slope(), rel=1e-12)  # slopes are dimensionless
    assert all(np.allclose(a.heights, b.heights * 1e-6) for a, b in zip(t.levels, s.levels))
    assert fit_hurst(t).hurst == pytest.approx(fit_hurst(s).hurst, abs=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_heights_are_refused(bad: float) -> None:
    h = np.zeros((8, 8))
    h[2, 5] = bad
    with pytest.raises(ProblemInputError, match="NaN/inf values .*\\(2, 5\\)"):
        Surface(h, 1e-6)


def test_rectangular_grids_are_kept_and_tiny_ones_refused() -> None:
    s = Surface(np.zeros((8, 9)), 1e-6, delta1=2e-6)
    assert s.shape == (8, 9) and s.spacing == (1e-6, 2e-6)
    assert s.lengths == pytest.approx((8e-6, 18e-6)) and s.area == pytest.approx(8e-6 * 18e-6)
    with pytest.raises(ProblemInputError, match="square grid; the surface 'surface' is 8 x 9"):
        _ = s.N
    with pytest.raises(ProblemInputError, match="square grid"):
        _ = Surface(np.zeros((8, 8)), 1e-6, delta1=2e-6).length  # square shape, rectangular pixels
    assert Surface(np.zeros((8, 8)), 1e-6, delta1=1e-6).length == pytest.approx(8e-6)
    with pytest.raises(ProblemInputError, match="delta1"):
        Surface(np.zeros((8, 9)), 1e-6, delta1=-1.0)
    with pytest.raises(ProblemInputError, match="at least 2 x 2, got 1 x 1"):
        Surface(np.zeros((1, 1)), 1e-6)
    with pytest.raises(ProblemInputError, match="at least 2 x 2, got 1 x 9"):
        Surface(np.zeros((1, 9)), 1e-6)
    with pytest.raises(ProblemInputError, match="2-D array, got 1-D"):
        Surface(np.zeros(8), 1e-6)


@pytest.mark.parametrize("bad", [0.0, -1e-6, np.nan])
def test_bad_grid_spacing_is_refused(bad: float) -> None:
    with pytest.raises(ProblemInputError, match="grid spacing delta must be a finite positive number"):
        Surface(np.zeros((4, 4)), bad)


@pytest.mark.parametrize("N, k, periodic", [(2, 1, True), (3, 1, False), (512, 9, True), (513, 9, False),
                                             (8192, 13, True), (16384, 14, True), (16385, 14, False),
                                             (65536, 16, True)])
def test_rmd_sizes_are_powers_of_two_or_one_more(N: int, k: int, periodic: bool) -> None:
    assert check_rmd_size(N) == (k, periodic)


@pytest.mark.parametrize("k", [14, 16])
def test_the_generator_takes_every_level_the_size_check_admits(k: int) -> None:
    """A level past 13 is refused by neither check: the first complaint is about the length
    (checked after the level, before any grid is allocated)."""
    assert check_rmd_size(2**k + 1) == (k, False)
    with pytest.raises(ProblemInputError, match="length L"):
        rmd_surface(k, 0.7, length=-1.0)
    with pytest.raises(ProblemInputError, match=f"RMD level k must be an integer in 1..{RMD_MAX_LEVEL}, got {RMD_MAX_LEVEL + 1}"):
        rmd_surface(RMD_MAX_LEVEL + 1, 0.7)


@pytest.mark.parametrize("bad", [1000, 1, 0, -4, 6, 131072, 131073, 512.5, "512", True])
def test_other_rmd_sizes_get_a_one_line_error(bad: object) -> None:
    with pytest.raises(ProblemInputError, match="RMD surface needs N = 2\\^k .* or 2\\^k \\+ 1") as err:
        check_rmd_size(bad)
    assert "\n" not in str(err.value) and repr(bad) in str(err.value)
    if isinstance(bad, int) and not isinstance(bad, bool):
        with pytest.raises(ProblemInputError, match=f"got N = {bad}$"):
            rmd_surface_n(bad, 0.7)


@pytest.mark.parametrize("bad", [1, 0, 2.5, "8"])
def test_spectral_surfaces_need_an_integer_size_of_at_least_2(bad: object) -> None:
    with pytest.raises(ProblemInputError, match="spectral surface needs an integer N >= 2"):
        spectral_surface(bad, 0.7)  # type: ignore[arg-type]
    assert check_grid_size(6) == 6 and check_grid_size(8.0) == 8


def test_a_flat_surface_gets_a_clear_error() -> None:
    flat = Surface(np.full((8, 8), 3e-6), 1e-6, name="plate")
    assert flat.is_flat and not rmd_surface_n(8, 0.7).is_flat
    with pytest.raises(ProblemInputError, match="the surface 'plate' is flat \\(all heights equal 3e-06 m\\)") as err:
        check_not_flat(flat)
    assert "\n" not in str(err.value)
    with pytest.raises(ProblemInputError, match="flat"):
        fit_hurst(flat)
    rough = rmd_surface_n(8, 0.7)
    assert check_not_flat(rough) is rough
