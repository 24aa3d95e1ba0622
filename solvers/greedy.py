"""Greedy methods (Bemporad & Paggi 2015, section 3.1, Algorithm 1).

Solve the unconstrained system H_II p_I = ubar_I on the current set I, drop every
element with p_j < -eps from I (tensile force), and repeat on the reduced set.  Three
variants for the unconstrained solve (paper: "Steps 2.1-2.4 can be replaced by any
other algorithm"):

* ``greedy-cg``   conjugate gradient (Algorithm 1 steps 2.1-2.4), warm started on each
                  pass from the previous pass's p_I; matrix-free (dense or FFT operator).
* ``greedy-gs``   Gauss-Seidel sweeps (as in Borri-Brunetto, Carpinteri & Chiaia, BCC),
                  block-row form; rows of H gathered with ``op.submatrix``.
* ``greedy-chol`` Cholesky of the dense block H_II on every pass (the paper's MATLAB
                  ``mldivide``); needs n^2 memory and raises ``MemoryBudgetError`` beyond
                  the budget.

**Intended method, not the printed loop.**  Read literally, Algorithm 1's outer loop tests
``min(p) < -eps`` only *after* step 2.5 has zeroed the negative entries, so it always
stops after one pass, with w_I != 0 on the reduced set.  What runs here is the intended
method: the reduced system is solved again after every removal, until a pass yields no
negative p (``info["passes"]`` counts the passes).

Hardness (``problems.constraints`` bounds): the saturation step.  A pass that leaves no
negative force fixes every element of I whose force exceeds its bound u_j at p_j = u_j (it
leaves I for the plastic set S, irreversibly, as a removal is; removals come first, since
an unconstrained solve with tensile elements still in I overshoots), and the reduced
system becomes
H_II p_I = ubar_I - H_IS u_S (one extra matvec per pass while S is not empty).  An
irreversible saturation can fix the wrong elements, so a loop that ends with plastic
elements claims convergence only where the scaled KKT error meets the tolerance
(``saturation_claim``).  Without bounds the method is unchanged.  No load control.

Greedy methods are not exact: nothing guarantees w >= 0 on the removed elements (the
paper's Example 1 is a counterexample), so ``Capabilities.exact`` is False.  No warm
start: eliminations are irreversible, so the paper's safe start is I = all, p = 0
(a supplied WarmStart is ignored, ``warm_started=False``).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import scipy.linalg as sla

from contactbench.problems.operators import ContactOperator, dense_nbytes, memory_budget

from ._kit import absolute_tol, cholesky_of_h, cholesky_solve, cholesky_seconds, conjugate_gradient, matvec_seconds
from .base import Capabilities, Deadline, Outcome, Param, ProblemTraits, SolveContext, Solver, Status
from .registry import register

#: The time models (``time_estimate``), all passes together.  ``greedy-cg``: about
#: ``CG_PRODUCTS_PER_ROOT4_N`` n^(1/4) products (paper sweep, cold: 106-718 at n = 86-35,218
#: on 128^2-512^2 grids, 35-52 n^(1/4)).  ``greedy-gs``: about ``GS_SWEEPS_PER_ROOT4_N``
#: n^(1/4) sweeps (124-512 at n = 86-2,227, 41-75 n^(1/4)), each costing about
#: ``GS_SWEEP_PRODUCTS`` dense products (its row blocks and their triangular solves: 3-11
#: measured).  ``greedy-chol``: ``CHOL_FACTORISATIONS`` Cholesky factors of the whole set
#: (4-7 passes on shrinking sets, 1.0-1.4 whole-set factors' time at n = 4,497-8,803).
CG_PRODUCTS_PER_ROOT4_N = 60.0
GS_SWEEPS_PER_ROOT4_N = 80.0
GS_SWEEP_PRODUCTS = 10.0
CHOL_FACTORISATIONS = 3.0


def root4(n: int) -> float:
    """n^(1/4), the growth of the greedy methods' work (``CG_PRODUCTS_PER_ROOT4_N``)."""
    return float(max(n, 1)) ** 0.25


