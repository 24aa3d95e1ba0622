"""Accelerated gradient projection on the primal QP (Bemporad & Paggi 2015, section 3.3.1,
Algorithm 4), alone (``gp``) and as the warm start of NNLS (``nnls-gp``).

    s = p + beta_i (p - p_prev),  beta_i = max((i - 1)/(i + 2), 0)
    p_prev = p;  p = max(s - (Hs - ubar)/L, 0)

L must bound lambda_max(H): ``lipschitz="frobenius"`` is the paper's ||H||_F (safe but up
to sqrt(n) too large, so steps are short); ``lipschitz="power"`` is lambda_max from a
few power iterations (inflated 1 %).  Under bounds or a load equality (``gp`` only) the
projection is onto the box and the equality (``problems.constraints.project_feasible``:
the load by bisection on a shift), the same iteration otherwise.  ``info["lipschitz"]`` records which, and
``info["L"]`` its value.  Optional ``restart=True`` resets the momentum when it points
uphill (O'Donoghue & Candes 2015) -- not in the paper, off by default.

``gp`` runs to the scaled KKT error of ``contactbench.problems.kkt`` (checked every
``check_every`` iterations, one extra matvec) or max_iter: a first-order method, not exact.
``nnls-gp`` runs exactly K GP steps (param ``K``, default 100 as in the paper's
section 4; Fig. 6 sweeps K = 0..200, the solver's ``grid``) and then NNLS (Algorithm 3)
from the GP point: exact.  Both accept a primal warm start (GP starts from it).

Under bounds or a load equality, NNLS's exact active-set step becomes its bounded form:
the K GP steps project onto the box and the equality, and block principal pivoting on the
three sets (p = 0, free, p = u) with the load row (``problems.mixed_lcp.box_polish``, the
same rule as the reference's) finishes from the GP point on the dense H; it stops on a
violation-free set, so the answer is exact.  That needs the n x n H within the memory
budget: above it the solver skips with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from contactbench.problems.constraints import fit_multiplier, project_feasible
from contactbench.problems.mixed_lcp import box_polish
from contactbench.problems.operators import dense_nbytes, memory_budget

from ._kit import lipschitz_constant, matvec_seconds
from ._scaling import dense_matrix
from .base import Capabilities, Outcome, Param, ProblemTraits, SolveContext, Solver, Status
from .nnls import FACTOR_MAX_N, LINEAR_PARAM, NNLS_CG_PRODUCTS, nnls_active_set, nnls_max_iter
from .registry import register

LIPSCHITZ_PARAM = Param("lipschitz", str, "frobenius", "bound of lambda_max(H): ||H||_F (paper) or power iteration",
                        choices=("frobenius", "power"))
RESTART_PARAM = Param("restart", bool, False, "adaptive momentum restart (O'Donoghue & Candes; not in the paper)")
#: Paper Fig. 6: the numbers K of gradient-projection steps before NNLS.
GP_K_VALUES: tuple[int, ...] = (0, 10, 25, 50, 100, 150, 200)


@dataclass
class GPOutcome:
    p: np.ndarray
    iterations: int
    converged: bool
    restarts: int
    diverged: bool = False  # a check met a non-finite scaled KKT error


def accelerated_gradient_projection(ctx: SolveContext, p0: np.ndarray, L: float, K: int, tol: float | None = None,
                                    check_every: int = 10, restart: bool = False) -> GPOutcome:
    """Algorithm 4 for at most K iterations, and never past the solve's deadline (checked
    at every iteration: K is the user's, 10^30 included); with ``tol``, stop early once
    the scaled KKT error of p (``ctx.kkt``, one extra matvec) is <= tol, checked and
    recorded every ``check_every`` iterations.  A non-finite error at a check ends the
    loop (``diverged``)."""
    op, ubar = ctx.qp.H, ctx.qp.ubar
    project = projection_of(ctx)
    p = p0.copy()
    p_prev = p.copy()
    j, restarts = 0, 0  # j: momentum counter (reset by restarts)
    for i in range(K):
        beta = max((j - 1) / (j + 2), 0.0)
        s = p + beta * (p - p_prev)  # step 2.2
        w = op.matvec(s) - ubar  # step 2.3
        p_prev = p  # step 2.4
        p = project(s - w / L)  # step 2.5
        j += 1
        if restart and float((s - p) @ (p - p_prev)) > 0.0:
            j, restarts = 0, restarts + 1
        if tol is not None and (i + 1) % check_every == 0:
            res = ctx.kkt(p, op.matvec(p) - ubar)
            ctx.record(i + 1, res)
            if res <= tol:
                return GPOutcome(p, i + 1, True, restarts)
            if not math.isfinite(res):
                return GPOutcome(p, i + 1, False, restarts, diverged=True)
        if ctx.expired():
            return GPOutcome(p, i + 1, False, restarts)
    return GPOutcome(p, K, False, restarts)


def projection_of(ctx: SolveContext) -> Callable[[np.ndarray], np.ndarray]:
    """Step 2.5's projection: onto p >= 0 (the paper's), or onto the box and the load
    equality of the QP's constraints (``problems.constraints.project_feasible``)."""
    c = ctx.constraints
    if c.plain:
        return lambda x: np.maximum(x, 0.0)
    return lambda x: project_feasible(x, c)


