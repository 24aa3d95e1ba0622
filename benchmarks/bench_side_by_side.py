"""Two checkouts of this repository side by side on the surface population (``plan`` of
bench_surface_population.py: its cells at the size, on the chosen seeds): for every member,
one cold top-step solve with each checkout's own code (its ``bench_surface_population.py``,
variant "default"), the two alternating member by member in one run, so that a change's
matvecs and seconds are compared on the same machine at the same time.  With ``--sweep K``
each member's solve is instead its K-step load sweep: the paper's instance (BCC,
non-periodic, L = 100 um) on the member's surface, every step warm-started from the last by
the harness (``contactbench.harness.solve_sequence``) and judged at the "high" profile;
matvecs, iterations, builds and seconds are the steps' sums, and the status is "solved"
when every step is.  With ``--load-per-slope X`` it is instead the member's cold
load-controlled problem of bench_aspher.py (non-periodic Love kernel, P / (E* A) = X x rms
slope), solved and judged as there (``bench_aspher.solve_entry``); with ``--sweep K`` too,
its K-step load sweep (step k at k / K of that load, warm-started from the last by the
harness, the sums as for the paper sweep); ``--cells`` keeps the
(Hurst, rms slope) cells given.  ``--hardness-over-pressure R`` adds a hardness to that problem:
every pressure bounded by R times the nominal mean pressure P / A (of the last step in a
sweep; R = 1 would saturate the whole grid; near 1 most of the contact is plastic).  Both checkouts pose it through their
own ``InstanceBuilder.build_load(..., hardness=)`` and solve it with ``solve_sequence`` at the
"high" profile, so a base without this option compares as well.

Each solve runs in a fresh process of the checkout's own virtual environment
(``CHECKOUT/.venv/bin/python``) with the thread variables set to ``--threads``; rows are
appended to ``--out`` (CSV: member, code, matvecs, iterations, builds, seconds, status, n) as
they finish, and the summary -- median and worst matvecs and seconds of each, the head / base
time ratio per member (median and range) and the members where the head needs more
products -- is printed at the end (``--summary-only`` prints it from the CSV alone).

Usage:
  python benchmarks/bench_side_by_side.py --base ../base-checkout --head . --size 1024
      [--seeds 3] [--first-seed 0] [--families saupe,...] [--threads 2] [--sweep K] --out side.csv
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

from bench_aspher import parse_cells
from bench_surface_population import FAMILIES, THREAD_VARS, Member, check_choices, plan
from csv_rows import refuse_bad_grid_sizes

COLUMNS = ("member", "code", "matvecs", "iterations", "builds", "seconds", "status", "n")

#: Run in the checkout's own interpreter: its code solves the member (argv: checkout, member key).
CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1] + "/benchmarks")
import bench_surface_population as bp
row = bp.solve_member(bp.Member.parse(sys.argv[2]), "default", float(sys.argv[3]), "side-by-side")
print("RESULT " + json.dumps({"matvecs": row.matvecs, "iterations": row.iterations,
                              "builds": row.preconditioner_builds, "seconds": row.seconds,
                              "status": row.status, "n": row.n}))
"""

#: The same for a K-step sweep (argv: checkout, member key, time limit of a step, K).
SWEEP_CHILD = """
import json, sys, tempfile
import numpy as np
sys.path.insert(0, sys.argv[1] + "/benchmarks")
import bench_surface_population as bp
from contactbench.harness import get_profile, solve_sequence
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
m = bp.Member.parse(sys.argv[2])
with tempfile.NamedTemporaryFile(suffix=".npy") as f:
    np.save(f.name, bp.surface_of(m).heights)
    scene = get_scene("paper-sweep")
    (spec,) = scene.instances(scene.config(SceneConfig(size=m.N, steps=int(sys.argv[4]), surface_path=f.name,
                                                       length=bp.LENGTH)))
    seq = scene.build(spec)
high = get_profile("high")
steps = solve_sequence("fast-dual-pccg", seq, SolverSettings(tol=high.tol, time_limit=float(sys.argv[3])),
                       check_tol=high.check_tol)
done = [s.result for s in steps if s.result is not None]
solved = len(done) == len(steps) == int(sys.argv[4]) and all(s.verdict.status == "solved" for s in steps)
print("RESULT " + json.dumps({"matvecs": sum(r.matvecs for r in done), "iterations": sum(r.iterations for r in done),
                              "builds": sum(r.info.get("preconditioner_builds", 0) for r in done),
                              "seconds": sum(s.seconds for s in steps), "status": "solved" if solved else "failed",
                              "n": max(s.inst.qp.n for s in steps)}))
"""

