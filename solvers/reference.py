"""``scipy-nnls``: the classical baseline and the harness's default reference solver.

It runs ``contactbench.problems.lcp.exact_solution`` -- the one implementation of the
exact LCP solution -- on the equilibrated problem (``solvers._scaling``): with the
Cholesky factor H~ = L L',

    1/2 p'H~p - u~'p = 1/2 || L'p - L^{-1} u~ ||^2 - 1/2 ||L^{-1} u~||^2,

so the contact QP (Bemporad & Paggi 2015, eq. (6)) is the non-negative least-squares
problem  min ||A p - b||, p >= 0  with A = L', b = L^{-1} u~, solved by
``scipy.optimize.nnls`` (the Lawson-Hanson active-set method, Lawson & Hanson 1974,
ch. 23, which the paper's section 4 also relates to).  Lawson-Hanson terminates finitely
with an exact solve on its final active set, hence ``exact=True``.  Block principal
pivoting (``bpp_polish``) then checks and, if needed, repairs that active set, so the
reference is at round-off.  ``max_iter`` caps Lawson-Hanson (default
``default_nnls_max_iter(n)``); at that limit scipy keeps no iterate, so the answer is the
start, p = 0, not converged, status max_iter (as at a limit of 0: ``base.ZERO_LIMIT_NOTE``),
never a non-finite p.  The tolerance is not used (the method is exact).  The
Cholesky factorization and NNLS are solve time; ``iterations`` counts polish rounds.
No warm start.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.lcp import (NNLSIterationLimit, default_nnls_max_iter, exact_solution,
                                       exact_solution_on_subset)
from contactbench.problems.mixed_lcp import (UncertifiedConstrainedSolution, constrained_exact_solution,
                                             constrained_solution_on_subset)

from ._kit import cholesky_seconds
from ._scaling import checked_claim, dense_matrix, finite_claim
from .base import Capabilities, Outcome, SolveContext, Solver, Status
from .registry import register
from ._scaling import BackendOutcome, EquilibratedAdapter, ScaledQP


@register
class ScipyNNLS(EquilibratedAdapter):
    """Lawson-Hanson NNLS on the Cholesky factor, polished by block principal pivoting
    (module doc).  Warm start: none."""

    name: ClassVar[str] = "scipy-nnls"
    family: ClassVar[str] = "reference"
    description: ClassVar[str] = "scipy.optimize.nnls (Lawson-Hanson) on the Cholesky factor of equilibrated H"
    capabilities: ClassVar[Capabilities] = Capabilities(
        needs_dense=True, warm_start="none", exact=True, input_format="dense"
    )
    required_package: ClassVar[str] = "scipy"
    # dense H, scaled copy, L, A = L' and nnls' own Fortran-order copy of A
    memory_copies: ClassVar[float] = 5.0
    time_coef: ClassVar[float] = 8e-10
    time_exponent: ClassVar[float] = 3.0

    def default_max_iter(self, n: int) -> int:
        return default_nnls_max_iter(n)

    def run_backend(self, sqp: ScaledQP, prepared: Any, ctx: SolveContext) -> BackendOutcome:
        try:
            sol = exact_solution(sqp.H, sqp.u, ctx.max_iter)
        except NNLSIterationLimit as exc:  # (the start, the last iterate held: module doc)
            return BackendOutcome(np.zeros_like(sqp.u), f"iteration limit: {exc}", False)
        except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
            return BackendOutcome(None, f"error: {type(exc).__name__}: {exc}", False)
        return BackendOutcome(
            sol.p, "solved" if sol.converged else "check failed", sol.converged, sol.polish_rounds,
            backend_setup_time=sol.factor_time, backend_solve_time=sol.nnls_time,
            info={"check_rounds": sol.polish_rounds, "check_time": sol.polish_time,
                  "active": int(np.count_nonzero(sol.p > 0))},
        )


#: ``bvls``'s time model, in Cholesky factorisations of the n x n dense H
#: (``_kit.cholesky_seconds``): with a box or with nothing but p >= 0, 4-10 measured at n =
#: 2,858-6,731; under a load (the regula falsi over the approach, each an exact solve) 6-22
#: at n = 1,089-4,225 (RMD H 0.7 on BCC, the 2-core vm).  A margin over the largest.
BVLS_FACTORISATIONS = 10
BVLS_LOAD_FACTORISATIONS = 25


@register
class BVLSReference(Solver):
    """The exact reference of the bounded and load-controlled families
    (``problems.mixed_lcp.constrained_exact_solution``): Stark & Parker's BVLS for a box,
    started from the clipped Lawson-Hanson solution; under load control the KKT solve with
    the multiplier (regula falsi on the approach Delta over exact BVLS solves, then block
    principal pivoting on the sets with the load row; a periodic whole grid, H 1 = 0: the
    active set on the bordered system, ``load_active_set``).  Certified to a scaled KKT error
    of 1e-10 or it fails.  Dense H, no warm start; without bounds or a load it runs
    ``exact_solution`` (as ``scipy-nnls``, without equilibration).  It has no iteration
    limit of its own (``default_max_iter`` None); under a load or a hardness a ``max_iter``
    given is refused (``ProblemInputError``): the certified solve cannot stop at one."""

    name = "bvls"
    family = "reference"
    description = "BVLS (Stark & Parker) for boxes; exact KKT solve with the load multiplier for load control"
    capabilities = Capabilities(needs_dense=True, warm_start="none", exact=True, input_format="dense",
                                load_control=True, bounds=True)
    default_tol = None
    time_scales_with_grid = False  # priced in dense factorisations

    def default_max_iter(self, n: int) -> int | None:
        return None

    def memory_estimate(self, n: int) -> float:
        return 4.0 * 8.0 * n * n

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """``BVLS_FACTORISATIONS`` dense factorisations (a load's count: the skip policy's
        ``LOAD_CONTROL_ITERATION_RATIO``), whatever the operator: it runs on the dense H."""
        return BVLS_FACTORISATIONS * cholesky_seconds(n)

    def iterate(self, ctx: SolveContext) -> Outcome:
        """The exact solve (class doc), claimed only with a finite answer whose scaled KKT
        error meets the check it will be judged at (``checked_claim``: a "certified" answer
        is exact to round-off, which a check below round-off does not meet)."""
        out = finite_claim(self.exact_outcome(ctx))
        if out.converged and out.w is None:
            out.w = ctx.qp.H.matvec(out.p) - ctx.qp.ubar
        return checked_claim(ctx, out)

    def exact_outcome(self, ctx: SolveContext) -> Outcome:
        """The certified exact solution of ``ctx``'s problem, or FAILED saying why."""
        H = dense_matrix(ctx.qp)
        ubar = np.asarray(ctx.qp.ubar, dtype=np.float64)
        ctx.mark_setup_done()
        c = ctx.constraints
        if c.plain:
            try:
                sol = exact_solution(H, ubar)
            except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:  # H not numerically SPD, LH cut short
                return on_a_subset(ctx, str(exc))
            return Outcome(sol.p, sol.polish_rounds, sol.converged, w=sol.w)
        if ctx.max_iter is not None:  # (the lifecycle answers a limit of 0 itself)
            raise ProblemInputError(f"bvls: under a load or a hardness the certified solve has no iteration limit "
                                    f"(max_iter {ctx.max_iter} asked); leave max_iter unset")
        try:
            ref = constrained_exact_solution(H, ubar, c)
        except np.linalg.LinAlgError as exc:  # H not numerically SPD: a periodic whole grid's
            return on_a_subset(ctx, str(exc))
        except (UncertifiedConstrainedSolution, RuntimeError, ValueError) as exc:
            return Outcome(np.full(ctx.n, np.nan), 0, False, f"bvls: {exc}", status=Status.FAILED)
        ctx.info.update(polish_rounds=ref.rounds, displacement_solves=ref.solves)
        return Outcome(ref.p, ref.rounds, True, "certified exact solution", w=H @ ref.p - ubar,
                       multiplier=ref.multiplier if c.load_control else None)


def on_a_subset(ctx: SolveContext, why: str) -> Outcome:
    """Where the whole problem's factorisation failed (``why``): the exact solve on a
    growing proper subset (``lcp.exact_solution_on_subset``; bounded or load-controlled:
    ``mixed_lcp.constrained_solution_on_subset``), for an H positive definite on proper
    subsets only, as a periodic whole grid's (H 1 = 0, where the Cholesky passes or fails
    on round-off: a 64 x 48 map failed); certified there, else failed with both reasons."""
    c = ctx.constraints
    try:
        sub = exact_solution_on_subset(ctx.qp) if c.plain else constrained_solution_on_subset(ctx.qp)
    except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
        return Outcome(np.full(ctx.n, np.nan), 0, False, f"bvls: {why}; on a proper subset: {exc}",
                       status=Status.FAILED)
    ctx.info.update(subset_size=int(sub.subset.size), subset_rounds=int(sub.rounds))
    return Outcome(sub.p, sub.rounds, True, f"certified exact solution on a proper subset ({why})",
                   multiplier=sub.multiplier)
