"""Polonsky-Keer constrained conjugate gradients (fast-ccg) and the Bugnicourt et al.
constrained CG without restart (fast-dual-ccg), both matrix-free on the FFT operator.

fast-ccg
    Polonsky & Keer, Wear 231 (1999) 206, displacement-controlled form: CG on the
    contact set S = {p > 0} with the gap g = Hp - ubar as residual; after each step
    p < 0 is clipped to 0, points with p = 0 and g < 0 (penetration) enter with the
    force -tau g, and conjugacy is reset (delta = 0) whenever a point entered.
fast-dual-ccg
    Bugnicourt, Sainsot, Dureisseix, Gauthier & Lubrecht, Tribol. Lett. 66 (2018) 29,
    algorithm OUT_LIN: projected CG on the pixel forces (ContactMechanics calls this
    the "dual" objective: variable = force, gradient = gap) with a Polak-Ribiere
    beta and *no restart*; the residual is the gap with admissible multipliers
    (g >= 0 where p = 0) removed.

fast-pccg, fast-dual-pccg
    the same two iterations with the CG direction preconditioned on the current free
    set (z = M^-1 r instead of r): by default the exact inverses of H over the
    contact islands (solvers/_preconditioners.py), or Vollebregt's Fourier |q|
    preconditioner (params={"precondition": "fourier"}).  Any of the four accepts
    params={"precondition": "islands" | "fourier" | "none"}.

All minimise the paper's QP (Bemporad & Paggi 2015, eq. (5)): min 1/2 p'Hp - ubar'p,
p >= 0.  One matvec per iteration while the projection is inactive (the gap is
updated as g += alpha H d), two when it clips.  Warm start: primal (WarmStart.p).
The stopping test is the harness's scaled KKT error (unit-invariant), confirmed on a
freshly recomputed gap.
"""

from __future__ import annotations

import time

import numpy as np

from contactbench.problems.instances import QP

from ._fast_common import (
    FAST_CAPABILITIES,
    GapState,
    begin_fast_solve,
    iteration_limit,
    make_result,
    scaled_kkt,
    time_left,
)
from ._preconditioners import MAX_BLOCK, SetPreconditioner, make_preconditioner
from .base import Solver, SolveResult, SolverSettings, Trace, WarmStart
from .registry import register


class _FastCG(Solver):
    family = "fast"
    capabilities = FAST_CAPABILITIES
    #: "islands", "fourier" or "none"; overridable per run by params["precondition"].
    default_precondition = "none"

    def memory_estimate(self, n: int) -> float:
        # Eight vectors; with the island preconditioner, block inverses of up to
        # MAX_BLOCK entries per point of the set (the set can be the whole trial set early).
        blocks = 8.0 * MAX_BLOCK * n if self.default_precondition == "islands" else 0.0
        return 8.0 * 8.0 * n + blocks

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        s = begin_fast_solve(qp, settings, warm)
        M = make_preconditioner(settings.param("precondition", self.default_precondition), qp)
        it, kkt = self._iterate(s.state, qp.ubar, s.diag_max, s.tol, iteration_limit(settings, qp.n), settings,
                                s.trace, M)
        info = {"preconditioner_builds": M.builds} if M is not None else {}
        return make_result(s.state, iterations=it, kkt=kkt, tol=s.tol, trace=s.trace, matvecs0=s.matvecs0,
                           warm_started=s.warm_started, setup_time=s.setup, info=info)

    def _iterate(self, state: GapState, ubar: np.ndarray, diag_max: float, tol: float, max_iter: int,
                 settings: SolverSettings, trace: Trace, M: SetPreconditioner | None = None) -> tuple[int, float]:
        raise NotImplementedError


def precondition_on(M: SetPreconditioner | None, r: np.ndarray, free: np.ndarray) -> np.ndarray:
    """z = M^-1 r on the free set (M moved to that set first when it changed); r itself
    without a preconditioner."""
    if M is None:
        return r
    if not np.array_equal(free, M.on):
        M.update(free)
    return M.apply(r)


def converged_now(state: GapState, ubar: np.ndarray, diag_max: float, tol: float) -> tuple[bool, float]:
    """Scaled KKT test on the running gap, confirmed on a recomputed one."""
    kkt = scaled_kkt(state.p, state.g, ubar, diag_max)
    if kkt > tol:
        return False, kkt
    state.refresh()
    kkt = scaled_kkt(state.p, state.g, ubar, diag_max)
    return kkt <= tol, kkt


