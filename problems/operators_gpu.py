"""The FFT operator on a GPU (CuPy), behind the ``ContactOperator`` interface.

``ArrayKernelTransform`` is the kernel transform of ``problems.operators`` with its
convolution written once against an array module ``xp``: the same pruned transform
pair as the CPU operator (row rFFTs on the N1 physical rows, column FFTs of length
P0, the real spectrum product, column iFFTs, then row irFFTs only on the N1 rows
that are read; periodic grids have P = N and the same code is a plain rfft2 pair).

* ``xp = cupy``: the kernel spectrum lives on the device (copied there once, on the
  first convolution, so a transform built in one process and sent to another never
  touches CUDA before it is used); each matvec sends x (n float64) to the device and
  brings H_II x back -- n * 8 bytes each way, small next to the transforms.
* ``xp = numpy``: the same code on the CPU.  It is the tested path on machines
  without a GPU (it equals ``FFTOperator`` to round-off) and no faster than the
  ducc0 path of ``KernelTransform``.

``ArrayFFTOperator`` is ``FFTOperator`` on such a transform: ``submatrix``,
``entries``, ``blocks``, ``diagonal`` and the dense switch for small trial sets are the
CPU operator's own (they read the kernel table on the host); only the convolutions
run through ``xp``.  ``matvec`` of a numpy array returns a numpy array (float64; float32
for an operator from ``with_precision(np.float32)``, computed in single precision on the
device); ``matvec`` of an array of the operator's ``space`` returns one there, with no
transfer: the product of a device-resident solve (solvers/_device.py).

``ArraySpace`` names where a solve's vectors live: its array module and the two explicit
transfers (``put``: host to device, ``get``: back).  ``named_space("numpy")`` is the host
itself (the tested path of the device-resident loop), ``named_space("cupy")`` the GPU;
a test may hand ``from_host`` a space of its own (tests/fake_device.py).

CuPy is optional (the ``gpu`` extra, ``pip install -e .[gpu]``; never needed):
``gpu_unavailable_reason()`` says why the "gpu" operator cannot be built here, and
``array_module("cupy")`` raises ``ProblemInputError`` with that reason.
"""

from __future__ import annotations

import functools
import importlib.util
import os
import subprocess
import sys
from collections import OrderedDict
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Callable, ClassVar

import numpy as np

from .errors import ProblemInputError
from .operator_state import SealRule
from .operators import FFTOperator, KernelTransform, even_table_product, operator_dtype

#: The array modules the convolution is written against.
ARRAY_MODULES = ("numpy", "cupy")
#: Device copies of index sets kept per transform (one per operator in use, about).
INDEX_CACHE_SIZE = 8
#: Entries a device partial product gathers at a time where it runs as array operations
#: (``FUSED_GATHER`` off, or a test's fake device; ``operators.even_table_product``):
#: the host's cache-sized chunk took one column a pass on the sets of a 4096^2 solve, some
#: 30 passes of six kernels each a product and a third of the solve (results/perf/gpu.md);
#: 2^24 entries hold 128 MiB of offsets and 128 MiB of entries in the pool.
DEVICE_PARTIAL_CHUNK = 1 << 24
#: Whether CuPy's partial products run as CUDA kernels (``device_even_product``): no offset
#: or entry array in the pool, one pass over the rows (6-16x faster than the chunks,
#: results/perf/gpu/device-partial.csv).  Otherwise (and on any other array module: a
#: test's fake device) in chunks of array operations (``even_table_product``).
FUSED_GATHER = True
#: Threads a fused partial product aims for, rows x column groups (an H100 or H200 holds
#: 132 x 2048 resident threads): fewer rows than that split the columns into groups.
GATHER_THREADS = 1 << 18

