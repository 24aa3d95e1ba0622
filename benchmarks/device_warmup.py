"""One untimed solve before a timed device solve.

CuPy compiles each elementwise and reduction kernel the first time a process needs it and
keeps it in a cache on disk; on a fresh machine the first solve of each precision pays for
every compilation (about 10 s on an H200: a 2048^2 cold top step took 15.4 s there as the
first solve, a 4096^2 one 5.9 s just after it; results/perf/gpu.md).  A timed device solve is
preceded by this one, on a grid where "auto" takes the same precision as large grids (the
paper's instance, mixed from ``MIXED_GRID_POINTS``), so its seconds are the solve's own.
"""

from __future__ import annotations

import math
import time

#: The warm-up's grid: the smallest where precision "auto" is mixed, as on every timed size.
WARMUP_N = 512


def warm_up_device(solver: str, params: dict, operator: str) -> float:
    """Seconds of one untimed ``solver`` solve (its ``params``) on a ``WARMUP_N``^2 instance
    by the "gpu" operator; NaN, and nothing done, for any other ``operator``."""
    if operator != "gpu":
        return math.nan
    from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
    from contactbench.problems.scenes.core import PAPER_E
    from contactbench.problems.surfaces import rmd_surface_n
    from contactbench.solvers.base import SolverSettings
    from contactbench.solvers.registry import get_solver

    t0 = time.perf_counter()
    surf = rmd_surface_n(WARMUP_N, 0.7, length=100e-6, seed=0)
    inst = InstanceBuilder(surf, PAPER_E, "bcc", periodic=False, operator="gpu").build(paper_max_displacement(surf))
    get_solver(solver).solve(inst.qp, SolverSettings(tol=1e-9, params=dict(params) or None))
    return time.perf_counter() - t0