@dataclass
class ReducedSolve:
    """Result of one unconstrained solve H_II x = ubar_I: ``broke_down`` when it stopped
    short of its tolerance for another reason than its limits (CG: no curvature along a
    direction; Cholesky: H_II not numerically positive definite), ``note`` why."""

    x: np.ndarray
    iterations: int
    converged: bool
    broke_down: bool = False
    note: str = ""


class GreedySolver(Solver):
    """Algorithm 1 (intended reading) with a pluggable unconstrained solve.

    Stops when a pass leaves no p_j < -tol p_s (``_kit.absolute_tol``); each pass's
    inner solve runs to ||ubar_I - H_II p_I||_inf <= tol u_s.  The trace records the
    scaled KKT error after every pass (one extra matvec per pass)."""

    family: ClassVar[str] = "paper"
    capabilities: ClassVar[Capabilities] = Capabilities(warm_start="none", exact=False, bounds=True)
    default_tol: ClassVar[float] = 1e-10
    #: The paper's Example 1 (``problems.instances.counterexample``, family
    #: "counterexample"): on about 40 % of its draws greedy stops with no negative p and
    #: a negative gap on a removed element, a wrong answer it claims.
    refuted_on: ClassVar[frozenset[str]] = frozenset({"counterexample"})
    params = (
        Param("max_passes", int, None, "outer passes at most (None: n + 1)", low=1),
        Param("literal_one_pass", bool, False, "stop after one pass, as Algorithm 1 is printed (a test aid)"),
    )

    def skip(self, traits: ProblemTraits) -> str | None:
        """Also a periodic grid whose trial set is the whole grid: the first pass solves
        H p = ubar on it, and H 1 = 0 there (the q = 0 mode removed), so that system has no
        solution unless ubar sums to 0 (greedy-gs ran to its time limit on it)."""
        why = super().skip(traits)
        if why:
            return why
        if traits.whole_periodic_grid:
            return (f"{self.name}'s first pass solves H p = ubar on the whole periodic grid, where H is singular "
                    "(H 1 = 0)")
        return None

    @abstractmethod
    def solve_reduced(self, ctx: SolveContext, op: ContactOperator, b: np.ndarray, x0: np.ndarray, atol: float,
                      max_iter: int) -> ReducedSolve:
        """Solve op x = b (op = H restricted to the current set I)."""

    def iterate(self, ctx: SolveContext) -> Outcome:
        """The passes (class doc).  Degenerate passes end the loop with an answer and an
        honest status: an empty set I is a pass with nothing negative (the method's own
        test passes); a reduced solve with non-finite entries, or one that broke down
        (``ReducedSolve.broke_down``), ends "stalled" at the last finite iterate."""
        qp = ctx.qp
        atol = absolute_tol(ctx, ctx.tol)
        max_passes = ctx.params["max_passes"] or qp.n + 1
        active = np.arange(qp.n)
        p = np.zeros(qp.n)
        u = ctx.constraints.upper_or_inf(qp.n)
        plastic = np.zeros(qp.n, dtype=bool)
        op: ContactOperator = qp.H
        total_it, passes, converged = 0, 0, False
        status, why = None, ""
        while passes < max_passes:
            passes += 1
            if active.size == 0:  # nothing left in I: no negative p, the method's stopping test
                converged = True
                break
            rhs = qp.ubar[active]
            if plastic.any():
                rhs = rhs - qp.H.matvec(np.where(plastic, u, 0.0))[active]
            red = self.solve_reduced(ctx, op, rhs, p[active], atol.disp, ctx.max_iter - total_it)
            total_it += red.iterations
            if not np.all(np.isfinite(red.x)) or red.broke_down:
                status = Status.STALLED
                why = (f"the reduced solve of pass {passes} {'gave non-finite forces' if red.broke_down is False else 'broke down'}"
                       f" ({red.note or 'no progress'}); the last finite iterate is returned")
                break
            p[:] = 0.0
            p[plastic] = u[plastic]
            p[active] = red.x
            negative = red.x < -atol.force
            over = (red.x > u[active] + atol.force) & ~negative.any()  # saturate once free of tension
            if not (negative.any() or over.any()):
                converged = red.converged
                break
            p[active[negative]] = 0.0  # step 2.5: zero tensile forces, shrink I
            p[active[over]] = u[active[over]]  # saturation: the plastic elements leave I at their bound
            plastic[active[over]] = True
            active = active[~(negative | over)]
            feasible = np.clip(p, 0.0, u)
            ctx.record(total_it, ctx.kkt(feasible, qp.H.matvec(feasible) - qp.ubar))
            if ctx.params["literal_one_pass"] or total_it >= ctx.max_iter or ctx.expired():
                break
            if active.size:
                op = ctx.track(qp.H.restrict(active))
        np.clip(p, 0.0, u, out=p)  # entries in (-eps, 0) count as zero, (u, u + eps) as u
        if converged and plastic.any():
            converged, status, why = saturation_claim(ctx, p, passes)
        ctx.info.update(method="greedy, repeated until no negative p (intended Algorithm 1)", passes=passes,
                        final_set_size=int(active.size), plastic=int(plastic.sum()))
        message = (why if status is not None else
                   f"no negative p after {passes} passes" if converged else f"stopped after {passes} passes")
        return Outcome(p, total_it, converged, message, status=status)


