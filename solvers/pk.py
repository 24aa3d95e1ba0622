"""Constrained conjugate gradient of Polonsky & Keer (1999), displacement control
(Bemporad & Paggi 2015, section 3.2, Algorithm 2): the paper's configuration of the one
Polonsky-Keer loop, ``_ccg.polonsky_keer`` (which fast-ccg runs as well).

Each iteration: a conjugate direction t on the current contact set S (t = 0 off S),
the exact line step tau = (w_S't_S) / (t'Ht), projection onto p >= 0, and re-entry of
the points with zero force and negative gap (I_ol, where the conjugacy is reset, d = 0).

Reading of the printed algorithm: w, t and the inner products are restricted to the
contact set S = {p > 0} of the previous iteration (as in P&K's paper); the first
iteration uses the initial trial domain.  The printed stopping test (relative change of
||w||) is replaced by the harness's scaled KKT error (``SolveContext.kkt``), which is
what "convergence" must mean for the harness.  Step 3.8 (w = Hp - ubar) is computed as
w -= tau H t when no point entered or was clipped (same numbers up to round-off, one
matvec per iteration instead of two).

What pk keeps of its own, and fast-ccg does not: the paper's trial domain.  Cold start:
p = 0 with the whole trial set as the first domain (Algorithm 2's input I_C = {1..n});
warm start (paper: "both an initial trial contact domain and a set of contact
pressures"): p from the previous step and its support as the first domain.  No
preconditioner.  Exact (converges to round-off); matrix-free (dense or FFT operator).
"""

from __future__ import annotations

import numpy as np

from ._ccg import GapState, outcome, polonsky_keer
from ._kit import matvec_seconds
from .base import Capabilities, Outcome, SolveContext, Solver
from .registry import register

TYPICAL_PK_ITERATIONS = 300


@register
class PolonskyKeer(Solver):
    """Constrained CG (Polonsky & Keer 1999; paper Algorithm 2), displacement control,
    ``_ccg.polonsky_keer`` without a preconditioner.

    Warm start: previous p and its support as the initial trial domain (cold: p = 0 and
    the whole trial set).  Exact; matrix-free."""

    name = "pk"
    family = "paper"
    description = "Polonsky-Keer constrained CG (Algorithm 2), warm start of p and domain"
    capabilities = Capabilities(warm_start="primal", exact=True)
    default_tol = 1e-10

    def iterate(self, ctx: SolveContext) -> Outcome:
        state = GapState.start(ctx)
        warm = ctx.p0 is not None and bool(np.any(ctx.p0 > 0.0))
        domain = state.p > 0.0 if warm else np.ones(ctx.n, dtype=bool)
        run = polonsky_keer(ctx, state, None, domain=domain)
        return outcome(state, run, {"initial_domain": int(domain.sum())})

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 2 * TYPICAL_PK_ITERATIONS * matvec_seconds(n, operator_kind)
