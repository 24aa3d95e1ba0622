"""fast-pdas: primal-dual active set / semismooth Newton with (preconditioned) CG on the
active set, matrix-free on the FFT operator.

The LCP  w = Hp - ubar >= 0, p >= 0, w'p = 0  (Bemporad & Paggi 2015, eq. (6)) is
written as the semismooth equation  min(p, c w) = 0  with c = 1/max diag H (scale
invariant).  A Newton step on it is the primal-dual active set step of Hintermueller,
Ito & Kunisch (SIAM J. Optim. 13, 2002):

    A = {i : p_i - c w_i > 0},   p_I = 0,   H_AA p_A = ubar_A,

so *every* point whose sign is wrong changes set at once (unlike Lawson-Hanson's one at
a time).  H_AA p_A = ubar_A is solved inexactly by ``_kit.conjugate_gradient`` on the
operator restricted to A, warm-started from the current p_A, optionally preconditioned
(param ``precondition``, default "none": "fourier", Vollebregt's |q| E*/2, measured
slower here, see docs/fast-solvers.md; or "islands"; both from
``_preconditioners.make_preconditioner``).  The inner tolerance tightens with the outer
KKT error (inexact Newton).  With ``precision="mixed"`` the step is one round of
iterative refinement: the residual r_A = ubar_A - H_AA p_A in float64 (one restricted
float64 matvec), the CG on the float32 operator (``ContactOperator.with_precision``) for
the correction H_AA d = r_A from d = 0, p_A += d; the outer Newton loop is the
refinement loop, and its KKT test is float64 (solvers/_refine.py).  Safeguard: PDAS can
cycle when H is not an M-matrix (the half-space kernel is positive everywhere); if the
scaled KKT error stops decreasing, or ``max_outer`` steps pass, the iterate is clipped to p >= 0 and finished by the Bugnicourt
CCG (``_ccg.bugnicourt``, as fast-dual-ccg) under the same deadline (one time limit per
solve).  Iterations = Newton steps + CCG iterations.  A whole-grid (periodic) problem is
solved on the points that can touch and proved on the whole grid (``screening="safe"``,
solvers/_screen.py).  Warm start: primal (``ctx.p0``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from contactbench.problems.kkt import kkt_figures
from contactbench.problems.operators import ContactOperator

from ._ccg import CCGRun, FastSolver, GapState, bugnicourt, outcome
from ._device import cold_if_worse
from ._refine import block_dtype, low_precision, precision_param, resolved_precision, solve_in_precision
from ._kit import conjugate_gradient
from ._preconditioners import KINDS, SetPreconditioner, make_preconditioner, on_subset
from ._screen import screening_param
from .base import Outcome, Param, SolveContext
from .registry import register

#: Outer steps without halving the KKT error before the CCG takes over.
STALL_STEPS = 3


def active_set(state: GapState, diag_max: float) -> np.ndarray:
    """A = {p - c w > 0}, c = 1/max diag H (the points that penetrate when p = 0)."""
    A = np.flatnonzero(state.p * diag_max - state.g > 0.0)
    return A if A.size else np.flatnonzero(state.g < 0.0)


@dataclass
class StepMatvecs:
    """Matvecs of the Newton steps' CGs by precision (restricted operators)."""

    float64: int = 0
    float32: int = 0


def newton_step(ctx: SolveContext, state: GapState, A: np.ndarray, kkt: float, M: SetPreconditioner | None,
                H32: ContactOperator | None, count: StepMatvecs) -> None:
    """p_A <- H_AA^-1 ubar_A (inexact CG from the current p_A; with ``H32``: on the
    float32 correction, module doc), p = 0 off A; the CG's matvecs go to ``count``."""
    qp = ctx.qp
    u_s = kkt_figures(state.p, state.g, qp.ubar, ctx.diag_max).u_scale
    atol = u_s * max(0.2 * ctx.tol, min(1e-2, 0.05 * kkt))
    precond = on_subset(M, A, qp.n) if M is not None else None
    H_AA = qp.H.restrict(A)
    if H32 is None:
        cg = conjugate_gradient(H_AA, qp.ubar[A], state.p[A], atol, ctx.max_iter, deadline=ctx.deadline,
                                precond=precond)
        count.float64 += cg.matvecs
        p_A = cg.x
    else:
        r_A = qp.ubar[A] - H_AA.matvec(state.p[A])  # the round's float64 residual
        cg = conjugate_gradient(H32.restrict(A), r_A, None, atol, ctx.max_iter, deadline=ctx.deadline,
                                precond=precond)
        count.float64 += 1
        count.float32 += cg.matvecs
        p_A = state.p[A] + cg.x
    state.p = np.zeros(qp.n)
    state.p[A] = p_A
    state.refresh()


