"""Active-set NNLS on the contact QP (Bemporad & Paggi 2015, section 3.3, Algorithm 3).

Lawson & Hanson's NNLS (1974, p. 161) applied to min 1/2 p'Hp - ubar'p, p >= 0 directly,
with no Cholesky factor of the whole H (the paper's extension), and warm started from a
given p (the load-history projection of paper section 3.3): the passive set starts as
P = {p > 0} and the first pass skips the "add an index" step (the paper's ``init`` flag).

Step 6 (solve H_PP s_P = ubar_P) never refactors from scratch after the first solve:

* ``cholesky`` -- an incremental Cholesky factor L L' = H_PP (LH74 ch. 24): appending an
  index adds one row (one triangular solve), removing one deletes a row and restores the
  triangle by a rank-one update of the trailing block.  The needed H entries are gathered
  with ``op.submatrix`` (works for dense and FFT operators).  Memory O(|P|^2).
* ``cg`` -- conjugate gradients on the matrix-free ``op.restrict(P)``, warm started from
  the current p_P.  Memory O(n).

``linear="auto"`` picks ``cholesky`` for a dense operator or a small FFT problem
(a full factor within 1/8 of the memory budget, ``FACTOR_MAX_N``) and ``cg`` otherwise;
``info["linear_solver"]`` records it.  The dense (re)factorisation is
``_kit.cholesky_of_h``.

Stopping: when no index of the zero set has w_j < -tol u_s, the answer is claimed
converged if its scaled KKT error (``SolveContext.kkt``) is <= tol, else "stalled".
Finite termination: an exact method (a reference candidate).  Warm start: primal.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import scipy.linalg as sla

from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET, ContactOperator, check_dense_budget

from ._kit import absolute_tol, cholesky_of_h, conjugate_gradient, is_dense, matvec_seconds
from .base import Capabilities, Outcome, Param, SolveContext, Solver, Status
from .registry import register

#: Under "auto", FFT operators use the incremental Cholesky backend while a full n x n
#: factor would fit in 1/8 of the memory budget (8 GiB budget: n <= 11585).
FACTOR_MAX_N = int(np.sqrt(DEFAULT_MEMORY_BUDGET / 8 / 8))
#: ``nnls``'s time model: a cold solve adds about this share of its n unknowns one by one
#: (cold paper-sweep steps: 0.09-0.13 n products at n = 1,163-8,803 on 128^2 and 256^2 grids),
#: each addition one product, and beyond ``FACTOR_MAX_N`` a CG solve of about
#: ``NNLS_CG_PRODUCTS`` products instead of a factor update.
NNLS_ADDITIONS_PER_UNKNOWN = 0.15
NNLS_CG_PRODUCTS = 30


# ---------------------------------------------------------------------------
# Step-6 backends: solve H_PP s = ubar_P as P changes one index at a time
# ---------------------------------------------------------------------------


class PassiveSetSolver(Protocol):
    name: str

    def reset(self, passive: np.ndarray) -> None: ...

    def add(self, j: int) -> bool: ...

    def remove(self, js: np.ndarray) -> None: ...

    def solve(self, rhs: np.ndarray, x0: np.ndarray) -> np.ndarray: ...

    @property
    def order(self) -> np.ndarray: ...


def cholesky_rank1_update(L: np.ndarray, x: np.ndarray) -> None:
    """In place: L L' + x x' = L_new L_new' for lower-triangular L (m x m view)."""
    m = L.shape[0]
    for k in range(m):
        lkk = L[k, k]
        r = np.hypot(lkk, x[k])
        c, s = r / lkk, x[k] / lkk
        L[k, k] = r
        if k + 1 < m:
            col = L[k + 1:, k]
            col += s * x[k + 1:]
            col /= c
            x[k + 1:] *= c
            x[k + 1:] -= s * col


