"""ADMM, scaled form with over-relaxation (Bemporad & Paggi 2015, section 3.4,
Algorithm 5; Boyd et al. 2011, section 3.4.3).

Splitting p = s with g(s) the indicator of s >= 0 (the paper's roles: s unconstrained,
p projected), scaled dual u = w_rho:

    s = (H/rho + I)^-1 (p - u + ubar/rho)          (5.1)
    s_hat = alpha s + (1 - alpha) p                (5.2)
    p = max(s_hat + u, 0)                          (5.3)
    u = u + s_hat - p                              (5.4)

Note: the printed step 5.1 has ``- ubar/rho``; minimising the augmented Lagrangian
1/2 s'Hs - ubar's + rho/2 ||s - p + u||^2 gives ``+ ubar/rho`` (used here).  At the
solution u = -w/rho with w = Hp - ubar (paper step 2), so a dual warm start w gives u.

rho: ``rho`` is *relative* to mean(diag H) by default (``rho_relative=True``): the paper's
rho = 1 has the units of H, a compliance [length/force] (rho/2 ||p - s||^2 is an energy),
and is meaningless unless H is of order one, so the effective rho is rho * mean(diag H)
(recorded in ``info["rho"]``).  With ``rho_relative=False`` rho is taken as given, in
the table's units (SI: m/N; the paper does not state its units).  alpha defaults to 1.5
(paper).

(H/rho + I)^-1: a Cholesky factor computed once per solve for a dense operator (n^2
memory); CG warm started from the previous s for the matrix-free operator (param
``linear`` = auto | cholesky | cg).  Stopping (param ``stop``): ``kkt`` (the default),
the scaled KKT error of p (``SolveContext.kkt``, one extra matvec, every ``check_every``
iterations) <= tol: p >= 0 holds at every iterate, so the error is zero exactly at the
solution; ``printed``, the paper's rule (tex 951: while (i <= K_max and
||p - s||_inf > eps) or i = 0), ||p - s||_inf <= tol in the units of p (force), s the
output of step 5.1, no product -- a small primal residual, not a KKT test, so the harness's
judge decides whether the answer is right.  Not exact; warm start: primal and dual.

Bounds and load control: step 5.3 projects onto the QP's feasible set
(``problems.constraints.project_feasible``: the box, and the load by bisection on a
shift); ADMM needs only a closed convex set there.  At the solution Hp - ubar = -rho u,
the approach Delta is fitted from it by the lifecycle.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ._kit import (absolute_tol, cholesky_of_h, cholesky_seconds, cholesky_solve, conjugate_gradient, is_dense,
                   matvec_seconds)
from .gp import projection_of
from .base import Capabilities, Outcome, Param, ParamError, SolveContext, Solver, Status, WarmStart
from .registry import register

#: ``admm``'s time model (``typical_admm_iterations``, ``ADMM.time_estimate``): a cold solve
#: at its default tolerance takes about ``ADMM_ITERATIONS_PER_ROOT_N`` sqrt(n) iterations
#: (cold paper-sweep steps: 22-135 iterations, 1.9-2.4 sqrt(n), at n = 86-4,497 on 128^2 and
#: 256^2 grids; 82 at n = 1,881 on 512^2), and on the matrix-free operator each iteration
#: takes about ``ADMM_PRODUCTS_PER_ITERATION`` products (the resolvent's warm-started CG and
#: the KKT check: 15-26 measured there, growing with n); on the dense operator two products'
#: worth (the Cholesky solve and the check) after one factorisation.
ADMM_ITERATIONS_PER_ROOT_N = 2.5
ADMM_PRODUCTS_PER_ITERATION = 25
#: The smallest normal float: the effective penalty must be at least this (and finite).
NORMAL_MIN = float(np.finfo(np.float64).tiny)
#: The stopping rules (module doc).
STOPS: tuple[str, ...] = ("kkt", "printed")
#: ADMM as the paper states it: alpha 1.5 and rho = 1 as given, in H's units (sec. 4, tex
#: 1027-1029), stopped on Algorithm 5's printed ||p - s||_inf <= eps (tex 951).
PAPER_PARAMS: dict[str, float | bool | str] = {"alpha": 1.5, "rho": 1.0, "rho_relative": False, "stop": "printed"}
#: CG iterations at most per resolvent application (matrix-free operator).
RESOLVENT_CG_MAX_ITER = 1000

Resolvent = Callable[[np.ndarray, np.ndarray], np.ndarray]


#: The least residual, in units of eps ||v||_inf, the resolvent's CG is asked for: the
#: round-off of (H/rho + I) x, whose eigenvalues are >= 1.  A tolerance below it (tol 1e-15)
#: left every inner solve to run to its stagnation window: 28 s for an 8-unknown problem.
RESOLVENT_ROUND_OFF = 16.0


def resolvent(ctx: SolveContext, rho: float, linear: str, atol: float) -> Resolvent:
    """(v, x0) -> (H/rho + I)^-1 v: cached Cholesky (dense) or CG warm started from x0 to
    the residual ``atol``, never below ``RESOLVENT_ROUND_OFF`` eps ||v||_inf."""
    op = ctx.qp.H
    if linear == "auto":
        linear = "cholesky" if is_dense(op) else "cg"
    ctx.info["linear_solver"] = linear
    if linear == "cholesky":
        L = cholesky_of_h(op, scale=1.0 / rho, shift=1.0, what="admm: Cholesky factor of H/rho + I")
        return lambda v, x0: cholesky_solve(L, v)
    ctx.info["inner_cg_iterations"] = 0

    def solve_cg(v: np.ndarray, x0: np.ndarray) -> np.ndarray:
        floor = RESOLVENT_ROUND_OFF * float(np.finfo(np.float64).eps) * float(np.max(np.abs(v), initial=0.0))
        r = conjugate_gradient(op, v, x0, max(atol, floor), RESOLVENT_CG_MAX_ITER, ctx.deadline, scale=1.0 / rho,
                               shift=1.0)
        ctx.info["inner_cg_iterations"] += r.iterations
        return r.x

    return solve_cg


#: The paper's iteration limit for ADMM (section 4: K_max = 3e3).
KMAX = 3000


def checked_rho_alpha(params: dict[str, float]) -> tuple[float, float]:
    """(rho, alpha) with rho > 0 and 0 < alpha < 2 (the declared ranges are closed)."""
    rho, alpha = params["rho"], params["alpha"]
    if not (rho > 0.0 and 0.0 < alpha < 2.0):
        raise ParamError(f"admm: need rho > 0 and 0 < alpha < 2, got rho={rho}, alpha={alpha}")
    return rho, alpha


@register
class ADMM(Solver):
    """ADMM with over-relaxation (paper section 3.4, Algorithm 5), stopped on the scaled
    KKT error of p, or on the paper's ||p - s||_inf (``stop="printed"``).  Params: rho
    (default 1, relative to mean diag H), rho_relative, alpha (default 1.5), linear,
    check_every, stop.  Not exact; warm start: primal-dual
    (u = -w/rho).  At most ``KMAX`` iterations unless the harness sets ``max_iter``."""

    name = "admm"
    family = "paper"
    description = "ADMM scaled form, alpha=1.5, rho relative to mean diag(H) (Algorithm 5)"
    #: first-order: promised to its default tolerance (it reaches 1e-8 too slowly for the
    #: battery's time limit on the high-profile cases)
    capabilities = Capabilities(warm_start="primal-dual", exact=False, promise=1e-6, load_control=True, bounds=True)
    default_tol = 1e-6
    params = (
        Param("rho", float, 1.0, "penalty (> 0); relative to mean diag H unless rho_relative is False", low=0.0,
              open="low"),
        Param("rho_relative", bool, True, "rho is a multiple of mean diag H (the paper's rho = 1 has units)"),
        Param("alpha", float, 1.5, "over-relaxation, 0 < alpha < 2", low=0.0, high=2.0, open="both"),
        Param("linear", str, "auto", "(H/rho + I)^-1 by a cached Cholesky factor, CG, or auto (Cholesky when dense)",
              choices=("auto", "cholesky", "cg")),
        Param("check_every", int, 1, "iterations between two KKT checks (one matvec each)", low=1),
        Param("stop", str, "kkt", "the scaled KKT error <= tol (kkt), or the paper's ||p - s||_inf <= tol "
              "in force units (printed, tex 951)", choices=STOPS),
    )

    def default_max_iter(self, n: int) -> int:
        return KMAX

    def iterate(self, ctx: SolveContext) -> Outcome:
        qp, tol = ctx.qp, ctx.tol
        rho, alpha = checked_rho_alpha(ctx.params)
        if ctx.params["rho_relative"]:
            rho *= float(np.mean(qp.H.diagonal()))
        if not (NORMAL_MIN <= rho < math.inf):  # (a subnormal or overflowing penalty divides by 0 or inf below)
            raise ParamError(f"admm: the penalty rho = {ctx.params['rho']:g}"
                             f"{' x mean diag H' if ctx.params['rho_relative'] else ''} is {rho:g}, outside the "
                             f"normal floats [{NORMAL_MIN:g}, inf); give another rho")
        ctx.info.update(rho=rho, alpha=alpha)
        apply_m = resolvent(ctx, rho, ctx.params["linear"], absolute_tol(ctx, 1e-2 * tol).force)
        ctx.mark_setup_done()
        p = ctx.first_p()
        u = np.zeros(qp.n) if ctx.p0 is None else initial_scaled_dual(ctx, p, rho)
        s = p.copy()
        project = projection_of(ctx)
        check_every, printed = ctx.params["check_every"], ctx.params["stop"] == "printed"
        converged, i, w, status, message = False, 0, None, None, ""
        while i < ctx.max_iter and not ctx.expired():
            s = apply_m(p - u + qp.ubar / rho, s)  # 5.1
            s_hat = alpha * s + (1.0 - alpha) * p  # 5.2
            p = project(s_hat + u)  # 5.3
            u += s_hat - p  # 5.4
            i += 1
            w = None
            if printed:
                gap = float(np.max(np.abs(p - s), initial=0.0))
                if gap <= tol:
                    converged, message = True, f"||p - s||_inf {gap:.3g} <= {tol:g} after {i} iterations"
                    break
                if not math.isfinite(gap):
                    status, message = Status.FAILED, f"diverged: non-finite ||p - s||_inf at iteration {i}"
                    break
            elif i % check_every == 0:
                w = qp.H.matvec(p) - qp.ubar
                res = ctx.kkt(p, w)
                ctx.record(i, res)
                if res <= tol:
                    converged = True
                    break
                if not math.isfinite(res):  # diverged (H not numerically SPD, an overflow): no usable answer
                    status, message = Status.FAILED, f"diverged: non-finite scaled KKT error at iteration {i}"
                    break
        return Outcome(p, i, converged, message, w=w, status=status)

    def memory_estimate(self, n: int) -> float:
        """The dense path's Cholesky factor of H/rho + I (n^2 floats) and six vectors (the
        matrix-free path needs the vectors only; the estimate is the larger)."""
        return 8.0 * n * n + 6 * 8.0 * n

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """``typical_admm_iterations`` iterations: on the dense operator one Cholesky factor
        and two dense products an iteration, else ``ADMM_PRODUCTS_PER_ITERATION`` products."""
        iterations = typical_admm_iterations(n)
        if operator_kind == "dense":
            return cholesky_seconds(n) + iterations * 2 * matvec_seconds(n, "dense")
        return iterations * ADMM_PRODUCTS_PER_ITERATION * matvec_seconds(n, "fft")


def typical_admm_iterations(n: int) -> float:
    """The iterations a typical cold ``admm`` solve of n unknowns takes
    (``ADMM_ITERATIONS_PER_ROOT_N``)."""
    return ADMM_ITERATIONS_PER_ROOT_N * float(np.sqrt(max(n, 1)))


def initial_scaled_dual(ctx: SolveContext, p: np.ndarray, rho: float) -> np.ndarray:
    """u = -w/rho from the warm dual w, or from w = Hp - ubar when none (or none of
    length n) is given."""
    warm: WarmStart | None = ctx.warm
    w = None if warm is None or warm.w is None else np.asarray(warm.w, dtype=np.float64)
    if ctx.constraints.load_control:
        w = None  # a warm w there is Hp - ubar - Delta; u needs Hp - ubar
    if w is None or w.shape != p.shape or not np.all(np.isfinite(w)):
        w = ctx.qp.H.matvec(p) - ctx.qp.ubar
    return -w / rho
