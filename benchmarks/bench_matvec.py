"""Cost of ONE matvec of the FFT operator against its FFT floor, float64 and float32.

For each N (RMD surface, H = 0.7, BCC kernel; non-periodic -- the paper's section 5
set-up -- unless --periodic) and two trial sets -- the whole grid and the paper's top
load step, Delta = (xi_max - xi_mean)/2 -- this times one H_II x product of the FFT
operator (problems/operators.py) in each precision (``with_precision``) and, in the
same run and interleaved with it, the FFT floor of that precision
(``fft_floor_pair``: the bare pruned r2c / c2c / c2c / c2r calls a matvec needs on the
padded grid, nothing else), timed in each of ``FLOOR_LAYOUTS`` (column transforms strided
or transposed; row transforms in one ducc0 call per direction, or in the matvec's row
blocks); floor_ms is the fastest.  ratio = matvec_ms / floor_ms (target: <= 1.2).

Memory: work_mib is the operator's FFT work arrays in that precision (what a matvec
runs in: half spectrum, row-block and column-block buffers); peak_mib is
tracemalloc's peak over one product (its temporaries: the gathered result, x cast);
held_mib is everything the operator holds (kernel table, spectrum (+ float32 copy),
work arrays, index arrays).

Run:  .venv/bin/python benchmarks/bench_matvec.py [--sizes 512 1024 2048] [--threads 1 2] [--periodic]
Writes results/perf/matvec.csv (or --out) and prints the table.
"""

from __future__ import annotations

import argparse
import csv
import os
import time
import tracemalloc
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import FLOOR_LAYOUTS, FFTOperator, fft_floor_pair
from contactbench.problems.surfaces import rmd_surface_n

OUT = Path(__file__).resolve().parents[1] / "results" / "perf" / "matvec.csv"
DTYPES = (np.float64, np.float32)


@dataclass
class MatvecRow:
    N: int
    periodic: bool
    trial_set: str
    n: int
    dtype: str
    fft_workers: int
    matvec_ms: float
    floor_ms: float  # the fastest of the layouts' floors
    floor_strided_ms: float  # row transforms in one ducc0 call per direction
    floor_transposed_ms: float
    floor_row_blocks_ms: float  # the faster column layout with the matvec's row blocks
    ratio: float
    work_mib: float
    peak_mib: float
    held_mib: float
    rel_diff_vs_float64: float


def interleaved_best(fns: dict[str, Callable[[], object]], repeats: int, burst: int = 3) -> dict[str, float]:
    """Best wall time (ms) of each function.  The functions take turns ``repeats`` times
    (so a slow spell of the machine slows them alike); at each turn a function runs once
    untimed, to bring its own arrays back into cache as a solver's repeated products
    find them, then ``burst`` timed calls.  The best of all is the least disturbed."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            fn()
            for _ in range(burst):
                t0 = time.perf_counter()
                fn()
                times[k].append(time.perf_counter() - t0)
    return {k: 1e3 * float(np.min(v)) for k, v in times.items()}


def traced_peak_mib(fn: Callable[[], object]) -> float:
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


TRIAL_SETS = ("full-grid", "paper-top-step")


def trial_set(name: str, builder: InstanceBuilder) -> np.ndarray:
    """Grid indices of a trial set: the whole grid, or the paper's top load step."""
    if name == "full-grid":
        return np.arange(builder.surface.heights.size)
    return builder.build(paper_max_displacement(builder.surface)).geometry.indices


def bench_size(N: int, periodic: bool, workers: int, repeats: int, set_names: tuple[str, ...] = TRIAL_SETS) -> list[MatvecRow]:
    os.environ["CONTACTBENCH_FFT_WORKERS"] = str(workers)
    surface = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
    builder = InstanceBuilder(surface, 1e9, "bcc", periodic=periodic)
    sets = {name: trial_set(name, builder) for name in set_names}
    rng = np.random.default_rng(0)
    rows: list[MatvecRow] = []
    for label, idx in sets.items():
        op64 = FFTOperator(builder.transform, idx, auto_dense=False)  # the FFT path at every n
        x = rng.random(op64.n)
        y64 = op64.matvec(x)
        for dtype in DTYPES:
            op = op64.with_precision(dtype)
            fns = {f"floor_{layout}": fft_floor_pair(builder.transform, dtype, layout) for layout in FLOOR_LAYOUTS}
            ms = interleaved_best({"matvec": lambda: op.matvec(x), **fns}, repeats)
            ms["floor"] = min(ms[k] for k in fns)
            ms["floor_row_blocks"] = min((v for k, v in ms.items() if k.endswith("-row-blocks")), default=float("nan"))
            del fns
            diff = float(np.linalg.norm(op.matvec(x) - y64) / np.linalg.norm(y64))
            rows.append(MatvecRow(
                N, periodic, label, op.n, np.dtype(dtype).name, workers, ms["matvec"], ms["floor"],
                ms["floor_strided"], ms["floor_transposed"], ms["floor_row_blocks"], ms["matvec"] / ms["floor"], op.matvec_work_nbytes / 2**20, traced_peak_mib(lambda: op.matvec(x)),
                op.memory_nbytes / 2**20, diff,
            ))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="ducc0 threads (fft_workers)")
    ap.add_argument("--periodic", action="store_true", help="periodic grid (default: the paper's non-periodic)")
    ap.add_argument("--trial-sets", nargs="+", choices=TRIAL_SETS, default=list(TRIAL_SETS))
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    rows = [r for N in args.sizes for w in args.threads for r in bench_size(N, args.periodic, w, args.repeats, tuple(args.trial_sets))]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(asdict(rows[0])))
        w.writeheader()
        w.writerows(asdict(r) for r in rows)
    print(f"{'N':>5} {'trial set':<15} {'n':>8} {'dtype':<8} {'thr':>3} {'matvec ms':>10} {'floor ms':>9} {'strided':>8} {'transp.':>8} {'row-blk':>8} {'ratio':>6} "
          f"{'work MiB':>9} {'peak MiB':>9} {'held MiB':>9} {'vs f64':>8}")
    for r in rows:
        print(f"{r.N:>5} {r.trial_set:<15} {r.n:>8} {r.dtype:<8} {r.fft_workers:>3} {r.matvec_ms:>10.2f} {r.floor_ms:>9.2f} {r.floor_strided_ms:>8.2f} {r.floor_transposed_ms:>8.2f} {r.floor_row_blocks_ms:>8.2f} "
              f"{r.ratio:>6.2f} {r.work_mib:>9.1f} {r.peak_mib:>9.2f} {r.held_mib:>9.1f} {r.rel_diff_vs_float64:>8.1e}")
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
