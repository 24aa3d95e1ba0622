"""The array-module FFT operator (problems/operators_gpu.py).

The convolution is one code path written against ``xp``: here it runs for real with
xp = numpy and must equal the CPU ``FFTOperator`` to round-off (periodic and not, after
restrict, on rectangular grids); the CuPy cases run only where CuPy sees a CUDA device.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, check_operator_kind
from contactbench.problems.kernels import kernel_table
from contactbench.problems.operators import FFTOperator, KernelTransform, even_table_product
from contactbench.problems import operators_gpu
from contactbench.problems.operators_gpu import (
    ArrayFFTOperator,
    ArrayKernelTransform,
    array_module,
    device_floor_pair,
    gpu_unavailable_reason,
    to_host,
)
from contactbench.problems.surfaces import rmd_surface_n
from tests.fake_device import SPACE

DELTA, E = 1.5e-6, 2.0e9
CASES = [("bcc", False), ("love", False), ("bcc", True), ("spectral", True)]
GPU_REASON = gpu_unavailable_reason()
needs_gpu = pytest.mark.skipif(GPU_REASON is not None, reason=f"needs CuPy and a CUDA device: {GPU_REASON}")


def host_transform(kernel: str, periodic: bool, shape: tuple[int, int]) -> KernelTransform:
    return KernelTransform(kernel_table(kernel, shape, DELTA, E, periodic), shape)


def operator_pair(kernel: str, periodic: bool, shape: tuple[int, int], idx: np.ndarray,
                  xp: str = "numpy") -> tuple[FFTOperator, ArrayFFTOperator]:
    """The CPU operator and the array-module one on the same transform (no dense switch:
    every matvec goes through a convolution)."""
    host = host_transform(kernel, periodic, shape)
    cpu = FFTOperator(host, idx, auto_dense=False)
    arr = ArrayFFTOperator(ArrayKernelTransform.from_host(host, xp), idx, auto_dense=False)
    return cpu, arr


def assert_close(a: np.ndarray, b: np.ndarray, rtol: float = 1e-12) -> None:
    assert a.dtype == np.float64 and a.shape == b.shape
    assert np.linalg.norm(a - b) <= rtol * np.linalg.norm(b), np.linalg.norm(a - b) / np.linalg.norm(b)


@pytest.mark.parametrize("kernel,periodic", CASES)
@pytest.mark.parametrize("shape", [(16, 16), (12, 18)])
@pytest.mark.parametrize("fraction", [0.3, 1.0])
def test_numpy_path_equals_cpu_fft_operator(kernel: str, periodic: bool, shape: tuple[int, int],
                                            fraction: float) -> None:
    rng = np.random.default_rng([CASES.index((kernel, periodic)), shape[1], int(10 * fraction)])
    size = shape[0] * shape[1]
    idx = np.sort(rng.choice(size, int(fraction * size), replace=False))
    cpu, arr = operator_pair(kernel, periodic, shape, idx)
    for _ in range(3):
        x = rng.normal(size=idx.size)
        assert_close(arr.matvec(x), cpu.matvec(x))
    assert arr.matvec_count == 3 and arr.transform.fft_count == 6
    f = rng.normal(size=idx.size)
    assert_close(arr.displacement_field(f), cpu.displacement_field(f))


@pytest.mark.parametrize("kernel,periodic", CASES)
def test_restrict_stays_on_the_array_module_and_agrees(kernel: str, periodic: bool) -> None:
    rng = np.random.default_rng(3)
    idx = np.sort(rng.choice(256, 150, replace=False))
    cpu, arr = operator_pair(kernel, periodic, (16, 16), idx)
    sub = np.sort(rng.choice(idx.size, 40, replace=False))
    r_cpu, r_arr = cpu.restrict(sub), arr.restrict(sub)
    assert isinstance(r_arr, ArrayFFTOperator) and r_arr.transform is arr.transform
    for _ in range(2):  # alternate between the two index sets (the device index cache)
        x, y = rng.normal(size=sub.size), rng.normal(size=idx.size)
        assert_close(r_arr.matvec(x), r_cpu.matvec(x))
        assert_close(arr.matvec(y), cpu.matvec(y))


def test_dense_gathers_are_the_cpu_operators() -> None:
    rng = np.random.default_rng(5)
    idx = np.sort(rng.choice(256, 120, replace=False))
    cpu, arr = operator_pair("bcc", False, (16, 16), idx)
    rows, cols = rng.choice(idx.size, 7), rng.choice(idx.size, 9)
    assert np.array_equal(arr.submatrix(rows, cols), cpu.submatrix(rows, cols))
    assert np.array_equal(arr.entries(rows[:5], cols[:5]), cpu.entries(rows[:5], cols[:5]))
    members = np.array([[0, 3, 5], [7, 2, -1]])
    assert np.array_equal(arr.blocks(members), cpu.blocks(members))
    assert np.array_equal(arr.diagonal(), cpu.diagonal())
    assert arr.memory_nbytes > cpu.transform.table.nbytes


def test_matvec_never_uses_the_cpu_convolutions(monkeypatch) -> None:
    def forbidden(*_a, **_k):
        raise AssertionError("the CPU convolution was called")

    monkeypatch.setattr(KernelTransform, "_ducc_convolve", forbidden)
    monkeypatch.setattr(KernelTransform, "_scipy_convolve", forbidden)
    idx = np.arange(0, 256, 3)
    _, arr = operator_pair("bcc", False, (16, 16), idx)
    assert np.all(arr.matvec(np.ones(idx.size)) > 0)  # H has positive entries (BCC, aperiodic)


def test_float32_precision_agrees_to_single_precision_and_stays_on_the_array_module() -> None:
    rng = np.random.default_rng(11)
    idx = np.sort(rng.choice(400, 300, replace=False))
    cpu, arr = operator_pair("bcc", False, (20, 20), idx)
    f32 = arr.with_precision(np.float32)
    assert isinstance(f32, ArrayFFTOperator) and f32.dtype == np.float32 and arr.with_precision(np.float64) is arr
    x = rng.random(idx.size)
    y = f32.matvec(x)
    assert y.dtype == np.float32
    assert_close(y.astype(np.float64), cpu.matvec(x), rtol=1e-5)
    sub = f32.restrict(np.arange(0, idx.size, 2))
    assert isinstance(sub, ArrayFFTOperator) and sub.dtype == np.float32
    assert_close(sub.matvec(x[::2]).astype(np.float64), cpu.restrict(np.arange(0, idx.size, 2)).matvec(x[::2]),
                 rtol=1e-5)


@pytest.mark.parametrize("xp", ["numpy", pytest.param("cupy", marks=needs_gpu)])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_device_apply_is_the_matvec_without_transfers(xp: str, dtype: type) -> None:
    rng = np.random.default_rng(13)
    idx = np.sort(rng.choice(400, 250, replace=False))
    cpu, arr = operator_pair("bcc", False, (20, 20), idx, xp=xp)
    mod = arr.transform.xp
    x = rng.random(idx.size)
    y = arr.transform.device_apply(arr.pidx, mod.asarray(x.astype(dtype)))
    assert isinstance(y, mod.ndarray) and y.dtype == dtype
    assert_close(to_host(y).astype(np.float64), cpu.matvec(x), rtol=1e-12 if dtype == np.float64 else 1e-5)
    with pytest.raises(ProblemInputError, match="float64 or float32"):
        arr.transform.device_apply(arr.pidx, mod.asarray(x.astype(np.float16)))


@pytest.mark.parametrize("xp", ["numpy", pytest.param("cupy", marks=needs_gpu)])
@pytest.mark.parametrize("periodic", [False, True])
def test_device_floor_pair_is_the_bare_transform_pair(xp: str, periodic: bool) -> None:
    """Without the spectrum product the floor's pair is the identity on the N1 rows it reads."""
    cpu, arr = operator_pair("bcc", periodic, (12, 18), np.arange(12 * 18), xp=xp)
    pair = device_floor_pair(arr.transform, np.float64)
    out = to_host(pair())
    n1, p1 = arr.transform.grid_shape[0], arr.transform.padded_shape[1]
    field = np.random.default_rng(0).random((n1, p1))
    assert out.shape == (n1, p1) and np.allclose(out, field, atol=1e-12)
    assert to_host(device_floor_pair(arr.transform, np.float32)()).dtype == np.float32


