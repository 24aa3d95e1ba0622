"""The stress battery over the registered solvers -> results/stress/.

    .venv/bin/python benchmarks/bench_stress.py cond      # cond(H_II) vs n, both kernels
    .venv/bin/python benchmarks/bench_stress.py survival  # every solver through the battery
    .venv/bin/python benchmarks/bench_stress.py report    # results/stress/README.md

``cond``: extreme eigenvalues of H_II (BCC and Love, aperiodic) on trial sets of
n = 1e2 .. 1e5 points at packing densities 1.0 and 0.2 -- dense eigvalsh up to
n = 2500, Lanczos (ARPACK) on the matrix-free FFT operator beyond.
``survival``: ``harness.conformance.validate`` of every available solver on the battery
("full" by default; ``--mode fast``), each solve in a killable worker with a time limit
and judged by ``harness.judging`` (the verdict of ``contactbench run``).  The verdict rows
(one per solve, plus the unit-agreement and perturbation rows, each with its solver's
outcome: conforms / wrong / incomplete) go to ``survival-MODE.csv``; ``report`` pivots
them into the survival and unit-scaling tables.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import pandas as pd

OUT = Path("results/stress")


def run_cond(out: Path, sizes: list[int], densities: list[float], tag: str = "") -> None:
    from contactbench.problems.scenes.stress import extreme_eigenvalues, packed_instance

    rows = []
    path = out / (f"conditioning-{tag}.csv" if tag else "conditioning.csv")
    for kernel in ("bcc", "love"):
        for density in densities:
            for n in sizes:
                inst = packed_instance(n, density, kernel, seed=0)
                t0 = time.perf_counter()
                lmin, lmax, method = extreme_eigenvalues(inst.qp.H)
                rows.append({"kernel": kernel, "density": inst.meta["density"], "target_density": density,
                             "n": inst.n, "N": inst.meta["N"], "lambda_min": lmin, "lambda_max": lmax,
                             "cond": lmax / lmin, "method": method, "matvecs": inst.qp.H.matvec_count,
                             "time_s": time.perf_counter() - t0})
                print(rows[-1], flush=True)
                pd.DataFrame(rows).to_csv(path, index=False)


def run_survival(out: Path, mode: str, timeout: float, solvers: list[str] | None) -> None:
    from contactbench.harness.conformance.battery import conformance_cases, validate
    from contactbench.solvers.registry import available_solvers

    names = solvers or list(available_solvers())
    cases = conformance_cases(mode)
    frames = []
    for name in names:
        t0 = time.perf_counter()
        table = validate(name, cases, mode=mode, timeout=timeout)
        print(f"{table.summary()}  [{time.perf_counter() - t0:.0f} s]", flush=True)
        if not table.rows:
            continue
        frames.append(table.to_frame())
        pd.concat(frames, ignore_index=True).to_csv(out / f"survival-{mode}.csv", index=False)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=("cond", "survival", "report"))
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--sizes", default="100,1000,10000,100000")
    ap.add_argument("--densities", default="1.0,0.2")
    ap.add_argument("--mode", default="full", choices=("fast", "full"))
    ap.add_argument("--timeout", type=float, default=10.0)
    ap.add_argument("--solvers", default=None, help="comma list (default: every available solver)")
    ap.add_argument("--tag", default="", help="cond: write conditioning-TAG.csv (the report reads them all)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.what == "cond":
        run_cond(out, [int(s) for s in a.sizes.split(",")], [float(d) for d in a.densities.split(",")], a.tag)
    elif a.what == "survival":
        run_survival(out, a.mode, a.timeout, a.solvers.split(",") if a.solvers else None)
    else:
        from contactbench.harness.report.sections.stress import write_stress_report

        print(write_stress_report(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