@register
class FastPolonskyKeer(_FastCG):
    """Polonsky-Keer CCG (1999) with warm start, FFT operator (see module doc)."""

    name = "fast-ccg"
    description = "Polonsky-Keer constrained CG on the FFT operator, warm-started (Wear 1999)"

    def _iterate(self, state, ubar, diag_max, tol, max_iter, settings, trace, M=None):
        H = state.H
        t = np.zeros_like(state.p)
        G_old, reset = 1.0, True
        t0 = time.perf_counter()
        kkt = np.inf
        for it in range(1, max_iter + 1):
            ok, kkt = converged_now(state, ubar, diag_max, tol)
            trace.record(it - 1, kkt)
            if ok or not time_left(t0, settings):
                return it - 1, kkt
            S = state.p > 0.0
            if not np.any(S):  # nothing in contact: the most penetrating points enter
                S = state.g < 0.0
            r = np.where(S, state.g, 0.0)
            z = precondition_on(M, r, S)
            G = float(r @ z)
            t = z if reset or G_old == 0.0 else np.where(S, z + (G / G_old) * t, 0.0)
            q = H.matvec(t)
            tq = float(t @ q)
            if tq <= 0.0:
                state.refresh()
                reset = True
                continue
            tau = float(r @ t) / tq
            p_new = state.p - tau * t
            entering = (state.p == 0.0) & (state.g < 0.0) & ~S
            p_new[entering] = -tau * state.g[entering]
            clipped = p_new < 0.0
            p_new[clipped] = 0.0
            if np.any(entering) or np.any(clipped):
                state.p = p_new
                state.refresh()
            else:
                state.p = p_new
                state.g -= tau * q
            reset = bool(np.any(entering))
            G_old = G
        return max_iter, kkt


@register
class FastBugnicourtCCG(_FastCG):
    """Bugnicourt et al. (2018) constrained CG without restart (see module doc)."""

    name = "fast-dual-ccg"
    description = "Bugnicourt et al. 2018 constrained CG without restart on the forces (ContactMechanics' 'dual'), FFT operator"

    def _iterate(self, state, ubar, diag_max, tol, max_iter, settings, trace, M=None):
        H = state.H
        res = self._residual(state)
        z = precondition_on(M, res, res != 0.0)
        d = -z
        t0 = time.perf_counter()
        kkt = np.inf
        for it in range(1, max_iter + 1):
            ok, kkt = converged_now(state, ubar, diag_max, tol)
            trace.record(it - 1, kkt)
            if ok or not time_left(t0, settings):
                return it - 1, kkt
            Hd = H.matvec(d)
            dHd = float(d @ Hd)
            if dHd <= 0.0:  # d = 0 (converged up to round-off) or lost conjugacy: restart
                state.refresh()
                res = self._residual(state)
                z = precondition_on(M, res, res != 0.0)
                d = -z
                if not np.any(d):
                    return it, scaled_kkt(state.p, state.g, ubar, diag_max)
                continue
            alpha = -float(res @ d) / dHd
            state.step(alpha, d, Hd)
            res_old = res
            res = self._residual(state)
            z = precondition_on(M, res, res != 0.0)
            # Polak-Ribiere (preconditioned: z = M^-1 res); alpha d'Hd = -res_old'd.
            beta = float(z @ (res - res_old)) / (alpha * dHd)
            d = -z + beta * d
            d[(state.p == 0.0) & (res == 0.0)] = 0.0
        return max_iter, kkt

    @staticmethod
    def _residual(state: GapState) -> np.ndarray:
        """Gap with the admissible multipliers (p = 0, g >= 0) removed."""
        return np.where((state.p <= 0.0) & (state.g >= 0.0), 0.0, state.g)


@register
class FastPolonskyKeerIslands(FastPolonskyKeer):
    """Polonsky-Keer CCG with the island block-Jacobi preconditioner (solvers/_preconditioners.py):
    the CG direction on the contact set S is z = B_S^-1 r with B_S the blocks of H over the
    8-connected islands of S (cut at 128 points), refactored when S drifts by 20 %.
    Same fixed point and KKT test as fast-ccg; warm start: primal.  Without grid
    positions (QP.geometry) it runs unpreconditioned."""

    name = "fast-pccg"
    description = "Polonsky-Keer CCG preconditioned by exact inverses of the contact islands' blocks, FFT operator"
    default_precondition = "islands"


@register
class FastBugnicourtIslands(FastBugnicourtCCG):
    """Bugnicourt et al. (2018) CCG without restart, with the island block-Jacobi
    preconditioner on the free set {res != 0} (Polak-Ribiere beta on z = B^-1 res).
    Warm start: primal."""

    name = "fast-dual-pccg"
    description = "Bugnicourt et al. 2018 CCG preconditioned by exact inverses of the contact islands' blocks, FFT operator"
    default_precondition = "islands"
