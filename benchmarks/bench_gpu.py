"""One matvec of the GPU operator (CuPy) against its device FFT floor and the CPU operator.

For each N (RMD surface, H = 0.7, BCC kernel, non-periodic -- the paper's section 5
set-up, as in bench_matvec.py) and two trial sets (the whole grid and the paper's top
load step), in float64 and float32, this times on the same machine, interleaved:

* ``gpu_ms``: ``ArrayFFTOperator.matvec`` -- x sent to the device, the pruned transform
  pair and the spectrum product there, H_II x brought back (what the solvers call);
* ``device_ms``: ``ArrayKernelTransform.device_apply`` -- the same product with x and the
  result already on the device (no host transfers);
* ``floor_ms``: ``device_floor_pair`` -- the bare cuFFT transform pair on the device;
* ``cpu_ms``: the CPU operator (ducc0, ``fft_workers()`` threads: all cores unless
  CONTACTBENCH_FFT_WORKERS says otherwise), up to --cpu-max.

Also: the relative difference of each product from the CPU float64 one (above --cpu-max,
from the GPU float64 one), and CuPy's memory pool after the size (MiB).  Rows are appended
to the CSV as they are measured.
Needs CuPy and a CUDA device (the ``gpu`` extra); elsewhere it exits with code 2 and
the reason.

Run:  python benchmarks/bench_gpu.py [--sizes 2048 4096 8192] [--cpu-max 4096] [--out results/perf/gpu-matvec.csv]
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import asdict, dataclass, fields
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Callable

import numpy as np

from csv_rows import host_name
from bench_matvec import TRIAL_SETS, interleaved_best, trial_set
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.operators import FFTOperator, fft_workers
from contactbench.problems.operators_gpu import (
    ArrayFFTOperator,
    ArrayKernelTransform,
    device_floor_pair,
    gpu_unavailable_reason,
)
from contactbench.problems.surfaces import rmd_surface_n

OUT = Path(__file__).resolve().parents[1] / "results" / "perf" / "gpu-matvec.csv"


@dataclass
class GpuRow:
    N: int
    trial_set: str
    n: int
    dtype: str
    device: str
    gpu_ms: float
    device_ms: float
    floor_ms: float
    cpu_ms: float  # NaN above --cpu-max
    cpu_threads: int
    device_over_floor: float
    cpu_over_gpu: float
    rel_diff_vs_cpu64: float
    pool_mib: float
    host: str


def synced(fn: Callable[[], object], sync: Callable[[], None]) -> Callable[[], None]:
    def run() -> None:
        fn()
        sync()

    return run


def append(path: Path, row: GpuRow) -> None:
    new = not path.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=[f.name for f in fields(GpuRow)])
        if new:
            w.writeheader()
        w.writerow(asdict(row))


def bench_size(N: int, cpu_max: int, repeats: int, out: Path) -> None:
    """Measure one N (``measure_size``), then give the device memory back: every device
    array of the size lives in ``measure_size``'s frame and is freed when it returns."""
    import cupy  # the `gpu` extra, checked by main() before any size

    measure_size(cupy, N, cpu_max, repeats, out)
    cupy.get_default_memory_pool().free_all_blocks()


def measure_size(cupy: ModuleType, N: int, cpu_max: int, repeats: int, out: Path) -> None:
    """Append one row per trial set and precision for size N (module doc)."""
    sync = cupy.cuda.Device().synchronize
    device = cupy.cuda.runtime.getDeviceProperties(0)["name"].decode()
    surface = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
    builder = InstanceBuilder(surface, 1e9, "bcc", periodic=False)
    gpu_transform = ArrayKernelTransform.from_host(builder.transform, "cupy")
    rng = np.random.default_rng(0)
    for label in TRIAL_SETS:
        idx = trial_set(label, builder)
        cpu64 = FFTOperator(builder.transform, idx, auto_dense=False)
        gpu64 = ArrayFFTOperator(gpu_transform, idx, auto_dense=False)
        x = rng.random(idx.size)
        y64 = cpu64.matvec(x) if N <= cpu_max else gpu64.matvec(x)
        for dtype in (np.float64, np.float32):
            gpu, cpu = gpu64.with_precision(dtype), cpu64.with_precision(dtype)
            d_x = cupy.asarray(x.astype(dtype))
            fns: dict[str, Callable[[], object]] = {
                "gpu": partial(gpu.matvec, x),
                "device": synced(partial(gpu_transform.device_apply, gpu.pidx, d_x), sync),
                "floor": synced(device_floor_pair(gpu_transform, dtype), sync),
            }
            if N <= cpu_max:
                fns["cpu"] = partial(cpu.matvec, x)
            ms = interleaved_best(fns, repeats)
            cpu_ms = ms.get("cpu", float("nan"))
            diff = float(np.linalg.norm(gpu.matvec(x) - y64) / np.linalg.norm(y64))
            row = GpuRow(N, label, idx.size, np.dtype(dtype).name, device, ms["gpu"], ms["device"], ms["floor"],
                         cpu_ms, fft_workers(), ms["device"] / ms["floor"], cpu_ms / ms["gpu"], diff,
                         cupy.get_default_memory_pool().total_bytes() / 2**20, host_name())
            append(out, row)
            print(f"N={N} {label} {row.dtype}: gpu {row.gpu_ms:.2f} ms, device {row.device_ms:.2f}, floor "
                  f"{row.floor_ms:.2f} ({row.device_over_floor:.2f}x), cpu {cpu_ms:.1f} ({row.cpu_over_gpu:.1f}x), "
                  f"diff {diff:.1e}, pool {row.pool_mib:.0f} MiB", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2048, 4096, 8192])
    ap.add_argument("--cpu-max", type=int, default=4096, help="largest N whose CPU matvec is timed")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    reason = gpu_unavailable_reason()
    if reason is not None:
        print(f"bench_gpu: error: needs CuPy and a CUDA device: {reason}", file=sys.stderr)
        sys.exit(2)
    if any(n < 8 for n in args.sizes):
        ap.error("--sizes: every N must be at least 8")
    print(f"host {host_name()}; CPU operator on {fft_workers()} threads", flush=True)
    for N in args.sizes:
        t0 = time.perf_counter()
        bench_size(N, args.cpu_max, args.repeats, args.out)
        print(f"N={N} done in {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