#: The same for the member's load-controlled problem (argv: checkout, member key, time limit,
#: P / (E* A) per unit of rms slope).
LOAD_CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1] + "/benchmarks")
import bench_aspher as ba
ba.LOAD_PER_SLOPE = float(sys.argv[4])
row = ba.solve_entry(ba.Problem.parse("nonperiodic@" + sys.argv[2]), ba.BY_LABEL["fast-dual-pccg"], None,
                     float(sys.argv[3]), "side-by-side")
print("RESULT " + json.dumps({"matvecs": row.matvecs, "iterations": row.iterations, "builds": 0,
                              "seconds": row.seconds, "status": row.status, "n": row.n}))
"""

#: A K-step load sweep of the member's load-controlled problem (argv: checkout, member key,
#: time limit of a step, P / (E* A) per unit of rms slope at the last step, K, hardness over
#: the last step's mean pressure or 0): step k carries k / K of the last load, every step
#: warm-started from the last by the harness; sums as ``SWEEP_CHILD``, and also gives the
#: last step's plastic share of the contact ("plastic", printed, not a column).  K = 1 is the
#: bounded problem's cold solve.
LOAD_SWEEP_CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1] + "/benchmarks")
import bench_aspher as ba
from contactbench.harness import get_profile, solve_sequence
from contactbench.problems.scenes.core import PAPER_E
from contactbench.solvers.base import SolverSettings
pr = ba.Problem.parse("nonperiodic@" + sys.argv[2])
top, K, R = float(sys.argv[4]) * pr.member.rms_slope, int(sys.argv[5]), float(sys.argv[6])
b, _ = ba.builder_of(pr)
hardness = R * top * PAPER_E if R > 0 else None
seq = [b.build_load(b.load_force(top * (k + 1) / K), hardness=hardness) for k in range(K)]
high = get_profile("high")
steps = solve_sequence("fast-dual-pccg", seq, SolverSettings(tol=high.tol, time_limit=float(sys.argv[3])),
                       check_tol=high.check_tol)
done = [s.result for s in steps if s.result is not None]
solved = len(done) == len(steps) == K and all(s.verdict.status == "solved" for s in steps)
print("RESULT " + json.dumps({"matvecs": sum(r.matvecs for r in done), "iterations": sum(r.iterations for r in done),
                              "builds": sum(r.info.get("preconditioner_builds", 0) for r in done),
                              "seconds": sum(s.seconds for s in steps), "status": "solved" if solved else "failed",
                              "n": seq[0].n, "plastic": seq[-1].plastic_fraction(done[-1].p) if solved else 0.0}))
"""


def child_argv(checkout: Path, m: Member, timeout: float, sweep: int, load_per_slope: float,
               hardness_over_pressure: float = 0.0) -> list[str]:
    """The child's ``-c`` program and arguments for one solve of ``m`` (module doc)."""
    if load_per_slope > 0.0 and (sweep or hardness_over_pressure > 0.0):
        return ["-c", LOAD_SWEEP_CHILD, str(checkout), m.key, str(timeout), repr(load_per_slope), str(max(sweep, 1)),
                repr(hardness_over_pressure)]
    if load_per_slope > 0.0:
        return ["-c", LOAD_CHILD, str(checkout), m.key, str(timeout), repr(load_per_slope)]
    if sweep:
        return ["-c", SWEEP_CHILD, str(checkout), m.key, str(timeout), str(sweep)]
    return ["-c", CHILD, str(checkout), m.key, str(timeout)]


def solve_in(checkout: Path, m: Member, threads: int, timeout: float, sweep: int = 0,
             load_per_slope: float = 0.0, hardness_over_pressure: float = 0.0) -> dict:
    """One solve of ``m`` (its ``sweep``-step sweep when ``sweep``, its load-controlled problem
    when ``load_per_slope``, bounded by a hardness when ``hardness_over_pressure``) by
    ``checkout``'s code in a fresh process; a "failed" row without a result."""
    env = dict(os.environ, **{v: str(threads) for v in THREAD_VARS})
    argv = child_argv(checkout, m, timeout, sweep, load_per_slope, hardness_over_pressure)
    try:
        proc = subprocess.run([str(checkout / ".venv" / "bin" / "python"), *argv], capture_output=True, text=True,
                              env=env, cwd=checkout, timeout=timeout * max(sweep, 1) + 120)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    except subprocess.TimeoutExpired:
        lines = []
    if not lines:
        return {"matvecs": 0, "iterations": 0, "builds": 0, "seconds": float("nan"), "status": "failed", "n": 0}
    return json.loads(lines[-1][len("RESULT "):])


