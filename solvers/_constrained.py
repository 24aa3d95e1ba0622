"""Load control and hardness bounds in the constrained CGs (not a solver module: the
registry skips "_" names): the one home of the rules that ``pk`` (``pk.pk_constrained``,
P & K's own two-matvec loop) and the fast CCGs' loops (``polonsky_keer_box`` for fast-ccg
and fast-pccg, ``bugnicourt_load`` for fast-dual-ccg and fast-dual-pccg) share.

The problem (``problems.constraints``): min 1/2 p'Hp - ubar'p on 0 <= p <= u, with the
load equality sum(p) = P when one is posed; w = Hp - ubar - Delta, Delta the equality's
multiplier (the rigid approach).

* ``wants_to_move`` -- a point at a bound that is not held by an admissible multiplier
  (``_ccg.at_rest``): p = 0 with w < 0 (it penetrates) or p = u with w > 0 (Almqvist,
  Sahlin, Larsson & Lugt, Tribol. Int. 40 (2007) 574: a plastic point that wants to shed
  force).  It re-enters and the conjugacy is reset.
* ``scale_to_load`` -- sum(p) = P restored after a projection (Polonsky & Keer 1999,
  section 3; the plastic points keep their force, Almqvist et al.; when the plastic
  points alone exceed P, the excess is shed by the largest gap first, ``shed_by_gap``,
  instead of scaling every force off its bound).
* ``constrained_start`` -- the first iterate: the warm start scaled to the load, else P
  spread evenly (capped by the box), else p = 0 (``pk``'s); the fast loops start cold
  from the summits (``winkler_start``).
* ``polonsky_keer_box`` -- the fast loop (below);
* ``bugnicourt_load`` -- Bugnicourt et al.'s loop under load control (its docstring).

Both loops end on every degenerate step with an answer and an honest status: an empty
CG set, a zero or non-finite direction, curvature or step restarts once from the
steepest direction and then stops "stalled"; before a stop that is not convergence
(and when the error has not halved in ``_finish.FINISH_PATIENCE`` iterations) the
undecided points -- nearly all plastic near saturation, so a handful -- are solved
exactly (``_finish.finish_exactly``), converged only on its own KKT test.  Where they are
too many for that, a stagnation makes the preconditioner drop its coarse part, and a later
one its island blocks or its wave numbers (``SetPreconditioner.simplify(blocks=True)``;
solvers/_ccg.py's "Cycling" keeps them), and the direction restarts.  On the 256^2 load
sweep the Polonsky-Keer loop with the island blocks and their far field cycled at a KKT
error of 0.05-0.14 until its iteration limit, and with the blocks alone for 900 iterations
of a step; without them it converges (results/perf/load-pk-default).

The fast loop, ``polonsky_keer_box``
------------------------------------
Each iteration, on the CG set F = {0 < p < u} plus the plastic points that want to shed
force (p = u, w > 0; when no point is inside the box -- or under load control one alone,
whose force no direction that keeps the load can move -- that point and every point that
wants to move),
with g = Hp - ubar kept by the cheap update g -= tau Ht:

* Delta = the mean gap over {0 < p < u} under load control (P & K eq. (9); with no point
  strictly inside the box, the Delta fitted from p), else 0; r = g - Delta on F;
* z = M^-1 r on F (M = I unpreconditioned).  Under load control the direction must keep
  sum(p) on F: z is projected onto {1'z = 0} in the metric of M,
  z <- z - (1'z / 1'M^-1 1) M^-1 1 (``zero_sum``).  This is the preconditioned CG of
  the equality-constrained problem on F: z = P r with P = M^-1 - M^-1 1 (1'M^-1 1)^-1 1'M^-1,
  symmetric positive semidefinite (M SPD), 1'P = 0 (the step keeps the load) and P 1 = 0
  (Delta does not change z), so G = r'z = r'Pr >= 0 as CG needs.  Without M it is
  z = r - mean(r_F), P & K's own direction;
* t = z + (G / G_old) t on F, G = r'z; under load control without M, t -= mean(t_F) (P &
  K: the direction sums to zero on F even after F changed, so a step moves the load only
  where it clips; measured on RMD 65^2 BCC under load control, 91 -> 51 matvecs to 1e-10;
  the same projection in M's metric made fast-pccg stall on one case in 35, so with M
  only z is projected); tau = r't / t'Ht; p -= tau t;
* projection: p clipped to [0, u]; the penetrating points at rest outside F (p = 0,
  w < 0) get p = -tau m_j (g_j - Delta) (m_j = 1, or the preconditioner's solo inverse
  1/H_jj: ``_ccg.entering_force``); under load control the forces are scaled to P.
  Without a box the clipped and entering forces are raised forces and the scaling carries
  the gap along (``_project_raised``: a matvec only where a partial product does not pay);
  with one, whenever the projection changed p, g is recomputed (one matvec).  A point
  entering or a plastic point rejoining F resets the conjugacy (a point only leaving does
  not, as in P & K).

Why the plastic points rejoin F instead of shedding by a jump as in ``pk`` (p_j -= tau
w_j): preconditioned, tau is dimensionless and the jump is m_j w_j = w_j / H_jj, each
point's shed as if it stood alone.  A plastic region is a block of strongly coupled
points, so its points shed together many times what they should, the freed load made
as many zero points penetrate, and the set oscillated (RMD 65^2, BCC, hardness 0.3 of
the elastic peak: fast-pccg at max_iter with 115 of 178 points plastic against 15).  In
F they move along the preconditioned direction, which sees the coupling (same case: 23
iterations, 34 matvecs).

So one matvec per iteration while the projection is inactive or its partial products
pay, two otherwise (pk: two always).  It stops on the harness's scaled KKT error of (p, g, Delta) -- under load
control the worse of the loop's Delta and the one fitted from p (``_kkt``) -- confirmed
on a recomputed g, and reports the loop's Delta as the multiplier.  A load the box
cannot carry (sum(u) < P) is refused before any solve (``Constraints.check``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from contactbench.problems.constraints import Constraints, fit_multiplier
from contactbench.problems.kkt import min_below_zero, read_scalars

from ._ccg import (CCGRun, GapState, at_rest, bugnicourt, conjugate, dual_residual, entering_force, inward, on_set,
                   precondition_on)
from ._finish import FINISH_MAX_ROUNDS, Stagnation, can_finish, finish_exactly
from ._preconditioners import SetPreconditioner
from ._screen import approach_floor
from ._steps import curved_step, exact_step, flat_curvature, polak_ribiere
from .base import SolveContext


#: A projection rescales p to the load P when sum(p) is off P by more than this fraction.
LOAD_DRIFT = 1e-14


def wants_to_move(p: np.ndarray, w: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The points at a bound that an admissible multiplier does not hold (module doc):
    p = 0 with w < 0, p = u with w > 0 (w: the gap less Delta)."""
    return ((p <= 0.0) | (p >= upper)) & ~at_rest(p, w, upper)


