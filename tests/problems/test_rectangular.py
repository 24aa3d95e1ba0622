"""Rectangular grids (N0 x N1, spacings d0 x d1): kernels, the FFT operator, exact solves
and measured maps read uncropped, against references built independently."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.io import load_surface
from contactbench.problems.kernels import bcc_coefficients, kernel_table, love_coefficients, periodic_table
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operators import FFTOperator, KernelTransform
from contactbench.problems.surfaces import Surface, rmd_surface_n, spectral_surface
from contactbench.solvers import SolverSettings, get_solver

E = 2.0e9
SHAPE = (48, 32)
SPACING = (1.0e-6, 1.5e-6)  # rectangular pixels


def _offsets(idx: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.divmod(idx, shape[1])
    return i[:, None] - i[None, :], j[:, None] - j[None, :]


def _spectral_dense(idx: np.ndarray, shape: tuple[int, int], spacing: tuple[float, float]) -> np.ndarray:
    """H[a, b] = (1 / (L0 L1)) sum_{q != 0} 2 / (E |q|) cos(q . (x_a - x_b)) / (d0 d1)
    summed mode by mode (no FFT): the periodic continuum compliance per unit force."""
    di, dj = _offsets(idx, shape)
    k0 = np.fft.fftfreq(shape[0]) * shape[0]
    k1 = np.fft.fftfreq(shape[1]) * shape[1]
    L0, L1 = shape[0] * spacing[0], shape[1] * spacing[1]
    H = np.zeros(di.shape)
    for a in k0:
        for b in k1:
            if a == 0 and b == 0:
                continue
            q = np.hypot(2 * np.pi * a / L0, 2 * np.pi * b / L1)
            H += 2.0 / (E * q) * np.cos(2 * np.pi * (a * di / shape[0] + b * dj / shape[1]))
    return H / (L0 * L1)


@pytest.mark.parametrize("kernel,periodic,spacing", [
    ("love", False, SPACING), ("love", False, 1.0e-6), ("bcc", False, 1.0e-6),
    ("spectral", True, SPACING), ("love", True, SPACING), ("bcc", True, 1.0e-6)])
def test_fft_matvec_equals_the_dense_kernel_on_a_rectangular_grid(kernel: str, periodic: bool,
                                                                   spacing: object) -> None:
    rng = np.random.default_rng(3)
    idx = np.sort(rng.choice(SHAPE[0] * SHAPE[1], 300, replace=False))
    op = FFTOperator(KernelTransform(kernel_table(kernel, SHAPE, spacing, E, periodic), SHAPE), idx, auto_dense=False)
    di, dj = _offsets(idx, SHAPE)
    if not periodic:
        H = {"love": love_coefficients, "bcc": bcc_coefficients}[kernel](di, dj, spacing, E)
    elif kernel == "spectral":
        H = _spectral_dense(idx, SHAPE, spacing)  # type: ignore[arg-type]
    else:
        H = periodic_table(kernel, SHAPE, spacing, E)[di % SHAPE[0], dj % SHAPE[1]]
    x = rng.normal(size=idx.size)
    assert np.linalg.norm(op.matvec(x) - H @ x) <= 1e-11 * np.linalg.norm(H @ x)
    np.testing.assert_allclose(op.to_dense(), H, rtol=0, atol=1e-11 * np.abs(H).max())


def test_love_rectangle_centre_value() -> None:
    """Centre of a 2a x 2b rectangle under unit pressure: (4 / (pi E*)) (a asinh(b/a) + b asinh(a/b))."""
    a, b = 0.5 * SPACING[0], 0.5 * SPACING[1]
    per_pressure = love_coefficients(np.array(0), np.array(0), SPACING, E) * SPACING[0] * SPACING[1]
    assert per_pressure == pytest.approx(4.0 / (np.pi * E) * (a * np.arcsinh(b / a) + b * np.arcsinh(a / b)), rel=1e-13)


def test_love_rectangle_is_the_square_kernel_transposed() -> None:
    """Swapping the axes of the element and of the offset gives the same coefficient."""
    i, j = np.mgrid[-5:6, -4:5]
    np.testing.assert_allclose(love_coefficients(i, j, SPACING, E), love_coefficients(j, i, SPACING[::-1], E),
                               rtol=1e-13)


def test_periodic_rectangular_image_tail_is_converged_and_scale_free() -> None:
    """The closed-form tail of the far images on a rectangular lattice: M = 2 matches M = 10
    to 1e-4 of the diagonal; the table scales as 1 / length (lattice density in the tail)."""
    t2 = periodic_table("love", (16, 10), (1.0, 2.0), E, images=2)
    t10 = periodic_table("love", (16, 10), (1.0, 2.0), E, images=10)
    assert np.abs(t2 - t10).max() <= 1e-4 * t10[0, 0]
    tiny = periodic_table("love", (16, 10), (1e-6, 2e-6), E, images=2)
    np.testing.assert_allclose(tiny * 1e-6, t2, rtol=0, atol=1e-12 * t2[0, 0])


def test_periodic_love_tends_to_the_spectral_kernel_away_from_the_element() -> None:
    love = periodic_table("love", SHAPE, SPACING, E)
    spec = periodic_table("spectral", SHAPE, SPACING, E)
    far = (np.abs(np.fft.fftfreq(SHAPE[0]) * SHAPE[0])[:, None] >= 8) | (np.abs(np.fft.fftfreq(SHAPE[1]) * SHAPE[1])[None, :] >= 8)
    assert np.abs(love - spec)[far].max() <= 2e-3 * love[0, 0]


def test_bcc_needs_square_elements() -> None:
    with pytest.raises(ProblemInputError, match="'bcc' kernel needs square elements"):
        kernel_table("bcc", SHAPE, SPACING, E, periodic=False)
    with pytest.raises(ProblemInputError, match="axis 1"):
        kernel_table("love", SHAPE, (1e-6, -1.0), E, periodic=False)


def rect_surface(shape: tuple[int, int] = SHAPE, spacing: tuple[float, float] = SPACING, seed: int = 1) -> Surface:
    """A rough rectangular surface: a 64 x 64 spectral surface cut to ``shape``, with the spacings given."""
    s = spectral_surface(64, 0.7, length=64e-6, rms_height=0.3e-6, seed=seed)
    return Surface(s.heights[: shape[0], : shape[1]].copy(), spacing[0], delta1=spacing[1], name="rect")


@pytest.mark.parametrize("solver", ["nnls", "pk"])
def test_exact_solvers_match_the_dense_nnls_reference_on_a_rectangular_map(solver: str) -> None:
    surf = rect_surface()
    builder = InstanceBuilder(surf, E, kernel="love", periodic=False)
    inst = builder.build(0.8 * paper_max_displacement(surf))
    ref = exact_solution(inst.qp.H.to_dense(), inst.qp.ubar)
    H = love_coefficients(*_offsets(inst.qp.geometry.indices, SHAPE), SPACING, E)  # independent of the table
    np.testing.assert_allclose(inst.qp.H.to_dense(), H, rtol=1e-12, atol=0)
    res = get_solver(solver).solve(inst.qp, SolverSettings(tol=1e-12))
    assert kkt_check(inst, res.p).kkt_error < 1e-8
    np.testing.assert_allclose(res.p, ref.p, rtol=0, atol=1e-7 * ref.p.max())
    assert inst.nominal_area == pytest.approx(SHAPE[0] * SHAPE[1] * SPACING[0] * SPACING[1])


def test_a_square_map_padded_below_contact_gives_the_square_answer() -> None:
    """Rows and columns far below the surface never enter the trial set: the 32 x 32 square
    and the same map padded to 32 x 48 have the same non-periodic answer."""
    sq = rmd_surface_n(32, 0.7, "saupe", length=32e-6, rms_height=0.3e-6, seed=2)
    padded = np.full((32, 48), sq.heights.min() - 10e-6)
    padded[:, 8:40] = sq.heights
    rect = Surface(padded, sq.delta, name="padded")
    D = 0.7 * paper_max_displacement(sq)
    a = InstanceBuilder(sq, E, kernel="bcc").build(D)
    b = InstanceBuilder(rect, E, kernel="bcc").build(D)
    ia, ja = np.divmod(a.qp.geometry.indices, 32)
    ib, jb = np.divmod(b.qp.geometry.indices, 48)
    np.testing.assert_array_equal(ia, ib)
    np.testing.assert_array_equal(ja + 8, jb)
    pa = exact_solution(a.qp.H.to_dense(), a.qp.ubar).p
    pb = exact_solution(b.qp.H.to_dense(), b.qp.ubar).p
    np.testing.assert_allclose(pb, pa, rtol=0, atol=1e-12 * pa.max())


def test_a_periodic_map_tiled_along_one_axis_gives_the_tiled_answer() -> None:
    """Periodic: the 16 x 16 map tiled to 16 x 32 (L1 doubled) has the tiled answer, twice the load."""
    sq = spectral_surface(16, 0.7, length=16e-6, rms_height=0.3e-6, seed=4)
    tiled = Surface(np.tile(sq.heights, (1, 2)), sq.delta, periodic=True, name="tiled")
    D = 0.3 * (sq.z_max - sq.z_mean)
    a = InstanceBuilder(sq, E, kernel="spectral", periodic=True).build(D)
    b = InstanceBuilder(tiled, E, kernel="spectral", periodic=True).build(D)
    # The whole grid is singular along the constant vector: solve on the rigid-body set with a margin.
    keep_a = np.flatnonzero(a.qp.ubar > -0.5 * D)
    keep_b = np.flatnonzero(b.qp.ubar > -0.5 * D)
    pa = exact_solution(a.qp.restrict(keep_a).H.to_dense(), a.qp.ubar[keep_a]).p
    pb = exact_solution(b.qp.restrict(keep_b).H.to_dense(), b.qp.ubar[keep_b]).p
    fa, fb = np.zeros(16 * 16), np.zeros(16 * 32)
    fa[keep_a], fb[keep_b] = pa, pb
    np.testing.assert_allclose(fb.reshape(16, 32), np.tile(fa.reshape(16, 16), (1, 2)), rtol=0, atol=1e-9 * pa.max())
    assert fb.sum() == pytest.approx(2.0 * fa.sum(), rel=1e-9)


def test_a_64_by_48_npy_map_given_its_true_width_runs_uncropped(tmp_path: Path) -> None:
    z = rect_surface((64, 48), (1.0, 1.0)).heights
    np.save(tmp_path / "map.npy", z)
    s = load_surface(tmp_path / "map.npy", length=64e-6, detrend="none")
    assert s.shape == (64, 48) and s.spacing == (1e-6, 1e-6) and s.lengths == pytest.approx((64e-6, 48e-6))
    np.testing.assert_array_equal(s.heights, z)
    inst = InstanceBuilder(s, E, kernel="bcc").build(0.5 * paper_max_displacement(s))
    assert inst.total_elements == 64 * 48
    res = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-10))
    assert kkt_check(inst, res.p).kkt_error < 1e-8
    ref = exact_solution(inst.qp.H.to_dense(), inst.qp.ubar).p
    np.testing.assert_allclose(res.p, ref, rtol=0, atol=1e-7 * ref.max())


def test_a_512_by_384_npy_map_keeps_its_shape_and_the_spacing_it_states(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    np.save(tmp_path / "big.npy", rng.normal(0.0, 1e-7, (512, 384)))
    s = load_surface(tmp_path / "big.npy", length=512e-6)  # the true size along axis 0: 1 um pixels
    assert s.shape == (512, 384) and s.spacing == (1e-6, 1e-6)
    assert s.lengths == pytest.approx((512e-6, 384e-6)) and s.meta["crop"] == "none"
    r = load_surface(tmp_path / "big.npy", length=(512e-6, 768e-6))
    assert r.shape == (512, 384) and r.spacing == pytest.approx((1e-6, 2e-6))
    with pytest.warns(UserWarning, match="cropped 512x384 to the central 384x384"):
        c = load_surface(tmp_path / "big.npy", length=512e-6, crop="square")
    assert c.shape == (384, 384) and c.spacing == (1e-6, 1e-6)  # a crop keeps the stated spacing


def test_a_surface_file_recipe_passes_its_cleaning_and_length_per_axis(tmp_path: Path) -> None:
    from contactbench.problems.scenes import SceneConfig, get_scene
    from contactbench.problems.scenes.core import surface_from_params

    np.save(tmp_path / "m.npy", rect_surface((24, 16), (1.0, 1.0)).heights)
    scene = get_scene("paper-sweep")
    with pytest.raises(ProblemInputError, match="'bcc' kernel needs square elements"):  # refused before anything runs
        scene.validate(scene.config(SceneConfig(surface_path=str(tmp_path / "m.npy"), length=(24e-6, 32e-6))))
    cfg = scene.config(SceneConfig(surface_path=str(tmp_path / "m.npy"), length=(24e-6, 32e-6), steps=2, kernel="love",
                                   extra={"detrend": "none", "crop": "none", "nan": "error"}))
    scene.validate(cfg)
    (spec,) = scene.instances(cfg)
    s = surface_from_params(spec.params)
    assert s.shape == (24, 16) and s.spacing == pytest.approx((1e-6, 2e-6)) and s.meta["detrend"] == "none"
    inst = spec.build().at(1)
    assert inst.qp.geometry.spacing == pytest.approx((1e-6, 2e-6))
    with pytest.warns(UserWarning, match="cropped"):
        sq = surface_from_params({**spec.params, "crop": "square"})
    assert sq.shape == (16, 16)
    with pytest.raises(ProblemInputError, match="a generated surface is square"):
        surface_from_params({"size": 32, "hurst": 0.7, "length": [1e-4, 2e-4], "seed": 0})
