"""Safe screening for the fast solvers (not a solver module: the registry skips "_" names):
the ``screening`` parameter of the four CCGs and fast-pdas.

A periodic problem is posed on the whole grid (``problems.instances.InstanceBuilder``:
its negative influence coefficients let points below the rigid-body trial set touch),
yet its contact set is a few per cent of the grid.  A CCG iteration does a dozen vector
operations over every unknown, so at 512^2 the loop's vector work, not the FFTs, was
most of a periodic solve.

``QP.can_touch(L)`` is a safe screening rule: if the solution carries a total force
sum(p) <= L, only the points with ubar_i >= f L (f = min H_ij <= 0) can be in contact.
``solve_screened`` solves on such a set T and proves the answer on the whole problem:

1. L = ``LOAD_MARGIN`` x sum(p) of the start (the warm start's load; 0 when cold, i.e.
   the rigid-body set, whose round is solved only to ``COLD_ROUND_TOL``: it is there to
   find the load), T = can_touch(L) plus the start's support;
2. the solver runs on the QP restricted to T (``SolveContext.restricted``: same
   tolerance, deadline, trace and matvec count, the whole problem's KKT scales);
3. one matvec on the whole problem gives w = Hp - ubar with p = 0 off T, and the
   whole problem's scaled KKT error; converged when it meets the tolerance;
4. else T grows by can_touch(``LOAD_MARGIN`` x the new load) and the points off T with
   w < 0 (under load control: ``near_contact``, below), and the solve goes on from p, warm.

Load control (sum(p) = P given, the approach Delta the unknown multiplier): the first
round's set is ``QP.can_touch(P, Delta_b)`` -- a point can touch only if ubar_i >= f P -
Delta_b for any Delta_b >= Delta -- with Delta_b = ``LOAD_MARGIN`` x a guess of Delta
(``approach_bound``, ``cold_approach``): ``COLD_APPROACH_FACTOR`` times as far in from the
first touch (Delta = -max ubar) as ``approach_floor``, the approach at which the points,
each pressed alone (stiffness 1/H_ii), would carry P; with an aperiodic kernel (H_ij >= 0)
the true Delta is never below it (p_i <= (ubar_i + Delta) / H_ii at a contact point).  A
cold solve whose first set would not pay (over ``MAX_SCREENED_FRACTION``) starts on the
whole problem instead, solved to ``COLD_ROUND_TOL`` as the cold round is.

The rule is safe but loose under a load: it bounds the rigid-body interference, while the
elastic deformation lifts most of those points off (on a 1024^2 RMD surface at P/(E* A) =
0.005: 82 % of the grid can touch at the answer's approach, 3.6 % does).  So after a round
the next set is read from the round's own answer (``near_contact``): the support of p and
the points whose gap less the approach, w - Delta, is below ``NEAR_GAP_FACTOR`` times the
round's tolerance (in the displacement scale, ``SolveContext.ubar_scale``), the penetrating
points off the round's set among them.  The round's tolerance, not the whole problem's error
after it: where the first set was too small, that error is the penetration off the set (0.07
on the 2048^2 Saupe problem of results/peers/load-0.005), and a margin of ten times it took
the whole grid.  After a cold round this set replaces the round's (it narrows: 12 % of the
grid in that example); after any later round it is added to it, so the sets only grow from
there and the rounds end.  A set that cannot carry the load (a hardness: sum(u_T) < P) is not run:
the whole problem is solved instead.

The answer is judged on the whole problem (step 3), so screening changes which points
the loop carries, never the fixed point (a round solved on T whose answer fails on the
whole problem while T cannot grow is solved once more on T to a tighter tolerance,
``RETRY_FACTOR``, then ends "stalled", never as if the iterations ran out): a solution of the restricted QP with w >= 0
off T is the solution of the whole one.  It is used only where the screened set is at
most ``MAX_SCREENED_FRACTION`` of the unknowns (an aperiodic trial set already is
{ubar >= 0}, so there it never applies).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from contactbench.problems.constraints import fit_multiplier, load_exceeds
from contactbench.problems.instances import QP

from .base import Outcome, Param, SolveContext, Status

#: The load bound of a round: this many times the load of the round's start.
LOAD_MARGIN = 1.25

#: Screen only when the screened set is at most this fraction of the unknowns.
MAX_SCREENED_FRACTION = 0.5

#: A cold start's first round runs on the rigid-body set, a guess: it is solved only to
#: this scaled KKT error, enough to bound the load for the next round.
COLD_ROUND_TOL = 1e-3

#: Load control: the first round's approach is this many times as far in from the first
#: touch as ``approach_floor`` (``cold_approach``).
COLD_APPROACH_FACTOR = 3.0

#: Load control: after a round, the next set holds the points within this many times the
#: round's tolerance of touching (``near_contact``).
NEAR_GAP_FACTOR = 10.0

#: A round solved on T whose answer misses the tolerance on the whole problem while T cannot
#: grow -- the two errors differ by round-off and the load's multiplier reading, e.g. 9.95e-9 on
#: T against 1.04e-8 on the whole -- runs once more on T, asked for this factor times
#: tol^2 / (the whole problem's error); a second miss ends "stalled" (module doc).
RETRY_FACTOR = 0.5

#: The values of a fast solver's ``screening`` parameter.
SCREENINGS = ("safe", "none")

Solve = Callable[[SolveContext], Outcome]


def screening_param() -> Param:
    """The one declaration of the fast solvers' ``screening`` parameter."""
    return Param("screening", str, "safe",
                 "safe: solve on the points that can touch (QP.can_touch), proved on the whole problem; none: all",
                 choices=SCREENINGS)


