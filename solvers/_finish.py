"""The exact finish of the constrained CGs (not a solver module: the registry skips "_"
names): what ``_constrained.polonsky_keer_box`` and ``_constrained.bugnicourt_load`` do
when their CG set is too small to carry a step.

Near saturation -- a box that carries nearly all of the load, so that every element but
a few is plastic -- the load-controlled loops' CG set is a handful of points: the
interior {0 < p < u} and the few bounded points that want to move.  A direction that
sums to zero on one or two points is (nearly) zero, so the loops broke down after a few
iterations or cycled: on a 32^2 rough surface whose box carries 99 % of the load, the
four fast CCGs stopped "stalled" at a KKT error of 1e-3 to 5e-2, or ran to max_iter.
Yet the unknowns still to decide are exactly those few points, and a set that small is
solved exactly at the cost of a dense block of H.

``finish_exactly``, from the state's p (in the box, carrying the load):

1. g = Hp - ubar recomputed (one matvec); Delta the caller's;
2. C = the points not held at a bound by an admissible multiplier of w = g - Delta
   (``_ccg.at_rest``): the interior and the bounded points that want to move.  The others
   are pinned where they are (at 0 or at u);
3. the QP on C with the pinned forces moved to the right-hand side,

       min 1/2 p_C' H_CC p_C - ubar_C' p_C,  0 <= p_C <= u_C,  [sum p_C = P - sum p_pinned],
       ubar_C' = ubar_C - H_C,pinned p_pinned = H_CC p_C - g_C,

   is solved exactly on the dense H_CC gathered from the operator
   (``ContactOperator.submatrix``), from the state's p_C, by a primal active-set method
   that keeps p feasible: ``problems.mixed_lcp.load_active_set`` under load control (the
   bordered solve with the multiplier), Stark & Parker's ``bvls`` without a load; at a
   tolerance tied to the solve's scaled KKT tolerance.  (Block principal pivoting,
   ``box_polish``, was tried first: on a free set that empties it stops "violation-free"
   with every point at a bound and the load not met, which is exactly this regime.);
4. g recomputed (one matvec); converged when the scaled KKT error meets ``ctx.tol`` (under
   load control with both readings of Delta, the sub-problem's multiplier and the one
   fitted from p, as the loops judge); else the pinned points that now want to move join
   C and the round repeats.

C only grows, so the rounds end: on convergence, when no point joins, when C exceeds
``FINISH_MAX_POINTS`` (the dense block's size; the finish then declines and the caller's
status stands) or after ``FINISH_MAX_ROUNDS`` (fewer when the caller's iteration limit
leaves fewer: a round counts as an iteration).  The finish never raises: a sub-problem
that cannot be factored (a periodic whole grid without a load, H singular along the
constant vector) or gives no finite answer leaves p as it was.

Why not always: on a contact set of a few hundred points the finish would replace the
CG altogether, and its cost grows with |C|^3.  The loops call it only when they cannot go
on -- a breakdown, an empty or one-point CG set, or no halving of the KKT error in
``FINISH_PATIENCE`` iterations (``Stagnation``) -- and only while C is small enough; at
the iteration limit a loop stops as it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from contactbench.problems.constraints import Constraints, fit_multiplier
from contactbench.problems.kkt import constrained_scales
from contactbench.problems.mixed_lcp import bvls, load_active_set

from ._ccg import GapState, at_rest
from .base import SolveContext

#: The largest set C the finish solves: a dense |C| x |C| block of H, and an active set
#: whose every step is one dense solve on it (so at most ``SUBSOLVE_STEPS_PER_POINT`` |C|
#: solves of O(|C|^3): a few seconds at this size).
FINISH_MAX_POINTS = 256

#: The sub-solve's active-set steps (elements freed) per point of C, plus ten.
SUBSOLVE_STEPS_PER_POINT = 2

#: Rounds (sub-solves, each followed by one matvec) before the finish gives up.
FINISH_MAX_ROUNDS = 20

#: Iterations of a loop without halving its KKT error before it tries the finish.
FINISH_PATIENCE = 25

#: The sub-solve's own tolerance never goes below this (round-off of the dense
#: sub-solve; below it, the active set would chase noise).
SOLVE_TOL_FLOOR = 1e-15


@dataclass
class Stagnation:
    """Whether a loop's KKT error has not halved in ``patience`` iterations."""

    patience: int = FINISH_PATIENCE
    best: float = math.inf
    since: int = 0

    def stuck(self, kkt: float) -> bool:
        """Record the iteration's error; True when the last ``patience`` did not halve it."""
        if kkt < 0.5 * self.best:
            self.best, self.since = kkt, 0
            return False
        self.since += 1
        return self.since >= self.patience

    def restart(self) -> None:
        self.since = 0


@dataclass
class FinishRun:
    """How the finish ended: the scaled KKT error of the final p (recomputed gap), whether
    it meets the tolerance, the rounds, the final size of C and Delta (None without a load)."""

    kkt: float
    converged: bool
    rounds: int
    size: int
    multiplier: float | None


