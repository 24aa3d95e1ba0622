"""FFT matrix-free operator versus a dense H assembled independently from the kernel
formulas; symmetry and positive definiteness of H on random trial sets."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.kernels import bcc_coefficients, kernel_table, love_coefficients
from contactbench.problems.operators import DenseOperator, FFTOperator, KernelTransform
from contactbench.problems.surfaces import Surface

N, DELTA, E = 14, 1.5e-6, 2.0e9
CASES = [("bcc", False), ("love", False), ("bcc", True), ("love", True), ("spectral", True)]
FORMULAS = {"bcc": bcc_coefficients, "love": love_coefficients}


def random_subset(rng: np.random.Generator, fraction: float) -> np.ndarray:
    return np.sort(rng.choice(N * N, int(fraction * N * N), replace=False))


def dense_from_formula(kernel: str, periodic: bool, idx: np.ndarray) -> np.ndarray:
    """H_II built entry by entry: the kernel formula at the pair offsets (aperiodic), or
    the periodic table read at the offsets modulo N."""
    i, j = np.divmod(idx, N)
    di = i[:, None] - i[None, :]
    dj = j[:, None] - j[None, :]
    if not periodic:
        return FORMULAS[kernel](di, dj, DELTA, E)
    table = kernel_table(kernel, (N, N), DELTA, E, periodic=True)
    return table[di % N, dj % N]


@pytest.mark.parametrize("kernel,periodic", CASES)
@pytest.mark.parametrize("fraction", [0.2, 0.6, 1.0])
def test_fft_matvec_equals_dense_matvec(kernel: str, periodic: bool, fraction: float) -> None:
    rng = np.random.default_rng([CASES.index((kernel, periodic)), int(10 * fraction)])
    idx = random_subset(rng, fraction)
    op = FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)
    H = dense_from_formula(kernel, periodic, idx)
    for _ in range(3):
        x = rng.normal(size=idx.size)
        y_dense = H @ x
        assert np.linalg.norm(op.matvec(x) - y_dense) <= 1e-12 * np.linalg.norm(y_dense)
    assert op.matvec_count == 3
    assert np.allclose(op.diagonal(), np.diag(H), rtol=1e-14, atol=0)
    cols = rng.choice(idx.size, 3, replace=False)
    assert np.allclose(op.submatrix(np.arange(idx.size), cols), H[:, cols], rtol=1e-13, atol=0)
    assert np.allclose(op.column(int(cols[0])), H[:, cols[0]], rtol=1e-13, atol=0)


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_restrict_and_dense_operator_agree(kernel: str, periodic: bool) -> None:
    rng = np.random.default_rng(7)
    idx = random_subset(rng, 0.5)
    op = FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)
    sub = rng.choice(idx.size, idx.size // 3, replace=False)
    restricted = op.restrict(sub)
    dense = DenseOperator(op.to_dense()).restrict(sub)
    x = rng.normal(size=sub.size)
    assert np.linalg.norm(restricted.matvec(x) - dense.matvec(x)) <= 1e-12 * np.linalg.norm(dense.matvec(x))
    assert restricted.frobenius_norm() == pytest.approx(dense.frobenius_norm(), rel=1e-10)


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_H_is_symmetric_positive_definite_on_random_subsets(kernel: str, periodic: bool) -> None:
    rng = np.random.default_rng(11)
    for fraction in (0.1, 0.5, 0.9):
        H = dense_from_formula(kernel, periodic, random_subset(rng, fraction))
        assert np.max(np.abs(H - H.T)) <= 1e-14 * np.max(np.abs(H))
        assert np.linalg.eigvalsh(H).min() > 1e-8 * np.abs(H).max()
        if not periodic:
            assert (H > 0).all()


def test_periodic_H_on_the_whole_grid_is_singular() -> None:
    """The q = 0 mode is removed, so H 1 = 0 on the full periodic grid (documented)."""
    H = dense_from_formula("bcc", True, np.arange(N * N))
    assert np.linalg.norm(H @ np.ones(N * N)) <= 1e-10 * np.linalg.norm(H)


def test_builder_dense_and_fft_operators_agree() -> None:
    rng = np.random.default_rng(3)
    surface = Surface(rng.normal(size=(N, N)) * 1e-6, DELTA)
    fft = InstanceBuilder(surface, E, "love", operator="fft").build(1.5e-6)
    dense = InstanceBuilder(surface, E, "love", operator="dense").build(1.5e-6)
    assert isinstance(dense.qp.H, DenseOperator) and isinstance(fft.qp.H, FFTOperator)
    x = rng.random(fft.n)
    assert np.linalg.norm(fft.qp.H.matvec(x) - dense.qp.H.matvec(x)) <= 1e-12 * np.linalg.norm(dense.qp.H.matvec(x))


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_ducc_and_scipy_fft_backends_agree_across_alternating_sets(kernel: str, periodic: bool, monkeypatch) -> None:
    """The ducc0 path reuses work arrays between calls and clears only what the last
    call wrote: alternate two index sets and a whole-field call on one transform and
    compare every result with the scipy.fft path and with the dense product."""
    from contactbench.problems.operators import _ducc_fft

    if _ducc_fft is None:
        pytest.skip("ducc0 not importable")
    rng = np.random.default_rng(11)
    transform = KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N))
    sets = [random_subset(rng, 0.7), random_subset(rng, 0.2)]
    ops = [FFTOperator(transform, idx, auto_dense=False) for idx in sets]
    dense = [dense_from_formula(kernel, periodic, idx) for idx in sets]
    for step in range(6):
        k = step % 2
        x = rng.normal(size=sets[k].size)
        monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "ducc")
        y_ducc = ops[k].matvec(x)
        field_ducc = ops[k].displacement_field(x) if step == 2 else None
        monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "scipy")
        y_scipy = ops[k].matvec(x)
        ref = dense[k] @ x
        assert np.linalg.norm(y_ducc - ref) <= 1e-12 * np.linalg.norm(ref)
        assert np.linalg.norm(y_ducc - y_scipy) <= 1e-12 * np.linalg.norm(ref)
        if field_ducc is not None:
            assert np.allclose(field_ducc.ravel()[sets[k]], ref, rtol=1e-11, atol=0)
            assert np.allclose(field_ducc, ops[k].displacement_field(x), rtol=0, atol=1e-12 * np.abs(ref).max())


def test_unknown_fft_backend_is_a_clear_error(monkeypatch) -> None:
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.operators import fft_backend

    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "fftw3")
    with pytest.raises(ProblemInputError, match="CONTACTBENCH_FFT_BACKEND"):
        fft_backend()


def test_fft_operator_pickles_after_use_and_still_agrees() -> None:
    """Instances travel to worker processes (harness --jobs, Dask): the transform's lock and
    work arrays must not stop that, and the copy must give the same products."""
    import pickle

    rng = np.random.default_rng(3)
    idx = random_subset(rng, 0.5)
    op = FFTOperator(KernelTransform(kernel_table("bcc", (N, N), DELTA, E, False), (N, N)), idx, auto_dense=False)
    x = rng.normal(size=idx.size)
    y = op.matvec(x)
    copy = pickle.loads(pickle.dumps(op))
    np.testing.assert_allclose(copy.matvec(x), y, rtol=1e-13, atol=0)
    np.testing.assert_allclose(op.matvec(x), y, rtol=1e-13, atol=0)
