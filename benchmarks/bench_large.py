"""Scale check for the fast solvers: one load step of the paper-sweep scene at 2048^2
(and optionally 4096^2), non-periodic BCC, solved and judged by the harness's
``solve_sequence`` (a sequence of one step).

The step solved is the paper's top step Delta = (z_max - z_mean)/2, cold-started
(the hardest single step; a sweep would warm-start it).  Prints wall time, matvecs,
trial-set size, kkt and the peak RSS, plus the state memory of the operator
(kernel table + real spectrum + FFT work arrays) -- the figure that decides
feasibility at 4096^2.

Every run is one child process (its own peak RSS), so "--backends ducc,scipy" compares
the two FFT libraries side by side in one run.  Rows are appended to --out (CSV).

Options of the fast solvers as columns: ``--precisions double,mixed`` (mixed:
float32 inner CCG under float64 iterative refinement; matvecs reported by precision) and
``--first-guesses zero,coarse`` (a cold start from the 2x-coarser grid's answer; its
matvecs, each on a 4x smaller grid, are in "coarse_matvecs" and in "matvecs").  Every
combination is one child process.  The FFT floor of each precision
(``problems.operators.fft_floor_pair``, the fastest of its layouts, best of 5, timed in the same child) is in
"floor64_ms" / "floor32_ms"; "ms_per_matvec" is solve seconds over matvecs (all work of
the solve included), "peak_rss_mib" the child's peak up to the end of the solve (read before the floors are timed).

Usage: python benchmarks/bench_large.py [--sizes 2048,4096] [--solvers fast-dual-pccg,fast-ccg]
       [--precisions double,mixed] [--first-guesses zero,coarse] [--backends ducc,scipy]
       [--fraction 1.0] [--out results/perf/large.csv]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from contactbench.harness.run.isolation import set_parent_death_signal
from contactbench.harness import solve_sequence
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import fft_backend, fft_workers
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import SolverSettings

try:  # the FFT floor; absent in checkouts before 26d4209
    from contactbench.problems.operators import fft_floor_pair
except ImportError:  # pragma: no cover
    fft_floor_pair = None
try:  # the floor's layouts; checkouts before b302c1c time the strided one only
    from contactbench.problems.operators import FLOOR_LAYOUTS
except ImportError:  # pragma: no cover
    FLOOR_LAYOUTS = ()


def floor_ms(transform, dtype: type) -> float | str:
    """Best of 5 of the bare FFT pair a matvec of ``dtype`` needs (ms), in the fastest of
    its layouts (one layout's arrays alive at a time), or "" without it."""
    if fft_floor_pair is None or fft_backend() != "ducc":
        return ""
    best = np.inf
    for layout in FLOOR_LAYOUTS or (None,):
        pair = fft_floor_pair(transform, dtype, layout) if layout else fft_floor_pair(transform, dtype)
        pair()
        for _ in range(5):
            t = time.perf_counter()
            pair()
            best = min(best, time.perf_counter() - t)
        del pair
    return round(1e3 * best, 1)


def solve_one(N: int, solver: str, fraction: float, tol: float, precision: str, first_guess: str) -> dict:
    t0 = time.perf_counter()
    surf = rmd_surface_n(N, 0.7, length=100e-6, seed=0)
    b = InstanceBuilder(surf, 1e9, "bcc", periodic=False)
    inst = b.build(fraction * paper_max_displacement(surf))
    setup = time.perf_counter() - t0
    op = inst.qp.H
    params = {"precision": precision, "first_guess": first_guess} if solver.startswith("fast-") else {}
    if solver == "fast-pdas":
        params.pop("first_guess")
    (step,) = solve_sequence(solver, [inst], SolverSettings(tol=tol, params=params))
    res, dt = step.result, step.seconds
    assert res is not None, step.error
    info = res.info
    peak_rss_mib = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)  # before the floors' arrays
    return {
        "N": N, "n": inst.n, "solver": solver, "precision": precision, "first_guess": first_guess,
        "fft": fft_backend(), "threads": fft_workers(),
        "setup_s": round(setup, 2), "solve_s": round(dt, 2), "iterations": res.iterations,
        "matvecs": res.matvecs, "matvecs_float64": info.get("matvecs_float64", ""),
        "matvecs_float32": info.get("matvecs_float32", ""), "coarse_matvecs": info.get("coarse_matvecs", 0),
        "ms_per_matvec": round(1e3 * dt / max(res.matvecs, 1), 1),
        "floor64_ms": floor_ms(op.transform, np.float64) if hasattr(op, "transform") else "",
        "floor32_ms": floor_ms(op.transform, np.float32) if hasattr(op, "transform") else "",
        "kkt": f"{step.kkt_error:.2e}", "load_N": f"{inst.load(res.p):.8e}",
        "contact_fraction": round(inst.contact_fraction(res.p), 6),
        "operator_state_mib": round(op.memory_nbytes / 2**20),
        "peak_rss_mib": peak_rss_mib,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="2048")
    ap.add_argument("--solvers", default="fast-dual-ccg")
    ap.add_argument("--precisions", default="double", help="comma list of double,mixed (fast solvers)")
    ap.add_argument("--first-guesses", default="zero", help="comma list of zero,coarse (fast CCGs)")
    ap.add_argument("--backends", default="", help="comma list of ducc,scipy (default: the operator's default)")
    ap.add_argument("--fraction", type=float, default=1.0, help="Delta as a fraction of the paper's top step")
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--out", default="results/perf/large.csv")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        set_parent_death_signal()  # a killed run takes its solve with it
        N, solver, precision, guess = args.child.split(":")
        print("RESULT " + json.dumps(solve_one(int(N), solver, args.fraction, args.tol, precision, guess)), flush=True)
        return
    out = Path(args.out)
    combos = [(N, solver, prec, guess, backend)
              for N in (int(s) for s in args.sizes.split(","))
              for solver in args.solvers.split(",")
              for prec in args.precisions.split(",")
              for guess in args.first_guesses.split(",")
              for backend in (args.backends.split(",") if args.backends else [""])]
    for N, solver, prec, guess, backend in combos:
        env = dict(os.environ)
        if backend:
            env["CONTACTBENCH_FFT_BACKEND"] = backend
        cmd = [sys.executable, __file__, "--child", f"{N}:{solver}:{prec}:{guess}",
               "--fraction", str(args.fraction), "--tol", str(args.tol)]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        rows = [json.loads(x[7:]) for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
        if not rows:
            print(f"N={N} {solver} {backend}: failed\n{proc.stderr[-800:]}", flush=True)
            continue
        row = rows[0]
        print(" ".join(f"{k}={v}" for k, v in row.items()), flush=True)
        new = not out.exists()
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(out, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)


if __name__ == "__main__":
    main()