class IncrementalCholesky:
    """L L' = H_PP kept up to date as indices enter and leave P (positions of ``op``).

    ``order`` lists P in factor order; the factor lives in a growing buffer."""

    name = "cholesky"

    def __init__(self, op: ContactOperator) -> None:
        self.op = op
        self.k = 0
        self._order = np.zeros(0, dtype=np.int64)
        self.buf = np.zeros((0, 0))
        self.updates = 0

    @property
    def order(self) -> np.ndarray:
        return self._order[: self.k]

    def _reserve(self, m: int) -> None:
        if m <= self.buf.shape[0]:
            return
        check_dense_budget(m, what="nnls: Cholesky factor of H_PP")
        cap = max(m, min(self.op.n, 2 * self.buf.shape[0] + 16))
        new = np.zeros((cap, cap))
        new[: self.k, : self.k] = self.buf[: self.k, : self.k]
        self.buf = new
        order = np.zeros(cap, dtype=np.int64)
        order[: self.k] = self._order[: self.k]
        self._order = order

    def reset(self, passive: np.ndarray) -> None:
        """Factor H_PP from scratch (once, for the warm-start set)."""
        m = passive.size
        self.k = 0
        self._reserve(m)
        self._order[:m] = passive
        if m:
            self.buf[:m, :m] = cholesky_of_h(self.op, passive, what="nnls: Cholesky factor of H_PP")
        self.k = m

    def add(self, j: int) -> bool:
        """Append index j (one new row of L).  False if H_PP+j is numerically singular."""
        k = self.k
        h = self.op.submatrix(np.array([j]), np.append(self.order, j))[0]
        l = sla.solve_triangular(self.buf[:k, :k], h[:k], lower=True, check_finite=False) if k else h[:0]
        d2 = h[k] - float(l @ l)
        if not d2 > 1e-14 * h[k]:
            return False
        self._reserve(k + 1)
        self.buf[k, :k] = l
        self.buf[k, k] = np.sqrt(d2)
        self._order[k] = j
        self.k = k + 1
        self.updates += 1
        return True

    def _remove_position(self, q: int) -> None:
        k = self.k
        L = self.buf
        x = L[q + 1:k, q].copy()  # the deleted column's trailing part
        # delete row q and column q: shift the trailing rows up and columns left
        L[q:k - 1, :q] = L[q + 1:k, :q]
        L[q:k - 1, q:k - 1] = L[q + 1:k, q + 1:k]
        L[k - 1, :k] = 0.0
        L[:k, k - 1] = 0.0
        self._order[q:k - 1] = self._order[q + 1:k]
        self.k = k - 1
        cholesky_rank1_update(L[q:k - 1, q:k - 1], x)
        self.updates += 1

    def remove(self, js: np.ndarray) -> None:
        pos = np.flatnonzero(np.isin(self.order, js))
        for q in pos[::-1]:  # from the back: earlier positions stay valid
            self._remove_position(int(q))

    def solve(self, rhs: np.ndarray, x0: np.ndarray) -> np.ndarray:
        if rhs.size == 0:
            return rhs.copy()
        L = self.buf[: self.k, : self.k]
        y = sla.solve_triangular(L, rhs, lower=True, check_finite=False)
        return sla.solve_triangular(L, y, lower=True, trans="T", check_finite=False)


class RestrictedCG:
    """H_PP s = ubar_P by CG on ``op.restrict(P)``, warm started from the current p_P."""

    name = "cg"

    def __init__(self, op: ContactOperator, atol: float, ctx: SolveContext) -> None:
        self.op = op
        self.atol = atol
        self.ctx = ctx
        self.mask = np.zeros(op.n, dtype=bool)
        self.cg_iterations = 0
        self.max_cg_iter = max(200, 10 * int(np.sqrt(op.n)) + 200)

    @property
    def order(self) -> np.ndarray:
        return np.flatnonzero(self.mask)

    def reset(self, passive: np.ndarray) -> None:
        self.mask[:] = False
        self.mask[passive] = True

    def add(self, j: int) -> bool:
        self.mask[j] = True
        return True

    def remove(self, js: np.ndarray) -> None:
        self.mask[js] = False

    def solve(self, rhs: np.ndarray, x0: np.ndarray) -> np.ndarray:
        if rhs.size == 0:
            return rhs.copy()
        sub = self.ctx.track(self.op.restrict(self.order))
        r = conjugate_gradient(sub, rhs, x0, self.atol, self.max_cg_iter, self.ctx.deadline)
        self.cg_iterations += r.iterations
        return r.x


#: The step-6 backends a solver may name (``linear`` parameter).
LINEAR_CHOICES = ("auto", "cholesky", "cg")
LINEAR_PARAM = Param("linear", str, "auto", "step-6 solve: incremental Cholesky, CG on H_PP, or auto "
                     "(Cholesky for a dense operator or n <= FACTOR_MAX_N)", choices=LINEAR_CHOICES)


def choose_backend(op: ContactOperator, linear: str, atol: float, ctx: SolveContext) -> PassiveSetSolver:
    if linear == "auto":
        linear = "cholesky" if (is_dense(op) or op.n <= FACTOR_MAX_N) else "cg"
    if linear == "cholesky":
        return IncrementalCholesky(op)
    return RestrictedCG(op, atol, ctx)


# ---------------------------------------------------------------------------
# Algorithm 3
# ---------------------------------------------------------------------------


