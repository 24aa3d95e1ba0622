"""problems.coarsen: the block-average filter, coarse levels and the cascade's choice of
them, element positions across levels, the coarse QP of a level, and the PSD power-law
check."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contactbench.problems.coarsen import (
    block_average,
    cascade_surfaces,
    coarse_level,
    coarse_levels,
    coarse_qp,
    grid_positions,
    level_sizes,
    level_trial_set,
    mean_level,
    power_law_check,
)
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import Surface, rmd_surface_n, spectral_surface

# --- coarsening filter ----------------------------------------------------------------


def test_block_average_is_the_2x2_area_mean() -> None:
    s = spectral_surface(8, 0.7, length=8.0, seed=1)
    c = block_average(s)
    assert c.N == 4 and c.delta == 2 * s.delta
    np.testing.assert_allclose(c.heights[1, 2], s.heights[2:4, 4:6].mean())
    assert c.heights.mean() == pytest.approx(s.heights.mean(), abs=1e-15)  # area-weighted: mean kept
    assert c.meta["origin"] == (0.5 * s.delta, 0.5 * s.delta)


def test_block_average_keeps_a_constant_and_a_plane() -> None:
    yy, xx = np.mgrid[0:8, 0:8].astype(float)
    s = Surface(3.0 + 2.0 * xx + yy, 1.0)
    c = block_average(s)
    cy, cx = np.mgrid[0:4, 0:4].astype(float)
    # a plane is reproduced at the coarse element centres (2i + 0.5, 2j + 0.5)
    np.testing.assert_allclose(c.heights, 3.0 + 2.0 * (2 * cx + 0.5) + (2 * cy + 0.5))


def test_coarse_levels_layout() -> None:
    s = spectral_surface(64, 0.7, seed=2)
    lv = coarse_levels(s, 3)
    assert [x.N for x in lv] == [8, 16, 32]  # coarsest first, the surface excluded
    # repeated 2 x 2 averaging is the s x s block mean
    np.testing.assert_allclose(lv[0].heights, block_average(block_average(block_average(s))).heights, rtol=1e-13)
    with pytest.raises(ProblemInputError):
        coarse_levels(s, -1)


@pytest.mark.parametrize("N, stride", [(64, 4), (64, 16), (33, 8), (30, 4)])
def test_mean_levels_are_block_means(N: int, stride: int) -> None:
    """coarse=mean: element (I, J) is the mean of the s x s fine block it covers (checked
    against an explicit reshape-mean), centred in that block in the fine frame; a last
    partial block is dropped."""
    s = spectral_surface(N, 0.7, length=float(N), seed=3)  # delta = 1
    lv = coarse_level(s, stride, "mean")
    n = N // stride
    h = s.heights
    explicit = np.array([[h[I * stride:(I + 1) * stride, J * stride:(J + 1) * stride].mean() for J in range(n)]
                         for I in range(n)])
    np.testing.assert_allclose(lv.heights, explicit, rtol=1e-13, atol=1e-20)
    assert lv.N == n and lv.delta == pytest.approx(stride * s.delta)
    c = 0.5 * (stride - 1)  # element (I, J) centre: (s I + (s-1)/2, s J + (s-1)/2)
    np.testing.assert_allclose(grid_positions(lv, np.array([0, n + 1])), [[c, c], [stride + c, stride + c]])
    assert mean_level(s, stride).meta["origin"] == (c, c)


def test_subsample_levels_are_the_fine_grid_subsampled() -> None:
    """coarse=subsample on a surface without generator stages: z[::s, ::s], centres on
    fine grid points; on an RMD surface: its own stages (equal to z[::s, ::s])."""
    s = spectral_surface(64, 0.7, length=64.0, seed=3)
    lv = coarse_level(s, 8, "subsample")
    np.testing.assert_array_equal(lv.heights, s.heights[::8, ::8])
    np.testing.assert_allclose(grid_positions(lv, np.array([9])), [[8.0, 8.0]])
    rmd = rmd_surface_n(64, 0.7, family="saupe", seed=2)
    assert coarse_level(rmd, 4, "subsample") is rmd.levels[-2]
    np.testing.assert_array_equal(coarse_level(rmd, 4).heights, rmd.heights[::4, ::4])
    with pytest.raises(ProblemInputError, match="unknown coarse-level kind 'median'"):
        coarse_level(s, 2, "median")


def test_cascade_refuses_a_coarsest_size_the_surface_cannot_give() -> None:
    s = rmd_surface_n(256, 0.7, family="saupe")
    assert level_sizes(256) == {128: 2, 64: 4, 32: 8, 16: 16, 8: 32, 4: 64, 2: 128}
    for kind in ("subsample", "mean"):
        assert [x.N for x in cascade_surfaces(s, 16, kind=kind)] == [16, 32, 64, 128]
        assert [x.N for x in cascade_surfaces(s, 64, kind=kind)] == [64, 128]
    with pytest.raises(ProblemInputError, match="coarsest level 20 is not available on the 256 x 256 surface"):
        cascade_surfaces(s, 20)
    with pytest.raises(ProblemInputError, match="coarsest level 256 is not available"):
        cascade_surfaces(s, 256)
    whole = rmd_surface_n(257, 0.7, family="saupe")  # 2^k + 1: a sub-sample keeps its closing row
    assert [x.N for x in cascade_surfaces(whole, 16)] == [17, 33, 65, 129]
    assert [x.N for x in cascade_surfaces(whole, 16, kind="mean")] == [16, 32, 64, 128]


# --- power-law check ------------------------------------------------------------------


@pytest.mark.parametrize("H", [0.3, 0.5, 0.7])
def test_power_law_check_passes_rmd_and_pure_spectra(H: float) -> None:
    assert power_law_check(rmd_surface_n(256, H)).power_law
    c = power_law_check(spectral_surface(256, H, seed=3))
    assert c.power_law and c.hurst == pytest.approx(H, abs=0.15)


def test_power_law_check_flags_a_rolloff_plateau() -> None:
    c = power_law_check(spectral_surface(256, 0.6, seed=3, rolloff_wavelength=100e-6 / 16))
    assert not c.power_law and "NOT a power law" in c.message
    assert abs(c.slope_low) < 1.0 < abs(c.slope_high)


def test_power_law_check_refuses_a_flat_surface() -> None:
    with pytest.raises(ProblemInputError, match="flat"):
        power_law_check(Surface(np.full((16, 16), 2.0), 1e-6, name="plate"))


# --- the cascade's levels and their QPs -------------------------------------------------


@pytest.mark.parametrize("family", ["saupe", "periodic"])
def test_cascade_surfaces_rmd_levels_are_subsamples(family: str) -> None:
    s = rmd_surface_n(64, 0.7, family=family)
    lv = cascade_surfaces(s, 16)
    assert [x.N for x in lv] == [16, 32]
    np.testing.assert_array_equal(lv[0].heights, s.heights[::4, ::4])
    assert [x.N for x in cascade_surfaces(s, 4, sizes=[8, 32])] == [8, 32]
    with pytest.raises(ProblemInputError, match="not available"):
        cascade_surfaces(s, 16, sizes=[24])


def test_grid_positions_put_block_averaged_centres_in_the_fine_frame() -> None:
    s = spectral_surface(8, 0.7, length=8.0, seed=1)  # delta = 1
    c = block_average(s)
    # coarse element (1, 2) covers fine elements 2..3 x 4..5: its centre is (2.5, 4.5)
    np.testing.assert_allclose(grid_positions(c, np.array([1 * c.N + 2])), [[2.5, 4.5]])
    np.testing.assert_allclose(grid_positions(s, np.array([9])), [[1.0, 1.0]])


def test_coarse_qp_is_the_instance_builders_qp_of_the_level() -> None:
    """Non-periodic: the coarse QP on the whole level trial set is exactly what
    InstanceBuilder builds for that level at the same Delta (one formula for ubar, H)."""
    s = rmd_surface_n(33, 0.7, seed=4)
    fine = InstanceBuilder(s, 1e9, "bcc").build(paper_max_displacement(s))
    level = s.levels[-1]
    idx = level_trial_set(level, fine.qp.geometry)
    qp = coarse_qp(level, fine.qp.geometry, idx, "dense")
    ref = InstanceBuilder(level, 1e9, "bcc", operator="dense").build(fine.delta).qp
    np.testing.assert_array_equal(qp.geometry.indices, ref.geometry.indices)
    np.testing.assert_array_equal(qp.ubar, ref.ubar)
    np.testing.assert_allclose(qp.H.to_dense(), ref.H.to_dense(), rtol=1e-13)
    assert qp.geometry.has_surface and qp.geometry.surface is level and qp.geometry.far_field == fine.delta
    sub = coarse_qp(level, fine.qp.geometry, idx[:3])
    assert sub.n == 3 and sub.H.kind == "FFTOperator"
    np.testing.assert_array_equal(sub.ubar, ref.ubar[:3])


def test_coarse_qp_poses_periodic_levels_on_their_rigid_body_trial_set() -> None:
    s = rmd_surface_n(32, 0.7, seed=1)
    fine = InstanceBuilder(s, 1e9, "bcc", periodic=True).build(paper_max_displacement(s))
    assert fine.n == s.heights.size  # the fine periodic problem is the whole grid ...
    level = s.levels[-1]
    idx = level_trial_set(level, fine.qp.geometry)
    qp = coarse_qp(level, fine.qp.geometry, idx)
    assert 0 < qp.n < level.heights.size and np.all(qp.ubar >= 0)  # ... a coarse level is not
    assert qp.geometry.periodic is True


def test_coarse_qp_needs_the_fine_context() -> None:
    s = rmd_surface_n(16, 0.7)
    g = InstanceBuilder(s, 1e9).build(paper_max_displacement(s)).qp.geometry
    with pytest.raises(ProblemInputError, match="far-field"):
        coarse_qp(s.levels[-1], replace(g, far_field=None), np.arange(3))
    with pytest.raises(ProblemInputError, match="E and kernel"):
        coarse_qp(s.levels[-1], replace(g, E=None), np.arange(3))
