"""Our solvers against the field's codes (ContactMechanics, Tamaas): ordinary harness runs.

The peers are registered solvers (solvers/peer_cm.py, solvers/peer_tamaas.py; the
optional ``peers`` extra), so this script only calls ``contactbench run`` and
``contactbench report`` -- the same load loop, warm starts, time limits and KKT judge as
every other solver -- and summarises the stored tables.  Two cases, because Tamaas has
no BCC kernel (docs/peers.md):

* ``bcc-nonperiodic``    the paper's problem (BCC, finite patch): ours and ContactMechanics
  (our influence coefficients through its Green's-function hook);
* ``spectral-periodic``  the periodic 2/(E*|q|) problem: ours, ContactMechanics and every
  Tamaas solver.

Each case runs once per thread count (``--threads 1,2``, passed to ``contactbench run
--threads``: the worker sets OMP/OpenBLAS/MKL thread limits and our ducc0 FFT workers,
``CONTACTBENCH_FFT_WORKERS``; harness/run/isolation.py ``limit_threads``), into
OUT/t<threads>/<case>.  The summary (printed, and written to
OUT/summary.md) gives per solver: total solve time over the steps, steps solved, the
ratio of its time to ContactMechanics' dual CCG in the same run (ours/CM), the largest
relative load difference to ours over the steps (the loads must be equal for the ratio
to mean anything), and the largest peak memory of its solves (the harness's
``peak_mem_mb``: resident-memory growth of the worker during one solve).

Usage: python benchmarks/bench_peers.py [--size 512] [--steps 10] [--threads 1,2]
       [--ours fast-dual-pccg,fast-ccg] [--peers cm-dual-ccg,...] [--timeout 120]
       [--out results/peers] [--summary-only]
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from csv_rows import cell

CB = str(Path(sys.executable).with_name("contactbench"))
#: The peer every ratio is taken against.
CM = "cm-dual-ccg"


@dataclass(frozen=True)
class Case:
    folder: str
    flags: tuple[str, ...]
    peers: tuple[str, ...]


CASES = (
    Case("bcc-nonperiodic", (), (CM, "cm-pk-ccg")),
    Case("spectral-periodic", ("--periodic", "--kernel", "spectral"),
         (CM, "tamaas-pkr", "tamaas-kato", "tamaas-beck-teboulle", "tamaas-condat")),
)


@dataclass(frozen=True)
class SolverTotals:
    """One solver's figures over the steps of one run."""

    solver: str
    seconds: float  # total solve time over the steps
    solved: int
    ran: int
    peak_mem_mb: float  # largest peak memory of its solves
    max_load_diff: float  # max over steps of |P - P_ours| / P_ours (NaN where not comparable)


def case_dir(out: Path, threads: int, case: Case) -> Path:
    return out / f"t{threads}" / case.folder


def run_case(case: Case, threads: int, args: argparse.Namespace) -> Path:
    out = case_dir(Path(args.out), threads, case)
    peers = [p for p in case.peers if args.peers is None or p in args.peers.split(",")]
    solvers = ",".join((*args.ours.split(","), *peers))
    cmd = [CB, "run", "paper-sweep", "--size", str(args.size), "--steps", str(args.steps), *case.flags,
           "--solvers", solvers, "--threads", str(threads), "--profile", "high", "--timeout", str(args.timeout),
           "--out", str(out), "--no-progress"]
    print("+ " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    subprocess.run([CB, "report", str(out)], check=True)
    return out


def solver_totals(out: Path, ours: str) -> list[SolverTotals]:
    """Per solver of the run in ``out``: totals, peak memory and load agreement with ``ours``."""
    from contactbench.harness import load_table

    t = load_table(out)
    t = t[t["status"] != "skipped"]
    key = ["instance", "step"]
    ref = t[t["solver"] == ours].groupby(key)["load"].first()
    rows = []
    for s, d in t.groupby("solver"):
        loads = d.groupby(key)["load"].first()
        common = loads.index.intersection(ref.index)
        diff = ((loads[common] - ref[common]).abs() / ref[common].abs()).max() if len(common) else math.nan
        rows.append(SolverTotals(str(s), float(d["solve_time_s"].sum()), int((d["status"] == "solved").sum()), len(d),
                                 float(d["peak_mem_mb"].max()), float(diff)))
    return rows


def summary_lines(case: Case, threads: int, rows: list[SolverTotals], ours: str) -> list[str]:
    cm = next((r.seconds for r in rows if r.solver == CM and r.solved == r.ran), math.nan)  # CM's time, when it solved all
    lines = [f"### {case.folder}, {threads} thread{'s' if threads > 1 else ''}", "",
             f"| solver | total solve s | solved/run | time / {CM} | max load diff to {ours} | peak RSS growth in a solve, MiB |",
             "|---|---:|---:|---:|---:|---:|"]
    for r in sorted(rows, key=lambda r: r.seconds):
        lines.append(f"| {r.solver} | {r.seconds:.2f} | {r.solved}/{r.ran} | "
                     f"{cell(r.seconds / cm if cm > 0 else math.nan, '.3f')} | {cell(r.max_load_diff, '.1e')} | "
                     f"{cell(r.peak_mem_mb, '.0f')} |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--threads", default="1,2", help="comma list of thread counts, one run of each case per count")
    ap.add_argument("--ours", default="fast-dual-pccg,fast-ccg", help="our solvers (the first is the load reference)")
    ap.add_argument("--peers", default=None, help="comma list restricting the peers (default: all of each case)")
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--out", default="results/peers")
    ap.add_argument("--summary-only", action="store_true", help="summarise the stored runs, run nothing")
    args = ap.parse_args()
    ours = args.ours.split(",")[0]
    lines = [f"# Peers: paper-sweep {args.size}^2, {args.steps} steps, profile high (benchmarks/bench_peers.py)", "",
             f"Ratios are total solve time over the steps divided by {CM}'s in the same run;",
             f"load differences are per step against {ours}.", ""]
    for threads in (int(t) for t in args.threads.split(",")):
        for case in CASES:
            out = case_dir(Path(args.out), threads, case)
            if not args.summary_only:
                run_case(case, threads, args)
            if out.exists():
                lines += summary_lines(case, threads, solver_totals(out, ours), ours)
    text = "\n".join(lines)
    print("\n" + text)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "summary.md").write_text(text + "\n")


if __name__ == "__main__":
    main()
