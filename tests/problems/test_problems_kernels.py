"""Influence-coefficient formulas (paper eqs. green, green2; Love 1929) and the
periodic table conventions of problems/kernels.py."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.kernels import bcc_coefficients, kernel_table, love_coefficients, periodic_table

E, DELTA = 3.0e9, 2.0e-6


def test_bcc_diagonal_is_2_over_pi_E_delta() -> None:
    assert bcc_coefficients(np.array(0), np.array(0), DELTA, E) == pytest.approx(2.0 / (np.pi * E * DELTA), rel=1e-14)


@pytest.mark.parametrize("dx,dy", [(1, 0), (0, 1), (1, 1), (3, -2), (-7, 5)])
def test_bcc_off_diagonal_is_arcsin_form(dx: int, dy: int) -> None:
    r = np.hypot(dx, dy) * DELTA
    expected = 2.0 / (np.pi * E * DELTA) * np.arcsin(DELTA / (2.0 * r))
    assert bcc_coefficients(np.array(dx), np.array(dy), DELTA, E) == pytest.approx(expected, rel=1e-14)


def test_love_centre_value_per_unit_pressure() -> None:
    """Centre of a square of half-side a under unit pressure: (8/pi) a ln(1+sqrt 2) / E*."""
    a = DELTA / 2.0
    per_unit_force = love_coefficients(np.array(0), np.array(0), DELTA, E)
    per_unit_pressure = per_unit_force * DELTA**2
    assert per_unit_pressure == pytest.approx(8.0 / np.pi * a * np.log(1.0 + np.sqrt(2.0)) / E, rel=1e-13)


@pytest.mark.parametrize("kernel", [bcc_coefficients, love_coefficients])
def test_far_field_tends_to_point_force(kernel) -> None:
    """Both kernels tend to Boussinesq's 1/(pi E* r) per unit force, error O(r^-2)."""
    errs = []
    for r in (10, 100, 1000):
        dx, dy = np.array(3 * r), np.array(4 * r)  # r_cells = 5 r
        dist = 5 * r * DELTA
        errs.append(abs(kernel(dx, dy, DELTA, E) * np.pi * E * dist - 1.0))
    assert errs[-1] < 1e-6
    assert errs[0] > errs[1] > errs[2]


@pytest.mark.parametrize("kernel", ["bcc", "love", "spectral"])
def test_periodic_table_has_zero_mean_and_is_even(kernel: str) -> None:
    t = periodic_table(kernel, (12, 12), DELTA, E)
    assert abs(t.mean()) <= 1e-12 * np.abs(t).max()
    mirrored = np.roll(np.roll(t[::-1, ::-1], 1, axis=0), 1, axis=1)  # t[-i, -j]
    assert np.allclose(t, mirrored, rtol=0, atol=1e-13 * np.abs(t).max())


def test_aperiodic_table_is_even_and_positive() -> None:
    N = 8
    for name in ("bcc", "love"):
        t = kernel_table(name, (N, N), DELTA, E, periodic=False)
        assert t.shape == (2 * N, 2 * N)
        mirrored = np.roll(np.roll(t[::-1, ::-1], 1, axis=0), 1, axis=1)
        assert np.allclose(t, mirrored, rtol=1e-14, atol=0)
        used = np.delete(np.delete(t, N, axis=0), N, axis=1)
        assert (used > 0).all()


def test_spectral_kernel_refuses_aperiodic_and_unknown_kernels() -> None:
    with pytest.raises(ProblemInputError, match="periodic domains only"):
        kernel_table("spectral", (8, 8), DELTA, E, periodic=False)
    with pytest.raises(ProblemInputError, match="unknown kernel 'hertz'"):
        kernel_table("hertz", (8, 8), DELTA, E, periodic=False)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_kernel_table_refuses_bad_E_and_delta(bad: float) -> None:
    with pytest.raises(ProblemInputError, match="E \\(composite modulus\\)"):
        kernel_table("bcc", (8, 8), DELTA, bad, periodic=False)
    with pytest.raises(ProblemInputError, match="delta \\(grid spacing\\)"):
        kernel_table("bcc", (8, 8), bad, E, periodic=False)


