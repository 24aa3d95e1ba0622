"""Where a cold solve's products go: finding the contact set, or converging on it.

For every member of the surface population (``plan`` of bench_surface_population.py: its
cells at the size, on the chosen seeds) this solves the paper's cold top step with
``fast-dual-pccg``'s defaults, judged by the harness at the "high" profile, and then runs
preconditioned CG on the answer's own contact set S alone: H_SS p_S = ubar_S, from p = 0,
with the island preconditioner and its far field (``make_preconditioner("farfield")``; the
far field on any set size) built once on S, until the max-norm residual falls by
``--reduction`` (1e-9, the solve's tolerance).  Those CG iterations are what the solve would
cost had it known S from the start; the rest of its products went to finding S.  The
population's spread of each part tells which one sets its worst member apart.

Rows (``--out``, CSV): member, matvecs (the solve's), fixed_set_cg, finding (their
difference), contact (|S|), n (the trial set), status.  The summary (printed, and beside the
CSV as .md) gives median, worst and worst / median of each part.

Usage:
  python benchmarks/bench_set_finding.py --size 1024 --seeds 2 --first-seed 5 --out set-finding.csv
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_surface_population as bp  # noqa: E402

from contactbench.harness import get_profile, solve_sequence  # noqa: E402
from contactbench.harness.run.sequence import StepSolve  # noqa: E402
from contactbench.problems.instances import ContactInstance  # noqa: E402
from contactbench.solvers._kit import conjugate_gradient  # noqa: E402
from contactbench.solvers._preconditioners import make_preconditioner  # noqa: E402
from contactbench.solvers.base import SolverSettings  # noqa: E402

SOLVER = "fast-dual-pccg"


@dataclass(frozen=True)
class SetFindingRow:
    member: str
    matvecs: int
    fixed_set_cg: int
    finding: int
    contact: int
    n: int
    status: str


def cg_on_set(qp, S: np.ndarray, precond, b: np.ndarray | None = None, reduction: float = 1e-9,
              max_iter: int = 1000) -> int:
    """CG iterations on H_SS p = b_S (default ubar_S) from 0, preconditioned by ``precond``
    restricted to S, until the max-norm residual falls by ``reduction``
    (``_kit.conjugate_gradient``); ``max_iter`` where it does not."""
    b = np.where(S, qp.ubar if b is None else b, 0.0)
    run = conjugate_gradient(lambda d: np.where(S, qp.H.matvec(d), 0.0), b, None,
                             atol=reduction * float(np.abs(b).max()), max_iter=max_iter,
                             precond=lambda r: np.where(S, precond(r), 0.0))
    return run.iterations


def fixed_set_cg(qp, S: np.ndarray, reduction: float, max_iter: int = 1000) -> int:
    """``cg_on_set`` with the island preconditioner and its far field built once on S (module
    doc)."""
    M = make_preconditioner("farfield", qp)
    M.far_fraction = 1.0  # the far field on S whatever its share of the trial set
    M.update(S)
    return cg_on_set(qp, S, M.apply, reduction=reduction, max_iter=max_iter)


def cold_solve(inst: ContactInstance, solver: str = SOLVER) -> StepSolve:
    """``inst`` solved from p = 0 by ``solver`` with its defaults at the "high" profile's
    tolerance, and judged by the harness at that profile."""
    prof = get_profile("high")
    (step,) = solve_sequence(solver, [inst], SolverSettings(tol=prof.tol), warm=False, check_tol=prof.check_tol)
    return step


def measure(m: bp.Member, reduction: float) -> SetFindingRow:
    inst, _ = bp.top_step(m)
    step = cold_solve(inst)
    S = step.result.p > 0.0
    k = fixed_set_cg(inst.qp, S, reduction)
    mv = int(step.result.matvecs)
    return SetFindingRow(m.key, mv, k, mv - k, int(S.sum()), int(inst.qp.n), str(step.verdict.status))


def summary_lines(rows: list[SetFindingRow]) -> list[str]:
    lines = ["| part | median | worst | worst / median |", "|---|---:|---:|---:|"]
    for name, values in (("the solve's products", [r.matvecs for r in rows]),
                         ("CG on the answer's contact set", [r.fixed_set_cg for r in rows]),
                         ("finding the set (the rest)", [r.finding for r in rows])):
        med, worst = statistics.median(values), max(values)
        lines.append(f"| {name} | {med:g} | {worst} | {worst / med:.2f}x |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--reduction", type=float, default=1e-9)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    if args.size < 2 or args.seeds < 1 or args.first_seed < 0 or not 0.0 < args.reduction < 1.0:
        ap.exit(2, "bench_set_finding: --size >= 2, --seeds >= 1, --first-seed >= 0 and 0 < --reduction < 1\n")
    members = bp.plan([args.size], list(bp.FAMILIES), {args.size: args.seeds}, args.first_seed)
    rows = []
    for m in members:
        rows.append(measure(m, args.reduction))
        print(*asdict(rows[-1]).values(), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(asdict(rows[0])))
        w.writeheader()
        w.writerows(asdict(r) for r in rows)
    lines = summary_lines(rows)
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
