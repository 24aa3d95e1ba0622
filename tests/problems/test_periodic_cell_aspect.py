"""Periodic real-space kernels ('bcc', 'love') on elongated cells: the image box is a
physical square, the table's spectrum is positive, a cell too long is refused, and the
square cell's table is what it was."""

from __future__ import annotations

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems import kernels
from contactbench.problems.kernels import kernel_table, periodic_table
from contactbench.problems.surfaces import Surface
from contactbench.solvers import SolverSettings, get_solver

E = 1.0


def _mode_compliance(table: np.ndarray) -> float:
    """The displacement amplitude of the longest cosine mode of pressure along axis 1 over
    Boussinesq's 2 / (E* q) (d = 1)."""
    n1, n2 = table.shape
    q = 2.0 * np.pi / n2
    p = np.tile(np.cos(q * np.arange(n2)), (n1, 1))
    u = np.real(np.fft.ifft2(np.fft.fft2(table) * np.fft.fft2(p)))
    return float(2.0 * np.sum(u * p) / p.size / (2.0 / (E * q)))


@pytest.mark.parametrize("kernel", ["love", "bcc"])
@pytest.mark.parametrize("shape", [(8, 256), (4, 256)])
def test_the_long_mode_of_an_elongated_cell_has_boussinesq_compliance(kernel: str, shape: tuple[int, int]) -> None:
    """Was 4.43 (8 x 256) and 16.2 (4 x 256): the image box reached a few short periods only."""
    ratio = _mode_compliance(kernel_table(kernel, shape, 1.0, E, periodic=True))
    assert abs(ratio - 1.0) < 1e-2


@pytest.mark.parametrize("kernel, shape, spacing", [("love", (8, 256), 1.0), ("bcc", (4, 256), 1.0),
                                                    ("love", (32, 32), (1.0, 32.0)), ("love", (256, 8), (2.0, 1.0))])
def test_elongated_tables_have_a_positive_spectrum(kernel: str, shape: tuple[int, int], spacing: object) -> None:
    lam = np.fft.rfft2(periodic_table(kernel, shape, spacing, E)).real  # type: ignore[arg-type]
    assert lam.ravel()[1:].min() > 0.0


def test_a_cell_longer_than_the_cap_is_refused_towards_spectral() -> None:
    n2 = int(4 * kernels.MAX_CELL_ASPECT) * 2
    with pytest.raises(ProblemInputError, match=r"'love'.*4 x 512.*aspect ratio 128.*--kernel spectral"):
        kernel_table("love", (4, n2), 1.0, E, periodic=True)
    assert kernel_table("spectral", (4, n2), 1.0, E, periodic=True).shape == (4, n2)


def test_an_indefinite_periodic_table_is_refused() -> None:
    table = -kernel_table("spectral", (8, 256), 1.0, E, periodic=True)
    with pytest.raises(ProblemInputError, match=r"'love' table on the 8 x 256 grid \(cell aspect ratio 32\).*spectral"):
        kernels.check_periodic_spectrum(table, "love", (1.0, 1.0))
    good = kernel_table("spectral", (8, 256), 1.0, E, periodic=True)
    assert kernels.check_periodic_spectrum(good, "spectral", (1.0, 1.0)) is good


def test_westergaard_contact_share_on_a_long_strip() -> None:
    """16 x 256 strip, one wavelength of a sinusoid along the long axis, pbar = p* / 2:
    Westergaard's contact share 2/pi asin(sqrt(1/2)) = 1/2 within 3 cells (was 0.23)."""
    Ey, lam, h = 2e9, 50e-6, 0.5e-6
    n = 256
    d = lam / n
    surf = Surface(np.tile(h * np.cos(2.0 * np.pi * np.arange(n) / n), (16, 1)), d, name="sin")
    pstar = np.pi * Ey * h / lam
    inst = InstanceBuilder(surf, Ey, kernel="love", periodic=True).build_load(0.5 * pstar * surf.lengths[0] * surf.lengths[1])
    res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-10))
    assert res.converged
    share = np.count_nonzero(res.p > 1e-9 * res.p.max()) / (16 * n)
    assert abs(share - 0.5) * n <= 3.0


# The 16 x 16 square cell's tables at d = 1, E* = 1, images = 2 (offsets (0,0), (0,1), (1,1),
# (0,8), (8,8), (3,5)), as built before the box was made physically square.
SQUARE = {
    "love": (1.044642904003152, 0.25304111464516665, 0.15347147519335802, -0.022672865766670436,
             -0.032095794487565554, -0.017047121442399615),
    "bcc": (0.5609234884736753, 0.25781347154375367, 0.15470708918147225, -0.020812196919758552,
            -0.030235353701623502, -0.01518688673534424),
}


@pytest.mark.parametrize("kernel", ["love", "bcc"])
def test_a_square_cell_table_is_unchanged(kernel: str) -> None:
    t = periodic_table(kernel, (16, 16), 1.0, E)
    got = [t[i, j] for i, j in ((0, 0), (0, 1), (1, 1), (0, 8), (8, 8), (3, 5))]
    np.testing.assert_allclose(got, SQUARE[kernel], rtol=1e-12, atol=0)
