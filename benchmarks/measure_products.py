"""One product with H on this host (results/perf/time-model/README.md): the FFT operator,
float64, the FFT path forced, on two trial sets of each grid; a dense H on BLAS with one
and two threads.  The fastest of several short bursts, and their median.

Run:  .venv/bin/python benchmarks/measure_products.py [SIDES ...]
"""
from __future__ import annotations

import sys
import time
from typing import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import DenseOperator, FFTOperator
from contactbench.problems.surfaces import rmd_surface_n


def bursts(fn: Callable[[], object], turns: int, burst: int = 3) -> tuple[float, float]:
    """(fastest, median) seconds of ``turns`` x (one untimed call, ``burst`` timed ones)."""
    times = []
    for _ in range(turns):
        fn()
        for _ in range(burst):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def main() -> None:
    sides = [int(a) for a in sys.argv[1:]] or [64, 128, 256, 512, 1024]
    rng = np.random.default_rng(0)
    print(f"{'N':>5} {'share':>6} {'n':>8} {'P':>9} {'min ms':>8} {'med ms':>8} {'s/PlogP':>10}")
    for N in sides:
        surface = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
        b = InstanceBuilder(surface, 1e9, "bcc")
        top = paper_max_displacement(surface)
        for share in (0.25, 1.0):
            op = FFTOperator(b.transform, b.build(share * top).geometry.indices, auto_dense=False)
            P = float(np.prod(op.transform.padded_shape))
            x = rng.random(op.n)
            mn, md = bursts(lambda: op.matvec(x), 5 if N <= 512 else 3)
            print(f"{N:>5} {share:>6} {op.n:>8} {int(P):>9} {1e3 * mn:>8.3f} {1e3 * md:>8.3f} "
                  f"{mn / (P * np.log2(P)):>10.3e}", flush=True)
    for threads in (1, 2):
        with threadpool_limits(threads, "blas"):
            for n in (64, 256, 1024, 2048, 4096):
                H = rng.random((n, n))
                op = DenseOperator(H + H.T)
                x = rng.random(n)
                mn, md = bursts(lambda: op.matvec(x), 7)
                print(f"dense, BLAS threads {threads}, n = {n:>5}: min {1e3 * mn:.4f} ms, median {1e3 * md:.4f} ms, "
                      f"{2 * n * n / mn:.3e} flop/s", flush=True)


if __name__ == "__main__":
    main()
