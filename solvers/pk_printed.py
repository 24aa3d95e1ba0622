"""The constrained CG of Bemporad & Paggi (2015), Algorithm 2, as printed (tex lines
726-760 of the paper's source): ``pk-printed``.

``pk`` (solvers/pk.py) is Polonsky & Keer's own algorithm (1999): the conjugate direction,
the step and the ratio restricted to the contact set, the ratio squared, one product per
iteration, stopped on the harness's scaled KKT error.  The paper's Fig. 4 measured a
"P&K1999" whose listing differs in three places, and this solver runs the listing:

* its own stopping rule: the relative change of ||w||_2 between two iterations, against
  the paper's eps (section 4, tex 1017-1020: eps = 1e-8, K_max = 1e5, cold start);
* the unsquared ratio n_w / n_w,old (Fletcher-Reeves would square it) over the whole w;
* two products with H per iteration (Ht for the step, Hp for the new gap).

Line by line (tex line: what runs here):

* 728-731 (input): H, ubar, an initial guess p >= 0 (a warm start, else p = 0: the
  paper's cold start), I_C = {1, ..., n}, K_max = ``ctx.max_iter`` - 1 (default: the
  paper's 1e5; the printed loop runs K_max + 1 iterations, so max_iter limits them as it
  does every solver's),
  eps (``ctx.tol``, default the paper's 1e-8: the relative change of ||w||, *not* a KKT
  error);
* 734 (step 1): i = 0, n_w,old = 1, d = 0, err = +inf;
* 735 (step 2): w = Hp - ubar (product 1 of the solve);
* 736 (step 3): while i <= K_max and err > eps -- so at most K_max + 1 iterations;
* 738-740 (3.1): t = w at i = 0, else t = w + d (n_w / n_w,old) t_old, on every point;
* 741 (3.2): tau = w't / t'Ht (one product, Ht);
* 742 (3.3): p = p - tau t, on every point;
* 743 (3.4): p_j = max(p_j, 0) for j in I_C -- see "Reading" below;
* 744-746 (3.5): I_ol = {j in I_C: p_j = 0, w_j < 0}; d = 1 if I_ol is empty, else d = 0;
  p_j = p_j - tau w_j on I_ol;
* 747 (3.6): I_C = {j: p_j > 0} union I_ol;
* 748 (3.7): t_old = t, n_w,old = n_w;
* 749 (3.8): w = Hp - ubar (the second product of the iteration);
* 750 (3.9): n_w = ||w||_2;
* 751 (3.10): err = |n_w - n_w,old| / n_w,old;
* 752 (3.11): i = i + 1;
* 754 (step 4): p* = p; u* = Hp* is w + ubar of step 3.8 (no further product).

Reading (where the listing does not define a value, or defines one that breaks its own
promise):

* n_w at i = 0: step 3.7 reads n_w before step 3.9 first sets it; it is read as ||w||_2 of
  step 2 (the only value it can mean: the first err is then the relative change from the
  initial gap; step 1's n_w,old = 1 is overwritten before it is used).
* Step 3.4 (param ``projection``): printed, it projects only the points of I_C.  Since t
  is the whole w, a point outside I_C moves by -tau t_j and is never projected, nor
  readmitted by step 3.6 (it needs p_j > 0): the iterate carries negative forces for good,
  against the paper's own statement that the method "assures the satisfaction of the LCP
  conditions" (tex 715-717).  ``projection="all"`` (the default) projects every point;
  ``projection="printed"`` runs line 743 word for word (tests/solvers/test_pk_printed.py
  shows what it returns on Example 1).

Degenerate steps end the loop with an honest status, never an exception: t'Ht <= 0 or not
finite (t = 0: w = 0, the exact answer, when every point is in I_C) is STALLED unless w = 0
(then CONVERGED); n_w,old = 0 reads err = 0 when n_w = 0 too, else +inf.  Not exact: the
rule stops on a small change of ||w||, not on a small w; its answer is the harness's to
judge (on the paper's problems it stops at a scaled KKT error of 1e-4 to 1e-2).  The trace
records the scaled KKT error of the first ``TRACE_EVERY`` iterations and then of every
``TRACE_EVERY``-th (no product: w is at hand).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._kit import matvec_seconds
from .base import Capabilities, Outcome, Param, SolveContext, Solver, Status
from .registry import register

#: The paper's K_max for the constrained CG (section 4, tex 1019).
PAPER_KMAX = 100_000
#: Iterations recorded one by one before the trace thins to one in ``TRACE_EVERY``.
TRACE_EVERY = 100
#: The iterations the time model assumes, at two products each (Example 1 at n = 100 takes
#: 1e3-2e4, tests/solvers/test_pk_printed.py; cold paper-sweep steps at tol 1e-8 took
#: 306-1,313 at n = 411-4,497 on 128^2 and 256^2 grids).
TYPICAL_PRINTED_ITERATIONS = 1500
#: The readings of step 3.4 (module doc).
PROJECTIONS: tuple[str, ...] = ("all", "printed")


@dataclass
class PrintedState:
    """The listing's variables between two iterations (tex 734-752)."""

    p: np.ndarray
    w: np.ndarray
    active: np.ndarray  # I_C as a mask
    t_old: np.ndarray
    n_w: float
    n_w_old: float = 1.0  # step 1
    d: int = 0  # step 1
    err: float = math.inf  # step 1