def approach_floor(qp: QP) -> float:
    """Under load control, the approach Delta_0 at which sum_i max(ubar_i + Delta_0, 0) /
    H_ii = P: the load the points would carry each pressed alone (module doc); 0 without a
    positive load.  Water-filling over the points in the order they touch, read from the
    highest ``k`` only (a partition, not a sort of the grid), k widened until the level
    falls inside them."""
    load = qp.constraints.load
    if load is None or not load > 0.0:
        return 0.0
    depth = -qp.ubar  # how far each point lies below the rigid body's first touch
    reach = load * float(np.max(qp.H.diagonal()))  # P / stiffness, stiffness 1 / max H_ii
    n = depth.size
    k = min(n, max(1024, n // 64))
    while True:
        part = np.partition(depth, k - 1) if k < n else depth
        top = np.sort(part[:k])
        beyond = float(np.min(part[k:])) if k < n else math.inf
        levels = (reach + np.cumsum(top)) / np.arange(1, k + 1)  # Delta when the first j points touch
        inside = levels <= np.append(top[1:], beyond)
        if inside.any():
            return float(levels[np.argmax(inside)])
        k = min(n, 8 * k)


def cold_approach(qp: QP) -> float:
    """The first round's guess of the approach (module doc): ``COLD_APPROACH_FACTOR`` times
    as far in from the first touch, -max(ubar), as ``approach_floor``.  A scene's ubar
    touches at 0 (so it is the factor times the floor); a QP whose ubar is positive
    somewhere (a displacement instance posed under a load) has a negative floor, which
    a plain multiple would move outward, to fewer points -- none at all."""
    first = -float(np.max(qp.ubar, initial=-math.inf))
    return first + COLD_APPROACH_FACTOR * (approach_floor(qp) - first)


def approach_bound(delta: float) -> float:
    """An approach a little beyond ``delta`` (``LOAD_MARGIN``, on either sign)."""
    return delta + (LOAD_MARGIN - 1.0) * abs(delta)


def mask_of(n: int, idx: np.ndarray) -> np.ndarray:
    """The boolean mask over n points of the positions ``idx`` (a sorted union of such
    sets is ``np.flatnonzero`` of their masks' or: O(n), where np.union1d sorts)."""
    mask = np.zeros(n, dtype=bool)
    mask[idx] = True
    return mask


def touching(ctx: SolveContext, p: np.ndarray) -> np.ndarray | None:
    """The points that can touch plus the support of p (None: the operator has no entry
    floor, or under a hardness the set cannot carry the load): can_touch(LOAD_MARGIN
    sum(p)) under displacement control; under load control can_touch(P,
    ``approach_bound`` of the first round's guess, ``cold_approach``) (module doc)."""
    c = ctx.constraints
    if c.load_control:
        touch = ctx.qp.can_touch(float(c.load), approach_bound(cold_approach(ctx.qp)))
    else:
        touch = ctx.qp.can_touch(LOAD_MARGIN * float(np.sum(p)))
    if touch is None:
        return None
    T = np.flatnonzero(mask_of(ctx.n, touch) | (p > 0.0))
    return T if carries_the_load(ctx, T) else None


def carries_the_load(ctx: SolveContext, T: np.ndarray) -> bool:
    """Whether the points ``T`` (indices or a mask) can carry the load under the
    hardness's bounds, sum(u_T) >= P to round-off (``constraints.load_exceeds``, as the
    problem's own check; True without a load or a hardness)."""
    c = ctx.constraints
    if not c.load_control or c.upper is None:
        return True
    u_T = c.upper[T]
    return not load_exceeds(float(c.load), float(np.sum(u_T)), int(u_T.size))


def screened_set(ctx: SolveContext, p: np.ndarray) -> np.ndarray | None:
    """The first round's set: ``touching`` at the start p; under load control from a cold
    start, the whole problem where that set would not pay (module doc); None -- no
    screening -- when it is unknown or not small enough to pay."""
    T = touching(ctx, p)
    if T is not None and 0 < T.size <= MAX_SCREENED_FRACTION * ctx.n:
        return T
    return np.arange(ctx.n) if ctx.constraints.load_control and ctx.p0 is None else None


def near_contact(ctx: SolveContext, p: np.ndarray, w: np.ndarray, delta: float, tol: float) -> np.ndarray | None:
    """Under load control, the mask of the support of p and of the points whose gap less
    the approach is below ``NEAR_GAP_FACTOR`` x ``tol`` x the displacement scale (module
    doc); None when those points cannot carry the load (a hardness)."""
    margin = NEAR_GAP_FACTOR * tol * ctx.ubar_scale()
    near = (p > 0.0) | (w - delta < margin)
    return near if carries_the_load(ctx, near) else None


def round_approach(ctx: SolveContext, out: Outcome, p: np.ndarray, w: np.ndarray) -> float | None:
    """Under load control the round's Delta (its loop's multiplier, else fitted from the
    whole problem's p and w); None without a load."""
    if not ctx.constraints.load_control:
        return None
    if out.multiplier is not None and math.isfinite(out.multiplier):
        return float(out.multiplier)
    return float(fit_multiplier(w, p, ctx.constraints.upper))


def merged_info(rounds: list[dict[str, Any]]) -> dict[str, Any]:
    """The rounds' info: counts summed, flags or-ed, anything else from the last round."""
    out: dict[str, Any] = {}
    for info in rounds:
        for key, value in info.items():
            if isinstance(value, bool):
                out[key] = bool(out.get(key, False)) or value
            elif isinstance(value, int) and isinstance(out.get(key, 0), int):
                out[key] = out.get(key, 0) + value
            else:
                out[key] = value
    return out


def next_set(ctx: SolveContext, T: np.ndarray, p: np.ndarray, w: np.ndarray, delta: float | None,
             tol: float, narrow: bool) -> np.ndarray | None:
    """The set after a round on T solved to ``tol``, whose whole-problem answer is (p, w,
    Delta) (module doc, step 4): T and its points' growth, or under load control
    ``near_contact``, added to T, or in its place when ``narrow`` (after a cold round);
    None when the set cannot carry the load."""
    if delta is not None:
        near = near_contact(ctx, p, w, delta, tol)
        if near is None:
            return None
        return np.flatnonzero(near if narrow else near | mask_of(ctx.n, T))
    touch = touching(ctx, p)
    if touch is None:
        return None
    return np.flatnonzero(mask_of(ctx.n, touch) | mask_of(ctx.n, T) | (w < 0.0))


def solve_screened(ctx: SolveContext, solve: Solve) -> Outcome:
    """``solve`` on the screened set, grown until the answer holds on the whole problem
    (module doc); on the whole problem when screening is off or does not apply
    (``screened_set``)."""
    p = ctx.first_p()
    T = None if ctx.params.get("screening", "safe") == "none" else screened_set(ctx, p)
    if T is None:
        return solve(ctx)
    used, infos, stuck, tighter = 0, [], False, None
    while True:
        cold = ctx.p0 is None and not infos  # a cold first round stays cold (its first guess)
        sub = ctx.restricted(T, None if cold else p[T], first=used)
        if cold and ctx.tol is not None:  # its set is a guess: it only has to find the load
            sub = replace(sub, tol=max(ctx.tol, COLD_ROUND_TOL))
        if tighter is not None:
            sub = replace(sub, tol=tighter)
        out = solve(sub)
        if ctx.setup_time is None:
            ctx.setup_time = sub.setup_time
        used += out.iterations
        infos.append(out.info)
        p = np.zeros(ctx.n)
        p[T] = np.maximum(out.p, 0.0)
        w = ctx.qp.H.matvec(p) - ctx.qp.ubar
        delta = round_approach(ctx, out, p, w)
        kkt = ctx.kkt(p, w, delta)
        ctx.record(used, kkt)
        out_of_iterations = ctx.max_iter is not None and used >= ctx.max_iter
        if kkt <= ctx.tol or not out.converged or ctx.expired() or out_of_iterations:
            break
        grown = next_set(ctx, T, p, w, delta, kkt if sub.tol is None else sub.tol, narrow=cold)
        if grown is None:  # the grown set cannot carry the load: the whole problem
            grown = np.arange(ctx.n)
        if grown.size == T.size and sub.tol is not None and sub.tol <= ctx.tol:  # solved on T, not on the whole
            if tighter is not None or not math.isfinite(kkt):  # T cannot grow, and solving it further did not do
                stuck = True
                break
            tighter = RETRY_FACTOR * ctx.tol * ctx.tol / kkt
        T = grown
    info = {**merged_info(infos), "screened_rounds": len(infos), "screened_size": int(T.size)}
    status = None if kkt <= ctx.tol else Status.STALLED if stuck else out.status
    return Outcome(p, used, kkt <= ctx.tol, f"scaled KKT error {kkt:.3e} after {used} iterations "
                   f"on {T.size} of {ctx.n} points ({len(infos)} screening rounds)", w=w,
                   status=status, info=info, multiplier=delta)