@pytest.mark.parametrize("chunk,threads", [(1, 1), (7 * 64, 64 * 7), (operators_gpu.DEVICE_PARTIAL_CHUNK, 1 << 18)])
@pytest.mark.parametrize("where,fused", [("fake", False), pytest.param("cupy", False, marks=needs_gpu),
                                         pytest.param("cupy", True, marks=needs_gpu)])
def test_partial_products_in_the_space_are_the_hosts_whatever_the_chunk(where: str, fused: bool, chunk: int,
                                                                       threads: int,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The device's partial product (the kernel table's quarter gathered there, a column a
    pass, several, or all at once; or by the fused kernel, its columns in one group, a
    few or one each) gives the host's, on a device that refuses transfers."""
    monkeypatch.setattr(operators_gpu, "DEVICE_PARTIAL_CHUNK", chunk)
    monkeypatch.setattr(operators_gpu, "GATHER_THREADS", threads)
    monkeypatch.setattr(operators_gpu, "FUSED_GATHER", fused)
    rng = np.random.default_rng(21)
    idx = np.sort(rng.choice(24 * 24, 300, replace=False))
    host = host_transform("bcc", False, (24, 24))
    space = SPACE if where == "fake" else operators_gpu.named_space("cupy")
    cpu = FFTOperator(host, idx, auto_dense=False)
    arr = ArrayFFTOperator(ArrayKernelTransform.from_host(host, space), idx, auto_dense=False)
    rows, cols = np.sort(rng.choice(300, 64, replace=False)), rng.choice(300, 40, replace=False)
    x = rng.random(cols.size)
    got = arr.partial_product(space.put(rows), space.put(cols), space.put(x))
    assert_close(space.get(got), cpu.partial_product(rows, cols, x), rtol=1e-13)
    assert space.get(arr.partial_product(space.put(rows[:0]), space.put(cols), space.put(x))).shape == (0,)


