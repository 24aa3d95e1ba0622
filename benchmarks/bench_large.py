"""Scale check for the fast solvers: one load step of the paper-sweep scene at 2048^2
(and optionally 4096^2), non-periodic BCC, judged by harness.kkt.kkt_check.

The step solved is the paper's top step Delta = (z_max - z_mean)/2, cold-started
(the hardest single step; a sweep would warm-start it).  Prints wall time, matvecs,
trial-set size, kkt and the peak RSS, plus the state memory of the operator
(kernel table + real spectrum + FFT work arrays) -- the figure that decides
feasibility at 4096^2.

Usage: python benchmarks/bench_large.py [--sizes 2048] [--solver fast-ccg] [--fraction 1.0]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from harness.kkt import kkt_check
from problems.instances import InstanceBuilder, paper_max_displacement
from problems.operators import fft_backend, fft_workers
from problems.surfaces import rmd_surface_n
from solvers.base import SolverSettings
from solvers.registry import get_solver


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="2048")
    ap.add_argument("--solver", default="fast-ccg")
    ap.add_argument("--fraction", type=float, default=1.0, help="Delta as a fraction of the paper's top step")
    ap.add_argument("--tol", type=float, default=1e-9)
    args = ap.parse_args()
    for N in (int(s) for s in args.sizes.split(",")):
        t0 = time.perf_counter()
        surf = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
        b = InstanceBuilder(surf, 1e9, "bcc", periodic=False)
        inst = b.build(args.fraction * paper_max_displacement(surf))
        setup = time.perf_counter() - t0
        op = inst.qp.H
        t = time.perf_counter()
        res = get_solver(args.solver).solve(inst.qp, SolverSettings(profile="high", tol=args.tol))
        dt = time.perf_counter() - t
        kkt = kkt_check(inst, res.p).kkt_error
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(f"N={N} n={inst.n} solver={args.solver} fft={fft_backend()}x{fft_workers()} setup={setup:.1f}s solve={dt:.1f}s "
              f"iterations={res.iterations} matvecs={res.matvecs} ({1e3 * dt / max(res.matvecs, 1):.0f} ms each) "
              f"kkt={kkt:.2e} load={inst.load(res.p):.6e} A/A0={inst.contact_fraction(res.p):.5f} "
              f"operator_state={op.memory_nbytes / 2**20:.0f} MiB peak_rss={rss:.0f} MiB", flush=True)


if __name__ == "__main__":
    main()