def iteration_limits(max_outer: int, max_iter: int | None, outer: int = 0) -> tuple[int, int | None]:
    """(Newton steps allowed, iterations left to the CCG after ``outer`` Newton steps): the
    Newton steps stop at ``min(max_outer, max_iter)``, and the CCG gets ``max_iter - outer``
    (None: no limit), so that Newton steps and CCG iterations together never pass
    ``max_iter``."""
    if max_iter is None:
        return max_outer, None
    return min(max_outer, max_iter), max(0, max_iter - outer)


@register
class FastPDAS(FastSolver):
    """Primal-dual active set (semismooth Newton; Hintermueller, Ito & Kunisch 2002) + CG
    on the active set, CCG safeguard (see module doc).  Warm start: primal."""

    name = "fast-pdas"
    description = "primal-dual active set / semismooth Newton, CG on the active set (FFT operator), CCG safeguard"
    params = (
        Param("precondition", str, "none", "inner CG preconditioner on the active set", choices=KINDS),
        Param("max_outer", int, 50, "active-set (Newton) steps before the CCG safeguard takes over", low=1),
        precision_param(),
        screening_param(),
    )

    #: The products of a typical cold solve (``FastSolver.typical_matvecs``;
    #: results/perf/cost-law.md: 173-463 at 256^2-4096^2, 3-4x the preconditioned CCGs').
    typical_matvecs = 200.0

    def memory_estimate(self, n: int) -> float:
        return 12.0 * 8.0 * n

    def iterate_on(self, ctx: SolveContext) -> Outcome:
        """Newton steps on ``ctx``'s QP as it is (``FastSolver.iterate`` screens it first)."""
        before = ctx.matvecs()
        state = GapState.start(ctx)
        dropped = cold_if_worse(ctx, state)
        precision = resolved_precision(ctx.params["precision"], ctx.qp)
        M = make_preconditioner(ctx.params["precondition"], ctx.qp, block_dtype(precision))
        H32 = low_precision(ctx.qp.H) if precision == "mixed" else None
        ctx.mark_setup_done()
        count = StepMatvecs()
        outer, kkt = 0, ctx.kkt(state.p, state.g)
        best, stall = kkt, 0
        A_prev: np.ndarray | None = None
        newton_limit, _ = iteration_limits(ctx.params["max_outer"], ctx.max_iter)
        while kkt > ctx.tol and outer < newton_limit and not ctx.expired():
            outer += 1
            A = active_set(state, ctx.diag_max)
            if A_prev is not None and np.array_equal(A, A_prev) and np.all(state.p[A] >= 0):
                stall += 1
            newton_step(ctx, state, A, kkt, M, H32, count)
            kkt = ctx.kkt(state.p, state.g)
            ctx.record(outer, kkt)
            A_prev = A
            if kkt < 0.5 * best:
                best, stall = kkt, 0
            else:
                stall += 1
            if stall >= STALL_STEPS:
                break
        ctx.add_matvecs(count.float64 + count.float32)
        info = {**dropped, "outer_iterations": outer, "inner_matvecs": count.float64 + count.float32,
                "inner_matvecs_float32": count.float32, "finished_by_ccg": False}
        run = CCGRun(outer, kkt, kkt <= ctx.tol and not np.any(state.p < 0.0))
        if not run.converged and np.any(state.p < 0.0):
            np.maximum(state.p, 0.0, out=state.p)
            state.refresh()
        _, left = iteration_limits(ctx.params["max_outer"], ctx.max_iter, outer)
        if not run.converged and not ctx.expired() and left != 0:  # finish with the CCG, same deadline
            ccg, more = solve_in_precision(replace(ctx, max_iter=left), state, bugnicourt, None, first=outer)
            info.update(finished_by_ccg=True, ccg_iterations=ccg.iterations, ccg_matvecs_by_precision=more)
            run = CCGRun(outer + ccg.iterations, ccg.kkt, ccg.converged, ccg.stalled)
        if M is not None:
            info["preconditioner_builds"] = M.builds
        float32 = count.float32 + int(info.get("ccg_matvecs_by_precision", {}).get("matvecs_float32", 0))
        info.update(precision="mixed" if H32 is not None else "double", matvecs_float32=float32,
                    matvecs_float64=ctx.matvecs() - before - float32)
        return outcome(state, run, info)
