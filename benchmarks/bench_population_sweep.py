"""Load sweeps on members of the surface population: ours against ContactMechanics' dual CCG
(``cm-dual-ccg``, solvers/peer_cm.py, the optional ``peers`` extra) side by side, in the same
``contactbench run`` per member.

For each member (``MEMBERS``, or ``--members`` keys family:N:H:slope:seed of
benchmarks/bench_surface_population.py, whose ``surface_of`` builds them), the surface is
written as OUT/surfaces/<key>.npy (heights in m) and swept by

    contactbench run paper-sweep --surface <file> --length 1e-4 --steps K --allow-steep
        --solvers <ours>,cm-dual-ccg --profile high --threads T --out OUT/<key>

-- the paper's instance (BCC, non-periodic, E, L = 100 um) on that surface, K warm-started
load steps up to the top step, judged at the "high" profile -- so both solvers see the same
instances, load loop, warm starts, time limits and judge in one run.  The summary (printed and
written to OUT/summary.md, with host, date and commit) gives per member each solver's total
solve time over the steps, steps solved and total matvecs, the ratio ours / cm-dual-ccg, the
largest relative load difference between the two, and the median ratio over the members.  A
ratio counts only when both solved every step.  ``--allow-steep``: the files are the
population's own surfaces in metres, whose steepest cell has an rms slope of 1, at the edge of
the range the CLI's unit check takes for a measured map.  A member the CLI refuses (exit 2) is
recorded with its one-line reason (OUT/<key>.refused) and the run goes on.

Usage:
  python benchmarks/bench_population_sweep.py [--size 512] [--steps 10] [--threads 2]
      [--members saupe:512:0.7:0.3:0,...] [--ours fast-dual-pccg] [--timeout 120]
      [--out results/perf/population-sweep] [--summary-only]
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from contactbench.harness import load_table
from csv_rows import host_name, refuse_bad_grid_sizes
from bench_surface_population import FAMILIES, LENGTH, Member, code_commit, surface_of

CB = str(Path(sys.executable).with_name("contactbench"))
#: The peer every ratio is taken against.
CM = "cm-dual-ccg"
#: Default members (N is replaced by --size): every family, Hurst 0.3-0.9, rms slope 0.05-0.3.
MEMBERS = ("saupe:512:0.7:0.3:0", "periodic:512:0.7:0.3:0", "fourier:512:0.5:0.05:0", "measured:512:0.7:0.3:1",
           "saupe:512:0.9:0.1:0", "periodic:512:0.3:0.3:1")


@dataclass(frozen=True)
class SweepTotals:
    """One solver's figures over the steps of one member's run."""

    solver: str
    seconds: float  # total solve time over the steps
    solved: int
    ran: int
    matvecs: int


def members_of(text: str, size: int) -> list[Member]:
    """The members of a comma list of keys, at grid size ``size``."""
    return [replace(Member.parse(k), N=size) for k in filter(None, text.split(","))]


def sweep_member(m: Member, args: argparse.Namespace) -> str:
    """Write the member's surface and run the sweep of both solvers on it (module doc): "",
    or the CLI's one-line refusal of the member (exit 2), also written to OUT/<key>.refused.
    Any other failure stops the run."""
    out = Path(args.out)
    (out / "surfaces").mkdir(parents=True, exist_ok=True)
    name = m.key.replace(":", "_")
    path = out / "surfaces" / f"{name}.npy"
    np.save(path, np.asarray(surface_of(m).heights, dtype=np.float64))
    cmd = [CB, "run", "paper-sweep", "--surface", str(path), "--length", repr(LENGTH), "--steps", str(args.steps),
           "--allow-steep", "--solvers", f"{args.ours},{CM}", "--threads", str(args.threads), "--profile", "high",
           "--timeout", str(args.timeout), "--out", str(out / name), "--no-progress", "--reference", "none"]
    print("+ " + " ".join(cmd), flush=True)
    proc = subprocess.run(cmd, stderr=subprocess.PIPE, text=True)
    sys.stderr.write(proc.stderr)
    if proc.returncode == 2:
        reason = ([ln for ln in proc.stderr.splitlines() if ln.strip()] or ["refused (exit 2)"])[-1]
        (out / f"{name}.refused").write_text(reason + "\n")
        return reason
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, cmd, stderr=proc.stderr)
    return ""


def totals(run_dir: Path) -> tuple[list[SweepTotals], float]:
    """Per solver of one member's run: totals; and the largest relative load difference
    between ours (the first solver) and cm-dual-ccg over the steps both solved."""
    t = load_table(run_dir)
    t = t[t["status"] != "skipped"]
    rows = [SweepTotals(str(s), float(d["solve_time_s"].sum()), int((d["status"] == "solved").sum()), len(d),
                        int(d["matvecs"].fillna(0).sum())) for s, d in t.groupby("solver")]
    key = ["instance", "step"]
    solved = t[t["status"] == "solved"]
    loads = {s: d.groupby(key)["load"].first() for s, d in solved.groupby("solver")}
    diff = math.nan
    if CM in loads and len(loads) == 2:
        ours = next(v for s, v in loads.items() if s != CM)
        common = ours.index.intersection(loads[CM].index)
        if len(common):
            diff = float(((loads[CM][common] - ours[common]).abs() / ours[common].abs()).max())
    return rows, diff


def ratio(rows: list[SweepTotals], ours: str) -> float:
    """ours / cm-dual-ccg total solve time; NaN unless both solved every step."""
    by = {r.solver: r for r in rows}
    a, b = by.get(ours), by.get(CM)
    if a is None or b is None or a.solved != a.ran or b.solved != b.ran or b.seconds <= 0:
        return math.nan
    return a.seconds / b.seconds


def summary(members: list[Member], args: argparse.Namespace) -> str:
    ours = args.ours
    lines = [f"# {ours} against {CM}: {args.steps}-step sweeps at {args.size}^2 on population members",
             "", "Written by `benchmarks/bench_population_sweep.py` (its module doc: instance, profile, ratio rule).",
             (f"Host {host_name()}, {args.threads} thread(s), commit {code_commit()}, "
              f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}."), "",
             (f"| member | {ours} s | {ours} solved | {ours} matvecs | {CM} s | {CM} solved | {CM} matvecs "
              f"| ours / {CM} | max load diff |"), "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    ratios = []
    for m in members:
        run_dir = Path(args.out) / m.key.replace(":", "_")
        refused = run_dir.with_name(run_dir.name + ".refused")
        if not run_dir.exists():
            why = f"refused: {refused.read_text().strip()}" if refused.exists() else "not run"
            lines.append(f"| {m.key} | {why} |||||||")
            continue
        rows, diff = totals(run_dir)
        by = {r.solver: r for r in rows}
        a, b = by.get(ours), by.get(CM)
        rt = ratio(rows, ours)
        if not math.isnan(rt):
            ratios.append(rt)

        def cells(r: SweepTotals | None) -> str:
            return "- | - | -" if r is None else f"{r.seconds:.3f} | {r.solved}/{r.ran} | {r.matvecs}"

        lines.append(f"| {m.key} | {cells(a)} | {cells(b)} | {rt:.3f} | {diff:.1e} |")
    med = float(np.median(ratios)) if ratios else math.nan
    lines += ["", f"Median ours / {CM} over {len(ratios)} member(s) with both solved throughout: {med:.3f}."]
    return "\n".join(lines) + "\n"


def check_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> list[Member]:
    """One-line errors for bad input, before anything runs; the members."""
    refuse_bad_grid_sizes(ap, "--size", [args.size])
    if args.steps < 1:
        ap.error(f"--steps must be >= 1, got {args.steps}")
    if not (args.timeout > 0):
        ap.error(f"--timeout must be > 0 s, got {args.timeout}")
    try:
        members = members_of(args.members, args.size)
    except ValueError:
        ap.error(f"--members must be keys family:N:H:slope:seed, got {args.members!r}")
    bad = [m.family for m in members if m.family not in FAMILIES]
    if bad:
        ap.error(f"unknown family {bad[0]!r}: choose from {', '.join(FAMILIES)}")
    if not members:
        ap.error("--members: at least one member")
    done = [m.key for m in members if (Path(args.out) / m.key.replace(":", "_")).exists()]
    if done and not args.summary_only:
        ap.error(f"--out {args.out} already holds a run of {done[0]}: choose a new folder (or --summary-only)")
    return members


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--members", default=",".join(MEMBERS), help="comma list of family:N:H:slope:seed (N ignored)")
    ap.add_argument("--ours", default="fast-dual-pccg")
    ap.add_argument("--timeout", type=float, default=120.0, help="time limit of one solve (s)")
    ap.add_argument("--out", default="results/perf/population-sweep")
    ap.add_argument("--summary-only", action="store_true", help="summarise the stored runs, run nothing")
    args = ap.parse_args()
    members = check_args(ap, args)
    if not args.summary_only:
        for m in members:
            sweep_member(m, args)
    text = summary(members, args)
    print("\n" + text)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "summary.md").write_text(text)


if __name__ == "__main__":
    main()
