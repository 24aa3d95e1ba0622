"""Exploration (why the H 0.9 members cost twice the median): CG iterations on one disk-shaped
contact set of radius R, against R, with the island blocks alone and with their far field.

The set S is a disk of radius R (grid points) at the centre of an N x N non-periodic BCC grid
whose trial set is the whole grid; CG (``bench_set_finding.cg_on_set``) solves H_SS p = b_S from
0 until the max-norm residual falls by 1e-9, for a flat punch (b = 1) and a parabolic
displacement (b = 1 - (r/R)^2), preconditioned by ``make_preconditioner("islands")`` and
``("farfield")`` (the far field on any set size).  A disk of up to ``_partition.WHOLE_ISLAND``
points is one block (one iteration); a larger one is cut into patches.

Usage: python benchmarks/explore_island_size.py [--size 1024]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_set_finding import cg_on_set  # noqa: E402

from contactbench.problems.instances import InstanceBuilder  # noqa: E402
from contactbench.problems.surfaces import Surface  # noqa: E402
from contactbench.solvers._preconditioners import make_preconditioner  # noqa: E402

RADII = (4, 8, 12, 16, 24, 32, 64, 128, 256, 400)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=1024)
    args = ap.parse_args()
    if args.size < 64:
        ap.exit(2, "explore_island_size: --size must be at least 64\n")
    N, L = args.size, 100e-6
    x = (np.arange(N) - N / 2) * (L / N)
    X, Y = np.meshgrid(x, x, indexing="ij")
    surface = Surface(heights=-(X**2 + Y**2) / 2e-3, delta=L / N)
    qp = InstanceBuilder(surface, 1e9, "bcc", periodic=False).build(1.0).qp  # deep: the whole grid
    i, j = np.divmod(np.asarray(qp.geometry.indices), N)
    r = np.hypot(i - N / 2, j - N / 2)
    print("| R | points | blocks alone, punch / parabola | blocks and far field, punch / parabola |")
    print("|---:|---:|---|---|")
    for R in (R for R in RADII if R < N / 2):
        S = r < R
        cells = []
        for kind in ("islands", "farfield"):
            M = make_preconditioner(kind, qp)
            M.far_fraction = 1.0
            M.update(S)
            counts = [str(cg_on_set(qp, S, M.apply, b)) for b in (np.ones(qp.n), 1.0 - (r / R) ** 2)]
            cells.append(" / ".join(counts))
        print(f"| {R} | {int(S.sum())} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