def count_and_mean(x: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """The points of ``mask`` and the mean of x over them (0 on an empty mask), in one read."""
    k, total = read_scalars(np.count_nonzero(mask), x @ mask)
    return k, (total / k if k else 0.0)


def mean_on(x: np.ndarray, mask: np.ndarray) -> float:
    """The mean of x over ``mask`` (0 on an empty mask)."""
    return count_and_mean(x, mask)[1]


def scale_to_load(p: np.ndarray, c: Constraints, u: np.ndarray, g: np.ndarray | None = None) -> np.ndarray:
    """p scaled so that sum(p) = P: the free forces scaled, the plastic ones kept (Almqvist
    et al.); when that fails (the plastic points alone exceed P, or a free one is
    scaled past its cap) every force is scaled, sum(min(s p, u)) = P (P & K's scaling, the
    box's cap applied after it; s by bisection, then exact on the uncapped points).  When
    the points carrying force cannot hold P at their caps, the rest goes to the others in
    the order of their gap ``g`` (the most penetrating first, each up to its cap; without
    g, evenly).  When the plastic points alone exceed P and g is given, the excess is
    taken from the points with the largest gap first (``shed_by_gap``): near saturation
    (a box carrying 99 % of P) scaling every force moved all of them off the bound and
    the loops oscillated between that and the plastic set.  p itself without a load
    equality."""
    if c.load is None:
        return p
    load = float(c.load)
    if c.upper is None and min_below_zero(p) >= 0.0:  # no box: the branch below, in one pass
        total = float(np.sum(p))
        if total > 0.0:
            p *= load / total
            return p
    sat = p >= u
    free = (p > 0.0) & ~sat
    rest, carried = load - float(np.sum(p[sat])), float(np.sum(p[free]))
    if rest >= 0.0 and carried > 0.0:  # Almqvist: the plastic points keep their force
        p[free] *= rest / carried
        if np.all(p[free] <= u[free]):
            return p
    if rest < 0.0 and g is not None:  # the plastic points alone exceed P: shed by the gap
        return shed_by_gap(p, float(np.sum(p)) - load, g)
    on = p > 0.0
    if float(np.sum(u[on])) <= load:
        p[on] = u[on]
        off = np.flatnonzero(~on)
        rest = load - float(np.sum(p[on]))
        if g is None:
            p[off] = np.minimum(rest / max(off.size, 1), u[off])
            return p
        order = off[np.argsort(g[off], kind="stable")]
        p[order] = taken_in_order(rest, u[order])
        return p
    lo, hi = 0.0, 1.0
    while float(np.sum(np.minimum(hi * p, u))) < load:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if float(np.sum(np.minimum(mid * p, u))) < load:
            lo = mid
        else:
            hi = mid
    q = np.minimum(hi * p, u)
    free = q < u
    carried = float(np.sum(q[free]))
    if carried > 0.0:
        q[free] *= (load - float(np.sum(q[~free]))) / carried
    return np.minimum(q, u, out=q)


def shed_by_gap(p: np.ndarray, excess: float, g: np.ndarray) -> np.ndarray:
    """p, in place, less ``excess`` (> 0) of force taken from the points in the order of
    their gap ``g``, the largest first (the points the contact holds least), each down
    to 0 at most: near saturation this keeps the plastic set, where scaling every force
    would move every point off its bound."""
    carrying = np.flatnonzero(p > 0.0)
    order = carrying[np.argsort(-g[carrying], kind="stable")]
    p[order] -= taken_in_order(excess, p[order])
    return p


def taken_in_order(amount: float, caps: np.ndarray) -> np.ndarray:
    """``amount`` dealt out to points in their order, each up to its cap (>= 0, inf for
    none), the first filled first: the part of each, min(cap, amount - the caps before it)
    and never below 0 -- a greedy pass, in one vector pass."""
    if caps.size == 0:
        return np.zeros(0)
    before = np.concatenate(([0.0], np.cumsum(caps)[:-1]))
    return np.clip(amount - before, 0.0, caps)


def constrained_start(ctx: SolveContext, u: np.ndarray) -> np.ndarray:
    """The first iterate (module doc): the warm start scaled to the load, else P spread
    evenly (capped by the box), else p = 0."""
    c = ctx.constraints
    if ctx.p0 is not None and np.any(ctx.p0 > 0.0):
        return scale_to_load(np.minimum(ctx.p0, u), c, u)
    if c.load is None:
        return np.zeros_like(u)
    return scale_to_load(np.minimum(np.full_like(u, float(c.load) / ctx.n), u), c, u)


def zero_sum(M: SetPreconditioner | None, z: np.ndarray, free: np.ndarray) -> np.ndarray:
    """z (= M^-1 r on ``free``, 0 elsewhere, M acting on ``free``) projected onto {sum over
    free = 0} in the metric of M: z - (1'z / 1'v) v with v = M^-1 1 (module doc; v of a set
    within ``_preconditioners.ONES_DRIFT`` of ``free``, ``SetPreconditioner.ones``: the sum
    is zero for any v); z - mean(z_free) without M."""
    if M is None:
        return on_set(z - mean_on(z, free), free)
    m1 = on_set(M.ones(), free)
    den, z_free = read_scalars(np.sum(m1), z @ free)
    if not den > 0.0:  # M^-1 not positive on 1 (cannot happen for an SPD M): plain projection
        return on_set(z - mean_on(z, free), free)
    return on_set(z - (z_free / den) * m1, free)


def _approach_and_free_set(state: GapState, u: np.ndarray, c: Constraints) -> tuple[float, np.ndarray]:
    """Delta and the CG set: under load control Delta is the mean gap over the interior
    {0 < p < u} (P & K), or, with no point inside, the one fitted from p
    (``fit_multiplier``: every point at a bound), and the gap is then made exact wherever
    the loops read it, {p > 0} U {g < Delta} (``GapState.level``: raised forces); 0
    without a load.  The CG set is the
    interior and the plastic points that want to shed force, or when no point is inside
    (under load control: at most one) the interior and every point that wants to move
    (module doc)."""
    p, g = state.p, state.g
    interior = p > 0.0 if c.upper is None else (p > 0.0) & (p < u)
    count, mean_gap = count_and_mean(g, interior)
    inside = count > 0
    delta = 0.0
    if c.load is not None:
        delta = mean_gap if inside else fit_multiplier(g, p, c.upper)
        state.level = delta  # the gap made exact wherever it is now read (raised forces)
        state.settle()
    if count < (2 if c.load is not None else 1):
        return delta, interior | wants_to_move(p, g - delta, u)
    return delta, interior if c.upper is None else interior | ((p >= u) & (g - delta > 0.0))


def _kkt(ctx: SolveContext, state: GapState, u: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(KKT error, Delta, free set) of the state.  Under load control the error is the
    loop's reading of Delta (the mean gap over the interior) and, once that meets the
    tolerance, the worse of it and the one a judge fits from p alone (``fit_multiplier``,
    what ``SolveContext.kkt`` takes without one), so a converged answer passes either way;
    above the tolerance the second reading, which cannot lower the error, is not taken."""
    delta, free = _approach_and_free_set(state, u, ctx.constraints)
    if not ctx.constraints.load_control:
        return ctx.kkt(state.p, state.g), delta, free
    return _load_kkt(ctx, state, delta), delta, free


def _load_kkt(ctx: SolveContext, state: GapState, delta: float) -> float:
    """The KKT error under load control at the loop's Delta and, once that meets the
    tolerance, the worse of it and the fitted one (``_kkt``)."""
    loops = ctx.kkt(state.p, state.g, delta)
    if not loops <= ctx.tol:
        return loops
    return max(loops, ctx.kkt(state.p, state.g))


def _checked(ctx: SolveContext, state: GapState, u: np.ndarray) -> tuple[float, float, np.ndarray]:
    """``_kkt``, confirmed on a recomputed gap when it meets the tolerance."""
    kkt, delta, free = _kkt(ctx, state, u)
    if kkt <= ctx.tol and state.confirm:
        state.refresh()
        kkt, delta, free = _kkt(ctx, state, u)
    return kkt, delta, free


def winkler_start(ctx: SolveContext, u: np.ndarray, ubar: np.ndarray | None = None) -> np.ndarray | None:
    """Under load control from p = 0, the points pressed each alone to the approach where
    they carry P (``_screen.approach_floor``: p_i = max(ubar_i + Delta_0, 0) / max H_ii),
    capped by the box and scaled to the load: the summits carry the load from the first
    iterate, where P spread evenly puts force on every point of the grid and the first
    iterations take it off nearly all of them.  None without a load or where that puts no
    force anywhere.  ``ubar``: the QP's, where the state keeps it (default ``ctx.qp.ubar``)."""
    c = ctx.constraints
    if c.load is None or not float(c.load) > 0.0:
        return None
    reach = np.maximum((ctx.qp.ubar if ubar is None else ubar) + approach_floor(ctx.qp), 0.0)
    if not np.any(reach > 0.0):
        return None
    p = np.minimum(reach / float(np.max(ctx.qp.H.diagonal())), u)
    return scale_to_load(p, c, u)


def feasible_start(ctx: SolveContext, state: GapState, u: np.ndarray) -> None:
    """Move the state's p into the feasible set: from p = 0 the ``winkler_start`` (else
    ``constrained_start``), else p capped by u and scaled to the load (its gap recomputed
    when p changed)."""
    c = ctx.constraints
    if not np.any(state.p > 0.0):
        p = winkler_start(ctx, u, state.ubar) if ctx.p0 is None else None
        p = constrained_start(ctx, u) if p is None else p
    else:
        p = scale_to_load(np.minimum(state.p, u), c, u)
    if not np.array_equal(p, state.p):
        state.p = p
        state.refresh()


def polonsky_keer_box(ctx: SolveContext, state: GapState, M: SetPreconditioner | None = None,
                      max_iter: int | None = None, first: int = 0) -> CCGRun:
    """The Polonsky-Keer CCG under ``ctx.constraints`` (module doc) from ``state`` until
    ``ctx.tol``, ``max_iter`` (default ``ctx.max_iter``) or the deadline.  The state's p
    is first moved into the feasible set (``constrained_start`` when cold).  Where the CG
    set cannot carry a step (empty, a zero or non-finite direction or step twice, no
    halving of the error in ``_finish.FINISH_PATIENCE`` iterations) the exact finish on
    the undecided points is tried (``_finish.finish_exactly``; its rounds count as
    iterations, within ``max_iter``).  The trace numbers iterations
    from ``first``."""
    c = ctx.constraints
    max_iter = ctx.max_iter if max_iter is None else max_iter
    u = c.upper_or_inf(ctx.n, state.p)
    load = c.load_control
    feasible_start(ctx, state, u)
    t = np.zeros_like(state.p)
    G_old, reset = 1.0, True
    floor = flat_curvature(ctx.diag_max, state.H.dtype)
    run = CCGRun(0, math.inf, False)
    last = np.zeros_like(state.p, dtype=bool)
    watch, extra = Stagnation(), 0
    for it in range(1, max_iter + 1):
        kkt, delta, free = _checked(ctx, state, u)
        reset |= bool(np.any(free & ~last & (state.p > 0.0)))  # a plastic point rejoined the set
        last = free
        ctx.record(first + it - 1 + extra, kkt)
        run = CCGRun(it - 1 + extra, kkt, kkt <= ctx.tol, multiplier=delta if load else None, finish_rounds=extra)
        done, finished = _loop_head(ctx, state, u, delta, run, watch, first, max_iter, M)
        if done is not None:
            return done
        if finished is not None:  # an exact finish ran and did not converge, or M dropped its coarse part or blocks
            extra, reset = finished, True
            continue
        reset |= M is not None and M.progress(kkt)  # a new stage (solvers/_opening.py)
        if not np.any(free):  # no point can move: degenerate set
            return _broke_down(ctx, state, u, run, first, max_iter)
        r = on_set(state.g - delta, free)
        z = on_set(precondition_on(M, r, free), free)
        if load:
            z = zero_sum(M, z, free)
        G = float(r @ z)
        if not math.isfinite(G):
            return _broke_down(ctx, state, u, run, first, max_iter)
        t = z if reset or not G_old > 0.0 else on_set(z + (G / G_old) * t, free)
        if load and M is None and not reset:  # P & K: the direction itself sums to zero on F
            t = on_set(t - mean_on(t, free), free)
        q = state.H.matvec(t)
        tau = curved_step(float(r @ t), float(t @ q), t, floor, state.p)
        if not (math.isfinite(tau) and tau != 0.0):  # t = 0, lost definiteness, flat or a zero step: restart
            state.refresh()
            if reset:
                return _broke_down(ctx, state, u, run, first, max_iter)
            reset = True
            continue
        entering = np.flatnonzero((state.p <= 0.0) & (state.g - delta < 0.0) & ~free)
        force = entering_force(M, tau, state.g - delta, entering)
        state.advance(-tau, t, q)
        raised = load and c.upper is None and _project_raised(state, float(c.load), entering, force)
        if not raised and _project(state.p, u, entering, force, c, state.g - delta):
            state.refresh()
        reset = bool(entering.size)
        G_old = G
    return replace(run, iterations=max_iter, converged=False)


def _loop_head(ctx: SolveContext, state: GapState, u: np.ndarray, delta: float, run: CCGRun, watch: Stagnation,
               first: int, max_iter: int, M: SetPreconditioner | None) -> tuple[CCGRun | None, int | None]:
    """What both constrained loops decide at the head of an iteration, ``run`` just
    recorded: (the run to return, None) when it converged, the deadline passed, the error
    is not finite, the finish's rounds spent the iterations, or a stagnation's exact finish
    converged; (None, the finish's rounds) when that finish ran and did not converge, or
    when a stagnation too large to finish made M drop its coarse part or blocks (module doc; the
    caller restarts its direction either way); (None, None) to go on."""
    if run.converged or ctx.expired() or not math.isfinite(run.kkt) or run.iterations >= max_iter:
        return run, None
    if not watch.stuck(run.kkt):
        return None, None
    if can_finish(state, delta, u):
        watch.restart()
        fin = _finish_inside(ctx, state, u, delta, run, first, max_iter)
        return (fin, None) if fin.converged else (None, fin.finish_rounds)
    if M is not None and M.simplify(blocks=True):
        watch.restart()
        return None, run.finish_rounds
    return None, None


def _finish_inside(ctx: SolveContext, state: GapState, u: np.ndarray, delta: float, run: CCGRun,
                   first: int, max_iter: int) -> CCGRun:
    """The exact finish (``_finish.finish_exactly``) from the loop's ``run``, in the
    iterations ``max_iter`` leaves: the run after it, its rounds added to the iterations
    and to ``finish_rounds`` (unchanged when the finish declined)."""
    left = min(FINISH_MAX_ROUNDS, max_iter - run.iterations)
    fin = finish_exactly(ctx, state, u, delta, left) if left > 0 else None
    if fin is None or fin.rounds == 0 and not fin.converged:
        return run
    done = run.iterations + fin.rounds
    ctx.record(first + done, fin.kkt)
    return CCGRun(done, fin.kkt, fin.converged, multiplier=fin.multiplier,
                  finish_rounds=run.finish_rounds + fin.rounds)


def _broke_down(ctx: SolveContext, state: GapState, u: np.ndarray, run: CCGRun, first: int,
                max_iter: int) -> CCGRun:
    """A loop's breakdown (no step left): the exact finish where it applies and time and
    iterations are left, else the run as it is; "stalled" unless the finish converged on
    its own KKT test."""
    delta = 0.0 if run.multiplier is None else run.multiplier
    if ctx.expired() or not math.isfinite(run.kkt) or not can_finish(state, delta, u):
        return replace(run, stalled=True)
    fin = _finish_inside(ctx, state, u, delta, run, first, max_iter)
    return fin if fin.converged else replace(fin, stalled=True)


def _project(p: np.ndarray, u: np.ndarray, entering: np.ndarray, force: np.ndarray, c: Constraints,
             w: np.ndarray) -> bool:
    """p, in place, back in the feasible set after a step (module doc): clipped to the box,
    the entering points moved by ``force`` (a raise at p = 0, a cut at p = u), scaled to
    the load.  Whether p changed."""
    before, outside = read_scalars(np.sum(p), np.any(p < 0.0) | np.any(p > u))
    clipped = outside == 1.0
    np.clip(p, 0.0, u, out=p)
    if entering.size:
        p[entering] = np.clip(p[entering] + force, 0.0, u[entering])
    if c.load is None:
        return clipped or bool(entering.size)
    total = float(np.sum(p))
    off = abs(total - float(c.load)) > LOAD_DRIFT * max(float(c.load), abs(before))
    if off:
        p[:] = scale_to_load(p, c, u, w)
    return clipped or bool(entering.size) or off


def _project_raised(state: GapState, load: float, entering: np.ndarray | None = None,
                    force: np.ndarray | None = None) -> bool:
    """``_project`` without a box and without a matvec where the partial products pay: the
    points below 0 raised to 0 and the ``entering`` points (at p = 0) by their ``force``
    where it is positive (``GapState.raise_forces``), then p scaled to the load
    (``GapState.scale``: the gap follows p without a product).  False where p carries no
    positive total to scale (a step keeps sum(p) = P and a raise only adds, so only a
    non-finite step gets there): the caller's ``_project`` then places the load."""
    state.clip(entering, None if force is None else np.maximum(force, 0.0))
    (total,) = read_scalars(np.sum(state.p))
    if not total > 0.0:
        return False
    if abs(total - load) > LOAD_DRIFT * load:
        state.scale(load / total)
    return True


def _dual_residual(state: GapState, u: np.ndarray, c: Constraints) -> tuple[float, np.ndarray]:
    """(Delta, residual): Delta as in ``_approach_and_free_set``; the residual is
    w = g - Delta with the admissible multipliers at both bounds removed (``at_rest``)."""
    delta, _ = _approach_and_free_set(state, u, c)
    return delta, dual_residual(state, u, delta)


def _dual_direction(M: SetPreconditioner | None, res: np.ndarray) -> np.ndarray:
    """z = M^-1 res on the free set {res != 0}, with zero sum there (``zero_sum``)."""
    free = res != 0.0
    return zero_sum(M, on_set(precondition_on(M, res, free), free), free)


def bugnicourt_load(ctx: SolveContext, state: GapState, M: SetPreconditioner | None = None,
                    max_iter: int | None = None, first: int = 0) -> CCGRun:
    """Bugnicourt et al.'s CCG (``_ccg.bugnicourt``) under load control, with or without
    a hardness: the residual is w = g - Delta (Delta the mean gap over the interior, as
    in the Polonsky-Keer loop) less the admissible multipliers at both bounds; the
    direction is -z + beta d (Polak-Ribiere) with z = M^-1 res projected to zero sum on
    the free set (``zero_sum``) and no component out of the box (``_ccg.inward``); a step
    is projected onto the box and scaled to the load: without a box by raised forces and
    a scaling that carry the gap along (``_project_raised``: a matvec only where a partial
    product does not pay), with one by ``_project``, the gap recomputed when that changed
    p.  A direction with no descent (d'Hd or the step not positive,
    not finite) restarts from the steepest one; where that is zero too, or the error has
    not halved in ``_finish.FINISH_PATIENCE`` iterations, the exact finish is tried as in
    ``polonsky_keer_box``.  Without a load: ``_ccg.bugnicourt``."""
    c = ctx.constraints
    if not c.load_control:
        return bugnicourt(ctx, state, M, max_iter=max_iter, first=first)
    max_iter = ctx.max_iter if max_iter is None else max_iter
    u = c.upper_or_inf(ctx.n, state.p)
    feasible_start(ctx, state, u)
    none = np.zeros_like(state.p, shape=(0,), dtype=np.int64)
    delta, res = _dual_residual(state, u, c)
    d = inward(-_dual_direction(M, res), state, res, u)
    floor = flat_curvature(ctx.diag_max, state.H.dtype)
    run = CCGRun(0, math.inf, False)
    watch, extra = Stagnation(), 0
    for it in range(1, max_iter + 1):  # (delta, res) are the state's at the head of every iteration
        kkt = _load_kkt(ctx, state, delta)
        if kkt <= ctx.tol and state.confirm:  # confirmed on a recomputed gap
            state.refresh()
            delta, res = _dual_residual(state, u, c)
            kkt = _load_kkt(ctx, state, delta)
        ctx.record(first + it - 1 + extra, kkt)
        run = CCGRun(it - 1 + extra, kkt, kkt <= ctx.tol, multiplier=delta, finish_rounds=extra)
        done, finished = _loop_head(ctx, state, u, delta, run, watch, first, max_iter, M)
        if done is not None:
            return done
        if finished is not None:  # an exact finish ran and did not converge, or M dropped its coarse part or blocks
            extra = finished
            delta, res = _dual_residual(state, u, c)
            d = inward(-_dual_direction(M, res), state, res, u)
            continue
        Hd = state.H.matvec(d)
        alpha, dHd = exact_step(res, d, Hd, floor, state.p)
        if not (math.isfinite(alpha) and alpha != 0.0):  # d = 0, lost conjugacy, flat or a zero step: restart
            state.refresh()
            delta, res = _dual_residual(state, u, c)
            steepest = inward(-_dual_direction(M, res), state, res, u)
            if not np.any(steepest) or np.array_equal(steepest, d):
                return _broke_down(ctx, state, u, run, first, max_iter)
            d = steepest
            continue
        state.advance(alpha, d, Hd)
        raised = c.upper is None and _project_raised(state, float(c.load))
        if not raised and _project(state.p, u, none, none, c, state.g - delta):
            state.refresh()
        res_old = res
        delta, res = _dual_residual(state, u, c)
        staged = M is not None and M.progress(kkt)  # a new stage (solvers/_opening.py): restart along -z
        z = _dual_direction(M, res)
        d = inward(conjugate(d, z, 0.0 if staged else polak_ribiere(z, res, res_old, alpha * dHd)), state, res, u)
    return replace(run, iterations=max_iter, converged=False)