def saturation_claim(ctx: SolveContext, p: np.ndarray, passes: int) -> tuple[bool, Status | None, str]:
    """(converged, status, message) of a pass that ended the loop with plastic elements:
    the saturation is ours, not the paper's, and fixes elements irreversibly, so its end
    is claimed only where the scaled KKT error (``SolveContext.kkt``, one matvec) meets the
    tolerance; else "stalled" with that error (the plastic-sweep scene: 0.05-0.16)."""
    kkt = ctx.kkt(p, ctx.qp.H.matvec(p) - ctx.qp.ubar)
    if kkt <= ctx.tol:
        return True, None, ""
    return False, Status.STALLED, (f"no negative p after {passes} passes, but the irreversible saturation left a "
                                   f"scaled KKT error of {kkt:.3e} > tol")


@register
class GreedyCG(GreedySolver):
    """Greedy method with conjugate gradient (paper Algorithm 1, intended reading).

    Each pass runs CG (steps 2.1-2.4) on the reduced operator ``H.restrict(I)``, warm
    started from the previous pass's p_I.  Matrix-free: dense or FFT operator.
    Not exact (paper Example 1); no warm start across load steps."""

    name = "greedy-cg"
    description = "Greedy + CG (Algorithm 1, repeated to no negative p); not exact"

    def solve_reduced(self, ctx: SolveContext, op: ContactOperator, b: np.ndarray, x0: np.ndarray, atol: float,
                      max_iter: int) -> ReducedSolve:
        r = conjugate_gradient(op, b, x0, atol, max_iter, ctx.deadline)
        broke = not r.converged and r.iterations < max_iter and not ctx.expired()
        return ReducedSolve(r.x, r.iterations, r.converged, broke,
                            f"CG stopped at residual {r.residual:.3g} > {atol:.3g}" if broke else "")

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return CG_PRODUCTS_PER_ROOT4_N * root4(n) * matvec_seconds(n, operator_kind)


class RowBlocks:
    """Row blocks H[B, :] of a reduced operator: sliced from one dense copy when it fits
    the memory budget, else gathered from the kernel table block by block."""

    def __init__(self, op: ContactOperator, block: int, budget: float) -> None:
        self.op = op
        self.block = block
        self.dense = op.to_dense(budget) if dense_nbytes(op.n) <= budget else None

    def rows(self, s: int, e: int) -> np.ndarray:
        if self.dense is not None:
            return self.dense[s:e]
        return self.op.submatrix(np.arange(s, e), np.arange(self.op.n))

    def residual(self, b: np.ndarray, x: np.ndarray) -> np.ndarray:
        if self.dense is not None:
            return b - self.dense @ x
        return b - self.op.matvec(x)