@pytest.mark.parametrize("kernel", ["bcc", "love"])
def test_periodic_image_sum_converges(kernel: str) -> None:
    """With the far-image correction two shells agree with twelve to 1e-4 of the diagonal
    (the plain truncated sum is off by ~7e-3 at this size)."""
    t2 = periodic_table(kernel, (16, 16), DELTA, E, images=2)
    t12 = periodic_table(kernel, (16, 16), DELTA, E, images=12)
    assert np.max(np.abs(t2 - t12)) < 1e-4 * t12[0, 0]


@pytest.mark.parametrize("kernel, shape, delta", [("bcc", (16, 16), 1e-6), ("love", (12, 20), (1e-6, 2e-6)),
                                                  ("bcc", (2, 2), 1e-6)])
def test_an_embedded_kernel_spectrum_from_its_quarter_is_the_full_transform(kernel, shape, delta) -> None:
    """The aperiodic embedding's spectrum by a DCT-I of its quarter equals rfft2 of the whole
    table to round-off; a table that is not exactly even, a periodic one and a grid of one
    row take the full transform (None)."""
    import scipy.fft as sfft

    from contactbench.problems.fft_transform import KernelTransform, embedded_even_spectrum

    table = kernel_table(kernel, shape, delta, 1e9, False)
    full = sfft.rfft2(table)
    quarter = embedded_even_spectrum(table, shape)
    assert quarter is not None and quarter.shape == full.shape and quarter.dtype == np.float64
    np.testing.assert_allclose(quarter, full.real, rtol=0, atol=1e-14 * np.abs(full).max())
    np.testing.assert_array_equal(KernelTransform(table, shape).khat, quarter)
    odd = table.copy()
    odd[1, 1] *= 1.0 + 1e-12  # its mirror [2 N1 - 1, 1] is left as it was
    assert embedded_even_spectrum(odd, shape) is None
    assert np.iscomplexobj(KernelTransform(odd, shape).khat) or np.abs(sfft.rfft2(odd).imag).max() <= 1e-12
    assert embedded_even_spectrum(kernel_table("bcc", (8, 8), 1e-6, 1e9, True), (8, 8)) is None
    assert embedded_even_spectrum(kernel_table("love", (1, 5), 1e-6, 1e9, False), (1, 5)) is None


def _reflection(table: np.ndarray) -> np.ndarray:
    p1, p2 = table.shape
    return table[(-np.arange(p1)) % p1][:, (-np.arange(p2)) % p2]


@pytest.mark.parametrize("shape", [(16, 16), (8, 12), (7, 5)])
def test_every_table_equals_its_reflection_exactly(shape: tuple[int, int]) -> None:
    """K(-k) == K(k) bit for bit, so H is exactly symmetric: the spectral table (an inverse
    FFT, even only to round-off) and the layer-corrected tables too."""
    from contactbench.problems.layers import Layer

    tables = [kernel_table("spectral", shape, (DELTA, 1.3 * DELTA), E, periodic=True),
              kernel_table("spectral", shape, DELTA, E, periodic=True, layer=Layer(5 * DELTA)),
              periodic_table("spectral", shape, DELTA, E)]
    for periodic in (True, False):
        for kernel in ("bcc", "love"):
            tables.append(kernel_table(kernel, shape, DELTA, E, periodic=periodic))
            tables.append(kernel_table(kernel, shape, DELTA, E, periodic=periodic, layer=Layer(30 * DELTA)))
    for table in tables:
        assert np.array_equal(table, _reflection(table))


def test_an_exported_spectral_h_is_exactly_symmetric() -> None:
    from contactbench.problems.instances import InstanceBuilder
    from contactbench.problems.surfaces import fourier_synthesis

    inst = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=3), 1e9, "spectral",
                           periodic=True).build(1e-6)
    H = inst.qp.H.to_dense()
    assert H.shape == (256, 256) and np.array_equal(H, H.T)
