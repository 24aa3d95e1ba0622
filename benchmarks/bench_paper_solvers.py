"""Benchmark of the paper's algorithms (Bemporad & Paggi 2015, section 4, Fig. 4-5).

RMD surfaces (H = 0.7, L = 100 um, BCC kernel, aperiodic, FFT operator) at 128^2 and
256^2, 10 displacement steps up to (z_max - z_mean)/2.  For each solver variant: total
time and iterations over the ramp, matvecs, steps converged and worst scaled KKT error.
Each variant's load loop is ``harness.sequence.solve_sequence``: warm-started variants
take their own previous answer mapped by grid index, and every answer is judged by the
harness's ``judge``.

    OMP_NUM_THREADS=1 CONTACTBENCH_FFT_WORKERS=1 .venv/bin/python benchmarks/bench_paper_solvers.py \
        --sizes 128 256 --time-limit 60 --budget 300

A variant that exceeds ``--budget`` seconds on one size skips the rest of its ramp
(marked in the table).  Not a test: figures depend on the machine.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from contactbench.harness import solve_sequence
from contactbench.problems.instances import ContactInstance, InstanceBuilder, load_ramp, paper_max_displacement
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import SolverSettings


@dataclass(frozen=True)
class Variant:
    label: str
    solver: str
    warm: bool
    params: dict = field(default_factory=dict)
    tol: float | None = None
    max_iter: int | None = None


VARIANTS = (
    Variant("greedy-cg", "greedy-cg", False),
    Variant("greedy-chol", "greedy-chol", False),
    Variant("greedy-gs", "greedy-gs", False),
    Variant("pk (cold)", "pk", False),
    Variant("pk (warm)", "pk", True),
    Variant("nnls (cold)", "nnls", False),
    Variant("nnls (warm)", "nnls", True),
    Variant("nnls-gp K=100 (cold)", "nnls-gp", False, {"K": 100}),
    Variant("nnls-gp K=100 (warm)", "nnls-gp", True, {"K": 100}),
    Variant("admm (warm, 1e-6)", "admm", True, tol=1e-6, max_iter=3000),
)


@dataclass
class Row:
    label: str
    N: int
    n_max: int = 0
    time: float = 0.0
    iterations: int = 0
    matvecs: int = 0
    converged: int = 0
    steps: int = 0
    kkt_max: float = 0.0
    note: str = ""


def run_variant(v: Variant, N: int, instances: list[ContactInstance], time_limit: float, budget: float) -> Row:
    row = Row(v.label, N, n_max=max(i.n for i in instances))
    settings = SolverSettings(tol=v.tol, max_iter=v.max_iter, time_limit=time_limit, params=dict(v.params))
    steps = solve_sequence(v.solver, instances, settings, warm=v.warm, budget_s=budget)
    for s in steps:
        if s.result is None:
            row.note = s.error[:60]
            break
        row.time += s.seconds
        row.steps += 1
        row.iterations += s.result.iterations
        row.matvecs += s.result.matvecs
        row.converged += int(s.result.converged)
        row.kkt_max = max(row.kkt_max, s.kkt_error)
    if row.time > budget:
        row.note = f"over budget after {row.steps} steps"
    return row


def print_table(rows: list[Row]) -> None:
    ref = {r.N: r.time / max(r.steps, 1) for r in rows if r.label.startswith("nnls-gp K=100 (cold)")}
    head = f"{'N':>4} {'solver':<22} {'n_max':>6} {'steps':>5} {'conv':>4} {'time s':>9} {'x nnls-gp':>9} {'iters':>8} {'matvecs':>8} {'kkt max':>8}  note"
    print(head)
    print("-" * len(head))
    for r in rows:
        per_step = r.time / max(r.steps, 1)
        ratio = per_step / ref[r.N] if ref.get(r.N) else float("nan")
        print(f"{r.N:>4} {r.label:<22} {r.n_max:>6} {r.steps:>5} {r.converged:>4} {r.time:>9.2f} {ratio:>9.1f} "
              f"{r.iterations:>8} {r.matvecs:>8} {r.kkt_max:>8.1e}  {r.note}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--time-limit", type=float, default=60.0, help="per-solve time limit (s)")
    ap.add_argument("--budget", type=float, default=300.0, help="per variant and size (s)")
    ap.add_argument("--only", nargs="*", default=None, help="labels (prefix match) to run")
    args = ap.parse_args()
    rows: list[Row] = []
    for N in args.sizes:
        surf = rmd_surface_n(N, 0.7, length=100e-6, seed=args.seed)
        builder = InstanceBuilder(surf, 1e9, "bcc", periodic=False, operator="fft")
        instances = [builder.build(d) for d in load_ramp(paper_max_displacement(surf), args.steps)]
        for v in VARIANTS:
            if args.only and not any(v.label.startswith(o) for o in args.only):
                continue
            row = run_variant(v, N, instances, args.time_limit, args.budget)
            rows.append(row)
            print(f"# done {N} {v.label}: {row.time:.2f} s", flush=True)
    print_table(rows)


if __name__ == "__main__":
    main()
