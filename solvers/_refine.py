"""Mixed precision by iterative refinement for the fast solvers (not a solver module: the
registry skips "_" names): the fast CCGs' and fast-pdas's ``precision="mixed"``.

Outer loop, in float64 (Wilkinson's iterative refinement, here for the bound-constrained
QP of Bemporad & Paggi 2015, eq. (5)):

1. g = H p - ubar in float64 -- the one float64 matvec of a round;
2. stop when the scaled KKT error of (p, g) (``SolveContext.kkt``, the harness's formula)
   is <= tol;
3. otherwise solve the correction problem  min 1/2 d'Hd + g'd  s.t.  p + d >= 0  with the
   *same* CCG loop of solvers/_ccg.py on the float32 operator
   (``ContactOperator.with_precision(np.float32)``), loosely: until its KKT error is
   ``INNER_REDUCTION`` times the round's starting one, or until tol itself when that would
   stop within ``LAST_ROUND_REACH`` x tol (``round_tolerance``).  The loop runs on the variable
   p + d with the state anchored at (p, g) (``_ccg.Anchor``), so its gap is
   g + H32 d and float32 round-off scales with the correction, not with p;
4. p <- max(p + d, 0) and repeat.

Constraints beyond p >= 0 (a hardness, a load equality: ``problems.constraints``) are
posed by the same loops: the anchored state iterates on the variable p + d itself, so
the box 0 <= p + d <= u and the load sum(p + d) = P are the loop's own constraints, and
only the gap's update runs in float32.

If a round fails to shrink the float64 error by ``MIN_ROUND_GAIN`` (float32 cannot go
further, or the loop stalled), the same loop finishes in float64 from there, so the
answer is exactly the double path's fixed point and the tolerance is always judged in
float64.  The island preconditioner's block inverses are float32 too (``block_dtype``).
Matvecs: the float32 and float64 products are both counted by the solve
(``ctx.track``) and reported apart in ``info`` ("matvecs_float32", "matvecs_float64").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from contactbench.problems.instances import QP
from contactbench.problems.operators import ContactOperator, runs_dense_blocks

from ._ccg import CCGRun, GapState
from ._preconditioners import SetPreconditioner, mixed_grid
from .base import Param, SolveContext

#: The precisions a fast solver runs in ("mixed": float32 inner, float64 outer; "auto":
#: ``resolved_precision``).
PRECISIONS = ("double", "mixed", "auto")

#: A round's inner tolerance, relative to the round's starting float64 KKT error.
INNER_REDUCTION = 1e-4

#: A round whose loose tolerance would be within this factor of the solve's tol is asked for
#: the tol itself: stopped just short of it, it would leave a further round -- a float64
#: product and a restart of the conjugacy -- to cover the rest.
LAST_ROUND_REACH = 10.0

#: A round must shrink the float64 KKT error at least by this factor, else float64 finishes.
MIN_ROUND_GAIN = 0.5


def precision_param(default: str = "double") -> Param:
    """The one declaration of the fast solvers' ``precision`` parameter."""
    return Param("precision", str, default,
                 "double: float64 throughout; mixed: float32 inner CCG, float64 iterative refinement; "
                 "auto: mixed from 512^2 grid points up, else double",
                 choices=PRECISIONS)


def resolved_precision(precision: str, qp: QP) -> str:
    """"double" or "mixed": ``precision`` with "auto" decided by the grid -- mixed on a
    grid of at least ``_preconditioners.MIXED_GRID_POINTS`` points (``mixed_grid``), else
    double -- and double wherever the products are a dense block of the set
    (``operators.runs_dense_blocks``): the periodic 512^2 sweep's second step, 391 points,
    took 7 FFT pairs and 30 ms mixed (each precision's operator runs FFTs until it
    switches), 4 and 24 ms double."""
    if precision == "auto":
        return "mixed" if mixed_grid(qp) and not runs_dense_blocks(qp.H) else "double"
    return precision


def block_dtype(precision: str) -> type:
    """The island preconditioner's block precision for a solve in (resolved) ``precision``."""
    return np.float32 if precision == "mixed" else np.float64


def low_precision(H: ContactOperator) -> ContactOperator | None:
    """H's float32 twin (``with_precision(np.float32)``), or None when the operator has none."""
    make = getattr(H, "with_precision", None)
    return None if make is None else make(np.float32)


