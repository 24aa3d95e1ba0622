"""Our solvers against the field's codes (ContactMechanics, Tamaas): an ordinary harness run.

The peers are registered solvers (solvers/peer_cm.py, solvers/peer_tamaas.py; the
optional ``peers`` extra), so this script only calls ``contactbench run`` and
``contactbench report`` -- the same load loop, warm starts, time limits and KKT judge as
every other solver -- and prints the ratio of total solve times from the stored tables.
Two runs, because Tamaas has no BCC kernel (docs/peers.md):

* ``bcc-nonperiodic``    the paper's problem (BCC, finite patch): ours and ContactMechanics
  (our influence coefficients through its Green's-function hook);
* ``spectral-periodic``  the periodic 2/(E*|q|) problem: ours, ContactMechanics and every
  Tamaas solver.

Usage: python benchmarks/bench_peers.py [--size 512] [--steps 10] [--out results/peers]
       [--ours fast-dual-pccg] [--timeout 120]
The committed run is results/peers/ (report.md in each run folder, ratio in README.md there).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

CB = str(Path(sys.executable).with_name("contactbench"))


@dataclass(frozen=True)
class Case:
    folder: str
    flags: tuple[str, ...]
    peers: tuple[str, ...]


CASES = (
    Case("bcc-nonperiodic", (), ("cm-dual-ccg", "cm-pk-ccg")),
    Case("spectral-periodic", ("--periodic", "--kernel", "spectral"),
         ("cm-dual-ccg", "tamaas-pkr", "tamaas-kato", "tamaas-beck-teboulle", "tamaas-condat")),
)


def run_case(case: Case, args: argparse.Namespace) -> Path:
    out = Path(args.out) / case.folder
    solvers = ",".join((args.ours, *case.peers))
    cmd = [CB, "run", "paper-sweep", "--size", str(args.size), "--steps", str(args.steps), *case.flags,
           "--solvers", solvers, "--threads", "1", "--profile", "high", "--timeout", str(args.timeout),
           "--out", str(out), "--no-progress"]
    print("+ " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    subprocess.run([CB, "report", str(out)], check=True)
    return out


def total_times(out: Path) -> dict[str, tuple[float, int, int]]:
    """solver -> (total solve seconds over its steps, steps solved, steps run)."""
    from contactbench.harness.schema import load_table

    t = load_table(out)
    t = t[t["status"] != "skipped"]
    g = t.groupby("solver")
    return {s: (float(d["solve_time_s"].sum()), int((d["status"] == "solved").sum()), len(d)) for s, d in g}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--ours", default="fast-dual-pccg")
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--out", default="results/peers")
    args = ap.parse_args()
    for case in CASES:
        out = run_case(case, args)
        times = total_times(out)
        ours = times.get(args.ours, (float("nan"), 0, 0))[0]
        print(f"\n== {case.folder}: total solve time over the steps (solved/run), ratio to {args.ours} ==")
        for s, (sec, solved, ran) in sorted(times.items()):
            print(f"  {s:22s} {sec:9.2f} s  ({solved}/{ran})  x{sec / ours:.2f}")


if __name__ == "__main__":
    main()
