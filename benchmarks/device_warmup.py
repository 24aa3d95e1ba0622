"""One untimed solve before a timed device solve.

CuPy compiles each elementwise, reduction and raw kernel the first time a process needs it
and keeps it in a cache on disk, and makes a cuFFT plan per transform shape the first time
a process uses it: on a fresh machine the first solve pays for all of it, and a warm-up on a
smaller grid leaves some of it to the timed solve (results/perf/gpu.md).  So a timed device solve
follows one untimed solve of a twin: an instance of the same recipe and size, built apart,
so that the kernels, plans and memory pool are those of the timed solve while no operator's
device arrays carry over (the timed solve copies its own spectrum and table) -- the
harness's own warm-up (``RunConfig.warmup``) solves the task itself.  The twin's seconds
are the cold figure, the row's ``warmup_s``.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

#: The warm-up's grid where no twin is given: the smallest where precision "auto" is mixed,
#: as on every timed size.
WARMUP_N = 512


def warm_up_device(solver: str, params: dict, operator: str, twin: Callable[[], Any] | None = None) -> float:
    """Seconds of one untimed ``solver`` solve (its ``params``) by the "gpu" operator: of the
    QP ``twin()`` builds (not timed), or of a ``WARMUP_N``^2 instance; NaN, and nothing done
    (``twin`` not called), for any other ``operator``."""
    if operator != "gpu":
        return math.nan
    from contactbench.solvers.base import SolverSettings
    from contactbench.solvers.registry import get_solver

    qp = twin() if twin is not None else warmup_qp()
    t0 = time.perf_counter()
    get_solver(solver).solve(qp, SolverSettings(tol=1e-9, params=dict(params) or None))
    return time.perf_counter() - t0


def warmup_qp() -> Any:
    """The paper's instance on a ``WARMUP_N``^2 RMD surface, by the "gpu" operator."""
    from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
    from contactbench.problems.scenes.core import PAPER_E
    from contactbench.problems.surfaces import rmd_surface_n

    surf = rmd_surface_n(WARMUP_N, 0.7, length=100e-6, seed=0)
    return InstanceBuilder(surf, PAPER_E, "bcc", periodic=False, operator="gpu").build(paper_max_displacement(surf)).qp