class MatvecTally:
    """Matvecs of the float64 and float32 operators since construction."""

    def __init__(self, H64: ContactOperator, H32: ContactOperator | None) -> None:
        self.H64, self.H32 = H64, H32
        self.c64 = H64.matvec_count
        self.c32 = H32.matvec_count if H32 is not None else 0

    def info(self) -> dict[str, Any]:
        n32 = self.H32.matvec_count - self.c32 if self.H32 is not None else 0
        return {"matvecs_float64": self.H64.matvec_count - self.c64, "matvecs_float32": n32}


#: A CCG loop of solvers/_ccg.py: (ctx, state, M, *, max_iter, first) -> CCGRun.
Loop = Callable[..., CCGRun]


@dataclass
class RefinementRun:
    """How the refinement stopped: the CCG run (float64 KKT error), rounds, and whether
    float64 had to finish."""

    run: CCGRun
    rounds: int
    finished_in_double: bool


def round_tolerance(tol: float, kkt: float) -> float:
    """The KKT error a round started at ``kkt`` is asked for: ``INNER_REDUCTION`` x kkt, or
    ``tol`` where that is below ``LAST_ROUND_REACH`` x tol (module doc)."""
    loose = INNER_REDUCTION * kkt
    return tol if loose <= LAST_ROUND_REACH * tol else loose


def inner_context(ctx: SolveContext, kkt: float, used: int) -> SolveContext:
    """The round's context: its tolerance (``round_tolerance``), the iterations left; same
    deadline and trace."""
    return replace(ctx, tol=round_tolerance(ctx.tol, kkt), max_iter=max(1, ctx.max_iter - used))


def refine(ctx: SolveContext, state: GapState, loop: Loop, M: SetPreconditioner | None,
           H32: ContactOperator, first: int = 0) -> RefinementRun:
    """Iterative refinement (module doc) of the float64 ``state`` with ``loop`` on ``H32``;
    ``state`` ends at the answer with its float64 gap.  The trace numbers iterations
    from ``first``."""
    used, rounds = 0, 0
    kkt = ctx.kkt(state.p, state.g)
    while kkt > ctx.tol and used < ctx.max_iter and not ctx.expired():
        if not math.isfinite(kkt):  # a non-finite gap: no round can shrink it
            return RefinementRun(CCGRun(used, kkt, False, stalled=True), rounds, False)
        inner = GapState.anchored(H32, state)
        run = loop(inner_context(ctx, kkt, used), inner, M, first=first + used)
        used += run.iterations
        rounds += 1
        if np.all(np.isfinite(inner.p)):
            state.p = np.maximum(inner.p, 0.0)
        state.refresh()  # the round's float64 matvec
        new = ctx.kkt(state.p, state.g)
        ctx.record(first + used, new)
        if not new <= MIN_ROUND_GAIN * kkt and new > ctx.tol:  # float32 went as far as it can (or no finite gain)
            if used >= ctx.max_iter:  # the rounds took every iteration the solve was given
                return RefinementRun(CCGRun(used, new, False), rounds, False)
            tail = loop(ctx, state, M, max_iter=ctx.max_iter - used, first=first + used)
            return RefinementRun(CCGRun(used + tail.iterations, tail.kkt, tail.converged, tail.stalled), rounds, True)
        kkt = new
    return RefinementRun(CCGRun(used, kkt, kkt <= ctx.tol), rounds, False)


def solve_in_precision(ctx: SolveContext, state: GapState, loop: Loop, M: SetPreconditioner | None,
                       first: int = 0) -> tuple[CCGRun, dict[str, Any]]:
    """``loop`` from ``state`` in the precision of ``ctx.params["precision"]`` (default
    double); the run and its matvecs by precision.  The trace numbers iterations from
    ``first``."""
    mixed = resolved_precision(ctx.params.get("precision", "double"), ctx.qp) == "mixed"
    H32 = low_precision(ctx.qp.H) if mixed else None
    if H32 is not None and H32 is not ctx.qp.H:
        ctx.track(H32)
    tally = MatvecTally(ctx.qp.H, H32)
    if H32 is None:
        info: dict[str, Any] = {"precision": "double"}
        if mixed:
            info["precision"] = "double (the operator has no float32 twin)"
        run = loop(ctx, state, M, first=first)
        return run, {**info, **tally.info()}
    ref = refine(ctx, state, loop, M, H32, first)
    return ref.run, {"precision": "mixed", "refinement_rounds": ref.rounds,
                     "finished_in_double": ref.finished_in_double, **tally.info()}