#: ``device_even_product``'s kernels (one CUDA module, compiled once per machine: CuPy keeps
#: it on disk): thread t = (group g, row r) sums table[|a - ci| width + |b - cj|] x over the
#: columns of g's span, in order; then one thread a row adds the groups' sums, in order.
_EVEN_GATHER_SOURCE = r"""
extern "C" __global__ void contactbench_even_gather(
    const double* table, long long width, const long long* ri, const long long* rj, long long nrows,
    const long long* ci, const long long* cj, const double* x, long long ncols, long long span,
    long long cells, double* out)
{
    long long t = (long long)blockIdx.x * blockDim.x + threadIdx.x;
    if (t >= cells) return;
    long long g = t / nrows;
    long long r = t - g * nrows;
    long long a = ri[r], b = rj[r];
    long long lo = g * span;
    long long hi = lo + span < ncols ? lo + span : ncols;
    double acc = 0.0;
    for (long long k = lo; k < hi; ++k) {
        long long di = a - ci[k];
        long long dj = b - cj[k];
        di = di < 0 ? -di : di;
        dj = dj < 0 ? -dj : dj;
        acc += table[di * width + dj] * x[k];
    }
    out[t] = acc;
}

extern "C" __global__ void contactbench_group_sum(const double* parts, long long groups, long long nrows,
                                                   double* out)
{
    long long r = (long long)blockIdx.x * blockDim.x + threadIdx.x;
    if (r >= nrows) return;
    double acc = 0.0;
    for (long long g = 0; g < groups; ++g) acc += parts[g * nrows + r];
    out[r] = acc;
}
"""
#: Threads a block of ``device_even_product``'s kernels.
GATHER_BLOCK = 256


#: Run in a child process: it initialises CUDA there, not here (the harness forks its
#: workers, and a forked child cannot use a CUDA context its parent opened).
_PROBE = "import cupy; print(int(cupy.cuda.runtime.getDeviceCount()))"


@functools.lru_cache(maxsize=1)
def gpu_unavailable_reason() -> str | None:
    """None when CuPy imports and sees a CUDA device, else why not (one sentence).
    Probed once per process, in a subprocess (no CUDA context is opened here)."""
    if importlib.util.find_spec("cupy") is None:
        return "CuPy is not installed; install the 'gpu' extra: pip install -e '.[gpu]'"
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=120, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"the CuPy device probe failed ({type(exc).__name__}: {exc})"
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        return f"CuPy finds no usable CUDA device ({last})"
    counted = proc.stdout.strip().splitlines()
    if not counted or not counted[-1].isdigit() or int(counted[-1]) < 1:
        return "CuPy finds no CUDA device"
    return None


#: Run in a child process, as ``_PROBE``: the device's total memory in bytes.
_MEMORY_PROBE = "import cupy; print(int(cupy.cuda.Device(0).mem_info[1]))"

#: CuPy's memory pool over the arrays a solve's convolutions allocate on the device
#: (``device_model_nbytes``), fitted on the H200 measurements of results/perf/gpu.md
#: (``fast-dual-pccg``'s cold top step, non-periodic, float64 and float32 products: the pool
#: held 15.1 GiB at 8192^2, where the arrays come to 10.5 GiB; at 4096^2 the model gives 3.76
#: GiB against 3.8 measured; at 2048^2 it over-states, 0.94 against 0.7).
POOL_FACTOR = 1.43


def convolution_work_nbytes(grid_shape: tuple[int, int], padded_shape: tuple[int, int],
                            dtype: object = np.float64) -> int:
    """Device bytes one convolution in ``dtype`` allocates on a grid of ``grid_shape``
    padded to ``padded_shape``: the row field, the padded spectrum, the back rows and the
    result rows."""
    item = operator_dtype(dtype).itemsize
    p0, p1 = padded_shape
    n1 = grid_shape[0]
    half = p1 // 2 + 1
    return int(2 * item * n1 * p1 + 2 * item * (p0 + 2 * n1) * half)


