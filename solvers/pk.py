"""Constrained conjugate gradient of Polonsky & Keer (1999), displacement control
(Bemporad & Paggi 2015, section 3.2, Algorithm 2).

Each iteration: a conjugate direction t on the current contact set S (t = 0 off S),
the exact line step tau = (w_S't_S) / (t'Ht), projection onto p >= 0, and re-entry of
the points with zero force and negative gap (I_ol, where the conjugacy is reset, d = 0).
Two matvecs per iteration (H t and the fresh w = Hp - ubar).

Reading of the printed algorithm: w, t and the inner products are restricted to the
contact set S = {p > 0} of the previous iteration (as in P&K's paper); the first
iteration uses the initial trial domain.  The printed stopping test (relative change of
||w||) is replaced by the shared scale-invariant KKT residual (``natural_residual``),
which is what "convergence" must mean for the harness.

Warm start (paper: "both an initial trial contact domain and a set of contact
pressures"): p from the previous step and its support as the first domain.  Cold
start: p = 0 with the whole trial set as the domain.  Exact (converges to round-off);
matrix-free (dense or FFT operator).
"""

from __future__ import annotations

import numpy as np

from contactbench.problems.instances import QP

from ._common import EXACT_TOL, RunRecorder, Scales, matvec_seconds, max_iter_of, natural_residual, warm_primal
from .base import Capabilities, SolveResult, Solver, SolverSettings, WarmStart
from .registry import register

TYPICAL_PK_ITERATIONS = 300


def polonsky_keer(qp: QP, p0: np.ndarray, domain: np.ndarray, tol: float, max_iter: int,
                  rec: RunRecorder) -> tuple[np.ndarray, np.ndarray, int, bool]:
    """Algorithm 2 from p0 >= 0 with initial domain ``domain`` (bool mask).
    Returns p, w, iterations, converged (natural residual <= tol)."""
    sc = Scales.of(qp)
    op, ubar = qp.H, qp.ubar
    p = p0.copy()
    w = op.matvec(p) - ubar
    S = domain.copy()
    t = np.zeros(qp.n)
    G_old, d = 1.0, 0.0
    res = natural_residual(p, w, sc)
    i = 0
    while res > tol and i < max_iter and not rec.deadline.expired():
        g = np.where(S, w, 0.0)
        G = float(g @ g)
        if G == 0.0:  # S is at rest but points with p = 0 became overlapping after the
            S = (p > 0.0) | (w < 0.0)  # last step: let them in, restart the conjugacy
            g, d = np.where(S, w, 0.0), 0.0
            G = float(g @ g)
            if G == 0.0:
                break
        t = g + (d * G / G_old) * np.where(S, t, 0.0)  # step 3.1
        r = op.matvec(t)
        tau = float(g @ t) / float(r @ t)  # step 3.2
        p -= tau * t  # step 3.3
        np.maximum(p, 0.0, out=p)  # step 3.4
        overlap = (p == 0.0) & (w < 0.0)  # step 3.5
        d = 0.0 if overlap.any() else 1.0
        p[overlap] -= tau * w[overlap]
        S = p > 0.0  # step 3.6
        G_old = G  # step 3.7
        w = op.matvec(p) - ubar  # step 3.8
        res = natural_residual(p, w, sc)
        i += 1
        rec.record(i, res)
    return p, w, i, res <= tol


@register
class PolonskyKeer(Solver):
    """Constrained CG (Polonsky & Keer 1999; paper Algorithm 2), displacement control.

    Warm start: previous p and its support as the initial trial domain.  Exact;
    matrix-free; two matvecs per iteration."""

    name = "pk"
    family = "paper"
    description = "Polonsky-Keer constrained CG (Algorithm 2), warm start of p and domain"
    capabilities = Capabilities(warm_start="primal", exact=True)

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        rec = RunRecorder(qp, settings)
        p0 = warm_primal(warm, qp.n)
        warm_started = p0 is not None and bool(np.any(p0 > 0.0))
        trivial = rec.trivial(warm_started)
        if trivial is not None:
            return trivial
        if warm_started:
            domain = p0 > 0.0
        else:
            p0, domain = np.zeros(qp.n), np.ones(qp.n, dtype=bool)
        rec.info["initial_domain"] = int(domain.sum())
        p, w, it, ok = polonsky_keer(qp, p0, domain, settings.tolerance(EXACT_TOL),
                                     max_iter_of(settings, 100_000), rec)
        status, message = rec.stop_status(ok)
        return rec.result(p, it, ok, status, message, warm_started, w)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 2 * TYPICAL_PK_ITERATIONS * matvec_seconds(n, operator_kind)