def test_pickles_after_use_without_device_state() -> None:
    idx = np.arange(0, 256, 2)
    cpu, arr = operator_pair("bcc", True, (16, 16), idx)
    x = np.random.default_rng(0).normal(size=idx.size)
    arr.matvec(x)
    clone = pickle.loads(pickle.dumps(arr))
    assert clone.transform._device is None
    assert_close(clone.matvec(x), cpu.matvec(x))


def test_bad_inputs_are_clear_errors() -> None:
    host = host_transform("bcc", False, (8, 8))
    with pytest.raises(ProblemInputError, match="needs an ArrayKernelTransform"):
        ArrayFFTOperator(host, np.arange(4))  # type: ignore[arg-type]
    with pytest.raises(ProblemInputError, match="array module must be one of"):
        ArrayKernelTransform.from_host(host, "jax")
    with pytest.raises(ProblemInputError, match="float64 or float32"):
        ArrayFFTOperator(ArrayKernelTransform.from_host(host, "numpy"), np.arange(4), dtype=np.float16)
    with pytest.raises(ProblemInputError, match="operator must be 'fft' or 'dense', got 'sparse'"):
        check_operator_kind("sparse")


@pytest.mark.skipif(GPU_REASON is None, reason="CuPy and a CUDA device are present")
def test_gpu_operator_without_a_device_is_a_clear_error() -> None:
    surf = rmd_surface_n(16, 0.7, length=1e-4, seed=0)
    with pytest.raises(ProblemInputError, match="operator 'gpu' is not available here"):
        InstanceBuilder(surf, E, operator="gpu")
    with pytest.raises(ProblemInputError, match="needs CuPy and a CUDA device"):
        array_module("cupy")


@needs_gpu
@pytest.mark.parametrize("kernel,periodic", CASES)
def test_cupy_path_equals_cpu_fft_operator(kernel: str, periodic: bool) -> None:
    rng = np.random.default_rng(1)
    idx = np.sort(rng.choice(24 * 24, 400, replace=False))
    cpu, gpu = operator_pair(kernel, periodic, (24, 24), idx, xp="cupy")
    assert gpu.kind == "gpu"
    x = rng.normal(size=idx.size)
    assert_close(gpu.matvec(x), cpu.matvec(x))
    sub = np.arange(0, idx.size, 3)
    assert_close(gpu.restrict(sub).matvec(x[sub]), cpu.restrict(sub).matvec(x[sub]))


