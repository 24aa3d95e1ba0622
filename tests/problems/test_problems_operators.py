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


@pytest.fixture(autouse=True, params=["whole", "blocked", "row-blocks"])
def column_pass(request, monkeypatch) -> str:
    """Every test of this module runs with both column passes of the ducc0 matvec -- one
    call per direction over the whole spectrum (short columns) and block by block in
    transposed buffers (long columns) -- and with the rows in one block, one row a block
    ("blocked"), or blocks of 2-8 rows with a short last one ("row-blocks"); a periodic grid
    with short columns takes the 2-D pair (``WHOLE_PERIODIC_PAIR``) in "whole" only."""
    from contactbench.problems import fft_transform

    monkeypatch.setattr(fft_transform, "WHOLE_PERIODIC_PAIR", request.param == "whole")

    monkeypatch.setattr(fft_transform, "TRANSPOSED_COLUMN_BYTES", 0 if request.param == "blocked" else 1 << 62)
    row_bytes = {"whole": fft_transform.ROW_BLOCK_BYTES, "blocked": 1, "row-blocks": 600}[request.param]
    monkeypatch.setattr(fft_transform, "ROW_BLOCK_BYTES", row_bytes)
    monkeypatch.setattr(fft_transform, "MIN_ROW_BLOCK", 1)
    return request.param


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
    """The ducc0 path reuses its row buffers between calls and clears what each call
    wrote: alternate two index sets and a whole-field call on one transform and compare
    every result with the scipy.fft path and with the dense product."""
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


@pytest.mark.parametrize("value", ["two", "1.5", "1e3"])
def test_fft_workers_not_a_whole_number_is_a_clear_error(value: str, monkeypatch) -> None:
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.fft_threads import fft_workers

    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", value)
    with pytest.raises(ProblemInputError, match="CONTACTBENCH_FFT_WORKERS"):
        fft_workers()


def test_fft_workers_default_is_the_cores_this_process_may_use(monkeypatch) -> None:
    import os

    from contactbench.problems.fft_threads import fft_workers

    monkeypatch.delenv("CONTACTBENCH_FFT_WORKERS", raising=False)
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert fft_workers() == usable
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", " 3 ")
    assert fft_workers() == 3


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


# --- precision (float32 products for mixed-precision solvers) and the blocked column pass


def _fft_op(kernel: str, periodic: bool, n: int, idx: np.ndarray) -> FFTOperator:
    return FFTOperator(KernelTransform(kernel_table(kernel, (n, n), DELTA, E, periodic), (n, n)), idx, auto_dense=False)


