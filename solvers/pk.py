"""Constrained conjugate gradient of Polonsky & Keer (1999), displacement control
(Bemporad & Paggi 2015, section 3.2, Algorithm 2): the paper's configuration of the one
Polonsky-Keer loop, ``_ccg.polonsky_keer`` (which fast-ccg runs as well).

Each iteration: a conjugate direction t on the current contact set S (t = 0 off S),
the exact line step tau = (w_S't_S) / (t'Ht), projection onto p >= 0, and re-entry of
the points with zero force and negative gap (I_ol, where the conjugacy is reset, d = 0).

Reading of the printed algorithm: w, t and the inner products are restricted to the
contact set S = {p > 0} of the previous iteration (as in P&K's paper); the first
iteration uses the initial trial domain.  The printed stopping test (relative change of
||w||) is replaced by the harness's scaled KKT error (``SolveContext.kkt``), which is
what "convergence" must mean for the harness.  Step 3.8 (w = Hp - ubar) is computed as
w -= tau H t when no point entered or was clipped (same numbers up to round-off, one
matvec per iteration instead of two).

What pk keeps of its own, and fast-ccg does not: the paper's trial domain.  Cold start:
p = 0 with the whole trial set as the first domain (Algorithm 2's input I_C = {1..n});
warm start (paper: "both an initial trial contact domain and a set of contact
pressures"): p from the previous step and its support as the first domain.  No
preconditioner.  Exact (converges to round-off); matrix-free (dense or FFT operator).

Load control and hardness (``problems.constraints``): ``pk_constrained``, P & K's own
algorithm (1999, section 3: the native load-controlled CCG) with the saturation of
Almqvist, Sahlin, Larsson & Lugt (Tribol. Int. 40 (2007) 574) for bounded pressures.
Each iteration, on the free set I_c = {0 < p < u}:

* g = Hp - ubar; under load control the approach is the mean gap over I_c,
  Delta = mean(g_Ic), and g -= Delta (P & K eq. (9)); without a load Delta = 0;
* t = g + d (G / G_old) t on I_c (0 elsewhere), G = sum g_Ic^2; r = Ht (minus its mean
  over I_c under load control); tau = (g't)_Ic / (r't)_Ic; p -= tau t;
* p < 0 -> 0 and p > u -> u (saturation); the points at rest that want force back
  (p = 0 with g < 0) and the saturated points that want to shed it (p = u with g > 0)
  re-enter with p -= tau g, and the conjugacy is reset (d = 0);
* under load control the free forces are scaled so that sum(p) = P
  (p_Ic *= (P - sum p_S) / sum p_Ic, then clipped to the box).

It stops on the harness's scaled KKT error of (p, g, Delta) (``SolveContext.kkt``) and
reports Delta as the multiplier.  Two matvecs per iteration.  The re-entry rule, the
scaling to the load and the first iterate are solvers/_constrained.py's
(``wants_to_move``, ``scale_to_load``, ``constrained_start``), shared with the fast
CCGs' loops.  Cold start: P spread evenly
over the trial set (load control), else p = 0 with the whole set as the first I_c; warm:
the previous p (scaled to the load), the whole set again the first I_c under displacement
control.
"""

from __future__ import annotations

import math

import numpy as np

from contactbench.problems.constraints import fit_multiplier

from ._ccg import GapState, outcome, polonsky_keer
from ._constrained import constrained_start, mean_on, scale_to_load, wants_to_move
from ._kit import absolute_tol, matvec_seconds
from ._unit_scale import at_unit_scale
from .base import Capabilities, Outcome, SolveContext, Solver, Status
from .registry import register

#: The iterations ``pk``'s time model assumes, at two products each: cold displacement steps
#: of the paper sweep took 31-94 products (about one an iteration) at n = 86-8,803 on its
#: 128^2 and 256^2 grids, 132 at the 512^2 top step (n = 35,218); the model's 200 cover them.
#: Under load control (two products an iteration): ``_kit.TYPICAL_PK_LOAD_ITERATIONS``.
TYPICAL_PK_ITERATIONS = 100


@register
class PolonskyKeer(Solver):
    """Constrained CG (Polonsky & Keer 1999; paper Algorithm 2), displacement control,
    ``_ccg.polonsky_keer`` without a preconditioner.

    Warm start: previous p and its support as the initial trial domain (cold: p = 0 and
    the whole trial set).  Exact; matrix-free."""

    name = "pk"
    family = "paper"
    description = "Polonsky-Keer constrained CG (Algorithm 2), warm start of p and domain"
    capabilities = Capabilities(warm_start="primal", exact=True, load_control=True, bounds=True)
    default_tol = 1e-10

    def iterate(self, ctx: SolveContext) -> Outcome:
        """The loop (class doc), at unit scale past ``_unit_scale.UNIT_SCALE_RANGE``."""
        return at_unit_scale(ctx, self.iterate_at_scale)

    def iterate_at_scale(self, ctx: SolveContext) -> Outcome:
        if not ctx.constraints.plain:
            return pk_constrained(ctx)
        state = GapState.start(ctx)
        warm = ctx.p0 is not None and bool(np.any(ctx.p0 > 0.0))
        domain = state.p > 0.0 if warm else np.ones(ctx.n, dtype=bool)
        run = polonsky_keer(ctx, state, None, domain=domain)
        return outcome(state, run, {"initial_domain": int(domain.sum())})

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 2 * TYPICAL_PK_ITERATIONS * matvec_seconds(n, operator_kind)