def summary(path: Path) -> list[str]:
    """The comparison of the CSV's member pairs (module doc)."""
    by: dict[str, dict[str, dict]] = defaultdict(dict)
    with path.open() as f:
        for r in csv.DictReader(f):
            by[r["member"]][r["code"]] = r
    pairs = [(v["base"], v["head"]) for v in by.values() if "base" in v and "head" in v
             and v["base"]["status"] == v["head"]["status"] == "solved"]
    if not pairs:
        return ["no member solved by both"]
    out = []
    for code, k in (("base", 0), ("head", 1)):
        mv = [int(p[k]["matvecs"]) for p in pairs]
        s = [float(p[k]["seconds"]) for p in pairs]
        med = statistics.median(mv)
        out.append(f"{code}: matvecs median {med:g}, worst {max(mv)} ({max(mv) / med:.2f}x the median); "
                   f"seconds median {statistics.median(s):.3f}, worst {max(s):.3f}")
    ratio = [float(h["seconds"]) / float(b["seconds"]) for b, h in pairs]
    more = [b["member"] for b, h in pairs if int(h["matvecs"]) > int(b["matvecs"])]
    out.append(f"head / base seconds per member: median {statistics.median(ratio):.3f}, "
               f"range {min(ratio):.2f}-{max(ratio):.2f}; {len(pairs)} members solved by both, "
               f"{len(by) - len(pairs)} not")
    out.append(f"head needs more matvecs on {len(more)}: {', '.join(more) or '-'}")
    return out


def checked_args(ap: argparse.ArgumentParser) -> argparse.Namespace:
    """The arguments, with one-line errors (exit 2) for bad input before anything runs."""
    args = ap.parse_args()
    if args.summary_only:
        if not Path(args.out).is_file():
            ap.error(f"--summary-only: no table at {args.out}")
        return args
    for name in ("base", "head"):
        if not (Path(getattr(args, name)) / ".venv" / "bin" / "python").is_file():
            ap.error(f"--{name} {getattr(args, name)}: no .venv/bin/python there (run `make` in that checkout)")
    check_choices(ap, "family", args.families, FAMILIES)
    refuse_bad_grid_sizes(ap, "--size", [args.size])
    if args.seeds < 1 or args.first_seed < 0 or args.threads < 1 or not args.timeout > 0 or args.sweep < 0:
        ap.error("--seeds and --threads must be >= 1, --first-seed and --sweep >= 0 and --timeout > 0")
    if not args.load_per_slope >= 0.0:
        ap.error("--load-per-slope must be >= 0")
    if not args.hardness_over_pressure >= 0.0 or (args.hardness_over_pressure > 0.0 and (
            args.load_per_slope == 0.0 or args.hardness_over_pressure <= 1.0)):
        ap.error("--hardness-over-pressure must be 0 (none) or above 1, and needs --load-per-slope")
    try:
        args.cells = parse_cells(args.cells)
    except ValueError:
        ap.error(f"--cells {args.cells!r}: give Hurst:rms-slope pairs, e.g. 0.7:0.3")
    return args


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", default="", help="the checkout to compare against")
    ap.add_argument("--head", default=".", help="the checkout with the change (default: this one)")
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--seeds", type=int, default=3, help="seeds per cell (default 3)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=900.0, help="time limit of one solve (s)")
    ap.add_argument("--sweep", type=int, default=0, help="K > 0: each member's K-step paper sweep (module doc)")
    ap.add_argument("--load-per-slope", type=float, default=0.0,
                    help="X > 0: each member's load-controlled problem at P / (E* A) = X x rms slope (module doc)")
    ap.add_argument("--hardness-over-pressure", type=float, default=0.0,
                    help="R > 1: bound every pressure by R x P / A in the load-controlled problem (module doc)")
    ap.add_argument("--cells", default="", help="Hurst:rms-slope cells to keep, e.g. 0.7:0.3 (default: all)")
    ap.add_argument("--out", required=True, help="the CSV (appended to)")
    ap.add_argument("--summary-only", action="store_true", help="print the summary of --out and exit")
    args = checked_args(ap)
    out = Path(args.out)
    if not args.summary_only:
        out.parent.mkdir(parents=True, exist_ok=True)
        fresh = not out.exists()
        with out.open("a", newline="") as f:
            w = csv.writer(f)
            if fresh:
                w.writerow(COLUMNS)
            for m in plan([args.size], args.families.split(","), {args.size: args.seeds}, args.first_seed):
                if args.cells is not None and (m.hurst, m.rms_slope) not in args.cells:
                    continue
                for code in ("base", "head"):
                    r = solve_in(Path(getattr(args, code)).resolve(), m, args.threads, args.timeout, args.sweep,
                                 args.load_per_slope, args.hardness_over_pressure)
                    w.writerow([m.key, code] + [r[c] for c in COLUMNS[2:]])
                    f.flush()
                    print(m.key, code, r, flush=True)
    print("\n".join(summary(out)))


if __name__ == "__main__":
    sys.exit(main())
