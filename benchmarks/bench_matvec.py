"""FFT matrix-free matvec versus dense matvec: time and peak memory.

For N = 256, 512, 1024, 2048 (RMD surface, H = 0.7, BCC kernel, non-periodic -- the
paper's section 5 set-up) and two trial sets -- the whole grid and the paper's top load
step, Delta = (xi_max - xi_mean)/2 -- this measures one H_II x product by the FFT
operator (problems/operators.py) and, where the dense matrix fits (n <= DENSE_MAX_N),
by the dense n x n matrix.  Peak memory is tracemalloc's peak over one product (numpy
reports its buffers to tracemalloc), plus the operator's own held bytes.

Run:  CONTACTBENCH_FFT_WORKERS=1 .venv/bin/python benchmarks/bench_matvec.py [--sizes 256 512]
Writes results/perf/matvec.csv and prints the table.
"""

from __future__ import annotations

import argparse
import csv
import time
import tracemalloc
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import ContactOperator, DenseOperator, fft_workers
from contactbench.problems.surfaces import rmd_surface_n

DENSE_MAX_N = 20_000
OUT = Path(__file__).resolve().parents[1] / "results" / "perf" / "matvec.csv"


@dataclass
class MatvecRow:
    N: int
    trial_set: str
    n: int
    operator: str
    setup_s: float
    matvec_ms: float
    matvec_peak_mib: float
    held_mib: float
    rel_diff_vs_fft: float
    fft_workers: int


def time_matvec(op: ContactOperator, x: np.ndarray, repeats: int) -> tuple[float, float]:
    """Median wall time (ms) of ``repeats`` products and tracemalloc's peak (MiB) of one."""
    op.matvec(x)  # warm-up (plans, caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        op.matvec(x)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    tracemalloc.reset_peak()
    op.matvec(x)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return 1e3 * float(np.median(times)), peak / 2**20


def bench_size(N: int, repeats: int) -> list[MatvecRow]:
    surface = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
    t0 = time.perf_counter()
    builder = InstanceBuilder(surface, 1e9, "bcc", periodic=False)
    _ = builder.transform
    transform_s = time.perf_counter() - t0
    rows: list[MatvecRow] = []
    sets = {"full-grid": np.arange(N * N), "paper-top-step": builder.build(paper_max_displacement(surface)).geometry.indices}
    rng = np.random.default_rng(0)
    for label, idx in sets.items():
        fft = builder.operator_on(idx, kind="fft")
        x = rng.random(fft.n)
        ms, peak = time_matvec(fft, x, repeats)
        rows.append(MatvecRow(N, label, fft.n, "fft", transform_s, ms, peak, fft.memory_nbytes / 2**20, 0.0, fft_workers()))
        if fft.n <= DENSE_MAX_N:
            t0 = time.perf_counter()
            dense = DenseOperator(fft.to_dense())
            setup = time.perf_counter() - t0
            ms_d, peak_d = time_matvec(dense, x, repeats)
            y_f, y_d = fft.matvec(x), dense.matvec(x)
            diff = float(np.linalg.norm(y_f - y_d) / np.linalg.norm(y_d))
            rows.append(MatvecRow(N, label, fft.n, "dense", setup, ms_d, peak_d, dense.memory_nbytes / 2**20, diff, fft_workers()))
            del dense
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024, 2048])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    rows = [r for N in args.sizes for r in bench_size(N, args.repeats)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(asdict(rows[0])))
        w.writeheader()
        w.writerows(asdict(r) for r in rows)
    print(f"{'N':>5} {'trial set':<15} {'n':>8} {'op':<5} {'setup s':>8} {'matvec ms':>10} {'peak MiB':>9} {'held MiB':>9} {'rel diff':>9}")
    for r in rows:
        print(f"{r.N:>5} {r.trial_set:<15} {r.n:>8} {r.operator:<5} {r.setup_s:>8.3f} {r.matvec_ms:>10.2f} "
              f"{r.matvec_peak_mib:>9.1f} {r.held_mib:>9.1f} {r.rel_diff_vs_fft:>9.1e}")
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