def lipschitz_of(ctx: SolveContext) -> float:
    """L of Algorithm 4 by the ``lipschitz`` parameter, recorded in ``ctx.info``."""
    method = ctx.params["lipschitz"]
    L = lipschitz_constant(ctx.qp.H, method)
    ctx.info.update(lipschitz=method, L=L)
    return L


def bounded_finish(ctx: SolveContext, p: np.ndarray, gp_steps: int, max_rounds: int) -> Outcome:
    """NNLS's exact step under bounds and a load row (module doc): block principal pivoting
    from the GP point ``p`` on the dense H, at most ``max_rounds`` rounds (at least one);
    iterations = ``gp_steps`` + pivoting rounds.  Converged
    when pivoting reached a violation-free set *and* the answer's scaled KKT error
    (``SolveContext.kkt``, at the pivoting's multiplier under a load) meets the tolerance,
    as the plain NNLS claims; a set whose solve round-off leaves it above is "stalled"."""
    H = dense_matrix(ctx.qp)
    c = ctx.constraints
    ctx.mark_setup_done()
    delta0 = fit_multiplier(H @ p - ctx.qp.ubar, p, c.upper) if c.load_control else 0.0
    try:
        sol = box_polish(H, ctx.qp.ubar, c, p, delta0, max_rounds=max(1, max_rounds))
    except np.linalg.LinAlgError as exc:  # a block of H (or the bordered load system) numerically singular
        ctx.info.update(gp_iterations=gp_steps, pivoting_rounds=0)
        return Outcome(p, gp_steps, False, f"block pivoting broke down on a singular system ({exc}); the GP point is "
                       "returned", status=Status.STALLED)
    ctx.info.update(gp_iterations=gp_steps, pivoting_rounds=sol.rounds)
    multiplier = sol.multiplier if c.load_control else None
    if not sol.converged:
        return Outcome(sol.p, gp_steps + sol.rounds, False, "block pivoting did not reach a violation-free set",
                       multiplier=multiplier)
    kkt = ctx.kkt(sol.p, H @ sol.p - ctx.qp.ubar, multiplier)  # a violation-free set, to round-off: the claim
    if kkt <= ctx.tol:
        return Outcome(sol.p, gp_steps + sol.rounds, True, multiplier=multiplier)
    return Outcome(sol.p, gp_steps + sol.rounds, False, f"block pivoting reached a violation-free set at a scaled KKT "
                   f"error of {kkt:.3e}, above tol", status=Status.STALLED, multiplier=multiplier)


#: ``gp``'s products grow like sqrt(n) (accelerated gradient steps ~ sqrt(cond H), and
#: cond H ~ sqrt(n) for the half-space kernels): 28-117 x sqrt(n), median 65, over the
#: 60 answered solves of the committed tables (n = 7-8,803, cold and warm), where a flat
#: 5,000 had predicted 94 s for a 0.014 s first step of ``plastic-sweep``.  The time
#: model's typical count (``harness.run.skips``).
GP_PRODUCTS_PER_ROOT_N = 65.0


#: ``nnls-gp``'s NNLS additions after its K gradient-projection steps, per unknown: cold
#: paper-sweep steps took 1-15 at n = 1,163-8,803 (128^2, 256^2) and 253 at the 512^2 top
#: step (n = 35,218, results/claims), 0.0017-0.0072 n; with a margin.
NNLS_GP_ADDITIONS_PER_UNKNOWN = 0.01


def typical_gp_products(n: int) -> float:
    """The products a typical ``gp`` solve of n unknowns takes (``GP_PRODUCTS_PER_ROOT_N``)."""
    return GP_PRODUCTS_PER_ROOT_N * float(np.sqrt(max(n, 1)))


def start_point(ctx: SolveContext) -> np.ndarray:
    return np.zeros(ctx.n) if ctx.p0 is None else ctx.p0


