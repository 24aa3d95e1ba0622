"""How far the surface population spreads a solver's products, ours beside a peer's: the
cold top step of each member (bench_surface_population.py's ``plan`` and ``top_step``), solved
by each solver in turn in this process and judged by the harness at profile "high"; per solver,
the median and worst products over the members and the worst over the median.

A worst-over-median ratio of products is a property of the solver *and* of the population: a
peer's spread on the same members says how much of it the members themselves carry.  Products
are the solver's own count (``SolveResult.matvecs``); rows go to ``OUT/population-spread.csv``
as they finish, with the host, the time and the code's commit.

Usage:
  python benchmarks/bench_population_spread.py --size 1024 --seeds 2 --first-seed 3
      --solvers fast-dual-pccg,cm-dual-ccg --threads 2 --out results/perf/population-spread
  python benchmarks/bench_population_spread.py --out results/perf/population-spread --summary-only
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_surface_population as bp  # noqa: E402
from bench_set_finding import cold_solve  # noqa: E402
from csv_rows import append_row, host_name, read_latest  # noqa: E402

from contactbench.solvers.registry import available_solvers  # noqa: E402

CSV_NAME = "population-spread.csv"


@dataclass
class SpreadRow:
    """One member's cold top step by one solver."""

    member: str
    hurst: float
    solver: str
    status: str
    matvecs: int
    iterations: int
    seconds: float
    kkt: float
    n: int
    threads: int
    host: str
    commit: str
    timestamp: str


def solve(m: bp.Member, solver: str, threads: int, commit: str) -> SpreadRow:
    inst, _ = bp.top_step(m)
    step = cold_solve(inst, solver)
    r = step.result
    return SpreadRow(m.key, m.hurst, solver, step.verdict.status if step.verdict else "failed",
                     int(r.matvecs) if r else -1, int(r.iterations) if r else -1, round(step.seconds, 3),
                     float(step.kkt_error), int(inst.qp.n), threads, host_name(), commit,
                     time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))


def summary(rows: list[SpreadRow]) -> list[str]:
    """Per solver: members solved, median and worst products, worst / median, the worst member;
    and per member the products of each solver over that solver's median."""
    solvers = list(dict.fromkeys(r.solver for r in rows))
    out = ["| solver | members solved | products, median | worst | worst / median | worst member |",
           "|---|---:|---:|---:|---:|---|"]
    medians = {}
    for s in solvers:
        ok = [r for r in rows if r.solver == s and r.status == "solved"]
        if not ok:
            continue
        med = statistics.median(r.matvecs for r in ok)
        worst = max(ok, key=lambda r: r.matvecs)
        medians[s] = med
        out.append(f"| {s} | {len(ok)} / {sum(r.solver == s for r in rows)} | {med:g} | {worst.matvecs} | "
                   f"{worst.matvecs / med:.2f}x | {worst.member} |")
    out += ["", "| member | " + " | ".join(f"{s}: products (/ median)" for s in medians) + " |",
            "|---|" + "---:|" * len(medians)]
    for key in dict.fromkeys(r.member for r in rows):
        cells = []
        for s in medians:
            r = next((x for x in rows if x.member == key and x.solver == s), None)
            cells.append("-" if r is None or r.status != "solved" else f"{r.matvecs} ({r.matvecs / medians[s]:.2f})")
        out.append(f"| {key} | " + " | ".join(cells) + " |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=3)
    ap.add_argument("--solvers", default="fast-dual-pccg,cm-dual-ccg")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("results/perf/population-spread"))
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()
    solvers = [s for s in args.solvers.split(",") if s]
    unknown = sorted(set(solvers) - set(available_solvers()))
    if unknown:
        ap.exit(2, f"bench_population_spread: unknown solver(s) {', '.join(unknown)}\n")
    if args.size < 16 or args.seeds < 1 or args.first_seed < 0 or args.threads < 1:
        ap.exit(2, "bench_population_spread: --size >= 16, --seeds and --threads >= 1, --first-seed >= 0\n")
    path = args.out / CSV_NAME
    if not args.summary_only:
        os.environ.update({v: str(args.threads) for v in bp.THREAD_VARS})
        commit = bp.code_commit()
        for m in bp.plan([args.size], list(bp.FAMILIES), {args.size: args.seeds}, args.first_seed):
            for s in solvers:
                row = solve(m, s, args.threads, commit)
                append_row(path, row)
                print(f"{row.member} {row.solver}: {row.status}, {row.matvecs} products, {row.seconds:.2f} s",
                      flush=True)
    if not path.exists():
        ap.exit(2, f"bench_population_spread: no {path} to summarise\n")
    rows = read_latest(path, SpreadRow, lambda r: (r.member, r.solver), lambda r: (r.hurst, r.member))
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