def relative_change(n_w: float, n_w_old: float) -> float:
    """Step 3.10, err = |n_w - n_w,old| / n_w,old (0 when both are 0, +inf when only the old
    one is)."""
    if n_w_old > 0.0:
        return abs(n_w - n_w_old) / n_w_old
    return 0.0 if n_w == 0.0 else math.inf


def direction(s: PrintedState, first: bool) -> np.ndarray:
    """Step 3.1: t = w (i = 0), else w + d (n_w / n_w,old) t_old, on every point."""
    if first or s.d == 0:
        return s.w.copy()
    return s.w + (s.n_w / s.n_w_old) * s.t_old


def project(p: np.ndarray, active: np.ndarray, projection: str) -> None:
    """Step 3.4 in place: p_j = max(p_j, 0) on I_C (``printed``) or on every point (``all``)."""
    if projection == "printed":
        p[active] = np.maximum(p[active], 0.0)
    else:
        np.maximum(p, 0.0, out=p)


def printed_iteration(ctx: SolveContext, s: PrintedState, first: bool, projection: str) -> bool:
    """Steps 3.1-3.10 of one iteration on ``s`` in place (two products); False, with ``s``
    untouched, when the step is degenerate (t'Ht <= 0 or not finite)."""
    H, ubar = ctx.qp.H, ctx.qp.ubar
    t = direction(s, first)  # 3.1
    q = H.matvec(t)
    tq = float(t @ q)
    if not (math.isfinite(tq) and tq > 0.0):
        return False
    tau = float(s.w @ t) / tq  # 3.2
    p = s.p - tau * t  # 3.3
    project(p, s.active, projection)  # 3.4
    entering = s.active & (p == 0.0) & (s.w < 0.0)  # 3.5
    s.d = 0 if np.any(entering) else 1
    p[entering] -= tau * s.w[entering]
    s.active = (p > 0.0) | entering  # 3.6
    s.t_old, s.n_w_old = t, s.n_w  # 3.7
    s.p = p
    s.w = H.matvec(p) - ubar  # 3.8
    s.n_w = float(np.linalg.norm(s.w))  # 3.9
    s.err = relative_change(s.n_w, s.n_w_old)  # 3.10
    return True


@register
class PrintedConstrainedCG(Solver):
    """Algorithm 2 of the paper as printed (module doc): whole-w direction with the
    unsquared ratio, two products per iteration, stopped when the relative change of ||w||
    is at most eps (``tol``).  Warm start: the initial guess p (I_C = all).  Not exact."""

    name = "pk-printed"
    family = "paper"
    description = "the paper's Algorithm 2 as printed: stop on the relative change of ||w||, unsquared ratio"
    #: its stop is not a KKT test: the promise is a loose floor (the conformance battery's
    #: worst case stops at a scaled KKT error of about 0.1)
    capabilities = Capabilities(warm_start="primal", exact=False, promise=0.5)
    default_tol = 1e-8
    params = (
        Param("projection", str, "all", "step 3.4 on every point (all) or on I_C only, word for word (printed)",
              choices=PROJECTIONS),
    )

    def default_max_iter(self, n: int) -> int:
        return PAPER_KMAX + 1  # K_max = max_iter - 1 (module doc)

    def iterate(self, ctx: SolveContext) -> Outcome:
        projection = ctx.params["projection"]
        p = ctx.first_p()
        w = ctx.qp.H.matvec(p) - ctx.qp.ubar  # step 2
        s = PrintedState(p, w, np.ones(ctx.n, dtype=bool), np.zeros(ctx.n), float(np.linalg.norm(w)))
        eps, kmax = float(ctx.tol if ctx.tol is not None else self.default_tol), int(ctx.max_iter) - 1
        i, status = 0, None
        while i <= kmax and s.err > eps:  # step 3
            if ctx.expired():
                break
            if not printed_iteration(ctx, s, i == 0, projection):
                status = Status.CONVERGED if not np.any(s.w) else Status.STALLED
                break
            i += 1  # 3.11
            if i <= TRACE_EVERY or i % TRACE_EVERY == 0:
                ctx.record(i, ctx.kkt(s.p, s.w))
        converged = s.err <= eps or status is Status.CONVERGED
        if not math.isfinite(s.n_w) and not converged:  # a non-finite iterate: no usable answer
            status = Status.FAILED
        ctx.info.update(projection=projection, final_err=s.err, eps=eps, contact_set=int(s.active.sum()))
        return Outcome(s.p, i, converged, w=s.w, status=status,
                       message=f"relative change of ||w|| {s.err:.3g} after {i} iterations (eps {eps:g})")

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 2 * TYPICAL_PRINTED_ITERATIONS * matvec_seconds(n, operator_kind)