@register
class GradientProjection(Solver):
    """Accelerated gradient projection on the primal QP (paper section 3.3.1,
    Algorithm 4) run until the scaled KKT error (``SolveContext.kkt``, checked every
    ``check_every`` iterations) is <= tol.  Params: lipschitz = frobenius | power,
    restart, check_every.  Not exact (first order); warm start: primal."""

    name = "gp"
    family = "paper"
    description = "Accelerated gradient projection (Algorithm 4), Frobenius or power-iteration L"
    capabilities = Capabilities(warm_start="primal", exact=False, load_control=True, bounds=True)
    default_tol = 1e-6
    params = (LIPSCHITZ_PARAM, RESTART_PARAM,
              Param("check_every", int, 10, "iterations between two KKT checks (one matvec each)", low=1))

    def default_max_iter(self, n: int) -> int:
        return 50_000

    def iterate(self, ctx: SolveContext) -> Outcome:
        L = lipschitz_of(ctx)
        ctx.mark_setup_done()
        out = accelerated_gradient_projection(ctx, start_point(ctx), L, ctx.max_iter, tol=ctx.tol,
                                              check_every=ctx.params["check_every"], restart=ctx.params["restart"])
        ctx.info["restarts"] = out.restarts
        if out.diverged:  # H not numerically SPD (or L below its lambda_max), an overflow: no usable answer
            return Outcome(out.p, out.iterations, False, f"diverged: non-finite scaled KKT error at iteration "
                           f"{out.iterations}", status=Status.FAILED)
        return Outcome(out.p, out.iterations, out.converged)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return typical_gp_products(n) * matvec_seconds(n, operator_kind)


@register
class NNLSGP(Solver):
    """NNLS warm started by K accelerated GP steps (paper section 3.3.1: Algorithm 4 then
    Algorithm 3; Fig. 6 sweeps K, ``grid``).  Params: K (default 100, the paper's
    section 4), lipschitz, restart, linear (NNLS step 6).  iterations = GP steps + NNLS
    iterations, and ``max_iter`` limits that sum: the GP steps are min(K, max_iter), NNLS
    has the rest (none left: the GP point, status max_iter).  The default limit leaves NNLS
    its own default (``nnls_max_iter``) after the largest K of the grid.  Exact; warm
    start: primal (the GP steps start from it)."""

    name = "nnls-gp"
    family = "paper"
    description = "K accelerated GP steps then NNLS (Algorithms 4 + 3); K param, default 100"
    capabilities = Capabilities(warm_start="primal", exact=True, load_control=True, bounds=True)
    default_tol = 1e-10
    params = (Param("K", int, 100, "gradient-projection steps before NNLS", low=0),
              LIPSCHITZ_PARAM, RESTART_PARAM, LINEAR_PARAM)
    grid = {"K": GP_K_VALUES}

    def default_max_iter(self, n: int) -> int:
        return nnls_max_iter(n) + max(GP_K_VALUES)

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why or not (traits.load_control or traits.bounded):
            return why
        need = dense_nbytes(traits.n)
        if need > memory_budget():
            return (f"{self.name} poses bounds and a load row on the dense H: n = {traits.n} needs "
                    f"{need / 2**30:.3g} GiB, over the memory budget of {memory_budget() / 2**30:.3g} GiB")
        return None

    def iterate(self, ctx: SolveContext) -> Outcome:
        K, limit = ctx.params["K"], int(ctx.max_iter)
        steps = min(K, limit)
        p = start_point(ctx)
        if not ctx.constraints.plain:
            p = project_feasible(p, ctx.constraints)
        if steps > 0:
            p = accelerated_gradient_projection(ctx, p, lipschitz_of(ctx), steps, restart=ctx.params["restart"]).p
        if steps == limit:
            ctx.info.update(K=K, gp_iterations=steps, nnls_iterations=0)
            return Outcome(p, steps, False, f"max_iter {limit} spent on the gradient-projection steps",
                           status=Status.MAX_ITER)
        if not ctx.constraints.plain:
            ctx.info.update(K=K)
            return bounded_finish(ctx, p, steps, limit - steps)
        out = nnls_active_set(ctx, p, limit - steps, ctx.params["linear"], it_offset=steps)
        ctx.info.update(K=K, gp_iterations=steps, nnls_iterations=out.iterations)
        out.iterations += steps
        return out

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """K = 100 gradient-projection products, then ``NNLS_GP_ADDITIONS_PER_UNKNOWN`` n NNLS
        additions (``NNLS.time_estimate``'s cost each)."""
        per = matvec_seconds(n, operator_kind) * (1 if operator_kind == "dense" or n <= FACTOR_MAX_N else NNLS_CG_PRODUCTS)
        return 100 * matvec_seconds(n, operator_kind) + NNLS_GP_ADDITIONS_PER_UNKNOWN * n * per