#: Float64 vectors of the unknowns a device-resident solve holds beside the operator's
#: (solvers/_device.py), counted in the load-controlled loop, the larger: ubar, p, the gap,
#: the direction, its product, the residual and the last one, z, the bounds, M^-1 1 and
#: three temporaries.  A count (the pools measured below fix only the sum with the next).
RESIDENT_VECTORS = 13
#: ... and float64 arrays of the whole grid: the kernel table's quarter the partial
#: products read (``ArrayFFTOperator.partial_product``), the wave numbers with the grid
#: indices, and what the pool keeps of the wave-number preconditioner's transforms and the
#: judge's whole-grid check.  Fitted so that the model bounds the pools of the
#: device-resident cold top steps measured on an H200 (results/perf/gpu.md: 0.80, 4.2, 17.4
#: and 77.4 GiB at 2048^2-16384^2, where 2 grids gave 1.1, 4.4, 17.7 and 70.7).
RESIDENT_GRIDS = 6


def operator_model_nbytes(grid_shape: tuple[int, int], periodic: bool, tight: bool = False) -> int:
    """The device memory of the "gpu" operator on a grid of ``grid_shape`` (zero-padded to
    twice each side unless ``periodic``): a real kernel spectrum in float64 and float32 and
    the convolutions' work in both (the mixed-precision rounds), times CuPy's
    ``POOL_FACTOR`` (fitted on pools measured with the loop on the host).  ``tight``: the
    pool gives back its unused blocks whenever the products change precision
    (``memory_tight``), so only the larger precision's work is held at a time."""
    n0, n1 = int(grid_shape[0]), int(grid_shape[1])
    padded = (n0, n1) if periodic else (2 * n0, 2 * n1)
    spectrum = 8 * padded[0] * (padded[1] // 2 + 1)
    works = [convolution_work_nbytes((n0, n1), padded, dt) for dt in (np.float64, np.float32)]
    return int(POOL_FACTOR * (1.5 * spectrum + (max(works) if tight else sum(works))))


def device_model_nbytes(grid_shape: tuple[int, int], periodic: bool, points: int | None = None,
                        tight: bool = False) -> int:
    """The device memory a device-resident solve takes on a grid of ``grid_shape``, before
    it is built: the operator's (``operator_model_nbytes``, ``tight`` or not), ``RESIDENT_VECTORS``
    float64 vectors of its ``points`` unknowns (default: every grid point, as a load-controlled
    solve carries) and ``RESIDENT_GRIDS`` of the whole grid, in CuPy's pool."""
    n0, n1 = int(grid_shape[0]), int(grid_shape[1])
    points = n0 * n1 if points is None else min(int(points), n0 * n1)
    resident = 8 * (RESIDENT_VECTORS * points + RESIDENT_GRIDS * n0 * n1)
    return operator_model_nbytes(grid_shape, periodic, tight) + int(POOL_FACTOR * resident)


def memory_tight(grid_shape: tuple[int, int], periodic: bool, total: int | None) -> bool:
    """Whether a solve on the grid runs tight on a device of ``total`` bytes (None: unknown,
    never tight): the model with both precisions' work held (``device_model_nbytes`` of the
    whole grid) does not fit, so the device state releases what the pool and the FFT plans
    hold unused at each change of precision (``_DeviceState.convolving_in``), at the price of
    allocating that work and planning those transforms again."""
    return total is not None and device_model_nbytes(grid_shape, periodic) > total


def release_cached_blocks(xp: Any) -> None:
    """Give the device back what CuPy's FFT plan cache and memory pool hold and no array
    uses -- the plans first, so that their work areas return to the pool before it is
    emptied; a module without them (NumPy) has nothing to give back."""
    plans = getattr(getattr(getattr(xp, "fft", None), "config", None), "get_plan_cache", None)
    if callable(plans):
        plans().clear()
    pool = getattr(xp, "get_default_memory_pool", None)
    if callable(pool):
        pool().free_all_blocks()


def capped_device_bytes() -> int | None:
    """env CONTACTBENCH_DEVICE_BYTES (a cap on the device's memory, or a stand-in device for
    tests) in bytes; None when unset."""
    env = os.environ.get("CONTACTBENCH_DEVICE_BYTES", "").strip()
    if not env:
        return None
    try:
        value = int(float(env))
    except ValueError as exc:
        raise ProblemInputError(f"CONTACTBENCH_DEVICE_BYTES={env!r}: expected a number of bytes") from exc
    if value <= 0:
        raise ProblemInputError(f"CONTACTBENCH_DEVICE_BYTES={env!r}: expected a positive number of bytes")
    return value


def device_bytes_here(xp: Any) -> int | None:
    """The device's memory as a process already computing on it sees it: the cap
    (``capped_device_bytes``), else the array module's device (CuPy's ``mem_info``); None
    for a module without one."""
    cap = capped_device_bytes()
    if cap is not None:
        return cap
    device = getattr(getattr(xp, "cuda", None), "Device", None)
    return int(device().mem_info[1]) if callable(device) else None


@functools.lru_cache(maxsize=1)
def device_total_bytes() -> int | None:
    """The device's memory in bytes: the cap (``capped_device_bytes``) when set, else probed
    once in a child process (no CUDA context here); None where there is no device."""
    cap = capped_device_bytes()
    if cap is not None:
        return cap
    if gpu_unavailable_reason() is not None:
        return None
    try:
        proc = subprocess.run([sys.executable, "-c", _MEMORY_PROBE], capture_output=True, text=True, timeout=120,
                              check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    last = (proc.stdout.strip().splitlines() or [""])[-1]
    return int(last) if proc.returncode == 0 and last.isdigit() else None


def device_misfit(grid_shape: tuple[int, int], periodic: bool, points: int | None = None) -> str | None:
    """None when a solve of ``points`` unknowns (default: the whole grid) on ``grid_shape``
    fits the device (``device_model_nbytes`` against ``device_total_bytes``) or there is
    no device to ask; else why not (one line)."""
    total = device_total_bytes()
    if total is None:
        return None
    need = device_model_nbytes(grid_shape, periodic, points, tight=memory_tight(grid_shape, periodic, total))
    if need <= total:
        return None
    n0, n1 = grid_shape
    return (f"a {n0} x {n1} {'periodic' if periodic else 'non-periodic'} grid needs about {need / 2**30:.1f} GiB "
            f"on the device (operators_gpu.device_model_nbytes, releasing the pool when the precision changes), "
            f"the device has {total / 2**30:.1f} GiB")


def array_module(name: str) -> ModuleType:
    """numpy or cupy by name; ``ProblemInputError`` naming the reason when CuPy or a
    device is missing."""
    if name == "numpy":
        return np
    if name == "cupy":
        reason = gpu_unavailable_reason()
        if reason is not None:
            raise ProblemInputError(f"the 'gpu' operator needs CuPy and a CUDA device: {reason}")
        import cupy

        return cupy
    raise ProblemInputError(f"array module must be one of {ARRAY_MODULES}, got {name!r}")


def to_host(a: Any) -> np.ndarray:
    """A numpy array from a numpy or cupy array."""
    get = getattr(a, "get", None)
    return np.asarray(get() if callable(get) else a)


def on_host(a: Any) -> bool:
    """Whether ``a`` is a host (numpy) array, not one on a device."""
    return isinstance(a, np.ndarray)


@dataclass(frozen=True)
class ArraySpace:
    """Where a solve's vectors live (module doc): the array module ``xp`` and the two
    explicit transfers, ``put`` (a host array onto the space) and ``get`` (back)."""

    name: str
    xp: Any
    put: Callable[[np.ndarray], Any]
    get: Callable[[Any], np.ndarray]

    @property
    def host(self) -> bool:
        """Whether the space is the host's own memory (numpy)."""
        return self.xp is np


#: The host's own memory: where every solve keeps its vectors unless its operator has a space.
HOST = ArraySpace("numpy", np, np.asarray, np.asarray)


def named_space(name: str) -> ArraySpace:
    """The space of the array module ``name`` (one of ``ARRAY_MODULES``)."""
    xp = array_module(name)
    return HOST if xp is np else ArraySpace(name, xp, xp.asarray, to_host)


class ArrayKernelTransform(KernelTransform):
    """A ``KernelTransform`` whose convolutions run through the array module ``xp``.

    Built from a host transform (``from_host``): the table, spectrum and shapes are
    shared with it, nothing is recomputed.  The device state (the spectrum in each
    precision used, and the padded indices of the operators that use it) is made on the
    first convolution.  Like the CPU transform, every convolution runs in float64 or
    float32 (``dtype``; float32 returns float32, for mixed-precision solvers).
    """

    xp_name: str
    _space: ArraySpace | None = None
    #: What the seal reads besides content (problems/operator_state.py): the device state,
    #: which the host cannot read in place, held to what this transform puts there.
    SEAL_RULE: ClassVar[SealRule] = SealRule(opaque={"_device": lambda t, state: t.device_state_intact(state)})

    @classmethod
    def from_host(cls, host: KernelTransform, xp: str | ArraySpace = "cupy") -> "ArrayKernelTransform":
        """The transform on the array module named ``xp`` (one of ``ARRAY_MODULES``), or on
        a space of the caller's (not sent to another process)."""
        if not isinstance(xp, ArraySpace) and xp not in ARRAY_MODULES:
            raise ProblemInputError(f"array module must be one of {ARRAY_MODULES}, got {xp!r}")
        self = cls.__new__(cls)
        self.__setstate__(host.__getstate__())
        self.xp_name = xp.name if isinstance(xp, ArraySpace) else xp
        self._space = xp if isinstance(xp, ArraySpace) else None
        self._device = None
        return self

    def __getstate__(self) -> dict:
        state = super().__getstate__()
        state["_device"] = None  # device arrays stay in their process
        return state

    def device_state_intact(self, state: Any) -> bool:
        """Whether ``state`` holds what this transform puts on the device (``_DeviceState.holds``,
        each array copied back and compared): the seal's check of it (``SEAL_RULE``)."""
        return isinstance(state, _DeviceState) and state.xp is self.xp and state.holds(self.khat, self.table,
                                                                                        self.grid_shape)

    @property
    def space(self) -> ArraySpace:
        """Where the convolutions run (module doc)."""
        return self._space if self._space is not None else named_space(self.xp_name)

    @property
    def xp(self) -> Any:
        return self.space.xp

    def _state(self) -> "_DeviceState":
        if self._device is None:
            xp = self.xp
            self._device = _DeviceState(xp, self.khat, memory_tight(self.grid_shape, self.periodic, device_bytes_here(xp)))
        return self._device

    def apply_on_set(self, pidx: np.ndarray, x: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """gather_I (K * scatter_I x) at the padded flat indices ``pidx`` (host arrays in
        and out; the convolution runs on ``xp`` in precision ``dtype``)."""
        dt = operator_dtype(dtype)
        with self._lock:
            dev = self._state()
            return to_host(self._apply_on_device(dev, dev.indices(pidx), dev.xp.asarray(x, dtype=dt)))

    def device_apply(self, pidx: np.ndarray, x: Any) -> Any:
        """``apply_on_set`` with x and the result on the device (no host transfers): the
        matvec a device-resident solver would call, in the precision of ``x``."""
        operator_dtype(x.dtype)
        with self._lock:
            dev = self._state()
            return self._apply_on_device(dev, dev.indices(pidx), x)

    def _apply_on_device(self, dev: "_DeviceState", d_idx: Any, d_x: Any) -> Any:
        field = dev.xp.zeros((self.grid_shape[0], self.padded_shape[1]), dtype=d_x.dtype)
        field.ravel()[d_idx] = d_x
        return self._convolve_rows(dev, field).ravel()[d_idx]

    def convolve_physical(self, f: np.ndarray, dtype: object = np.float64) -> np.ndarray:
        """(K * f) on the physical N1 x N2 grid for a field f given on it (host arrays)."""
        dt = operator_dtype(dtype)
        n1, n2 = self.grid_shape
        with self._lock:
            dev = self._state()
            field = dev.xp.zeros((n1, self.padded_shape[1]), dtype=dt)
            field[:, :n2] = dev.xp.asarray(f, dtype=dt)
            return to_host(self._convolve_rows(dev, field)[:, :n2])

    def _convolve_rows(self, dev: "_DeviceState", field: Any) -> Any:
        """K * field for a field on the N1 physical rows of the padded grid (N1 x P1,
        zero beyond the physical columns), in the field's precision: the pruned
        transform pair; returns the N1 x P1 result rows."""
        dev.convolving_in(field.dtype)
        fft = dev.xp.fft
        n1 = self.grid_shape[0]
        p0, p1 = self.padded_shape
        self.fft_count += 2
        rows = fft.rfft(field, axis=1)  # N1 x (P1/2 + 1)
        spec = fft.fft(rows, n=p0, axis=0)  # P0 x (P1/2 + 1); P0 = N1 when periodic
        spec *= dev.spectrum(field.dtype)
        back = fft.ifft(spec, axis=0)[:n1]
        return fft.irfft(back, n=p1, axis=1)

    def matvec_work_nbytes(self, dtype: object = np.float64) -> int:
        """Device bytes a convolution in ``dtype`` allocates: the row field, the padded
        spectrum, the back rows and the result rows."""
        return convolution_work_nbytes(self.grid_shape, self.padded_shape, dtype)

    def device_nbytes(self, dtype: object = np.float64) -> int:
        """Bytes on the device: the spectrum (and its float32 copy) and the work of ``dtype``."""
        dt = operator_dtype(dtype)
        spectrum = self.khat.nbytes + (self.khat.nbytes // 2 if dt == np.float32 else 0)
        return int(spectrum + self.matvec_work_nbytes(dt))

    def work_nbytes(self, dtype: object = np.float64) -> int:
        # Host: the kernel table and its spectrum (kept for blocks/submatrix); plus the device.
        return int(self.table.nbytes + self.khat.nbytes + self.device_nbytes(dtype))


class _DeviceState:
    """What one process holds on the device for one transform: the spectrum in each
    precision used and the padded indices of recently used operators (an upload per
    operator, not per matvec).  ``tight`` (``memory_tight``): the unused blocks are given
    back whenever the convolutions change precision."""

    def __init__(self, xp: ModuleType, khat: np.ndarray, tight: bool = False) -> None:
        self.xp = xp
        self.tight = tight
        self._precision: str | None = None  # of the last convolution
        self._khat = khat
        self._stored: Any = None  # the spectrum as the host holds it, copied once
        self._spectra: dict[str, Any] = {}
        self._quarter: Any = None
        self._indices: OrderedDict[int, tuple[np.ndarray, Any]] = OrderedDict()

    def convolving_in(self, dtype: Any) -> None:
        """Before each convolution, in ``dtype``: when tight and the precision changed, the
        pool's and the FFT plans' unused blocks go back first (``release_cached_blocks``)."""
        name = np.dtype(dtype).name
        if self.tight and self._precision not in (None, name):
            release_cached_blocks(self.xp)
        self._precision = name

    def spectrum(self, dtype: Any) -> Any:
        """The kernel spectrum on the device in the precision of a real ``dtype``: the host's
        copied once as it is, another precision converted from it there (no host copy)."""
        real = np.dtype(dtype)
        got = self._spectra.get(real.name)
        if got is None:
            if self._stored is None:
                self._stored = self.xp.asarray(self._khat)
            target = np.result_type(real, np.complex64) if np.iscomplexobj(self._khat) else real
            got = self._spectra[real.name] = self._stored if self._stored.dtype == target else self._stored.astype(target)
        return got

    def quarter_table(self, table: np.ndarray, grid_shape: tuple[int, int]) -> tuple[Any, int]:
        """The kernel table at the offsets within the grid (|di| < N0, |dj| < N1) on the
        device, flat, and its row width: what an even table's partial products read."""
        if self._quarter is None:
            n0, n1 = grid_shape
            self._quarter = self.xp.asarray(np.ascontiguousarray(table[:n0, :n1]).ravel())
        return self._quarter, int(grid_shape[1])

    def holds(self, khat: np.ndarray, table: np.ndarray, grid_shape: tuple[int, int]) -> bool:
        """Whether every array held here is what ``spectrum``, ``quarter_table`` and
        ``indices`` put here from ``khat``, ``table`` and the host indices (copied back)."""
        if self._khat is not khat or (self._stored is not None and not np.array_equal(to_host(self._stored), khat)):
            return False
        for name, got in self._spectra.items():
            target = np.result_type(np.dtype(name), np.complex64) if np.iscomplexobj(khat) else np.dtype(name)
            if not np.array_equal(to_host(got), khat.astype(target)):
                return False
        n0, n1 = grid_shape
        if self._quarter is not None and not np.array_equal(to_host(self._quarter), table[:n0, :n1].ravel()):
            return False
        return all(key == id(pidx) and np.array_equal(to_host(dev), pidx) for key, (pidx, dev) in self._indices.items())

    def indices(self, pidx: np.ndarray) -> Any:
        key = id(pidx)
        hit = self._indices.get(key)
        if hit is not None and hit[0] is pidx:
            self._indices.move_to_end(key)
            return hit[1]
        dev = self.xp.asarray(pidx)
        self._indices[key] = (pidx, dev)  # the host array is held, so its id stays unique
        while len(self._indices) > INDEX_CACHE_SIZE:
            self._indices.popitem(last=False)
        return dev


@functools.lru_cache(maxsize=1)
def _even_gather_module(xp: ModuleType) -> Any:
    """``_EVEN_GATHER_SOURCE`` as a CuPy module of ``xp`` (compiled on its first call)."""
    return xp.RawModule(code=_EVEN_GATHER_SOURCE)


def device_even_product(xp: ModuleType, table: Any, width: int, rows: tuple[Any, Any], cols: tuple[Any, Any],
                        x: Any) -> Any:
    """``operators.even_table_product`` by CUDA kernels of CuPy ``xp``: each (column group,
    row) thread sums its row's entries over a span of the columns in column order, and the
    groups' sums are added in group order, so the answer does not depend on the launch.
    rows and cols are grid (row, column) positions; x the columns' amounts."""
    (ri, rj), (ci, cj) = rows, cols
    nrows, ncols = int(ri.size), int(ci.size)
    if nrows == 0 or ncols == 0:
        return xp.zeros(nrows, dtype=np.float64)
    span = -(-ncols // min(ncols, max(1, -(-GATHER_THREADS // nrows))))
    groups = -(-ncols // span)
    cells = groups * nrows
    ri, rj, ci, cj = (xp.ascontiguousarray(v, dtype=np.int64) for v in (ri, rj, ci, cj))
    table, x = xp.ascontiguousarray(table, dtype=np.float64), xp.ascontiguousarray(x, dtype=np.float64)
    module = _even_gather_module(xp)
    parts = xp.empty(cells, dtype=np.float64)
    module.get_function("contactbench_even_gather")(
        (-(-cells // GATHER_BLOCK),), (GATHER_BLOCK,),
        (table, np.int64(width), ri, rj, np.int64(nrows), ci, cj, x, np.int64(ncols), np.int64(span),
         np.int64(cells), parts))
    if groups == 1:
        return parts
    out = xp.empty(nrows, dtype=np.float64)
    module.get_function("contactbench_group_sum")(
        (-(-nrows // GATHER_BLOCK),), (GATHER_BLOCK,), (parts, np.int64(groups), np.int64(nrows), out))
    return out


class ArrayFFTOperator(FFTOperator):
    """``FFTOperator`` whose convolutions run through ``xp`` (CuPy on a GPU); every
    dense gather (submatrix, entries, blocks) and the precision handling are the CPU
    operator's own."""

    transform: ArrayKernelTransform

    def __init__(self, transform: ArrayKernelTransform, grid_idx: np.ndarray, auto_dense: bool | None = None,
                 dtype: object = np.float64) -> None:
        if not isinstance(transform, ArrayKernelTransform):
            raise ProblemInputError("ArrayFFTOperator needs an ArrayKernelTransform (ArrayKernelTransform.from_host)")
        super().__init__(transform, grid_idx, auto_dense=auto_dense, dtype=dtype)

    @property
    def kind(self) -> str:
        return "gpu" if self.transform.xp_name == "cupy" else f"ArrayFFTOperator[{self.transform.xp_name}]"

    @property
    def space(self) -> ArraySpace:
        """Where a device-resident solve keeps its vectors (``matvec`` takes them there)."""
        return self.transform.space

    def matvec(self, x: Any) -> Any:
        """H_II x: a numpy array in and out (module doc), or an array of ``space`` in and
        out with no transfer (in the operator's precision; no dense switch there)."""
        if on_host(x) or self.space.host:
            return super().matvec(x)
        self.matvec_count += 1
        return self.transform.device_apply(self.pidx, x.astype(self.dtype, copy=False))

    def partial_product(self, rows: Any, cols: Any, x: Any) -> Any:
        """``FFTOperator.partial_product``; with rows, cols and x in ``space``, there: the
        entries gathered from the kernel table's quarter on the device (an even table,
        K(di, dj) = table[|di|, |dj|]; on CuPy by CUDA kernels, ``device_even_product``,
        unless ``FUSED_GATHER`` is off); for a table that is not even, the host's, its few
        rows and columns moved explicitly."""
        if on_host(rows) or self.space.host:
            return super().partial_product(rows, cols, x)
        if np.iscomplexobj(self.transform.khat):
            get = self.space.get
            return self.space.put(super().partial_product(get(rows), get(cols), get(x)))
        with self.transform._lock:
            dev = self.transform._state()
            table, width = dev.quarter_table(self.transform.table, self.transform.grid_shape)
            pi, pj = dev.indices(self._pi), dev.indices(self._pj)
        rows_at, cols_at, x = (pi[rows], pj[rows]), (pi[cols], pj[cols]), x.astype(np.float64, copy=False)
        if FUSED_GATHER and self.transform.xp_name == "cupy":
            return device_even_product(dev.xp, table, width, rows_at, cols_at, x)
        return even_table_product(table, width, rows_at, cols_at, x, chunk=DEVICE_PARTIAL_CHUNK)

    def _same_kind(self, op: FFTOperator) -> "ArrayFFTOperator":
        """``op`` (made by an inherited method) as an operator of this class."""
        out = ArrayFFTOperator(self.transform, op.grid_idx, auto_dense=op.auto_dense, dtype=op.dtype)
        out._dense = op._dense
        return out

    def restrict(self, idx: np.ndarray) -> "ArrayFFTOperator":
        return self._same_kind(super().restrict(idx))

    def _in_precision(self, dtype: np.dtype) -> "ArrayFFTOperator":
        return self._same_kind(super()._in_precision(dtype))


def device_floor_pair(transform: ArrayKernelTransform, dtype: object = np.float64) -> Callable[[], Any]:
    """The FFT floor of a device matvec (the GPU counterpart of ``fft_floor_pair``): a
    function that runs only the pruned transform pair on device arrays of its own -- row
    rFFTs on the N1 rows, column FFT and iFFT of length P0, row irFFTs -- with no scatter,
    gather, product or transfer.  It returns the last array (the caller synchronises)."""
    dt = operator_dtype(dtype)
    xp = transform.xp
    n1 = transform.grid_shape[0]
    p0, p1 = transform.padded_shape
    field = xp.asarray(np.random.default_rng(0).random((n1, p1)).astype(dt))

    def pair() -> Any:
        spec = xp.fft.fft(xp.fft.rfft(field, axis=1), n=p0, axis=0)
        return xp.fft.irfft(xp.fft.ifft(spec, axis=0)[:n1], n=p1, axis=1)

    return pair


def array_fft_operator(host: KernelTransform, grid_idx: np.ndarray, xp: str = "cupy") -> ArrayFFTOperator:
    """H_II on the array module ``xp`` for the grid indices ``grid_idx`` of ``host``'s grid."""
    return ArrayFFTOperator(ArrayKernelTransform.from_host(host, xp), grid_idx)


__all__ = [
    "ARRAY_MODULES",
    "ArraySpace",
    "HOST",
    "ArrayFFTOperator",
    "ArrayKernelTransform",
    "array_fft_operator",
    "device_even_product",
    "device_floor_pair",
    "array_module",
    "gpu_unavailable_reason",
    "named_space",
    "operator_model_nbytes",
    "on_host",
]