@pytest.mark.parametrize("backend", ["ducc", "scipy"])
@pytest.mark.parametrize("n", [14, 72])
@pytest.mark.parametrize("kernel,periodic", [("bcc", False), ("love", True)])
def test_float32_operator_matches_float64_after_restrict(kernel: str, periodic: bool, n: int, backend: str, monkeypatch) -> None:
    """with_precision(float32): same trial set, float32 products within ~1e-6 of float64
    (norm-wise), for float32 and float64 input, and after restrict; 72^2 has more
    spectrum columns than one block and is run on two threads (blocks split)."""
    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", backend)
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", "2")
    rng = np.random.default_rng([n, int(periodic)])
    idx = np.sort(rng.choice(n * n, n * n // 2, replace=False))
    op = _fft_op(kernel, periodic, n, idx)
    op32 = op.with_precision(np.float32)
    assert op.with_precision(np.float64) is op and op32.with_precision(np.float32) is op32
    assert op32.dtype == np.float32 and op32.n == op.n and op32.transform is op.transform
    for _ in range(2):
        x = rng.normal(size=op.n)
        y64 = op.matvec(x)
        for xin in (x, x.astype(np.float32)):
            y32 = op32.matvec(xin)
            assert y32.dtype == np.float32
            assert np.linalg.norm(y32 - y64) <= 3e-6 * np.linalg.norm(y64)
    sub = np.sort(rng.choice(op.n, op.n // 3, replace=False))
    r32, r64 = op32.restrict(sub), op.restrict(sub)
    assert r32.dtype == np.float32
    x = rng.normal(size=sub.size)
    assert np.linalg.norm(r32.matvec(x) - r64.matvec(x)) <= 3e-6 * np.linalg.norm(r64.matvec(x))
    assert op32.transform.spectrum(np.float32) is op.transform.spectrum(np.float32)  # one copy per transform


def test_float32_differs_from_float64_by_single_precision_roundoff() -> None:
    """The float32 path really runs in single precision (not a float64 product cast)."""
    rng = np.random.default_rng(5)
    op = _fft_op("bcc", False, 40, np.arange(1600))
    x = rng.normal(size=1600)
    rel = np.linalg.norm(op.with_precision(np.float32).matvec(x) - op.matvec(x)) / np.linalg.norm(op.matvec(x))
    assert 1e-9 < rel < 3e-6


def test_dense_operator_with_precision_and_bad_precision() -> None:
    from contactbench.problems.errors import ProblemInputError

    rng = np.random.default_rng(2)
    idx = random_subset(rng, 0.4)
    dense = DenseOperator(dense_from_formula("bcc", False, idx))
    d32 = dense.with_precision(np.float32)
    assert d32.H.dtype == np.float32 and dense.with_precision(np.float64) is dense
    assert d32.restrict(np.arange(5)).dtype == np.float32
    x = rng.normal(size=idx.size)
    assert np.linalg.norm(d32.matvec(x) - dense.matvec(x)) <= 1e-6 * np.linalg.norm(dense.matvec(x))
    assert d32.diagonal().dtype == np.float64
    with pytest.raises(ProblemInputError, match="precision"):
        dense.with_precision(np.float16)
    with pytest.raises(ProblemInputError, match="precision"):
        _fft_op("bcc", False, N, idx).with_precision("int32")


@pytest.mark.parametrize("periodic", [False, True])
def test_whole_grid_permuted_and_subset_sets_alternate_on_one_transform(periodic: bool, monkeypatch) -> None:
    """The whole grid in row-major order is loaded as a block; the same points in another
    order, and a subset, go through the indexed path; calls alternate on the shared work
    arrays (the clearing of the last call's entries) in both precisions."""
    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "ducc")
    rng = np.random.default_rng(9)
    transform = KernelTransform(kernel_table("bcc", (N, N), DELTA, E, periodic), (N, N))
    sets = [np.arange(N * N), rng.permutation(N * N)[: N * N], random_subset(rng, 0.3)]
    for dtype, tol in ((np.float64, 1e-12), (np.float32, 3e-6)):
        ops = [FFTOperator(transform, idx, auto_dense=False, dtype=dtype) for idx in sets]
        dense = [dense_from_formula("bcc", periodic, idx) for idx in sets]
        for step in (0, 2, 1, 1, 0, 0, 2, 1):
            x = rng.normal(size=sets[step].size)
            ref = dense[step] @ x
            assert np.linalg.norm(ops[step].matvec(x) - ref) <= tol * np.linalg.norm(ref)


@pytest.mark.parametrize("periodic", [False, True])
def test_row_pruned_transforms_agree_with_dense_for_sparse_inputs(periodic: bool, monkeypatch) -> None:
    """Sets on a few separated rows, and inputs zero on whole rows of the set (a CG
    direction on a small free set): a block's row transforms run only from its first to
    its last row holding input, and back only on the rows that hold points; calls with
    all-zero, sparse and full inputs alternate on one operator, in both precisions."""
    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "ducc")
    rng = np.random.default_rng(4)
    transform = KernelTransform(kernel_table("bcc", (N, N), DELTA, E, periodic), (N, N))
    rows = np.array([0, 1, 5, 12, 13])  # with blocks of 1, 2-8 and all rows: empty, partial and full blocks
    idx = np.sort(np.concatenate([r * N + rng.choice(N, 6, replace=False) for r in rows]))
    dense = dense_from_formula("bcc", periodic, idx)
    row_of = idx // N
    for dtype, tol in ((np.float64, 1e-12), (np.float32, 3e-6)):
        op = FFTOperator(transform, idx, auto_dense=False, dtype=dtype)
        for keep in ([0, 1, 5, 12, 13], [13], [], [0], [5, 12], [0, 1, 5, 12, 13]):
            x = rng.normal(size=idx.size) * np.isin(row_of, keep)
            ref = dense @ x
            got = op.matvec(x)
            assert np.linalg.norm(got - ref) <= tol * max(np.linalg.norm(ref), 1e-300)


@pytest.mark.parametrize("increasing", [True, False])
def test_row_plan_puts_every_point_in_its_block(increasing: bool) -> None:
    """The row plan of an index set: block k's points, taken in increasing index order,
    are the set's points on its rows, at their offsets inside the block."""
    from contactbench.problems.fft_threads import row_batch
    from contactbench.problems.fft_transform import _DuccWork, row_block

    assert all(row_block(p1) in (1, 2, 4, 8, 16, 32, 64) for p1 in (2, 28, 1000, 1 << 14, 1 << 20))
    assert row_batch(1 << 12, 4) == 8 and row_batch(1 << 12, 8) == 0 and row_batch(64, 4) == 0
    rng = np.random.default_rng(2)
    work = _DuccWork((N, N), (2 * N, 2 * N), np.dtype(np.float64))
    p1, rb = 2 * N, work.row_rows
    grid = random_subset(rng, 0.4)
    pidx = (grid // N) * p1 + grid % N
    if not increasing:
        pidx = rng.permutation(pidx)
    plan = work.plan(pidx)
    assert work.plan(pidx) is plan and not plan.whole and work.row_blocks == -(-N // rb)
    ordered = pidx if plan.order is None else pidx[plan.order]
    assert (plan.order is None) == increasing and np.all(np.diff(ordered) > 0)
    for k in range(work.row_blocks):
        s, e = plan.seg[k], plan.seg[k + 1]
        assert np.array_equal(plan.local[s:e] + k * rb * p1, ordered[s:e])
        assert np.all((plan.local[s:e] >= 0) & (plan.local[s:e] < rb * p1))
    whole = (np.arange(N)[:, None] * p1 + np.arange(N)).ravel()
    assert work.plan(whole).whole and work.plan(None).whole


def test_float32_operator_pickles_and_reports_at_most_half_the_work_memory() -> None:
    import pickle

    rng = np.random.default_rng(4)
    op32 = _fft_op("bcc", False, N, random_subset(rng, 0.5)).with_precision(np.float32)
    x = rng.normal(size=op32.n)
    y = op32.matvec(x)
    np.testing.assert_allclose(pickle.loads(pickle.dumps(op32)).matvec(x), y, rtol=1e-6, atol=1e-6 * np.abs(y).max())
    op64 = op32.with_precision(np.float64)
    assert 0 < 2 * op32.matvec_work_nbytes <= op64.matvec_work_nbytes  # float32 row blocks have fewer rows


@pytest.mark.parametrize("periodic", [False, True])
def test_fft_floor_pair_runs_the_transform_pair_on_its_own_arrays(periodic: bool) -> None:
    """The benchmark's FFT floor runs in both precisions and both layouts, leaves the
    operator's work alone, and names an unknown layout."""
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.operators import FLOOR_LAYOUTS, fft_floor_pair

    rng = np.random.default_rng(8)
    idx = random_subset(rng, 0.5)
    op = _fft_op("bcc", periodic, N, idx)
    x = rng.normal(size=idx.size)
    y = op.matvec(x)
    for dtype in (np.float64, np.float32):
        for layout in FLOOR_LAYOUTS:
            fft_floor_pair(op.transform, dtype, layout)()
    np.testing.assert_allclose(op.matvec(x), y, rtol=1e-13, atol=0)
    with pytest.raises(ProblemInputError, match="layout 'diagonal'"):
        fft_floor_pair(op.transform, np.float64, "diagonal")


def test_small_trial_sets_switch_to_the_dense_block_with_the_same_numbers() -> None:
    """The hybrid operator: after DENSE_SWITCH_AFTER products a set small enough for
    ``dense_pays`` (DENSE_SWITCH_FACTOR x P log2 P entries) is multiplied as a dense block
    gathered from the kernel table; a larger set stays on the FFT."""
    from contactbench.problems.operators import DENSE_SWITCH_AFTER, DENSE_SWITCH_FACTOR

    transform = KernelTransform(kernel_table("bcc", (N, N), DELTA, E, False), (N, N))
    P = int(np.prod(transform.padded_shape))
    limit = int(np.sqrt(DENSE_SWITCH_FACTOR * P * np.log2(P)))
    rng = np.random.default_rng(3)
    for n, switches in ((limit, True), (limit + 1, False)):
        idx = np.sort(rng.choice(N * N, n, replace=False))
        op = FFTOperator(transform, idx, auto_dense=True)
        H = dense_from_formula("bcc", False, idx)
        for k in range(DENSE_SWITCH_AFTER + 2):
            x = rng.normal(size=n)
            assert np.linalg.norm(op.matvec(x) - H @ x) <= 1e-12 * np.linalg.norm(H @ x)
        assert op.uses_dense is switches


def test_a_block_no_dearer_than_an_fft_pair_is_taken_at_the_first_product() -> None:
    """At most ``DENSE_SWITCH_AT_ONCE_FACTOR`` x P log2 P entries: the block is gathered at
    the first matvec and no FFT runs; above it (within ``dense_pays``) the FFT runs until
    the ``DENSE_SWITCH_AFTER``-th product, which is the block's.  The same numbers either way."""
    from contactbench.problems.operators import DENSE_SWITCH_AFTER, DENSE_SWITCH_AT_ONCE_FACTOR, DENSE_SWITCH_FACTOR

    transform = KernelTransform(kernel_table("bcc", (N, N), DELTA, E, False), (N, N))
    P = int(np.prod(transform.padded_shape))
    at_once = int(np.sqrt(DENSE_SWITCH_AT_ONCE_FACTOR * P * np.log2(P)))
    later = int(np.sqrt(DENSE_SWITCH_FACTOR * P * np.log2(P)))
    rng = np.random.default_rng(4)
    fft_products = DENSE_SWITCH_AFTER - 1
    for n, ffts_before in ((at_once, 0), (at_once + 1, fft_products), (later, fft_products)):
        idx = np.sort(rng.choice(N * N, n, replace=False))
        op = FFTOperator(transform, idx, auto_dense=True)
        H = dense_from_formula("bcc", False, idx)
        count0 = transform.fft_count
        for _ in range(DENSE_SWITCH_AFTER + 2):
            x = rng.normal(size=n)
            assert np.linalg.norm(op.matvec(x) - H @ x) <= 1e-12 * np.linalg.norm(H @ x)
        assert op.uses_dense and transform.fft_count - count0 == 2 * ffts_before, n


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_partial_product_is_the_block_times_x_and_signs_are_known(kernel: str, periodic: bool) -> None:
    """H[rows, cols] x without the block, against the formula's dense H: the FFT operator
    (even table read at |offsets|, chunked over columns), the dense one, and the generic
    path; ``entry_floor`` is at or under every entry (< 0 for the periodic kernels)."""
    from contactbench.problems import operators
    from contactbench.problems.operators import ContactOperator

    rng = np.random.default_rng(5)
    idx = random_subset(rng, 0.7)
    op = FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)
    H = dense_from_formula(kernel, periodic, idx)
    rows = np.sort(rng.choice(idx.size, idx.size // 2, replace=False))
    cols = rng.choice(idx.size, 9, replace=False)  # unsorted, as raised points come
    x = rng.random(cols.size)
    want = H[np.ix_(rows, cols)] @ x
    chunk = operators.PARTIAL_PRODUCT_CHUNK
    for op_ in (op, DenseOperator(H)):
        for operators.PARTIAL_PRODUCT_CHUNK in (chunk, 7):  # one chunk, and many
            np.testing.assert_allclose(op_.partial_product(rows, cols, x), want, rtol=1e-13, atol=0)
        operators.PARTIAL_PRODUCT_CHUNK = chunk
        floor = op_.entry_floor()
        assert floor is not None and floor <= min(0.0, H.min()) and (floor < 0) is periodic
    np.testing.assert_allclose(ContactOperator.partial_product(op, rows, cols, x), want, rtol=1e-13, atol=0)
    assert op.partial_product(rows, cols[:0], x[:0]).tolist() == [0.0] * rows.size
    assert ContactOperator.partial_product_pays(op, 1) is False and ContactOperator.entry_floor(op) is None
    P = int(np.prod(op.transform.padded_shape))
    budget = operators.PARTIAL_PRODUCT_FACTOR * P * np.log2(P)
    assert op.partial_product_pays(int(budget)) and not op.partial_product_pays(int(budget) + 1)


@pytest.mark.parametrize("kernel,periodic", [("bcc", False), ("love", True)])
def test_a_large_partial_product_is_shared_out_the_same_on_any_threads(kernel: str, periodic: bool,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Past ``PARALLEL_PARTIAL_ENTRIES`` the columns go out in ``PARTIAL_PRODUCT_GROUPS``
    groups over the FFT threads and come back in group order: the formula's answer, and the
    same numbers on 1, 2 or 3 threads (and with fewer columns than groups, one pass)."""
    from contactbench.problems import operators

    rng = np.random.default_rng(8)
    idx = random_subset(rng, 0.8)
    op = FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)
    H = dense_from_formula(kernel, periodic, idx)
    rows = np.sort(rng.choice(idx.size, idx.size // 2, replace=False))
    cols = rng.choice(idx.size, 21, replace=False)
    x = rng.random(cols.size)
    monkeypatch.setattr(operators, "PARALLEL_PARTIAL_ENTRIES", 1)
    answers = []
    for workers in ("1", "2", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        answers.append(op.partial_product(rows, cols, x))
    np.testing.assert_allclose(answers[0], H[np.ix_(rows, cols)] @ x, rtol=1e-13, atol=0)
    assert all(np.array_equal(answers[0], a) for a in answers[1:])
    few = cols[:operators.PARTIAL_PRODUCT_GROUPS - 1]
    np.testing.assert_allclose(op.partial_product(rows, few, x[:few.size]), H[np.ix_(rows, few)] @ x[:few.size],
                               rtol=1e-13, atol=0)


@pytest.mark.parametrize("kernel,periodic", [("bcc", False), ("love", True)])
def test_many_partial_products_on_the_threads_are_each_one_alone(kernel: str, periodic: bool,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """``partial_products`` runs each product whole on one thread: the numbers of one
    ``partial_product`` each, items large (column groups) and small, empty ones too, on 1 or
    3 threads; the generic operator's is the same loop."""
    from contactbench.problems import operators
    from contactbench.problems.operators import ContactOperator

    rng = np.random.default_rng(9)
    idx = random_subset(rng, 0.8)
    op = FFTOperator(KernelTransform(kernel_table(kernel, (N, N), DELTA, E, periodic), (N, N)), idx)
    H = dense_from_formula(kernel, periodic, idx)
    monkeypatch.setattr(operators, "PARALLEL_PARTIAL_ENTRIES", 200)
    items = []
    for size in (3, 40, 0, 25, 90, 1):
        rows = np.sort(rng.choice(idx.size, max(size, 1), replace=False))
        cols = rng.choice(idx.size, size, replace=False)
        items.append((rows, cols, rng.normal(size=size)))
    for workers in ("1", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        got = op.partial_products(items)
        assert len(got) == len(items)
        for (rows, cols, x), y in zip(items, got):
            np.testing.assert_allclose(y, op.partial_product(rows, cols, x), rtol=1e-15, atol=0)
            np.testing.assert_allclose(y, H[np.ix_(rows, cols)] @ x, rtol=1e-12, atol=1e-30)
    generic = ContactOperator.partial_products(op, items)
    assert all(np.array_equal(a, op.partial_product(*it)) for a, it in zip(generic, items))
    assert op.partial_products([]) == []


def test_each_on_pool_keeps_the_order_and_every_item_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Items of unequal cost come back in their order, each computed once, on more threads
    than items, fewer, or one; no items, no call."""
    import threading
    import time

    from contactbench.problems.fft_threads import each_on_pool

    for workers in (1, 3, 8):
        calls: list[int] = []
        lock = threading.Lock()

        def compute(k: int) -> int:
            time.sleep(0.002 * (k % 3))
            with lock:
                calls.append(k)
            return k * k

        assert each_on_pool(compute, 7, workers) == [k * k for k in range(7)]
        assert sorted(calls) == list(range(7))
        assert each_on_pool(compute, 0, workers) == []
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", "2")
    assert each_on_pool(lambda k: -k, 5) == [0, -1, -2, -3, -4]


def test_positions_extremes_and_inner_products_read_in_bands(monkeypatch: pytest.MonkeyPatch) -> None:
    """``flatnonzero_in_bands``, ``kkt.min_below_zero`` / ``max_above_zero`` and ``dots_in_bands`` in bands of 7 on
    1 or 3 threads: the positions of the whole mask in order (none, some, all), its least
    entry, a NaN in any band included, and inner products summed in band order (within
    round-off of the whole product, the same on any thread count)."""
    from contactbench.problems import fft_threads
    from contactbench.problems.fft_threads import dots_in_bands, flatnonzero_in_bands
    from contactbench.problems.kkt import max_above_zero, min_below_zero

    rng = np.random.default_rng(10)
    x = rng.normal(size=100)
    monkeypatch.setattr(fft_threads, "BANDED_VECTOR_MIN", 1)
    monkeypatch.setattr(fft_threads, "VECTOR_BAND", 7)
    for workers in ("1", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        for cut in (-np.inf, 0.5, np.inf):
            got = flatnonzero_in_bands(lambda s: x[s] < cut, x)
            assert got.tolist() == np.flatnonzero(x < cut).tolist()
        assert min_below_zero(x) == min(0.0, float(np.min(x)))
        assert min_below_zero(np.abs(x)) == 0.0
        assert max_above_zero(x) == max(0.0, float(np.max(x)))
        assert max_above_zero(-np.abs(x)) == 0.0
        for k in (0, 50, 99):
            bad = x.copy()
            bad[k] = np.nan
            assert np.isnan(min_below_zero(bad)) and np.isnan(max_above_zero(bad))
            assert np.isnan(dots_in_bands([(bad, x)])[0])
        y = rng.normal(size=100)
        got = dots_in_bands([(x, y), (y, y)])
        assert all(isinstance(v, float) for v in got)
        np.testing.assert_allclose(got, [x @ y, y @ y], rtol=1e-13)
        assert got == [sum(float(x[a:a + 7] @ y[a:a + 7]) for a in range(0, 100, 7)),
                       sum(float(y[a:a + 7] @ y[a:a + 7]) for a in range(0, 100, 7))]  # band order
    monkeypatch.setattr(fft_threads, "BANDED_VECTOR_MIN", 101)
    assert dots_in_bands([(x, x)]) == [x @ x]  # a short vector: the whole product


@pytest.mark.parametrize("periodic", [False, True])
def test_a_product_is_the_same_on_any_threads_and_a_small_grid_takes_one(periodic: bool,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The row blocks and the column pass go out over ``row_threads`` of the FFT threads: one
    thread for a field under ``ROW_THREAD_BYTES`` a thread (a float32 field counts half a
    float64 one), never more than the workers; with the threshold at one byte the products
    on 1, 2 and 3 threads are the one-thread product, in both precisions."""
    from contactbench.problems import fft_transform

    small, big = fft_transform.ROW_THREAD_BYTES // 8, fft_transform.ROW_THREAD_BYTES
    assert fft_transform.row_threads(1, small, 16) == 1 and fft_transform.row_threads(1, 2 * big // 4, 16, 4) == 2
    assert fft_transform.row_threads(1, 2 * big // 8, 16, 4) == 1 and fft_transform.row_threads(1024, big, 3) == 3
    assert fft_transform.row_threads(1, 1, 0) == 1
    rng = np.random.default_rng(12)
    idx = random_subset(rng, 0.7)
    op = FFTOperator(KernelTransform(kernel_table("bcc", (N, N), DELTA, E, periodic), (N, N)), idx, auto_dense=False)
    x = rng.random(idx.size)
    monkeypatch.setattr(fft_transform, "ROW_THREAD_BYTES", 1)
    for dtype in (np.float64, np.float32):
        answers = []
        for workers in ("1", "2", "3"):
            monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
            answers.append(op.with_precision(dtype).matvec(x))
        for a in answers[1:]:
            np.testing.assert_allclose(a, answers[0], rtol=1e-6 if dtype == np.float32 else 1e-13, atol=0)


@pytest.mark.parametrize("workers", ["1", "3"])
@pytest.mark.parametrize("shape", [(40, 40), (300, 170)])
def test_the_transposed_spectrum_is_the_spectrum_transposed(shape: tuple[int, int], workers: str,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Tile by tile (``fft_transform.TRANSPOSE_TILE``), ragged edges included, in each precision,
    the bands of tiles on one thread or shared over three."""
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
    transform = KernelTransform(kernel_table("bcc", shape, DELTA, E, False), shape)
    assert transform.khat.shape[0] > 256 or shape == (40, 40)
    for dtype in (np.float64, np.float32):
        got = transform.transposed_spectrum(dtype)
        assert got.flags.c_contiguous and got.dtype == transform.spectrum(dtype).dtype
        np.testing.assert_array_equal(got, transform.spectrum(dtype).T)


def test_a_periodic_grid_with_short_columns_takes_one_2d_pair_with_the_same_products(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``WHOLE_PERIODIC_PAIR``: a float32 product on an unpadded grid whose spectrum is held
    whole and whose rows ducc0 takes in one call runs as one 2-D transform pair (and only
    there); its products on a set, a permuted whole grid and the whole grid are the row
    blocks' to round-off; float64, and float32 rows long enough for ``row_batch``, keep the
    row blocks."""
    from contactbench.problems import fft_threads, fft_transform

    monkeypatch.setattr(fft_transform, "TRANSPOSED_COLUMN_BYTES", 1 << 62)  # short columns
    calls: list[int] = []
    pair = fft_transform.KernelTransform._periodic_pair

    def spy(self, *args):
        calls.append(1)
        return pair(self, *args)

    monkeypatch.setattr(fft_transform.KernelTransform, "_periodic_pair", spy)
    rng = np.random.default_rng(5)
    whole = np.arange(N * N)
    for periodic, long_rows in ((True, False), (False, False), (True, True)):
        monkeypatch.setattr(fft_threads, "FLOAT32_LONG_ROW", N if long_rows else 1 << 62)
        transform = KernelTransform(kernel_table("bcc", (N, N), DELTA, E, periodic), (N, N))
        for idx in (random_subset(rng, 0.3), rng.permutation(N * N), whole):
            x = rng.random(idx.size)
            for dtype, rtol in ((np.float64, 1e-12), (np.float32, 1e-5)):
                op = FFTOperator(transform, idx, auto_dense=False).with_precision(dtype)
                calls.clear()
                monkeypatch.setattr(fft_transform, "WHOLE_PERIODIC_PAIR", True)
                got = op.matvec(x)
                taken = 1 if periodic and dtype == np.float32 and not long_rows else 0
                assert len(calls) == taken
                monkeypatch.setattr(fft_transform, "WHOLE_PERIODIC_PAIR", False)
                want = op.matvec(x)
                assert len(calls) == taken
                np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * float(np.max(np.abs(want))))
