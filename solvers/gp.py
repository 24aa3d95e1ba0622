"""Accelerated gradient projection on the primal QP (Bemporad & Paggi 2015, section 3.3.1,
Algorithm 4), alone (``gp``) and as the warm start of NNLS (``nnls-gp``).

    s = p + beta_i (p - p_prev),  beta_i = max((i - 1)/(i + 2), 0)
    p_prev = p;  p = max(s - (Hs - ubar)/L, 0)

L must bound lambda_max(H): ``lipschitz="frobenius"`` is the paper's ||H||_F (safe but up
to sqrt(n) too large, so steps are short); ``lipschitz="power"`` is lambda_max from a
few power iterations (inflated 1 %).  ``info["lipschitz"]`` records which, and
``info["L"]`` its value.  Optional ``restart=True`` resets the momentum when it points
uphill (O'Donoghue & Candes 2015) -- not in the paper, off by default.

``gp`` runs to the scale-invariant KKT residual (checked every ``check_every``
iterations, one extra matvec) or max_iter: a first-order method, not exact.
``nnls-gp`` runs exactly K GP steps (param ``K``, default 100 as in the paper's
section 4; Fig. 6 sweeps 0..200) and then NNLS (Algorithm 3) from the GP point: exact.
Both accept a primal warm start (GP starts from it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactbench.problems.instances import QP

from ._common import (
    PrimalWarmSolver,
    EXACT_TOL,
    FIRST_ORDER_TOL,
    RunRecorder,
    Scales,
    lipschitz_constant,
    matvec_seconds,
    max_iter_of,
    natural_residual,
)
from .base import Capabilities, SolveResult, SolverSettings, WarmStart
from .nnls import FACTOR_MAX_N, nnls_active_set
from .registry import register


@dataclass
class GPOutcome:
    p: np.ndarray
    iterations: int
    converged: bool
    restarts: int


def accelerated_gradient_projection(
    qp: QP, p0: np.ndarray, L: float, K: int, rec: RunRecorder,
    tol: float | None = None, check_every: int = 10, restart: bool = False,
) -> GPOutcome:
    """Algorithm 4 for at most K iterations; with ``tol``, stop early once the natural
    residual of p is <= tol (checked every ``check_every`` iterations)."""
    sc = Scales.of(qp) if tol is not None else None
    op, ubar = qp.H, qp.ubar
    p = p0.copy()
    p_prev = p.copy()
    j, restarts = 0, 0  # j: momentum counter (reset by restarts)
    for i in range(K):
        beta = max((j - 1) / (j + 2), 0.0)
        s = p + beta * (p - p_prev)  # step 2.2
        w = op.matvec(s) - ubar  # step 2.3
        p_prev = p  # step 2.4
        p = np.maximum(s - w / L, 0.0)  # step 2.5
        j += 1
        if restart and float((s - p) @ (p - p_prev)) > 0.0:
            j, restarts = 0, restarts + 1
        if sc is not None and (i + 1) % check_every == 0:
            res = natural_residual(p, op.matvec(p) - ubar, sc)
            rec.record(i + 1, res)
            if res <= tol:
                return GPOutcome(p, i + 1, True, restarts)
            if rec.deadline.expired():
                return GPOutcome(p, i + 1, False, restarts)
    return GPOutcome(p, K, False, restarts)


def lipschitz_of(qp: QP, settings: SolverSettings, rec: RunRecorder) -> float:
    method = str(settings.param("lipschitz", "frobenius"))
    L = lipschitz_constant(qp.H, method)
    rec.info.update(lipschitz=method, L=L)
    return L


@register
class GradientProjection(PrimalWarmSolver):
    """Accelerated gradient projection on the primal QP (paper Algorithm 4) run to
    tolerance.  Params: lipschitz = frobenius | power, restart, check_every.
    Not exact (first order); warm start: primal."""

    name = "gp"
    family = "paper"
    description = "Accelerated gradient projection (Algorithm 4), Frobenius or power-iteration L"
    capabilities = Capabilities(warm_start="primal", exact=False)

    def run(self, qp: QP, settings: SolverSettings, warm: WarmStart | None, rec: RunRecorder,
            p0: np.ndarray | None) -> SolveResult:
        L = lipschitz_of(qp, settings, rec)
        rec.mark_setup_done()
        out = accelerated_gradient_projection(
            qp, np.zeros(qp.n) if p0 is None else p0, L, max_iter_of(settings, 50_000), rec,
            tol=settings.tolerance(FIRST_ORDER_TOL), check_every=int(settings.param("check_every", 10)),
            restart=bool(settings.param("restart", False)))
        rec.info["restarts"] = out.restarts
        status, message = rec.stop_status(out.converged)
        return rec.result(out.p, out.iterations, out.converged, status, message, p0 is not None)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 5000 * matvec_seconds(n, operator_kind)


@register
class NNLSGP(PrimalWarmSolver):
    """NNLS warm started by K accelerated GP steps (paper section 3.3.1: Algorithm 4 then
    Algorithm 3).  Params: K (default 100), lipschitz, restart, linear (NNLS step 6).
    Exact; warm start: primal (the GP steps start from it)."""

    name = "nnls-gp"
    family = "paper"
    description = "K accelerated GP steps then NNLS (Algorithms 4 + 3); K param, default 100"
    capabilities = Capabilities(warm_start="primal", exact=True)

    def run(self, qp: QP, settings: SolverSettings, warm: WarmStart | None, rec: RunRecorder,
            p0: np.ndarray | None) -> SolveResult:
        K = int(settings.param("K", 100))
        if K < 0:
            raise ValueError(f"nnls-gp: K (GP iterations) must be >= 0, got {K}")
        p = np.zeros(qp.n) if p0 is None else p0
        if K > 0:
            L = lipschitz_of(qp, settings, rec)
            gp = accelerated_gradient_projection(qp, p, L, K, rec, restart=bool(settings.param("restart", False)))
            p = gp.p
        out = nnls_active_set(qp, p, settings.tolerance(EXACT_TOL), max_iter_of(settings, 5 * qp.n + 100),
                              str(settings.param("linear", "auto")), rec)
        rec.info.update(K=K, gp_iterations=K, nnls_iterations=out.iterations)
        status, _ = rec.stop_status(out.converged)
        return rec.result(out.p, K + out.iterations, out.converged, status, out.message, p0 is not None, out.w)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        per = matvec_seconds(n, operator_kind) * (1 if operator_kind == "dense" or n <= FACTOR_MAX_N else 30)
        return 100 * matvec_seconds(n, operator_kind) + 0.05 * n * per