#: Iterations without the KKT error falling below ``STALL_GAIN`` of its least that make
#: ``pk_constrained`` let the points at a bound that want to move into its CG set.
STALL_WINDOW = 10
STALL_GAIN = 0.9


def pk_constrained(ctx: SolveContext) -> Outcome:
    """Polonsky & Keer (1999) under load control with Almqvist's saturation (module doc).

    Degenerate steps end the loop with an answer and an honest status: a free set whose
    own residual is within the tolerance (e.g. a single free point under load control,
    its gap equal to Delta) is widened by the points at a bound that want to move
    (``cg_set``); a direction with no curvature after a conjugate step restarts from the
    steepest one; nothing left to move, or no curvature along the steepest direction,
    is "stalled" with the reason."""
    H, ubar, c = ctx.qp.H, ctx.qp.ubar, ctx.constraints
    u = c.upper_or_inf(ctx.n)
    load = c.load is not None
    atol = absolute_tol(ctx, ctx.tol or 0.0).disp
    p = constrained_start(ctx, u)
    t = np.zeros(ctx.n)
    G_old, conj = 1.0, False
    delta = 0.0
    # Displacement control: the whole set is the first I_c, from p = 0 or from the warm start.
    # From a warm start's own free set (0 < p < u), a step that lets thousands of points enter
    # can swing them between 0 and the bound on alternate iterations, for ever.
    first = not load
    status, why = None, ""
    best, since = math.inf, 0  # the least KKT error, and the iterations since it last fell
    for it in range(int(ctx.max_iter or 0) + 1):
        g = H.matvec(p) - ubar
        free = np.ones(ctx.n, dtype=bool) if first else (p > 0.0) & (p < u)
        if not np.any(free):  # every element at a bound: those whose gradient points inward move
            free = wants_to_move(p, g - delta, u)
        if load:
            delta = mean_on(g, free) if np.any(free) else fit_multiplier(g, p, c.upper)
        res = ctx.kkt(p, g, delta if load else None)
        ctx.record(it, res)
        if res <= (ctx.tol or 0.0):
            return Outcome(p, it, True, w=g, multiplier=delta if load else None)
        if it == ctx.max_iter or ctx.expired() or not math.isfinite(res):
            break
        first = False
        best, since = (res, 0) if res < STALL_GAIN * best else (best, since + 1)
        free, delta, widened = cg_set(p, g, delta, free, u, load, atol, since >= STALL_WINDOW)
        since = 0 if widened else since
        r_g = np.where(free, g - delta, 0.0)
        G = float(r_g @ r_g)
        if not G > 0.0:
            status, why = Status.STALLED, "no point can move: the free set is solved and no point at a bound wants to move"
            break
        conj = conj and not widened
        t = r_g + (G / G_old if conj else 0.0) * np.where(free, t, 0.0)
        r = H.matvec(t)
        if load:
            r -= mean_on(r, free)
        den = float(r[free] @ t[free])
        if not den > 0.0:
            if conj:  # the conjugate direction lost its curvature by round-off: restart steepest
                conj = False
                continue
            status, why = Status.STALLED, f"no curvature along the steepest direction (t'Ht = {den:.3g})"
            break
        G_old = G
        tau = float(r_g[free] @ t[free]) / den
        p = p - tau * t
        np.maximum(p, 0.0, out=p)
        np.minimum(p, u, out=p)
        wants = wants_to_move(p, g - delta, u) & ~free
        conj = not np.any(wants)
        if not conj:
            p[wants] -= tau * (g[wants] - delta)
            np.clip(p, 0.0, u, out=p)
        p = scale_to_load(p, c, u, g - delta)
    if status is None and not math.isfinite(res):
        status, why = Status.FAILED, f"non-finite KKT error at iteration {it}"
    message = f"{status.value} after {it} iterations: {why}" if status is not None else ""
    return Outcome(p, it, False, message, w=g, multiplier=delta if load else None, status=status)


def cg_set(p: np.ndarray, g: np.ndarray, delta: float, free: np.ndarray, u: np.ndarray, load: bool,
           atol: float, stalled: bool = False) -> tuple[np.ndarray, float, bool]:
    """(CG set, Delta, widened): ``free`` and Delta as they are while the free set's own
    residual max |g - Delta| exceeds ``atol`` (the tolerance in displacement units); once
    it does not, the free set is solved on its own and the error lies at the bounds, so
    the points at a bound that want to move (``wants_to_move``) join it and Delta is
    the mean gap over the widened set (under load control).  ``stalled`` (the KKT error
    has not fallen for ``STALL_WINDOW`` iterations) widens it too: a few free points
    beside thousands at the bound, a handful of them stepping off and back on alternate
    iterations, can keep the free set's residual from ever falling."""
    if not stalled and np.any(free) and float(np.max(np.abs(g[free] - delta))) > atol:
        return free, delta, False
    wants = wants_to_move(p, g - delta, u) & ~free
    if not np.any(wants):
        return free, delta, False
    free = free | wants
    return free, (mean_on(g, free) if load else delta), True
