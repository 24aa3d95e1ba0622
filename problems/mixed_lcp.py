"""The exact solution of the contact QP under bounds and a load equality: the reference
of the constrained families (``problems.constraints``).

    min 1/2 p'Hp - ubar'p   s.t.  0 <= p <= u,  [sum(p) = P]

with H dense SPD (or, under a load equality, positive definite on {sum d = 0}).  Its KKT
conditions (a mixed LCP) are, with w = Hp - ubar - Delta (Delta = 0 without a load):
w >= 0 where p = 0, w <= 0 where p = u, w = 0 in between, sum(p) = P.

``box_polish`` -- block principal pivoting on the three sets Z (p = 0), F (free),
S (p = u) (Judice & Pires 1994, extended to the box): given the sets it solves

    H_FF p_F - Delta 1 = ubar_F - H_FS u_S,   1'p_F = P - 1'u_S     (load control)
    H_FF p_F = ubar_F - H_FS u_S                                    (otherwise)

and moves every violated element: a free p below 0 to Z, above u to S; an element of Z
with w < 0 or of S with w > 0 to F; with no free element, a load the bounded elements
miss frees the one nearest to taking (or shedding) force (``_load_unmet``).  The load
row's right side is shifted by its largest entry, so that a tiny load's p keeps its own
precision.  After ``BLOCK_PATIENCE`` rounds without fewer
violations it moves only the least violated index (Murty's rule).  It stops on a
violation-free set: then p is the exact solution (up to round-off).  Violations are
measured in the units of ``problems.kkt`` (tol x p_s, tol x u_s).

``bvls`` -- bounded-variable least squares (Stark & Parker, Comput. Stat. 10 (1995) 129)
stated on the QP: Lawson-Hanson's active-set method with a second bound.  The free set F
is solved exactly (Cholesky of H_FF, the bounded elements held at 0 or u); the element
of Z with the most negative gradient g = Hp - ubar, or of S with the most positive one,
is freed; when the free solution leaves the box the step is cut at the first bound
reached and the elements there are fixed (the inner loop).  It starts, as Stark & Parker
allow, from any point of the box (a warm start): ``constrained_exact_solution`` starts
it from the displacement-controlled exact solution (``problems.lcp.exact_solution``,
Lawson-Hanson) clipped to the box, and ``box_polish`` checks its final sets.

``constrained_exact_solution`` -- the reference: for a box, ``bvls`` from that point;
under load control, the KKT solve with the multiplier: ``bvls`` at an approach Delta
found by regula falsi (Illinois) on the total force P(Delta) (non-decreasing), and after
each step ``box_polish`` with the load row from that point, until one converges or the
search meets a degenerate step (``_load_controlled``).  Every
answer is certified by ``problems.kkt.constrained_figures``.

Periodic load control.  A periodic kernel on the whole grid has its mean mode removed:
H 1 = 0 (``constant_null_space``), H is positive definite only on {sum d = 0}.  The
displacement-controlled QP at a fixed Delta is then not the sub-problem to solve (its
P(Delta) is infinite once Delta reaches xi_max - xi_mean, the approach of full contact,
and finite loads beyond that point all have that same Delta), so regula falsi on Delta
does not apply.  The equality-constrained QP is solved directly instead
(``load_active_set``): a primal active-set method in the manner of BVLS whose free
solve is the bordered KKT system of ``solve_on_sets``,

    [H_FF  -1] [p_F  ]   [ubar_F - H_FS u_S]
    [ 1'    0] [Delta] = [P - 1'u_S        ],

non-singular for every non-empty F (H is positive definite on the vectors that sum to
zero).  It keeps p feasible (0 <= p <= u, sum p = P): a free solution that leaves the
box is cut at the first bound reached (the load is kept along the step) and the
elements there are fixed; on a feasible free solution the bounded element whose gap
w = Hp - ubar - Delta has the wrong sign by most (w < 0 at p = 0, w > 0 at p = u) is
freed, until none is.  Where no element is free, one freed alone could not move (its force
is the load left over, which the others fix), so it is freed with its exchange partner
(``exchange_partner``): the element at the other bound whose gap favours handing force
across most.  It starts from an accelerated projected-gradient answer
(``projected_gradient_guess``), projected onto the feasible set, and ``box_polish``
repairs the final sets if the certificate fails.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg as sla

from .constraints import Constraints, fit_multiplier, project_box, project_feasible
from .kkt import constrained_figures, constrained_scales
from .lcp import BLOCK_PATIENCE, SubsetSolution, exact_solution, exact_solution_on_subset

if TYPE_CHECKING:
    from .instances import QP

#: Scaled KKT error at which ``constrained_exact_solution`` certifies its answer.
CERTIFY_KKT = 1e-10
#: Approaches Delta (each a displacement-controlled solve and a polish) the load search of
#: ``constrained_exact_solution`` tries, bracket and regula falsi together, before it gives up.
MAX_MULTIPLIER_STEPS = 60
#: Accelerated projected-gradient steps of ``projected_gradient_guess`` (the start of the
#: periodic load-control active set: it need only find most of the contact set).
GUESS_STEPS = 300
#: |H 1| / max row sum of |H| below which H annihilates the constant vector
#: (``constant_null_space``): a periodic kernel's removed mean (round-off ~ 1e-15) passes,
#: an aperiodic kernel's positive row sums (of order one) do not.
NULL_SPACE_TOL = 1e-9

Z, F, S = 0, 1, 2


class UncertifiedConstrainedSolution(RuntimeError):
    """No certified exact solution was found (the message says why)."""


@dataclass
class ConstrainedSolution:
    """p, the multiplier Delta (0 without a load equality), the scaled KKT error of
    ``constrained_figures``, whether the last polish ended on a violation-free set, and
    the polish rounds and displacement-controlled solves it took."""

    p: np.ndarray
    multiplier: float
    kkt_error: float
    converged: bool
    rounds: int
    solves: int = 0


def _scales(H: np.ndarray, ubar: np.ndarray) -> tuple[float, float]:
    u_s = float(np.max(np.abs(ubar), initial=0.0)) or 1.0
    return u_s, u_s / float(np.max(np.diag(H)))


def _initial_sets(p0: np.ndarray, w0: np.ndarray, u: np.ndarray, u_s: float, p_s: float) -> np.ndarray:
    """Z where p0 / p_s <= w0 / u_s, S where (u - p0) / p_s <= -w0 / u_s, F otherwise."""
    state = np.full(p0.shape, F, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        state[np.isfinite(u) & ((u - p0) / p_s <= -w0 / u_s)] = S
    state[p0 / p_s <= w0 / u_s] = Z
    return state


def solve_on_sets(H: np.ndarray, ubar: np.ndarray, u: np.ndarray, load: float | None,
                  state: np.ndarray) -> tuple[np.ndarray, float]:
    """(p, Delta) with p = 0 on Z, u on S and the free equations (module doc) on F.
    Without a load Delta = 0; with one and F empty, Delta is NaN (any value in a range)."""
    p = np.zeros_like(ubar)
    sat = np.flatnonzero(state == S)
    free = np.flatnonzero(state == F)
    p[sat] = u[sat]
    rhs = ubar[free] - H[np.ix_(free, sat)] @ u[sat]
    if load is None:
        if free.size:
            c = sla.cho_factor(H[np.ix_(free, free)], lower=True, check_finite=False)
            p[free] = sla.cho_solve(c, rhs, check_finite=False)
        return p, 0.0
    if free.size == 0:
        return p, math.nan
    m = free.size
    # The bordered system, its border in H's units (d = the largest diagonal entry, the
    # unknown Delta / d), so that LU's pivoting sees entries of one scale.  Its right side
    # is shifted by its largest entry (Delta = the unknown less the shift): a load
    # far below the relief's force has p tiny beside ubar, and unshifted the solve would
    # leave p with round-off of ubar's size, not of its own.
    H_FF = H[np.ix_(free, free)]
    d = float(np.max(np.diag(H_FF)))
    shift = float(np.max(rhs))
    K = np.zeros((m + 1, m + 1))
    K[:m, :m] = H_FF
    K[:m, m] = -d
    K[m, :m] = d
    b = np.append(rhs - shift, d * (float(load) - float(np.sum(u[sat]))))
    x = sla.solve(K, b, check_finite=False)
    p[free] = x[:m]
    return p, d * float(x[m]) - shift


def _load_unmet(g: np.ndarray, p: np.ndarray, state: np.ndarray, load: float, slack: float) -> int | None:
    """With no free element the load row is not solved, only met or not: the element to
    free when sum(p) misses ``load`` by more than ``slack`` -- short, the element at 0 with
    the least gap g (the first to take force as Delta grows); over, the one at u with the
    largest (the first to shed it) -- else None (the load is met, or no element can move)."""
    short = load - float(np.sum(p))
    cand = np.flatnonzero(state == (Z if short > 0.0 else S))
    if abs(short) <= slack or cand.size == 0:
        return None
    return int(cand[np.argmin(g[cand])] if short > 0.0 else cand[np.argmax(g[cand])])


def box_polish(H: np.ndarray, ubar: np.ndarray, constraints: Constraints, p0: np.ndarray,
               delta0: float = 0.0, max_rounds: int = 100, tol: float = 1e-11) -> ConstrainedSolution:
    """Block principal pivoting on the box and load equality from the guess (p0, delta0)
    (module doc).  ``converged``: it stopped on a violation-free set."""
    u = constraints.upper_or_inf(ubar.size)
    load = constraints.load
    u_s, p_s = constrained_scales(ubar, float(np.max(np.diag(H))), constraints)
    state = _initial_sets(p0, H @ p0 - ubar - delta0, u, u_s, p_s)
    best, stall = math.inf, 0
    p, delta = p0, delta0
    for rnd in range(1, max_rounds + 1):
        p, delta = solve_on_sets(H, ubar, u, load, state)
        g = H @ p - ubar
        if load is not None and not math.isfinite(delta):
            delta = fit_multiplier(g, p, constraints.upper)
        w = g - delta
        moves = np.full(p.shape, -1, dtype=np.int8)
        moves[(state == F) & (p < -tol * p_s)] = Z
        moves[(state == F) & (p > u + tol * p_s)] = S
        moves[(state == Z) & (w < -tol * u_s)] = F
        moves[(state == S) & (w > tol * u_s)] = F
        if load is not None and not np.any(state == F):
            unmet = _load_unmet(g, p, state, load, tol * (load or p_s))
            if unmet is not None:
                moves[unmet] = F
        bad = np.flatnonzero(moves >= 0)
        if bad.size == 0:
            return ConstrainedSolution(project_box(p, constraints.upper), delta, 0.0, True, rnd)
        if bad.size < best:
            best, stall = bad.size, 0
        else:
            stall += 1
        if stall < BLOCK_PATIENCE:
            state[bad] = moves[bad]
        else:
            state[bad[0]] = moves[bad[0]]
    return ConstrainedSolution(project_box(p, constraints.upper), delta, math.inf, False, max_rounds)


@dataclass
class BVLSOutcome:
    """p, its outer iterations (elements freed), inner steps (cuts at a bound), and
    whether it stopped with no element to free."""

    p: np.ndarray
    iterations: int
    inner: int
    converged: bool


def _solve_free(H: np.ndarray, ubar: np.ndarray, u: np.ndarray, state: np.ndarray) -> np.ndarray:
    return solve_on_sets(H, ubar, u, None, state)[0]


def _cut_to_box(p: np.ndarray, z: np.ndarray, u: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, bool]:
    """Step from p towards z, cut at the first bound a free element reaches; the elements
    at a bound join Z or S.  Returns (new p, whether z itself was inside the box)."""
    free = state == F
    low = free & (z <= 0.0)
    high = free & (z >= u)
    if not (np.any(low) or np.any(high)):
        return z, True
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a far bound: inf, not taken
        a_low = np.where(low, p / (p - z), np.inf)
        a_high = np.where(high, (u - p) / (z - p), np.inf)
    alpha = float(min(np.min(a_low), np.min(a_high)))
    alpha = min(max(alpha, 0.0), 1.0)
    q = p + alpha * (z - p)
    q = np.where(free, q, p)
    tiny = 1e-14 * max(float(np.max(np.abs(p), initial=0.0)), 1e-300)
    to_z = free & (q <= tiny) & (z <= p)
    to_s = free & np.isfinite(u) & (q >= u * (1.0 - 1e-14)) & (z >= p)
    if not (np.any(to_z) or np.any(to_s)):  # round-off: fix the element that set alpha
        k = int(np.argmin(np.minimum(a_low, a_high)))
        (to_z if low[k] else to_s)[k] = True
    state[to_z], state[to_s] = Z, S
    q[to_z] = 0.0
    q[to_s] = u[to_s]
    return q, False


def bvls(H: np.ndarray, ubar: np.ndarray, upper: np.ndarray | None, p0: np.ndarray | None = None,
         max_iter: int | None = None, tol: float = 1e-12) -> BVLSOutcome:
    """Stark & Parker's BVLS on min 1/2 p'Hp - ubar'p, 0 <= p <= upper (module doc), from
    ``p0`` (clipped to the box; None: p = 0).  An element is freed only when its gradient
    violates by more than tol x u_s."""
    H = np.asarray(H, dtype=np.float64)
    ubar = np.asarray(ubar, dtype=np.float64)
    n = ubar.size
    u = np.full(n, math.inf) if upper is None else np.asarray(upper, dtype=np.float64)
    u_s, _ = _scales(H, ubar)
    p = np.zeros(n) if p0 is None else project_box(np.asarray(p0, dtype=np.float64), upper)
    state = np.where(p <= 0.0, Z, np.where(p >= u, S, F)).astype(np.int8)
    limit = 10 * n + 10 if max_iter is None else int(max_iter)
    inner = 0
    for it in range(limit + 1):
        while np.any(state == F):  # make the free solution feasible (Stark & Parker's loop B)
            p, inside = _cut_to_box(p, _solve_free(H, ubar, u, state), u, state)
            inner += 1
            if inside:
                break
        g = H @ p - ubar
        score = np.where(state == Z, -g, np.where(state == S, g, 0.0))
        j = int(np.argmax(score))
        if score[j] <= tol * u_s or it == limit:
            return BVLSOutcome(p, it, inner, bool(score[j] <= tol * u_s))
        state[j] = F
    return BVLSOutcome(p, limit, inner, False)


def _certified(H: np.ndarray, ubar: np.ndarray, constraints: Constraints, sol: ConstrainedSolution,
               tol: float) -> ConstrainedSolution | None:
    g = H @ sol.p - ubar
    mult = sol.multiplier if constraints.load_control else None
    f = constrained_figures(sol.p, g, ubar, float(np.max(np.diag(H))), constraints, mult)
    sol.kkt_error = f.kkt_error
    return sol if sol.converged and f.kkt_error <= tol else None


def _displacement_solution(H: np.ndarray, ubar: np.ndarray, constraints: Constraints, delta: float) -> np.ndarray:
    """The exact solution at approach ``delta`` within the box: Lawson-Hanson's unbounded
    solution, clipped to the box and taken by ``bvls`` to the bounded one."""
    p = exact_solution(H, ubar + delta).p
    if not constraints.bounded:
        return p
    return bvls(H, ubar + delta, constraints.upper, p).p


def constrained_solution_on_subset(qp: "QP", tol: float = CERTIFY_KKT) -> SubsetSolution:
    """The certified exact solution of a bounded or load-controlled ``qp`` whose H is
    positive definite on proper subsets only (a periodic whole grid, whose Cholesky fails
    on round-off): ``constrained_exact_solution`` on a growing proper subset
    (``lcp.exact_solution_on_subset``), the bounds restricted to it and the load kept.
    Raises as those do (``UncertifiedSolutionError``, ``UncertifiedConstrainedSolution``,
    ``ProblemInputError`` when a subset cannot carry the load)."""
    u = np.asarray(qp.ubar, dtype=np.float64)
    c = qp.constraints

    def solve(T: np.ndarray) -> tuple[np.ndarray, float | None]:
        sol = constrained_exact_solution(qp.H.submatrix(T, T), u[T], c.restrict(T), tol)
        return sol.p, (sol.multiplier if c.load_control else None)

    return exact_solution_on_subset(qp, tol=tol, solve=solve)


def constant_null_space(H: np.ndarray) -> bool:
    """H 1 = 0 to round-off (``NULL_SPACE_TOL``): a periodic kernel on the whole grid,
    its mean mode removed (module doc)."""
    scale = float(np.max(np.sum(np.abs(H), axis=1), initial=0.0))
    return bool(scale > 0.0 and float(np.max(np.abs(np.sum(H, axis=1)))) <= NULL_SPACE_TOL * scale)


def projected_gradient_guess(H: np.ndarray, ubar: np.ndarray, constraints: Constraints,
                             steps: int = GUESS_STEPS) -> np.ndarray:
    """A feasible approximate solution: FISTA (Beck & Teboulle 2009) with the projection
    onto the feasible set (``constraints.project_feasible``), step 1/L with L the largest
    row sum of |H| (Gershgorin: >= the largest eigenvalue), restarted whenever the
    momentum points uphill (O'Donoghue & Candes 2015), from the load spread evenly
    (without a load: p = 0).  ``steps`` gradient steps (matvecs)."""
    n = ubar.size
    lip = float(np.max(np.sum(np.abs(H), axis=1), initial=0.0)) or 1.0
    start = np.full(n, float(constraints.load) / n) if constraints.load_control else np.zeros(n)
    x = project_feasible(start, constraints)
    y, t = x, 1.0
    for _ in range(int(steps)):
        x_new = project_feasible(y - (H @ y - ubar) / lip, constraints)
        if float(np.dot(y - x_new, x_new - x)) > 0.0:  # gradient restart
            t, y = 1.0, x_new
        else:
            t_new = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * t * t))
            y, t = x_new + ((t - 1.0) / t_new) * (x_new - x), t_new
        x = x_new
    return x


@dataclass
class LoadActiveSetOutcome:
    """p, the multiplier Delta, the outer iterations (elements freed), inner steps (cuts at
    a bound; every step is one bordered solve) and whether it stopped with no element to
    free."""

    p: np.ndarray
    multiplier: float
    iterations: int
    inner: int
    converged: bool


def exchange_partner(g: np.ndarray, state: np.ndarray, j: int) -> int | None:
    """The element to free with ``j`` when no element is free (module doc): for j at 0 the
    one at u with the largest gap g (the most ready to shed force), for j at u the one at 0
    with the smallest; None when there is none.  Moving force from the partner to j lowers
    the objective by g_partner - g_j per unit, which is positive wherever no single
    multiplier holds both at their bounds."""
    other = S if state[j] == Z else Z
    cand = np.flatnonzero(state == other)
    if cand.size == 0:
        return None
    return int(cand[np.argmax(g[cand])] if other == S else cand[np.argmin(g[cand])])


def load_active_set(H: np.ndarray, ubar: np.ndarray, constraints: Constraints, p0: np.ndarray,
                    max_iter: int | None = None, tol: float = 1e-12) -> LoadActiveSetOutcome:
    """The primal active-set method on min 1/2 p'Hp - ubar'p, 0 <= p <= u, sum p = P
    (module doc, periodic load control) from ``p0`` projected onto the feasible set.
    Needs H positive definite on {sum d = 0} and a load.  An element is freed only when
    its gap violates by more than tol x u_s."""
    if not constraints.load_control:
        raise ValueError("load_active_set needs a load equality")
    load = float(constraints.load)  # type: ignore[arg-type]
    n = ubar.size
    u = constraints.upper_or_inf(n)
    u_s, _ = constrained_scales(ubar, float(np.max(np.diag(H))), constraints)
    p = project_feasible(np.asarray(p0, dtype=np.float64), constraints)
    state = np.where(p <= 0.0, Z, np.where(p >= u, S, F)).astype(np.int8)
    limit = 10 * n + 10 if max_iter is None else int(max_iter)
    inner = 0
    delta = math.nan
    for it in range(limit + 1):
        delta = math.nan
        while np.any(state == F):  # the free solution made feasible, as in ``bvls``
            z, delta = solve_on_sets(H, ubar, u, load, state)
            p, inside = _cut_to_box(p, z, u, state)
            inner += 1
            if inside:
                break
            delta = math.nan
        g = H @ p - ubar
        if not math.isfinite(delta):  # no free element: Delta is any value in a range
            delta = fit_multiplier(g, p, constraints.upper)
        w = g - delta
        score = np.where(state == Z, -w, np.where(state == S, w, 0.0))
        j = int(np.argmax(score))
        if score[j] <= tol * u_s or it == limit:
            return LoadActiveSetOutcome(p, delta, it, inner, bool(score[j] <= tol * u_s))
        partner = exchange_partner(g, state, j) if not np.any(state == F) else None
        state[j] = F
        if partner is not None:
            state[partner] = F
    return LoadActiveSetOutcome(p, delta, limit, inner, False)


def _periodic_load_controlled(H: np.ndarray, ubar: np.ndarray, constraints: Constraints,
                              tol: float) -> ConstrainedSolution:
    """Periodic load control (module doc): the active set from the projected-gradient
    guess, certified; else ``box_polish`` from its answer, certified.  ``rounds`` counts
    the bordered solves, ``solves`` (displacement-controlled solves) is 0."""
    act = load_active_set(H, ubar, constraints, projected_gradient_guess(H, ubar, constraints))
    sol = ConstrainedSolution(project_box(act.p, constraints.upper), act.multiplier, math.inf,
                              act.converged, act.inner)
    out = _certified(H, ubar, constraints, sol, tol)
    if out is not None:
        return out
    polished = box_polish(H, ubar, constraints, act.p, act.multiplier)
    polished.rounds += act.inner
    out = _certified(H, ubar, constraints, polished, tol)
    if out is None:
        raise UncertifiedConstrainedSolution(
            f"periodic load control: active set ({act.iterations} iterations, converged {act.converged}, kkt "
            f"{sol.kkt_error:.2e}) and polish (kkt {polished.kkt_error:.2e}) did not certify")
    return out


def constrained_exact_solution(H: np.ndarray, ubar: np.ndarray, constraints: Constraints,
                               tol: float = CERTIFY_KKT) -> ConstrainedSolution:
    """The certified exact solution (module doc) for a dense H, non-singular or (under
    load control) singular along the constant vector only (a periodic whole grid:
    ``load_active_set``); raises ``UncertifiedConstrainedSolution`` when nothing certifies."""
    H = np.asarray(H, dtype=np.float64)
    ubar = np.asarray(ubar, dtype=np.float64)
    constraints.check(ubar.size)
    if not constraints.load_control:
        sol = box_polish(H, ubar, constraints, _displacement_solution(H, ubar, constraints, 0.0))
        sol.solves = 1
        out = _certified(H, ubar, constraints, sol, tol)
        if out is None:
            raise UncertifiedConstrainedSolution(f"box polish did not certify (kkt {sol.kkt_error:.2e})")
        return out
    if constant_null_space(H):
        return _periodic_load_controlled(H, ubar, constraints, tol)
    return _load_controlled(H, ubar, constraints, tol)


def _load_controlled(H: np.ndarray, ubar: np.ndarray, constraints: Constraints, tol: float) -> ConstrainedSolution:
    """The load search of ``constrained_exact_solution`` (module doc): at each approach
    Delta tried, the displacement-controlled solution, then ``box_polish`` with the load row
    from it, returned as soon as one certifies.  The approaches: P(-max ubar) = 0, so the
    bracket starts at [-max ubar, -max ubar + u_s] and its upper end steps up, each step
    twice the bracket's width (``_bracket_step``), until P(hi) >= P; then regula falsi
    (Illinois, ``_falsi_step``).  It ends on a degenerate step -- a Delta not strictly
    inside the bracket (after the polish from the end it reached), a Delta tried already,
    a bracket end not finite -- or after ``MAX_MULTIPLIER_STEPS`` solves, raising
    ``UncertifiedConstrainedSolution``.  The polish, not the search, sets the answer's
    precision: a load far below the relief's force has its approach within round-off of
    -max ubar, where the search cannot resolve it, and the polish from there frees the
    elements the load reaches first (``box_polish``)."""
    load = float(constraints.load)  # type: ignore[arg-type]
    u_s, _ = _scales(H, ubar)
    lo, hi = -float(np.max(ubar)), -float(np.max(ubar)) + u_s
    f_lo, f_hi = -load, math.nan
    solves, side = 0, 0
    last: ConstrainedSolution | None = None
    delta, final = hi, False
    tried: set[float] = set()
    while solves < MAX_MULTIPLIER_STEPS and delta not in tried:
        solves += 1
        tried.add(delta)
        p = _displacement_solution(H, ubar, constraints, delta)
        last = box_polish(H, ubar, constraints, p, delta)
        out = _certified(H, ubar, constraints, last, tol)
        if out is not None:
            out.solves = solves
            return out
        if final:
            break
        fd = float(np.sum(p)) - load
        if delta == hi and not f_hi >= 0.0:  # the bracket's upper end, not yet above the load
            f_hi = fd
            if fd < 0.0:
                lo, f_lo, hi = hi, fd, _bracket_step(lo, hi)
                delta = hi
                if not math.isfinite(hi):
                    break
                continue
        elif fd > 0.0:
            hi, f_hi = delta, fd
            f_lo = f_lo / 2.0 if side == 1 else f_lo
            side = 1
        else:
            lo, f_lo = delta, fd
            f_hi = f_hi / 2.0 if side == -1 else f_hi
            side = -1
        delta = _falsi_step(lo, hi, f_lo, f_hi)
        final = not lo < delta < hi  # degenerate: the polish from the end it reached is the last
        delta = min(max(delta, lo), hi)
    raise UncertifiedConstrainedSolution(
        f"no certified solution for the load {load:g} after {solves} solves "
        f"(last kkt {math.inf if last is None else last.kkt_error:.2e})")


def _bracket_step(lo: float, hi: float) -> float:
    """The next upper end of a growing bracket [lo, hi]: hi + 2 (hi - lo), so that the
    next bracket [hi, hi + 2 (hi - lo)] is twice as wide (inf once it overflows)."""
    with np.errstate(over="ignore"):
        return float(np.float64(hi) + 2.0 * (np.float64(hi) - np.float64(lo)))


def _falsi_step(lo: float, hi: float, f_lo: float, f_hi: float) -> float:
    """The regula-falsi point of the bracket [lo, hi] with f_lo <= 0 <= f_hi: the root of
    the chord, written as a share of the width so that neither the products lo f_hi nor
    the difference f_hi - f_lo can overflow (a share of 0 or 1 gives an end itself)."""
    if f_hi <= 0.0:
        return hi
    share = 1.0 / (1.0 + (-f_lo) / f_hi)  # f_hi / (f_hi - f_lo)
    return hi - share * (hi - lo)


__all__ = ["BVLSOutcome", "CERTIFY_KKT", "ConstrainedSolution", "LoadActiveSetOutcome",
           "UncertifiedConstrainedSolution", "box_polish", "bvls", "constant_null_space",
           "constrained_exact_solution", "constrained_solution_on_subset", "exchange_partner", "load_active_set",
           "projected_gradient_guess", "solve_on_sets"]
