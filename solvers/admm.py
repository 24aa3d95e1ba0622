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
rho = 1 has units of stiffness [force/length] and is meaningless unless H is of order
one, so the effective rho is rho * mean(diag H) (recorded in ``info["rho"]``).  With
``rho_relative=False`` rho is taken as given.  alpha defaults to 1.5 (paper).

(H/rho + I)^-1: a Cholesky factor computed once per solve for a dense operator (n^2
memory); CG warm started from the previous s for the matrix-free operator (param
``linear`` = auto | cholesky | cg).  Stopping (scale-invariant): primal residual
||s - p||_inf / p_s <= tol (the paper's test) and dual residual
rho ||p - p_prev||_inf / u_s <= tol.  Not exact; warm start: primal and dual.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg as sla

from contactbench.problems.instances import QP
from contactbench.problems.operators import check_dense_budget

from ._common import (
    PrimalWarmSolver,
    FIRST_ORDER_TOL,
    RunRecorder,
    Scales,
    conjugate_gradient,
    is_dense,
    matvec_seconds,
    max_iter_of,
)
from .base import Capabilities, SolveResult, SolverSettings, WarmStart
from .registry import register

TYPICAL_ADMM_ITERATIONS = 1000


def resolvent(qp: QP, rho: float, linear: str, atol: float, rec: RunRecorder) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """x -> (H/rho + I)^-1 x: cached Cholesky (dense) or warm-started CG (matrix-free)."""
    op = qp.H
    if linear == "auto":
        linear = "cholesky" if is_dense(op) else "cg"
    rec.info["linear_solver"] = linear
    if linear == "cholesky":
        check_dense_budget(op.n, what="admm: Cholesky factor of H/rho + I")
        idx = np.arange(op.n)
        A = np.array(op.submatrix(idx, idx), dtype=np.float64, copy=True)
        A /= rho
        A[np.diag_indices_from(A)] += 1.0
        factor = sla.cho_factor(A, lower=True, overwrite_a=True, check_finite=False)
        return lambda v, x0: sla.cho_solve(factor, v, check_finite=False)
    if linear == "cg":
        counter = {"cg_iterations": 0}
        rec.info["inner_cg"] = counter

        def solve_cg(v: np.ndarray, x0: np.ndarray) -> np.ndarray:
            r = conjugate_gradient(op, v, x0, atol, 1000, rec.deadline, scale=1.0 / rho, shift=1.0)
            counter["cg_iterations"] += r.iterations
            return r.x

        return solve_cg
    raise ValueError(f"admm: linear must be 'auto', 'cholesky' or 'cg', got {linear!r}")


@register
class ADMM(PrimalWarmSolver):
    """ADMM with over-relaxation (paper Algorithm 5).  Params: rho (default 1, relative to
    mean diag H), rho_relative, alpha (default 1.5), linear.  Warm start: primal-dual."""

    name = "admm"
    family = "paper"
    description = "ADMM scaled form, alpha=1.5, rho relative to mean diag(H) (Algorithm 5)"
    capabilities = Capabilities(warm_start="primal-dual", exact=False)

    def run(self, qp: QP, settings: SolverSettings, warm: WarmStart | None, rec: RunRecorder,
            p0: np.ndarray | None) -> SolveResult:
        sc = Scales.of(qp)
        tol = settings.tolerance(FIRST_ORDER_TOL)
        alpha = float(settings.param("alpha", 1.5))
        rho = float(settings.param("rho", 1.0))
        if not (rho > 0.0 and 0.0 < alpha < 2.0):
            raise ValueError(f"admm: need rho > 0 and 0 < alpha < 2, got rho={rho}, alpha={alpha}")
        if bool(settings.param("rho_relative", True)):
            rho *= float(np.mean(qp.H.diagonal()))
        rec.info.update(rho=rho, alpha=alpha)
        apply_m = resolvent(qp, rho, str(settings.param("linear", "auto")), 1e-2 * tol * sc.p_s, rec)
        rec.mark_setup_done()
        p = np.zeros(qp.n) if p0 is None else p0.copy()
        u = self._initial_scaled_dual(qp, p, warm, rho) if p0 is not None else np.zeros(qp.n)
        s = p.copy()
        max_iter = max_iter_of(settings, 10_000)
        converged, i = False, 0
        while i < max_iter and not rec.deadline.expired():
            s = apply_m(p - u + qp.ubar / rho, s)  # 5.1
            s_hat = alpha * s + (1.0 - alpha) * p  # 5.2
            p_prev = p
            p = np.maximum(s_hat + u, 0.0)  # 5.3
            u += s_hat - p  # 5.4
            i += 1
            r_primal = float(np.max(np.abs(s - p))) / sc.p_s
            r_dual = rho * float(np.max(np.abs(p - p_prev))) / sc.u_s
            rec.record(i, max(r_primal, r_dual))
            if r_primal <= tol and r_dual <= tol:
                converged = True
                break
        if "inner_cg" in rec.info:
            rec.info["inner_cg_iterations"] = rec.info.pop("inner_cg")["cg_iterations"]
        status, message = rec.stop_status(converged)
        return rec.result(p, i, converged, status, message, p0 is not None)

    @staticmethod
    def _initial_scaled_dual(qp: QP, p: np.ndarray, warm: WarmStart | None, rho: float) -> np.ndarray:
        """u = -w/rho from the warm dual w, or from w = Hp - ubar when none is given."""
        w = None if warm is None or warm.w is None else np.asarray(warm.w, dtype=np.float64)
        if w is None or w.shape != p.shape:
            w = qp.H.matvec(p) - qp.ubar
        return -w / rho

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        per = matvec_seconds(n, "dense") if operator_kind == "dense" else 20 * matvec_seconds(n, "fft")
        return TYPICAL_ADMM_ITERATIONS * per
