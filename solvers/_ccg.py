"""The constrained conjugate gradients of ``pk`` and the fast solvers (not a solver module:
the registry skips "_" names): one gap state, one Polonsky-Keer loop, one Bugnicourt loop.

* ``GapState``      -- p and its gap g = Hp - ubar, kept consistent at one matvec per
                       linear step (g += alpha Hd), corrected where it is read when a
                       projection raised forces ("Raised forces" below), and recomputed
                       every ``refresh_every`` steps against round-off drift.
* ``polonsky_keer`` -- Polonsky & Keer, Wear 231 (1999) 206, displacement control (Bemporad &
                       Paggi 2015, Algorithm 2): CG on the contact set S = {p > 0} with the
                       gap as residual; p < 0 is clipped to 0, points with p = 0 and g < 0
                       (penetration, I_ol) enter, and the conjugacy is reset whenever a point
                       entered.  Optionally preconditioned on S (z = M^-1 r).
* ``bugnicourt``    -- Bugnicourt, Sainsot, Dureisseix, Gauthier & Lubrecht, Tribol. Lett. 66
                       (2018) 29, algorithm OUT_LIN: projected CG on the forces with a
                       Polak-Ribiere beta and no restart; the residual is the gap with the
                       admissible multipliers (p = 0, g >= 0) removed.  Optionally
                       preconditioned on its free set {res != 0}; never a direction out of
                       the feasible set at a point at the bound ("Points at the bound").

Raised forces (the gap after a projection without a matvec)
-----------------------------------------------------------
A projection only ever raises forces: clipping p < 0 to 0, or giving an entering point
a force delta >= 0 (``GapState.raise_forces``).  With f = min(0, min H_ij)
(``ContactOperator.entry_floor``: 0 for the aperiodic BCC and Love kernels, < 0 for the
periodic ones, whose mean is removed) every gap is first moved by f sum(delta), and
what a gap then still lacks, sum_j (H_ij - f) delta_j, is >= 0: a gap not yet corrected
is a lower bound of the true one.  The loops read the gap only through the
contact set {p > 0} and the penetrating points {g < 0}: at a point with p = 0 and a
stored gap >= 0 the true gap is >= 0 as well, and the point is at rest either way.  So
the raise is applied exactly, by a partial product H[rows, raised] delta gathered from
the kernel table (``ContactOperator.partial_product``), to those rows only -- the few
thousand contact points, not the whole trial set -- and the other rows catch up when
they come to need it (each row remembers how many raises its gap includes).  A partial
product is used only when it gathers fewer entries than a matvec is worth
(``partial_product_pays``); else -- and for an operator with no ``entry_floor`` -- one
matvec recomputes g as before.  Same iterates to round-off; on the paper's cold top
step at 1024^2, fast-dual-pccg: 103 -> 81 matvecs for the same 68 iterations.

Both loops stop on the harness's scaled KKT error (``SolveContext.kkt``) of the running
gap, confirmed on a freshly recomputed one, and honour the solve's one deadline.  Both
minimise the paper's QP (eq. (5)): min 1/2 p'Hp - ubar'p, p >= 0.

Preconditioned entry (why fast-pccg once failed the paper's Example 1)
---------------------------------------------------------------------
Unpreconditioned, the direction is t = g, so tau = g't / t'Ht has units of 1/H and an
entering point gets the force -tau g_j (Algorithm 2, step 3.5).  Preconditioned, t = M^-1 r
is a force and tau is dimensionless, so -tau g_j is a length posing as a force: its size
depends on the units (on the counterexample, E = 0.01 and diag H = 64, every entering point
got 64 times its force; PK then cycled, 97 of 100 seeds stopped at max_iter, and the
iterate it stopped at depended on round-off, i.e. on the thread count).  The entering
points get the force -tau m_j g_j instead, with m_j the preconditioner's own inverse for a
point that forms a set alone (``SetPreconditioner.solo``: 1 / H_jj for the island blocks),
which is -tau g_j again without a preconditioner.

Points at the bound (Bugnicourt with a preconditioner)
------------------------------------------------------
Bugnicourt's free set {res != 0} holds the contact set and the points at the bound that
penetrate (p = 0, g < 0).  Unpreconditioned, z = res there, so -z points into the
feasible set (only the Polak-Ribiere term can turn d).  Preconditioned, z = M^-1 res couples such a point j to its contact
neighbours (island blocks: negative off-diagonal entries of the inverse) and to its whole
tile (far field), and z_j can take the sign opposite to res_j: the direction pushes p_j
below 0.  The projection then clipped p_j back to 0 at every iteration, the same points
every time, while Polak-Ribiere without restart kept the direction: the steps shrank
geometrically and the iterate converged to a point that is not the answer (periodic RMD,
1024^2, H 0.9: 72 points clipped at every iteration for 500 iterations, the KKT error
frozen at 4.48e-4; 613 matvecs where float64 needed 116).  So a direction never points
out of the feasible set at a point at the bound (``inward``): there d_j < 0 is set to 0,
as at the points at rest.  It stays a descent direction (the dropped terms only ascended)
and the projection only clips points that leave the contact set.

Points kept out (Bugnicourt with a preconditioner)
--------------------------------------------------
``inward`` can keep a penetrating point at the bound out for good: when z_j keeps the sign
opposite to res_j, d_j is cut to 0 at every iteration, the point never takes a force, and
the rest of the set converges around it with the KKT error frozen at its penetration.  With
islands of up to 512 points as single blocks (solvers/_partition.py) it happened on one
population member at 2048^2 (Saupe RMD, H 0.7, rms slope 0.3, seed 0): 140 points at a gap
of -5e-10 had d_j < 0 for 110 iterations, the error stayed at 1.15e-3, 173 products against
60 with those islands cut.  So when the error has not moved by 1 % (``STALL_FLAT``) for
``STALL_PATIENCE`` iterations, those points take the direction of a point alone,
-M_solo res_j > 0 (``let_in``): a descent direction there, and they enter.  The test never
fires on the surface population at 512^2 and 1024^2; on that member, 69 products
(results/perf/whole-islands).  Under load control a direction must keep the load, so
``_constrained.bugnicourt_load`` has no ``let_in``: its stagnation test hands such a frozen
run to the exact finish (solvers/_finish.py), which converges.

A refactored preconditioner (Bugnicourt)
----------------------------------------
Polak-Ribiere's beta joins z = M^-1 res to the last direction, which the last M shaped.  The
island preconditioner refactors its blocks when the free set drifts and rebuilds its far
field (solvers/_farfield.py), and M^-1 is then another operator.  So when M's ``version``
has changed since the last direction, the loop restarts along -z.  On the surface
population's slowest members at 1024^2 (H 0.9), 3-4 fewer products; the median the same
(results/perf/refactored-restart).

A warm start's first iterations (Bugnicourt)
--------------------------------------------
A warm start is the answer of a nearby problem: on a load sweep, the previous step's, under
an approach deeper by Delta.  Its contact set S0 is then short of Delta everywhere, and every
point whose gap was below Delta penetrates: on the paper's 512^2 sweep, 11,344 points at the
start of the top step around a contact set of 1,930.  Left to Bugnicourt's free set, they all
take a force in the first step, and the next ten iterations shed them again, the island
blocks rebuilt on each shrinking set.  So a warm start's first round *holds* the points at
the bound: the residual is the gap on {p > 0} only (``held_residual``), a CG on S0 that
pushes it down and lifts the gaps around it -- 11,344 penetrating points become 1,456 after
one step and 706 after two.  The hold ends, and the conjugacy restarts along -z, once the
penetrating set shrinks by less than ``HOLD_SHEDDING`` in a step, after ``HOLD_MAX`` steps,
or when the held direction gives no step.  Only where there is no upper bound: the iterates
and the KKT test are Bugnicourt's own, and the stopping test is the whole problem's
throughout.  Figures: results/perf/warm-hold.

Cycling (Polonsky-Keer with a coarse preconditioner)
----------------------------------------------------
With the far-field correction (solvers/_farfield.py) Polonsky-Keer cycled on the paper's
4096^2 cold top step: after ~50 good iterations a few points entered and as many were
clipped every iteration, the conjugacy was reset each time, and the KKT error stayed at
7.8e-4 (``benchmarks/diagnose_pk_farfield.py``).  So when the error has not halved in
``CYCLE_PATIENCE`` iterations, the loop asks its preconditioner to drop its coarse part
(``SetPreconditioner.simplify``; the island blocks stay) and restarts the conjugacy.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from contactbench.problems.fft_threads import each_band, flatnonzero_in_bands
from contactbench.problems.kkt import min_below_zero, read_scalars
from contactbench.problems.operators import ContactOperator
from contactbench.problems.operators_gpu import HOST, ArraySpace

from ._farfield import MAX_AGGREGATES
from ._kit import matvec_seconds, serial_blas
from ._partition import WHOLE_BUDGET
from ._preconditioners import BUILD_BUDGET, ISLAND_KINDS, MAX_BLOCK, SetPreconditioner
from ._screen import solve_screened
from ._steps import curved_step, exact_step, flat_curvature, polak_ribiere
from ._unit_scale import at_unit_scale
from .base import Capabilities, Outcome, SolveContext, Solver, Status

#: A warm start's held iterations (module doc, "A warm start's first iterations") go on while
#: each step shrinks the penetrating set to less than this fraction of what it was ...
HOLD_SHEDDING = 0.7

#: ... for at most this many steps.
HOLD_MAX = 8

#: Polonsky-Keer iterations without halving the KKT error before its preconditioner drops
#: its coarse part (module doc, "Cycling").
CYCLE_PATIENCE = 25

#: A Bugnicourt loop whose KKT error stayed above ``STALL_FLAT`` times the last one for this
#: many iterations lets the points at the bound in that its direction keeps out (module doc,
#: "Points kept out").
STALL_PATIENCE = 5
STALL_FLAT = 0.99


@dataclass(frozen=True)
class Anchor:
    """A base point p0 (>= 0) and its gap g0 = H p0 - ubar computed in float64: a state
    anchored there recomputes its gap as g0 + H (p - p0), i.e. it iterates on the
    correction d = p - p0 (bound d >= -p0) of iterative refinement (solvers/_refine.py),
    so the error of a low-precision H scales with |d|, not with |p|."""

    p0: np.ndarray
    g0: np.ndarray


@dataclass
class GapState:
    """Iterate p (>= 0) and its gap g = Hp - ubar, kept consistent at one matvec per
    linear step, and through a projection by ``raise_forces`` (module doc, "Raised
    forces").  With an ``anchor`` the gap is g0 + H (p - p0) (``Anchor``) and starts at
    g0 without a matvec.  ``space``: where ubar, p and g live (solvers/_device.py)."""

    H: ContactOperator
    ubar: np.ndarray
    p: np.ndarray
    refresh_every: int = 50
    anchor: Anchor | None = None
    #: Whether a loop confirms convergence on a recomputed gap (``converged_now``); an
    #: anchored round of iterative refinement leaves that to its float64 refresh.
    confirm: bool = True
    space: ArraySpace = HOST
    #: The loops read the gap at a point with p = 0 where it is below this level: 0, or the
    #: approach Delta under load control (``_constrained.bugnicourt_load`` sets it).
    level: float = 0.0
    g: np.ndarray = field(init=False)
    _since_refresh: int = field(init=False, default=0)
    #: Forces raised since g was last exact everywhere: (positions, amounts >= 0) ...
    _raised: list[tuple[np.ndarray, np.ndarray]] = field(init=False, default_factory=list)
    #: ... and how many of them each point's gap includes (None: all).
    _upto: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        if self.anchor is None:
            self.refresh()
        else:
            self.g = self.anchor.g0.copy()

    @classmethod
    def anchored(cls, H: ContactOperator, base: GapState) -> GapState:
        """A state on operator ``H`` (e.g. float32) at ``base``'s p, anchored at base's
        (p, g): the correction problem min 1/2 d'Hd + g'd, p + d >= 0, in the variable
        p + d, so the CCG loops run on it unchanged."""
        return cls(H, base.ubar, base.p.copy(), base.refresh_every, Anchor(base.p.copy(), base.g.copy()),
                   confirm=False, space=base.space)

    @classmethod
    def start(cls, ctx: SolveContext) -> GapState:
        """The state at the warm start ``ctx.p0``, or at p = 0 (cold)."""
        return cls(ctx.qp.H, ctx.qp.ubar, ctx.first_p())

    @property
    def exact(self) -> bool:
        """Whether g is H p - ubar at every point (to round-off), not only where it is read."""
        return not self._raised

    def refresh(self) -> None:
        """Recompute g from scratch (one matvec): Hp - ubar, or g0 + H (p - p0) when
        anchored; -ubar without a matvec at p = 0 (a cold start)."""
        if self.anchor is None:
            self.g = self.H.matvec(self.p) - self.ubar if np.any(self.p) else -self.ubar
        else:
            self.g = self.anchor.g0 + self.H.matvec(self.p - self.anchor.p0)
        self._since_refresh = 0
        self._raised, self._upto = [], None

    def advance(self, alpha: float, d: np.ndarray, Hd: np.ndarray) -> None:
        """The linear step p <- p + alpha d, g <- g + alpha Hd (no projection), in bands
        (``each_band``)."""
        p, g = self.p, self.g

        def part(s: slice) -> None:
            ps, gs = p[s], g[s]
            ps += alpha * d[s]
            gs += alpha * Hd[s]

        each_band(part, p)
        self._since_refresh += 1

    def step(self, alpha: float, d: np.ndarray, Hd: np.ndarray, upper: np.ndarray | None = None) -> bool:
        """p <- max(p + alpha d, 0), and <= ``upper`` when given; returns True when the
        projection was active.  A force cut to its upper bound is not a raise, so then the
        gap is recomputed (one matvec)."""
        self.advance(alpha, d, Hd)
        if upper is not None and np.any(self.p > upper):
            np.clip(self.p, 0.0, upper, out=self.p)
            self.refresh()
            return True
        clipped = self.clip()
        if self._since_refresh >= self.refresh_every:
            self.refresh()
        return clipped

    def clip(self, cols: np.ndarray | None = None, amounts: np.ndarray | None = None) -> bool:
        """The projection's raises after a linear step: p < 0 raised to 0, and ``cols`` by
        ``amounts`` (>= 0) when given, in one ``raise_forces``; else g made exact where it
        newly needs to be (``settle``).  Whether p was below 0 anywhere."""
        p = self.p
        clipped = min_below_zero(p) < 0.0
        if clipped:
            below = flatnonzero_in_bands(lambda s: p[s] < 0.0, p)
            lift = -p[below]
            cols, amounts = (below, lift) if cols is None else (np.concatenate([below, cols]),
                                                               np.concatenate([lift, amounts]))
        if cols is None or cols.size == 0:
            self.settle()
        else:
            self.raise_forces(cols, amounts)
        return clipped

    def raise_forces(self, cols: np.ndarray, amounts: np.ndarray) -> None:
        """p[cols] += amounts (all >= 0), the gap kept exact where the loops read it --
        on the contact set and at the penetrating points -- by partial products over the
        raised points when they cost less than a matvec; elsewhere the gap stays a lower
        bound (module doc, "Raised forces").  Otherwise one matvec recomputes g."""
        self.p[cols] += amounts
        floor = self.H.entry_floor()
        if floor is None:
            self.refresh()
            return
        if self._upto is None:
            self._upto = np.zeros_like(self.p, dtype=np.int32)
        if floor < 0.0:  # every gap takes its share of the negative entries now
            self.g += floor * float(np.sum(amounts))
        self._raised.append((cols, amounts))
        self._settle()

    def scale(self, factor: float) -> None:
        """p <- factor p (factor > 0) without a matvec: H p scales with p, so g <- factor g +
        (factor - 1) ubar -- anchored too, since g0 = H p0 - ubar -- and the raises a row
        has yet to take scale with it.  A gap that was a lower bound stays one."""
        p, g, ubar = self.p, self.g, self.ubar

        def part(s: slice) -> None:
            ps, gs = p[s], g[s]
            ps *= factor
            gs *= factor
            gs += (factor - 1.0) * ubar[s]

        each_band(part, p)
        self._raised = [(cols, amounts * factor) for cols, amounts in self._raised]

    def settle(self) -> None:
        """After a linear step with no projection, or a new ``level``: make g exact where
        it newly needs to be."""
        if self._raised:
            self._settle()

    def _settle(self) -> None:
        """Make g exact on the points that need it, {p > 0} U {g < level}: each gets the
        raises since the last refresh that its gap does not include yet."""
        assert self._upto is not None
        p, g, level = self.p, self.g, self.level
        need = flatnonzero_in_bands(lambda s: (p[s] > 0.0) | (g[s] < level), p)
        done = len(self._raised)
        behind = self._upto[need]
        groups = [(k, need[behind == k]) for k in np.unique(behind[behind < done]).tolist()]
        sizes = np.cumsum([0] + [c.size for c, _ in self._raised])
        entries = sum(rows.size * int(sizes[-1] - sizes[k]) for k, rows in groups)
        if not self.H.partial_product_pays(entries):
            self.refresh()
            return
        floor = self.H.entry_floor() or 0.0
        for k, rows in groups:
            cols = np.concatenate([c for c, _ in self._raised[k:]])
            amounts = np.concatenate([a for _, a in self._raised[k:]])
            self.g[rows] += self.H.partial_product(rows, cols, amounts) - floor * float(np.sum(amounts))
        self._upto[need] = done


@dataclass
class CCGRun:
    """How a constrained CG loop stopped: iterations, the last scaled KKT error, and
    whether it stopped on a breakdown (no descent direction left) rather than a limit."""

    iterations: int
    kkt: float
    converged: bool
    stalled: bool = False
    #: Under load control, the approach Delta of the last iterate (None: no load equality).
    multiplier: float | None = None
    #: Rounds of the exact finish among the iterations (solvers/_finish.py).
    finish_rounds: int = 0


def converged_now(ctx: SolveContext, state: GapState) -> tuple[bool, float]:
    """Scaled KKT test on the running gap, confirmed on a recomputed one (unless the
    state leaves that to its caller: ``GapState.confirm``)."""
    kkt = ctx.kkt(state.p, state.g)
    if kkt > ctx.tol or not state.confirm:
        return kkt <= ctx.tol, kkt
    state.refresh()
    kkt = ctx.kkt(state.p, state.g)
    return kkt <= ctx.tol, kkt


def checkpoint(ctx: SolveContext, state: GapState, done: int, first: int) -> CCGRun:
    """The KKT test after ``done`` iterations (``converged_now``), recorded on the trace
    as iteration ``first + done``."""
    ok, kkt = converged_now(ctx, state)
    ctx.record(first + done, kkt)
    return CCGRun(done, kkt, ok)


def precondition_on(M: SetPreconditioner | None, r: np.ndarray, free: np.ndarray) -> np.ndarray:
    """z = M^-1 r on the free set (M moved to that set first when it changed); r itself
    without a preconditioner."""
    if M is None:
        return r
    if not np.array_equal(free, M.on):
        M.update(free)
    return M.apply(r)


def entering_force(M: SetPreconditioner | None, tau: float, g: np.ndarray, entering: np.ndarray) -> np.ndarray:
    """Force of the ``entering`` points (p = 0, gap g < 0) after a step tau (module doc)."""
    return -tau * (g[entering] if M is None else M.solo(g)[entering])


def polonsky_keer(ctx: SolveContext, state: GapState, M: SetPreconditioner | None = None,
                  domain: np.ndarray | None = None, max_iter: int | None = None, first: int = 0) -> CCGRun:
    """Polonsky & Keer's CCG (module doc) from ``state`` until ``ctx.tol``, ``max_iter``
    (default ``ctx.max_iter``) or the deadline.  ``domain``: the contact set of the first
    iteration (default: the support of p, or {g < 0} when p = 0).  One matvec per
    iteration, plus one when a point enters or is clipped and the partial product does
    not pay ("Raised forces").  The trace numbers
    iterations from ``first``."""
    max_iter = ctx.max_iter if max_iter is None else max_iter
    t = np.zeros_like(state.p)
    G_old, reset = 1.0, True
    run = CCGRun(0, np.inf, False)
    best, since = np.inf, 0
    floor = flat_curvature(ctx.diag_max, state.H.dtype)
    for it in range(1, max_iter + 1):
        run = checkpoint(ctx, state, it - 1, first)
        if run.converged or ctx.expired():
            return run
        best, since = (run.kkt, 0) if run.kkt < 0.5 * best else (best, since + 1)
        if M is not None and M.progress(run.kkt):  # a new stage (solvers/_opening.py)
            reset = True
        if since >= CYCLE_PATIENCE and M is not None and M.simplify():  # module doc, "Cycling"
            since, reset = 0, True
        if domain is not None and it == 1:
            S = domain
        else:
            S = state.p > 0.0
            if not np.any(S):  # nothing in contact: the penetrating points enter
                S = state.g < 0.0
        r = on_set(state.g, S)
        if not np.any(r):  # S is at rest; let the penetrating points in and restart
            S = S | (state.g < 0.0)
            r, reset = on_set(state.g, S), True
            if not np.any(r):
                return CCGRun(it - 1, run.kkt, False, stalled=True)
        z = precondition_on(M, r, S)
        G = float(r @ z)
        if not math.isfinite(G):  # a non-finite gap: no step can be taken
            return CCGRun(it - 1, run.kkt, False, stalled=True)
        t = z if reset or not G_old > 0.0 else on_set(z + (G / G_old) * t, S)  # step 3.1
        q = state.H.matvec(t)
        tau = curved_step(float(r @ t), float(t @ q), t, floor, state.p)  # step 3.2
        if not (math.isfinite(tau) and tau != 0.0):  # t = 0, lost definiteness, flat or a zero step: restart
            state.refresh()
            if reset:  # the steepest direction itself gives no step
                return CCGRun(it, run.kkt, False, stalled=True)
            reset = True
            continue
        entering = np.flatnonzero((state.p == 0.0) & (state.g < 0.0) & ~S)  # step 3.5 (I_ol)
        force = entering_force(M, tau, state.g, entering)
        state.advance(-tau, t, q)  # step 3.3 (t = 0 off S, so p stays 0 at the entering points)
        clipped = np.flatnonzero(state.p < 0.0)  # step 3.4
        if entering.size or clipped.size:  # step 3.8: the gap of the projected p
            state.raise_forces(np.concatenate([entering, clipped]),
                               np.concatenate([np.maximum(force, 0.0), -state.p[clipped]]))
        else:
            state.settle()
        reset = bool(entering.size)
        G_old = G  # step 3.7
    return CCGRun(max_iter, ctx.kkt(state.p, state.g), False)  # (the error of the last step's iterate)


def on_set(x: np.ndarray, mask: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """x on ``mask``, 0 elsewhere (into ``out`` when given), for a finite x: a product,
    several times faster than np.where on the scattered masks of a contact set (a
    non-finite x off the mask gives NaN there, which the loops' finiteness tests stop on)."""
    return np.multiply(x, mask, out=out)


def at_rest(p: np.ndarray, g: np.ndarray, upper: np.ndarray | None = None) -> np.ndarray:
    """The points held by an admissible multiplier: at the lower bound with g >= 0, or at
    the upper bound with g <= 0 (g: the gap, less Delta under load control).  The one
    home of the rule; a point at a bound and not at rest wants to move inside
    (``_constrained.wants_to_move``)."""
    rest = (p <= 0.0) & (g >= 0.0)
    if upper is not None:
        rest |= (p >= upper) & (g <= 0.0)
    return rest


def dual_residual(state: GapState, upper: np.ndarray | None = None, approach: float | None = None) -> np.ndarray:
    """Gap with the admissible multipliers removed (``at_rest``), in bands (``each_band``);
    under load control the gap less the ``approach`` Delta."""
    p, g = state.p, state.g
    res = np.empty_like(g)

    def part(s: slice) -> None:
        w = g[s] if approach is None else g[s] - approach
        on_set(w, ~at_rest(p[s], w, None if upper is None else upper[s]), out=res[s])

    each_band(part, g)
    return res


def inward(d: np.ndarray, state: GapState, res: np.ndarray, upper: np.ndarray | None = None) -> np.ndarray:
    """d, in place, with no component at a point at a bound that is at rest (res = 0) or
    that d would push out of the box (d < 0 at p = 0, d > 0 at p = upper): module doc,
    "Points at the bound"."""
    p = state.p

    def part(s: slice) -> None:
        moves = res[s] != 0.0
        keep = (p[s] != 0.0) | (moves & (d[s] >= 0.0))
        if upper is not None:
            keep &= (p[s] < upper[s]) | (moves & (d[s] <= 0.0))
        np.multiply(d[s], keep, out=d[s])

    each_band(part, d)
    return d


def bugnicourt(ctx: SolveContext, state: GapState, M: SetPreconditioner | None = None,
               max_iter: int | None = None, first: int = 0) -> CCGRun:
    """Bugnicourt et al.'s CCG without restart (module doc) from ``state`` until
    ``ctx.tol``, ``max_iter`` (default ``ctx.max_iter``) or the deadline.  One matvec per
    iteration, plus one when the projection clips and the partial product does not pay
    ("Raised forces").  The trace numbers iterations from
    ``first``.  With upper bounds (``ctx.constraints.bounded``: a hardness) the projection
    is onto the box 0 <= p <= u, the residual drops the admissible multipliers at both
    bounds (``at_rest``) and the preconditioner acts on the rest; a clip at the upper
    bound costs one matvec (``GapState.step``).  Without bounds: the same iterates as
    before they were posed.  The load equality: ``_constrained.bugnicourt_load``."""
    max_iter = ctx.max_iter if max_iter is None else max_iter
    u = ctx.constraints.upper if ctx.constraints.bounded else None
    hold = holds(ctx, first, u)
    penetrating = penetrating_count(state) if hold else 0
    res = held_residual(state) if hold else dual_residual(state, u)
    d = inward(-precondition_on(M, res, res != 0.0), state, res, u)
    version = version_of(M)
    floor = flat_curvature(ctx.diag_max, state.H.dtype)
    run = CCGRun(0, np.inf, False)
    flat, last = 0, math.inf  # iterations with the KKT error within STALL_FLAT of the last
    for it in range(1, max_iter + 1):
        run = checkpoint(ctx, state, it - 1, first)
        if run.converged or ctx.expired():
            return run
        flat, last = (flat + 1 if run.kkt >= STALL_FLAT * last else 0), run.kkt
        Hd = state.H.matvec(d)
        alpha, dHd = exact_step(res, d, Hd, floor, state.p)
        if not (math.isfinite(alpha) and alpha != 0.0):  # d = 0, lost conjugacy, flat or a zero step: restart
            hold = False
            state.refresh()
            res = dual_residual(state, u)
            steepest = inward(-precondition_on(M, res, res != 0.0), state, res, u)
            if not np.any(steepest) or np.array_equal(steepest, d):  # the steepest gives no step either
                kkt = ctx.kkt(state.p, state.g)
                return CCGRun(it, kkt, kkt <= ctx.tol, stalled=kkt > ctx.tol)
            d = steepest
            continue
        state.step(alpha, d, Hd, u)
        res_old = res
        released = False
        if hold:
            now = penetrating_count(state)
            hold = now < HOLD_SHEDDING * penetrating and it < HOLD_MAX
            released, penetrating = not hold, now
        res = held_residual(state) if hold else dual_residual(state, u)
        # a new stage (solvers/_opening.py), the hold's end or new factors: restart along -z
        staged = (M is not None and M.progress(run.kkt)) or released
        z = precondition_on(M, res, res != 0.0)
        now = version_of(M)
        refactored, version = now != version, now
        beta = 0.0 if staged or refactored else polak_ribiere(z, res, res_old, alpha * dHd)
        conjugate(d, z, beta)
        if flat >= STALL_PATIENCE and let_in(d, state, res, M):
            flat = 0
        inward(d, state, res, u)
    return CCGRun(max_iter, ctx.kkt(state.p, state.g), False)  # (the error of the last step's iterate)


def version_of(M: SetPreconditioner | None) -> int:
    """``SetPreconditioner.version`` (0 without a preconditioner)."""
    return 0 if M is None else M.version


def let_in(d: np.ndarray, state: GapState, res: np.ndarray, M: SetPreconditioner | None) -> bool:
    """d, in place, along -M_solo res (``SetPreconditioner.solo``; -res without M) at the
    points at the bound that penetrate (res < 0) and that d would keep out (d < 0): module
    doc, "Points kept out".  Whether there were any."""
    out = (state.p <= 0.0) & (res < 0.0) & (d < 0.0)
    (count,) = read_scalars(np.count_nonzero(out))
    if not count:
        return False
    solo = res if M is None else M.solo(res)
    d[out] = -solo[out]
    return True


def conjugate(d: np.ndarray, z: np.ndarray, beta: float) -> np.ndarray:
    """d <- beta d - z, in place, in bands (``each_band``): the next direction."""

    def part(s: slice) -> None:
        ds = d[s]
        ds *= beta
        ds -= z[s]

    each_band(part, d)
    return d


def holds(ctx: SolveContext, first: int, upper: np.ndarray | None) -> bool:
    """Whether a Bugnicourt run starts by holding the points at the bound (module doc, "A
    warm start's first iterations"): a warm start's first round, with no upper bound."""
    return ctx.p0 is not None and first == 0 and upper is None


def held_residual(state: GapState) -> np.ndarray:
    """The gap on the contact set {p > 0}: every point at the bound held there."""
    return on_set(state.g, state.p > 0.0)


def penetrating_count(state: GapState) -> int:
    """Points at the bound that no multiplier holds (``at_rest``): a negative gap (one read)."""
    (count,) = read_scalars(np.count_nonzero((state.p <= 0.0) & ~at_rest(state.p, state.g)))
    return int(count)


def outcome(state: GapState, run: CCGRun, info: dict | None = None) -> Outcome:
    """The lifecycle's ``Outcome`` of a CCG run, with the state's gap as w (recomputed
    when the run converged; otherwise within round-off drift of Hp - ubar, and no
    matvec is spent after a deadline) -- or none, for the lifecycle to recompute, when
    the gap is exact only where the loop reads it (``GapState.exact``)."""
    return Outcome(
        p=state.p,
        iterations=run.iterations,
        converged=run.converged,
        message=f"scaled KKT error {run.kkt:.3e} after {run.iterations} iterations",
        w=state.g if state.exact else None,
        status=Status.STALLED if run.stalled and not run.converged else None,
        info={**(info or {}), **({"finish_rounds": run.finish_rounds} if run.finish_rounds else {})},
        multiplier=run.multiplier,
    )


#: The fast solvers' time model (``FastSolver.time_estimate``): a preconditioned loop's cold
#: solve takes about this many products (``_kit.matvec_seconds``; the population's medians are
#: 47-94, 0.60 s at 512^2 and 51 s at 4096^2 on 2 cores, the model 0.66 s and 51 s:
#: results/perf/surface-population.md); a loop that takes more says so (``typical_matvecs``).
FAST_TYPICAL_MATVECS = 60.0


class FastSolver(Solver):
    """What the matrix-free fast solvers share: family, capabilities (exact, primal warm
    start, dense or FFT operator), the default iteration limit, the memory and the time
    model."""

    family = "fast"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), needs_dense=False, warm_start="primal",
                                exact=True)
    #: The products of a typical cold solve (``time_estimate``; ``FAST_TYPICAL_MATVECS``).
    typical_matvecs: ClassVar[float] = FAST_TYPICAL_MATVECS

    def default_max_iter(self, n: int) -> int:
        """20 sqrt(n) + 2000, far above the 30-150 iterations these loops take at 512^2-4096^2
        (not the peers': under a hardness ContactMechanics' P&K took 2,106 at n = 256)."""
        return 20 * int(np.sqrt(max(n, 1))) + 2000

    def memory_estimate(self, n: int) -> float:
        # Eight vectors; with the island preconditioner, block inverses of up to
        # MAX_BLOCK entries per point of the set (the set can be the whole trial set early),
        # the whole islands' blocks above that (solvers/_partition.py: their entries, sum s^2,
        # are at most sum s^3 / 16 <= WHOLE_BUDGET x BUILD_BUDGET / 16 a grid point; taken
        # here per unknown),
        # and the far field's m x m matrices (solvers/_farfield.py).
        entries = MAX_BLOCK + WHOLE_BUDGET * BUILD_BUDGET / 16
        blocks = 8.0 * entries * n + 3 * 8.0 * MAX_AGGREGATES**2 if self.uses_islands() else 0.0
        return 8.0 * 8.0 * n + blocks

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return self.typical_matvecs * matvec_seconds(n, operator_kind)

    def uses_islands(self) -> bool:
        """Whether the default preconditioner is the island one (memory model)."""
        for p in self.params:
            if p.name == "precondition":
                return p.default in ISLAND_KINDS
        return False

    def iterate(self, ctx: SolveContext) -> Outcome:
        """``iterate_on`` the QP's screened set (solvers/_screen.py; under load control
        narrowed to the points near contact after the cold round), or on the whole QP
        where screening is off or does not pay; with BLAS on one thread
        (``_kit.serial_blas``); at unit scale past ``_unit_scale.UNIT_SCALE_RANGE``."""
        with serial_blas():
            return at_unit_scale(ctx, lambda c: solve_screened(c, self.iterate_on))

    @abstractmethod
    def iterate_on(self, ctx: SolveContext) -> Outcome:
        """The solver's own iteration on ``ctx``'s QP as it is."""