def gauss_seidel(rows: RowBlocks, b: np.ndarray, x0: np.ndarray, atol: float, max_sweeps: int,
                 deadline: Deadline, check_every: int = 4) -> ReducedSolve:
    """Forward Gauss-Seidel sweeps on H x = b in block-row form: for each row block B,
    x_B <- tril(H_BB)^-1 (b_B - H_B,<B x_<B(new) - triu(H_BB, 1) x_B(old) - H_B,>B x_>B(old)),
    which is exactly
    point Gauss-Seidel.  Stops when ||b - Hx||_inf <= atol (checked every few sweeps)."""
    n = b.size
    x = x0.copy()
    sweeps = 0
    res = float(np.max(np.abs(rows.residual(b, x)))) if n else 0.0
    while res > atol and sweeps < max_sweeps and not deadline.expired():
        for s in range(0, n, rows.block):
            e = min(n, s + rows.block)
            R = rows.rows(s, e)
            D = R[:, s:e]
            rhs = b[s:e] - R[:, :s] @ x[:s] - R[:, e:] @ x[e:] - np.triu(D, 1) @ x[s:e]
            x[s:e] = sla.solve_triangular(D, rhs, lower=True, check_finite=False)
        sweeps += 1
        if sweeps % check_every == 0 or sweeps >= max_sweeps:
            res = float(np.max(np.abs(rows.residual(b, x))))
    return ReducedSolve(x, sweeps, res <= atol)


@register
class GreedyGS(GreedySolver):
    """Greedy method with Gauss-Seidel (paper section 3.1 / section 4, as in BCC).

    The unconstrained solve of each pass is forward Gauss-Seidel, warm started from the
    previous pass; one iteration = one sweep.  Rows come from ``op.submatrix`` (one dense
    copy of H_II when it fits the memory budget, else gathered per block on every sweep,
    so memory stays O(block x n)).  Not exact; no warm start."""

    name = "greedy-gs"
    description = "Greedy + Gauss-Seidel (BCC); not exact"
    time_scales_with_grid = False  # its sweeps read dense rows, whatever the FFT grid

    def solve_reduced(self, ctx: SolveContext, op: ContactOperator, b: np.ndarray, x0: np.ndarray, atol: float,
                      max_iter: int) -> ReducedSolve:
        rows = RowBlocks(op, block=256, budget=memory_budget() / 4)
        return gauss_seidel(rows, b, x0, atol, max_iter, ctx.deadline)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return GS_SWEEPS_PER_ROOT4_N * root4(n) * GS_SWEEP_PRODUCTS * matvec_seconds(n, "dense")


@register
class GreedyCholesky(GreedySolver):
    """Greedy method with a Cholesky solve (the paper's MATLAB ``mldivide``).

    Every pass gathers the dense block H_II with ``op.submatrix`` and factors it afresh
    (as mldivide does).  Needs n^2 memory: raises MemoryBudgetError over the budget (the
    paper: "lack of memory for n > 20000").  Not exact; no warm start."""

    name = "greedy-chol"
    description = "Greedy + Cholesky (mldivide); dense n^2; not exact"
    capabilities = Capabilities(warm_start="none", exact=False, needs_dense=True, bounds=True)
    time_scales_with_grid = False  # priced in Cholesky factors

    def memory_estimate(self, n: int) -> float:
        return float(dense_nbytes(n))

    def solve_reduced(self, ctx: SolveContext, op: ContactOperator, b: np.ndarray, x0: np.ndarray, atol: float,
                      max_iter: int) -> ReducedSolve:
        try:
            L = cholesky_of_h(op, what="greedy-chol: dense block H_II for the Cholesky factor")
        except np.linalg.LinAlgError as exc:  # H_II not numerically positive definite
            return ReducedSolve(x0, 1, False, True, f"Cholesky of H_II failed: {exc}")
        x = cholesky_solve(L, b)
        res = float(np.max(np.abs(b - op.matvec(x)))) if b.size else 0.0
        if not res <= atol:  # factored, but too near singular for its solve (a periodic whole grid: H 1 = 0)
            return ReducedSolve(x, 1, False, True, f"the Cholesky solve left a residual {res:.3g} > {atol:.3g}")
        return ReducedSolve(x, 1, True)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return CHOL_FACTORISATIONS * cholesky_seconds(n)