def undecided(p: np.ndarray, g: np.ndarray, delta: float, u: np.ndarray) -> np.ndarray:
    """The points not held at a bound by an admissible multiplier of w = g - Delta (C)."""
    return ~at_rest(p, g - delta, u)


def can_finish(state: GapState, delta: float, u: np.ndarray) -> bool:
    """Whether the finish would start on a set of at most ``FINISH_MAX_POINTS`` points."""
    return int(np.count_nonzero(undecided(state.p, state.g, delta, u))) <= FINISH_MAX_POINTS


def _kkt_of(ctx: SolveContext, state: GapState, delta: float) -> float:
    """The scaled KKT error of the state; under load control the worse of Delta's two
    readings (``delta`` and the one fitted from p)."""
    if not ctx.constraints.load_control:
        return ctx.kkt(state.p, state.g)
    return max(ctx.kkt(state.p, state.g, delta), ctx.kkt(state.p, state.g))


def _solve_tol(ctx: SolveContext, ubar_C: np.ndarray, H_CC: np.ndarray, sub: Constraints) -> float:
    """The sub-solve's tolerance (in its own scales) that keeps its residual violations a
    tenth of ``ctx.tol`` in the whole problem's scales."""
    u_s, p_s = constrained_scales(ctx.qp.ubar, ctx.diag_max, ctx.constraints, ctx.ubar_scale())
    u_c, p_c = constrained_scales(ubar_C, float(np.max(np.diag(H_CC))), sub)
    tol = 0.1 * float(ctx.tol) * min(u_s / u_c, p_s / p_c)
    return max(tol, SOLVE_TOL_FLOOR) if math.isfinite(tol) else SOLVE_TOL_FLOOR


def _solve_on(ctx: SolveContext, state: GapState, C: np.ndarray, u: np.ndarray,
              delta: float) -> tuple[np.ndarray, float] | None:
    """(p_C, Delta) of the sub-problem on the positions ``C`` (module doc, step 3), or None
    when it cannot be solved (a singular block, a non-finite answer)."""
    c = ctx.constraints
    get = state.space.get  # C is small: its rows cross to the host (a device state)
    pos = get(C)
    p_C, g_C, u_C = get(state.p[C]), get(state.g[C]), get(u[C])
    H_CC = state.H.submatrix(pos, pos)
    ubar_C = H_CC @ p_C - g_C
    load = None
    if c.load is not None:
        pinned = float(np.sum(state.p)) - float(np.sum(p_C))
        load = min(max(float(c.load) - pinned, 0.0), float(np.sum(u_C)))
    sub = Constraints(None if not np.any(np.isfinite(u_C)) else u_C, load)
    tol = _solve_tol(ctx, ubar_C, H_CC, sub)
    steps = SUBSOLVE_STEPS_PER_POINT * C.size + 10
    try:
        if load is None:
            p_C, mult = bvls(H_CC, ubar_C, sub.upper, p_C, max_iter=steps, tol=tol).p, 0.0
        else:
            out = load_active_set(H_CC, ubar_C, sub, p_C, max_iter=steps, tol=tol)
            p_C, mult = out.p, out.multiplier
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None
    if not np.all(np.isfinite(p_C)):
        return None
    return np.clip(p_C, 0.0, u_C), mult


def finish_exactly(ctx: SolveContext, state: GapState, u: np.ndarray, delta: float,
                   max_rounds: int = FINISH_MAX_ROUNDS) -> FinishRun | None:
    """The exact finish (module doc) from ``state`` with the caller's Delta; None when its
    set C would exceed ``FINISH_MAX_POINTS`` from the start (nothing was changed but a
    recomputed gap).  Otherwise ``state`` ends at the finish's p with its exact gap, after
    at most ``max_rounds`` rounds."""
    load = ctx.constraints.load_control
    state.refresh()
    if not load:
        delta = 0.0
    C = undecided(state.p, state.g, delta, u)
    if int(np.count_nonzero(C)) > FINISH_MAX_POINTS:
        return None
    kkt = _kkt_of(ctx, state, delta)
    rounds = 0
    while rounds < max_rounds and not ctx.expired():
        if kkt <= ctx.tol or not np.any(C):
            break
        rounds += 1
        pos = np.flatnonzero(C)
        solved = _solve_on(ctx, state, pos, u, delta)
        if solved is None:
            break
        before = state.p.copy()
        state.p[pos] = state.space.put(solved[0])
        state.refresh()
        new_delta = solved[1] if math.isfinite(solved[1]) else fit_multiplier(state.g, state.p, ctx.constraints.upper)
        new_kkt = _kkt_of(ctx, state, new_delta if load else 0.0)
        if not new_kkt <= kkt and not new_kkt <= ctx.tol:  # no better: keep the better point
            state.p = before
            state.refresh()
            grown = C | undecided(state.p, state.g, delta, u)
        else:
            kkt, delta = new_kkt, (new_delta if load else 0.0)
            grown = C | undecided(state.p, state.g, delta, u)
        if np.array_equal(grown, C) or int(np.count_nonzero(grown)) > FINISH_MAX_POINTS:
            break
        C = grown
    return FinishRun(kkt, kkt <= ctx.tol, rounds, int(np.count_nonzero(C)), delta if load else None)
