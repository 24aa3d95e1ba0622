"""CMR against the direct solve (Bemporad & Paggi 2015, section 5.2, Figs. 8-9) -- a thin
driver of the harness run that makes results/cmr.

It runs, as one harness run into one folder,

    contactbench run cmr-paper --out results/cmr --jobs 2 --threads 1 --report --no-progress

and prints the wall time against ``BUDGET_S``.  The study design is the composite
``cmr-paper`` of ``contactbench.harness.run.studies``: the scenes ``cmr`` and ``cmr-h-sweep``
at 256^2 with the FFT base ``fast-dual-pccg`` and CMR over it (coarse = subsample and
mean, h = 2 and the h grid, first levels 16 / 32 / 64), and at 128^2 with the paper's
dense base ``scipy-nnls`` and CMR over it; 20 seeds each.  The tables and figures are the
report's sections (harness/report/sections/cmr.py): results/cmr holds results.parquet / results.csv
(every solve), meta.json, report.md, report.html and figures/.

Run:  OMP_NUM_THREADS=1 python benchmarks/bench_cmr.py [--seeds 0-19] [--jobs 2]
                                                      [--surface-family saupe|periodic] [--out results/cmr]

Any further argument goes to ``contactbench run`` unchanged (e.g. --no-warmup; not --size,
which would give every part one size, so the FFT parts and the dense parts of ``cmr``
would plan the same instances twice).  Running
the same command again completes only the missing cells (the harness resumes).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Sequence

from contactbench.harness.cli import main as contactbench

#: Section 5 as distributions over seeds: the composite of harness/run/studies.py.
SCENES = ("cmr-paper",)
#: The benchmark budget of both scenes at 20 seeds on the 2-core benchmark machine, s.
BUDGET_S = 30 * 60


def harness_args(ns: argparse.Namespace, rest: Sequence[str]) -> list[str]:
    """The ``contactbench`` command line this driver runs."""
    args = ["run", *SCENES, "--out", ns.out, "--jobs", str(ns.jobs), "--threads", "1", "--report", "--no-progress"]
    if ns.seeds is not None:
        args += ["--seeds", ns.seeds]
    if ns.surface_family is not None:
        args += ["--surface-family", ns.surface_family]
    return args + list(rest)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default=None, help="seeds per H (default: the composite's 0-19)")
    ap.add_argument("--jobs", type=int, default=2, help="instances run at once (one per core, one thread each)")
    ap.add_argument("--surface-family", default=None, help="saupe (default) or periodic")
    ap.add_argument("--out", default="results/cmr")
    ns, rest = ap.parse_known_args(argv)
    args = harness_args(ns, rest)
    print("contactbench " + " ".join(args), flush=True)
    t0 = time.perf_counter()
    rc = contactbench(args)
    wall = time.perf_counter() - t0
    print(f"wall time {wall:.0f} s ({wall / 60:.1f} min) against the budget {BUDGET_S / 60:.0f} min: "
          f"{'within' if wall <= BUDGET_S else 'OVER'}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