def nnls_active_set(ctx: SolveContext, p0: np.ndarray, max_iter: int, linear: str, it_offset: int = 0) -> Outcome:
    """Paper Algorithm 3 from p0 >= 0 (P = {p0 > 0}) until the scaled KKT error of
    (p, w) is <= ctx.tol (checked at step 3, where w is at hand).  Inner thresholds
    (``_kit.absolute_tol``): an index may enter P when w_j < -tol u_s, and a candidate
    s_P is accepted when s_P >= -tol p_s.  ``it_offset`` shifts the trace's iteration
    numbers (iterations done before this call)."""
    qp = ctx.qp
    op, ubar = qp.H, qp.ubar
    atol = absolute_tol(ctx, ctx.tol)
    eps_w, eps_p = atol.disp, atol.force
    backend = choose_backend(op, linear, 0.1 * eps_w, ctx)
    p = p0.copy()
    passive = p > 0.0
    try:
        backend.reset(np.flatnonzero(passive))
    except np.linalg.LinAlgError:  # the warm set's H_PP is not numerically positive definite: start cold
        p[:] = 0.0
        passive[:] = False
        backend.reset(np.flatnonzero(passive))
        ctx.info["warm_set_refused"] = True
    w = op.matvec(p) - ubar
    init = not passive.any()  # steps 1-2: a warm p skips the first "add"
    rejected = np.zeros(qp.n, dtype=bool)
    k, adds, removes, message, status = 0, 0, 0, "", None
    while True:
        if init:  # steps 4-5
            cand = ~passive & ~rejected
            wmin = float(w[cand].min()) if cand.any() else 0.0
            if wmin >= -eps_w:
                converged = ctx.kkt(p, w) <= ctx.tol
                message = ("optimal: w >= -eps on the zero set" if converged else
                           "stalled: no index left to add, scaled KKT error above tol")
                status = Status.CONVERGED if converged else Status.STALLED
                break
            if k >= max_iter or ctx.expired():
                message = "stopped before optimality"
                break
            t = int(np.flatnonzero(cand)[np.argmin(w[cand])])
            if not backend.add(t):
                rejected[t] = True
                continue
            passive[t] = True
            adds += 1
        else:
            t = -1
        init = True
        while True:  # steps 6-12
            order = backend.order
            s = backend.solve(ubar[order], p[order])
            k += 1
            if not np.all(np.isfinite(s)):  # step 6 broke down: p is the last feasible iterate
                message, status = "stalled: the step-6 solve gave non-finite values", Status.STALLED
                break
            if t >= 0 and s[order == t][0] <= 0.0:  # LH anti-cycling guard
                backend.remove(np.array([t]))
                passive[t] = False
                rejected[t] = True
                break
            t = -1
            if s.min(initial=0.0) >= -eps_p:  # step 7
                p[:] = 0.0
                p[order] = np.maximum(s, 0.0)
                rejected[:] = False
                break
            po = p[order]
            neg = s < -eps_p
            ratios = po[neg] / (po[neg] - s[neg])  # step 8
            jmin = int(np.argmin(ratios))
            alpha = float(ratios[jmin])
            po += alpha * (s - po)  # step 9
            po[np.flatnonzero(neg)[jmin]] = 0.0  # the blocking index lands exactly on zero
            leaving = order[po <= eps_p]
            p[order] = np.maximum(po, 0.0)
            p[leaving] = 0.0
            passive[leaving] = False  # steps 10-11
            backend.remove(leaving)
            removes += leaving.size
            if k >= max_iter or ctx.expired():
                break
        w = op.matvec(p) - ubar  # step 3
        ctx.record(it_offset + k, ctx.kkt(p, w))
        if status is Status.STALLED:
            break
    ctx.info.update(linear_solver=backend.name, additions=adds, removals=removes, passive_size=int(passive.sum()))
    if isinstance(backend, IncrementalCholesky):
        ctx.info["factor_updates"] = backend.updates
    if isinstance(backend, RestrictedCG):
        ctx.info["inner_cg_iterations"] = backend.cg_iterations
    return Outcome(p, k, status is Status.CONVERGED, message, w=w, status=status)


def nnls_max_iter(n: int) -> int:
    """Iteration limit of Algorithm 3 (solves of step 6) when the settings give none."""
    return 5 * n + 100


@register
class NNLS(Solver):
    """Lawson-Hanson NNLS on the QP (paper section 3.3, Algorithm 3), warm started from p.

    Step 6 by incremental Cholesky updates (dense / small) or warm-started CG on
    ``op.restrict(P)`` (matrix-free); param ``linear`` = auto | cholesky | cg.
    One iteration = one solve of step 6.  Stops on the scaled KKT error
    (``SolveContext.kkt``).  Exact (finite termination); warm start: primal (the load
    history: P starts as supp p)."""

    name = "nnls"
    family = "paper"
    description = "Lawson-Hanson active set on the QP (Algorithm 3), incremental Cholesky or CG"
    capabilities = Capabilities(warm_start="primal", exact=True)
    default_tol = 1e-10
    params = (LINEAR_PARAM,)

    def default_max_iter(self, n: int) -> int:
        return nnls_max_iter(n)

    def iterate(self, ctx: SolveContext) -> Outcome:
        p0 = np.zeros(ctx.n) if ctx.p0 is None else ctx.p0
        return nnls_active_set(ctx, p0, ctx.max_iter, ctx.params["linear"])

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """``NNLS_ADDITIONS_PER_UNKNOWN`` n additions, each one product plus a factor update
        (or a CG solve of about ``NNLS_CG_PRODUCTS`` products beyond ``FACTOR_MAX_N``)."""
        per = matvec_seconds(n, operator_kind) * (1 if operator_kind == "dense" or n <= FACTOR_MAX_N else NNLS_CG_PRODUCTS)
        return NNLS_ADDITIONS_PER_UNKNOWN * n * per