@needs_gpu
def test_builder_gpu_operator_matches_fft() -> None:
    surf = rmd_surface_n(32, 0.7, length=1e-4, seed=0)
    d = 0.5 * (surf.z_max - surf.z_mean)
    fft = InstanceBuilder(surf, E, operator="fft").build(d)
    gpu = InstanceBuilder(surf, E, operator="gpu").build(d)
    assert gpu.qp.H.kind == "gpu" and np.array_equal(gpu.qp.ubar, fft.qp.ubar)
    x = np.random.default_rng(2).random(fft.n)
    assert_close(gpu.qp.H.matvec(x), fft.qp.H.matvec(x))


@pytest.mark.parametrize("solver", ["fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "fast-pdas"])
def test_fast_solvers_run_on_the_array_operator(solver: str) -> None:
    """Every fast solver solves the same QP through the numpy path as through the CPU
    operator (no dense switch on either, so every product is a convolution)."""
    from contactbench.harness import solve_sequence
    from contactbench.problems.instances import QP, paper_max_displacement
    from contactbench.solvers.base import SolverSettings

    surf = rmd_surface_n(64, 0.7, length=1e-4, seed=0)
    builder = InstanceBuilder(surf, E)
    inst = builder.build(paper_max_displacement(surf))
    idx, answers = inst.qp.geometry.indices, []
    for op in (FFTOperator(builder.transform, idx, auto_dense=False),
               ArrayFFTOperator(ArrayKernelTransform.from_host(builder.transform, "numpy"), idx, auto_dense=False)):
        inst.qp = QP(op, inst.qp.ubar, inst.qp.geometry)
        (step,) = solve_sequence(solver, [inst], SolverSettings(tol=1e-9), warm=False, check_tol=1e-8)
        assert step.verdict is not None and step.verdict.status == "solved", step.error
        answers.append(step.result.p)
    assert np.max(np.abs(answers[0] - answers[1])) <= 1e-8 * np.max(answers[0])


def test_a_failing_device_probe_is_a_reason_not_a_crash(monkeypatch) -> None:
    import contactbench.problems.operators_gpu as gpu

    monkeypatch.setattr(gpu.importlib.util, "find_spec", lambda name: object())
    monkeypatch.setattr(gpu, "_PROBE", "raise SystemExit('cudaErrorNoDevice: no CUDA-capable device')")
    assert "no usable CUDA device (cudaErrorNoDevice" in gpu.gpu_unavailable_reason.__wrapped__()
    monkeypatch.setattr(gpu, "_PROBE", "print(0)")
    assert gpu.gpu_unavailable_reason.__wrapped__() == "CuPy finds no CUDA device"


def test_the_operator_memory_model_against_the_measured_pools() -> None:
    """``operator_model_nbytes`` against CuPy's pool measured on an H200 with the loop on the
    host (results/perf/gpu.md): 15.1 GiB at 8192^2 and 3.8 GiB at 4096^2 non-periodic,
    within 2 %; at 2048^2 (0.7 GiB) it may over-state, never under-state by more than
    that; it grows as N^2, and a periodic grid (no padding) needs less than half."""
    from contactbench.problems.operators_gpu import operator_model_nbytes

    gib = 2.0**30
    for N, measured in ((8192, 15.1), (4096, 3.8)):
        assert abs(operator_model_nbytes((N, N), False) / gib - measured) <= 0.02 * measured
    assert operator_model_nbytes((2048, 2048), False) / gib >= 0.98 * 0.7
    ratio = operator_model_nbytes((16384, 16384), False) / operator_model_nbytes((8192, 8192), False)
    assert 3.99 <= ratio <= 4.01
    assert operator_model_nbytes((4096, 4096), True) < 0.5 * operator_model_nbytes((4096, 4096), False)


def test_a_device_resident_solve_adds_its_vectors_to_the_operator() -> None:
    """``device_model_nbytes``: the operator's bytes and the resident arrays, which grow
    with the unknowns (a screened trial set costs less than the whole grid, never more)."""
    from contactbench.problems.operators_gpu import (POOL_FACTOR, RESIDENT_GRIDS, RESIDENT_VECTORS,
                                                     device_model_nbytes, operator_model_nbytes)

    shape, grid = (1024, 1024), 1024 * 1024
    op = operator_model_nbytes(shape, False)
    whole = device_model_nbytes(shape, False)
    assert whole == device_model_nbytes(shape, False, grid) == device_model_nbytes(shape, False, 10 * grid)
    assert abs(whole - op - POOL_FACTOR * 8 * (RESIDENT_VECTORS + RESIDENT_GRIDS) * grid) <= 1
    few = device_model_nbytes(shape, False, grid // 8)
    assert op < few < whole
    assert abs((whole - few) - POOL_FACTOR * 8 * RESIDENT_VECTORS * (grid - grid // 8)) <= 2


def test_device_misfit_says_why_and_stays_quiet_without_a_device(monkeypatch) -> None:
    import contactbench.problems.operators_gpu as gpu

    monkeypatch.setattr(gpu, "device_total_bytes", lambda: None)
    assert gpu.device_misfit((65536, 65536), False) is None  # no device to ask: nothing to refuse
    monkeypatch.setattr(gpu, "device_total_bytes", lambda: 139 * 2**30)  # an H200
    assert gpu.device_misfit((16384, 16384), False, 36_000_000) is None  # the trial set of n = 36 M fits
    monkeypatch.setattr(gpu, "device_total_bytes", lambda: 80 * 2**30)  # an H100: its pool took 77.4 GiB on an H200
    # 82 GiB with both precisions' work held; 65 GiB tight (the pool released when the precision changes)
    assert gpu.device_model_nbytes((16384, 16384), False, 36_000_000) > 80 * 2**30
    assert gpu.device_misfit((16384, 16384), False, 36_000_000) is None
    assert "16384 x 16384 non-periodic grid needs about 97" in gpu.device_misfit((16384, 16384), False)  # the whole
    why = gpu.device_misfit((32768, 32768), False)
    assert why is not None and "needs about 389" in why and "has 80.0 GiB" in why


def test_the_tight_model_holds_one_precision_s_work() -> None:
    """Tight, the two precisions' convolution work is not held at once: the model drops the
    smaller (float32) one's, and nothing else."""
    from contactbench.problems.operators_gpu import (POOL_FACTOR, convolution_work_nbytes, device_model_nbytes,
                                                     memory_tight, operator_model_nbytes)

    for shape, periodic in (((16384, 16384), False), ((1000, 600), True)):
        padded = shape if periodic else (2 * shape[0], 2 * shape[1])
        float32_work = convolution_work_nbytes(shape, padded, np.float32)
        assert float32_work < convolution_work_nbytes(shape, padded, np.float64)
        drop = operator_model_nbytes(shape, periodic) - operator_model_nbytes(shape, periodic, tight=True)
        assert abs(drop - POOL_FACTOR * float32_work) <= 2
        assert (device_model_nbytes(shape, periodic) - device_model_nbytes(shape, periodic, tight=True)) == drop
    need = device_model_nbytes((256, 256), False)
    assert memory_tight((256, 256), False, need - 1) and not memory_tight((256, 256), False, need)
    assert not memory_tight((256, 256), False, None)


def test_release_gives_the_fft_plans_back_before_emptying_the_pool() -> None:
    """The plans' work areas go back to the pool first, then the pool to the device; NumPy
    has neither and nothing happens."""
    from types import SimpleNamespace

    from contactbench.problems.operators_gpu import release_cached_blocks

    calls: list[str] = []
    cache = SimpleNamespace(clear=lambda: calls.append("plans"))
    pool = SimpleNamespace(free_all_blocks=lambda: calls.append("pool"))
    xp = SimpleNamespace(fft=SimpleNamespace(config=SimpleNamespace(get_plan_cache=lambda: cache)),
                         get_default_memory_pool=lambda: pool)
    release_cached_blocks(xp)
    assert calls == ["plans", "pool"]
    release_cached_blocks(np)


@pytest.mark.parametrize("tight", [True, False])
def test_a_tight_device_gives_its_pool_back_when_the_precision_changes(monkeypatch, tight: bool) -> None:
    """A device state made where the model does not fit with both precisions held releases
    the pool's unused blocks and the FFT plans once per change of precision (not per
    product); one where it fits never does.  The products are the same."""
    from contactbench.problems.operators_gpu import ArrayKernelTransform, device_model_nbytes
    from tests.fake_device import POOL, SPACE

    host = KernelTransform(kernel_table("bcc", (32, 32), 1e-6, 1e9, False), (32, 32))
    need = device_model_nbytes((32, 32), False)
    monkeypatch.setenv("CONTACTBENCH_DEVICE_BYTES", str(need - 1 if tight else need))
    dev = ArrayKernelTransform.from_host(host, SPACE)
    pidx = host.padded_index(np.arange(0, 32 * 32, 3))
    x = np.linspace(0.0, 1.0, pidx.size)
    before = POOL.released
    got = [dev.apply_on_set(pidx, x, dt) for dt in (np.float32, np.float32, np.float64, np.float64, np.float32)]
    assert POOL.released - before == (2 if tight else 0)
    for dt, y in zip((np.float32, np.float32, np.float64, np.float64, np.float32), got):
        np.testing.assert_allclose(y, host.apply_on_set(pidx, x, dt), rtol=1e-5 if dt == np.float32 else 1e-12)


class _KernelStandIn:
    """CuPy's RawModule for ``device_even_product``'s source, its two kernels done in NumPy
    from the launch's arguments (what the CUDA code computes, checked here for the launch:
    the argument order and types, the grid covering every cell, the column groups)."""

    def __init__(self, code: str) -> None:
        assert "contactbench_even_gather" in code and "contactbench_group_sum" in code

    def get_function(self, name: str):
        def gather(grid, block, args):
            table, width, ri, rj, nrows, ci, cj, x, ncols, span, cells, out = args
            assert all(isinstance(v, np.int64) for v in (width, nrows, ncols, span, cells))
            assert table.dtype == x.dtype == out.dtype == np.float64
            assert ri.dtype == rj.dtype == ci.dtype == cj.dtype == np.int64
            assert grid[0] * block[0] >= cells == out.size and cells % nrows == 0
            for g in range(int(cells // nrows)):
                k = np.arange(g * span, min(g * span + span, int(ncols)))
                entries = table[np.abs(ri[:, None] - ci[k]) * width + np.abs(rj[:, None] - cj[k])]
                out[g * nrows:(g + 1) * nrows] = entries @ x[k]

        def group_sum(grid, block, args):
            parts, groups, nrows, out = args
            assert grid[0] * block[0] >= nrows == out.size
            out[:] = parts.reshape(int(groups), int(nrows)).sum(axis=0)

        return {"contactbench_even_gather": gather, "contactbench_group_sum": group_sum}[name]


@pytest.mark.parametrize("threads", [1, 64 * 5, 1 << 18])
def test_the_fused_partial_products_launch_gives_the_formula(threads: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``device_even_product`` on a NumPy stand-in for CuPy's kernels: its columns in one
    group, a few or one each, the groups added back; the chunked formula's answer, and no
    rows or no columns give zeros of the rows' length."""
    class StandInCuPy:  # hashable, as a module is (the kernel module is cached per array module)
        zeros, empty, ascontiguousarray = staticmethod(np.zeros), staticmethod(np.empty), staticmethod(np.ascontiguousarray)
        RawModule = _KernelStandIn

    monkeypatch.setattr(operators_gpu, "GATHER_THREADS", threads)
    xp = StandInCuPy()
    operators_gpu._even_gather_module.cache_clear()
    rng = np.random.default_rng(5)
    table, width = rng.random(24 * 24), 24
    ri, rj = np.divmod(np.sort(rng.choice(24 * 24, 60, replace=False)), 24)
    ci, cj = np.divmod(rng.choice(24 * 24, 37, replace=False), 24)
    x = rng.random(37)
    try:
        got = operators_gpu.device_even_product(xp, table, width, (ri, rj), (ci, cj), x)
        none = operators_gpu.device_even_product(xp, table, width, (ri, rj), (ci[:0], cj[:0]), x[:0])
    finally:
        operators_gpu._even_gather_module.cache_clear()
    want = even_table_product(table, width, (ri, rj), (ci, cj), x)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)
    assert none.shape == (60,) and not none.any()
