"""fast-pdas: primal-dual active set / semismooth Newton with preconditioned CG on the
active set, matrix-free on the FFT operator.

The LCP  w = Hp - ubar >= 0, p >= 0, w'p = 0  (Bemporad & Paggi 2015, eq. (6)) is
written as the semismooth equation  min(p, c w) = 0  with c = 1/max diag H (scale
invariant).  A Newton step on it is the primal-dual active set step of Hintermueller,
Ito & Kunisch (SIAM J. Optim. 13, 2002):

    A = {i : p_i - c w_i > 0},   p_I = 0,   H_AA p_A = ubar_A,

so *every* point whose sign is wrong changes set at once (unlike Lawson-Hanson's one at
a time).  H_AA p_A = ubar_A is solved inexactly by CG on the FFT operator restricted to
A, warm-started from the current p_A, optionally preconditioned (param
``precondition``, default False: it measured slower here, see docs/fast-solvers.md)
with the inverse continuous Boussinesq kernel |q| E*/2 in Fourier space (Vollebregt,
J. Optim. Theory Appl. 162, 2014).  The inner tolerance tightens with the outer KKT
error (inexact Newton).  Safeguard: PDAS can cycle when H is not an M-matrix (the
half-space kernel is positive everywhere); if the scaled KKT error stops decreasing
the iterate is clipped to p >= 0 and finished by the Bugnicourt CCG (fast-dual-ccg).
Warm start: primal (WarmStart.p).
"""

from __future__ import annotations

import time

import numpy as np

from contactbench.problems.instances import QP

from ._fast_common import (
    begin_fast_solve,
    FAST_CAPABILITIES,
    fourier_inverse_preconditioner,
    iteration_limit,
    make_result,
    scaled_kkt,
    time_left,
)
from .base import SolveResult, Solver, SolverSettings, WarmStart
from .fast_ccg import FastBugnicourtCCG
from .registry import register


def pcg(matvec, b: np.ndarray, x0: np.ndarray, stop_abs: float, max_iter: int, precond=None) -> tuple[np.ndarray, int]:
    """Preconditioned CG for the SPD system on the active set; stops when
    max|b - Hx| <= stop_abs.  Returns (x, matvecs)."""
    x = x0.copy()
    r = b - matvec(x)
    mv = 1
    if np.max(np.abs(r), initial=0.0) <= stop_abs:
        return x, mv
    z = precond(r) if precond else r
    d = z.copy()
    rz = float(r @ z)
    for _ in range(max_iter):
        Hd = matvec(d)
        mv += 1
        dHd = float(d @ Hd)
        if dHd <= 0.0:
            break
        alpha = rz / dHd
        x += alpha * d
        r -= alpha * Hd
        if np.max(np.abs(r)) <= stop_abs:
            break
        z = precond(r) if precond else r
        rz_new = float(r @ z)
        d = z + (rz_new / rz) * d
        rz = rz_new
    return x, mv


@register
class FastPDAS(Solver):
    """Primal-dual active set (semismooth Newton) + CG on the active set (see module doc)."""

    name = "fast-pdas"
    family = "fast"
    description = "primal-dual active set / semismooth Newton, CG on the active set (FFT operator), CCG safeguard"
    capabilities = FAST_CAPABILITIES

    def memory_estimate(self, n: int) -> float:
        return 12.0 * 8.0 * n

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        s = begin_fast_solve(qp, settings, warm)
        tol, state, trace, diag_max = s.tol, s.state, s.trace, s.diag_max
        use_m = bool(settings.param("precondition", False))
        max_outer = int(settings.param("max_outer", 50))
        inner_max = iteration_limit(settings, qp.n)
        extra_mv, outer, kkt = 0, 0, scaled_kkt(state.p, state.g, qp.ubar, diag_max)
        best, stall = kkt, 0
        A_prev = None
        t0 = time.perf_counter()
        while kkt > tol and outer < max_outer and time_left(t0, settings):
            outer += 1
            A = np.flatnonzero(state.p * diag_max - state.g > 0.0)
            if A.size == 0:
                A = np.flatnonzero(state.g < 0.0)
            if A_prev is not None and np.array_equal(A, A_prev) and np.all(state.p[A] >= 0):
                stall += 1
            sub = qp.H.restrict(A)
            u_s = max(float(np.max(np.abs(qp.ubar))), float(np.max(np.abs(state.g + qp.ubar))))
            stop = u_s * max(0.2 * tol, min(1e-2, 0.05 * kkt))
            M = fourier_inverse_preconditioner(QP(sub, qp.ubar[A])) if use_m else None
            xA, mv = pcg(sub.matvec, qp.ubar[A], state.p[A], stop, inner_max, M)
            extra_mv += mv
            state.p = np.zeros(qp.n)
            state.p[A] = xA
            state.refresh()
            kkt = scaled_kkt(state.p, state.g, qp.ubar, diag_max)
            trace.record(outer, kkt)
            A_prev = A
            if kkt < 0.5 * best:
                best, stall = kkt, 0
            else:
                stall += 1
            if stall >= 3:
                break
        info = {"outer_iterations": outer, "inner_matvecs": extra_mv, "finished_by_ccg": False}
        if kkt > tol or np.any(state.p < 0):
            state.p = np.maximum(state.p, 0.0)
            state.refresh()
            ccg = FastBugnicourtCCG()
            it, kkt = ccg._iterate(state, qp.ubar, diag_max, tol, inner_max, settings, trace)
            info.update(finished_by_ccg=True, ccg_iterations=it)
        res = make_result(state, iterations=outer, kkt=kkt, tol=tol, trace=trace, matvecs0=s.matvecs0,
                          warm_started=s.warm_started, setup_time=s.setup, info=info)
        res.matvecs += extra_mv
        return res
