"""The exact solution of the contact LCP: the one implementation.

The contact QP  min 1/2 p'Hp - ubar'p, p >= 0  (Bemporad & Paggi 2015, eq. (6)) with H
symmetric positive definite is the LCP

    w = Hp - ubar >= 0,   p >= 0,   w'p = 0,

whose solution is unique.  Two exact (finitely terminating) methods meet here:

* ``exact_solution``: with the Cholesky factor H = L L' (``cholesky_factor``),

      1/2 p'Hp - ubar'p = 1/2 || L'p - L^{-1} ubar ||^2 - 1/2 || L^{-1} ubar ||^2,

  so the QP is the non-negative least-squares problem min ||A p - b||, p >= 0 with
  A = L', b = L^{-1} ubar, solved by Lawson-Hanson (Lawson & Hanson 1974, ch. 23;
  ``scipy.optimize.nnls``), then polished by ``bpp_polish`` to round-off.
* ``bpp_polish``: block principal pivoting (Judice & Pires 1994).  From a guess p0 it
  takes the contact set A = {i : p0_i > w0_i}, solves H_AA p_A = ubar_A by Cholesky
  (p = 0 off A), and moves every violated index across: p_i < 0 out of A, w_i < 0 into
  A.  After three rounds without fewer violations it falls back to Murty's single
  least-index pivot, which terminates for a P-matrix; a later improvement returns it to
  block steps.  Violations are measured in the units of ``problems.kkt``: p_i against
  tol * p_s and w_i against tol * u_s with u_s = max|ubar|, p_s = u_s / max diag H, so
  the polish is invariant under a change of units.

Both work on a dense H (an n x n array).  Used by the reference solver
(``scipy-nnls``), the conformance battery's reference and the ``+polish`` QP adapters.

Singular H: ``exact_solution_on_subset``.  A periodic problem is posed on the whole
grid, where H is singular along the constant vector (its q = 0 mode is removed) but
positive definite on every proper subset.  Since sum(ubar) < 0 there, the contact set
is a proper subset (w = 0 on every point would give 0 = 1'Hp = sum(ubar)).  So it is
solved exactly on a proper subset T (``exact_solution`` on the dense H_TT), extended by
zeros and certified on the whole problem with ``problems.kkt.kkt_check``: p is the
exact solution iff its whole-problem KKT error is at round-off.  Points off T that
penetrate (w_i < 0) join T and the solve is repeated.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np
import scipy.linalg as sla
from scipy.optimize import nnls

from contactbench.problems.kkt import kkt_check, scaled_kkt_error

if TYPE_CHECKING:
    from contactbench.problems.instances import QP

#: Block pivoting rounds without fewer violations before Murty's single pivot.
BLOCK_PATIENCE = 3
#: Whole-problem scaled KKT error at which ``exact_solution_on_subset`` certifies its answer.
CERTIFY_KKT = 1e-12
#: Subset solves ``exact_solution_on_subset`` tries before it gives up.
MAX_SUBSET_ROUNDS = 20


class UncertifiedSolutionError(RuntimeError):
    """``exact_solution_on_subset`` could not certify a subset solution on the whole problem."""


class NNLSIterationLimit(RuntimeError):
    """Lawson-Hanson hit its ``max_iter`` (``nnls_on_factor``); scipy hands back no iterate."""


@dataclass
class PolishOutcome:
    """What ``bpp_polish`` returns.

    p         : the polished point, or p0 itself when the polish did not improve on it;
    rounds    : solves on a contact set;
    converged : the last contact set had no violation (p is the exact solution);
    active    : size of the last contact set;
    improved  : the polished point's scaled KKT error is <= that of p0 (p is it);
    history   : violations per round.
    """

    p: np.ndarray
    rounds: int
    converged: bool
    active: int
    improved: bool
    history: list[int] = field(default_factory=list)


@dataclass
class LCPSolution:
    """The exact solution of the LCP (H, ubar) (``exact_solution``).

    p, w          : the solution and its gap w = Hp - ubar;
    kkt_error     : ``problems.kkt.scaled_kkt_error`` of (p, w);
    polish_rounds : ``bpp_polish`` rounds after NNLS (1 when NNLS was already exact);
    converged     : the polish ended on a contact set without violations;
    factor_time, nnls_time, polish_time : seconds of the three steps.
    """

    p: np.ndarray
    w: np.ndarray
    kkt_error: float
    polish_rounds: int
    converged: bool
    factor_time: float = 0.0
    nnls_time: float = 0.0
    polish_time: float = 0.0


def _check_dense(H: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    H = np.asarray(H, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    if H.ndim != 2 or H.shape[0] != H.shape[1]:
        raise ValueError(f"H must be a square matrix, got shape {H.shape}")
    if u.shape != (H.shape[0],):
        raise ValueError(f"ubar has shape {u.shape}, H is {H.shape[0]} x {H.shape[1]}")
    return H, u


def cholesky_factor(H: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor L of a dense SPD H (H = L L'); a ``LinAlgError``
    saying so when H is not positive definite."""
    H = np.asarray(H, dtype=np.float64)
    try:
        return sla.cholesky(H, lower=True, check_finite=False)
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError(f"H is not positive definite (Cholesky failed: {exc})") from exc


def default_nnls_max_iter(n: int) -> int:
    """Lawson-Hanson iteration limit: generous (it needs about one per contact element)."""
    return 50 * max(int(n), 10)


def nnls_on_factor(L: np.ndarray, ubar: np.ndarray, max_iter: int | None = None) -> np.ndarray:
    """min 1/2 p'Hp - ubar'p, p >= 0 for H = L L' as NNLS with A = L', b = L^{-1} ubar
    (module doc).  Raises ``NNLSIterationLimit`` (a ``RuntimeError``) when Lawson-Hanson
    hits ``max_iter``."""
    b = sla.solve_triangular(L, ubar, lower=True, check_finite=False)
    A = np.ascontiguousarray(L.T)
    n = int(b.size)
    limit = default_nnls_max_iter(n) if max_iter is None else int(max_iter)
    try:
        p, _ = nnls(A, b, maxiter=limit)
    except RuntimeError as exc:  # (scipy's only RuntimeError: its iteration limit)
        raise NNLSIterationLimit(f"Lawson-Hanson reached its limit of {limit} iterations ({exc})") from exc
    return p


def _solve_on_set(H: np.ndarray, u: np.ndarray, active: np.ndarray) -> np.ndarray:
    """p with H_AA p_A = u_A on the contact set A, zero elsewhere."""
    p = np.zeros_like(u)
    idx = np.flatnonzero(active)
    if idx.size:
        c = sla.cho_factor(H[np.ix_(idx, idx)], lower=True, check_finite=False)
        p[idx] = sla.cho_solve(c, u[idx], check_finite=False)
    return p


def _scales(H: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """(u_s, p_s) of the module doc: the units violations are measured in."""
    u_s = float(np.max(np.abs(u), initial=0.0)) or 1.0
    return u_s, u_s / float(np.max(np.diag(H), initial=0.0))


def bpp_polish(H: np.ndarray, u: np.ndarray, p0: np.ndarray, max_rounds: int = 50,
               tol: float = 1e-11) -> PolishOutcome:
    """Block principal pivoting with Murty's fallback (module doc) from the contact set
    guessed from ``p0``.  Returns the polished point only when its scaled KKT error is
    no worse than that of ``p0``; else ``p0`` (``improved`` False)."""
    H, u = _check_dense(H, u)
    p0 = np.asarray(p0, dtype=np.float64)
    if p0.shape != u.shape:
        raise ValueError(f"the guess p0 has shape {p0.shape}, the problem has n = {u.size}")
    if u.size == 0:
        return PolishOutcome(p0.copy(), 0, True, 0, True, [])
    diag_max = float(np.max(np.diag(H), initial=0.0))
    u_s, p_s = _scales(H, u)
    w0 = H @ p0 - u
    active = p0 > w0
    best_viol, stall, history = np.inf, 0, []
    p = p0
    converged, rounds = False, max_rounds
    for rnd in range(1, max_rounds + 1):
        p = _solve_on_set(H, u, active)
        w = H @ p - u
        bad_p = active & (p < -tol * p_s)
        bad_w = ~active & (w < -tol * u_s)
        nviol = int(np.count_nonzero(bad_p) + np.count_nonzero(bad_w))
        history.append(nviol)
        if nviol == 0:
            p = np.where(active, np.maximum(p, 0.0), 0.0)
            converged, rounds = True, rnd
            break
        if nviol < best_viol:
            best_viol, stall = nviol, 0
        else:
            stall += 1
        if stall < BLOCK_PATIENCE:
            active = (active & ~bad_p) | bad_w
        else:  # Murty's least-index rule: finite termination
            j = int(np.flatnonzero(bad_p | bad_w)[0])
            active[j] = not active[j]
    else:
        p = np.maximum(p, 0.0)
    improved = (scaled_kkt_error(p, H @ p - u, u, diag_max)
                <= scaled_kkt_error(p0, w0, u, diag_max))
    return PolishOutcome(p if improved else p0, rounds, converged, int(active.sum()), improved, history)


def exact_solution(H: np.ndarray, ubar: np.ndarray, max_iter: int | None = None) -> LCPSolution:
    """The exact solution of the LCP (H, ubar) for a dense SPD H: Lawson-Hanson NNLS on
    the Cholesky factor, then ``bpp_polish`` to round-off (module doc).  ``max_iter``
    caps Lawson-Hanson (None: ``default_nnls_max_iter``); hitting it raises
    ``NNLSIterationLimit``, a non-SPD H raises ``LinAlgError``."""
    H, ubar = _check_dense(H, ubar)
    if ubar.size == 0:
        return LCPSolution(np.zeros(0), np.zeros(0), 0.0, 0, True)
    t0 = time.perf_counter()
    L = cholesky_factor(H)
    t1 = time.perf_counter()
    p = nnls_on_factor(L, ubar, max_iter)
    t2 = time.perf_counter()
    pol = bpp_polish(H, ubar, p)
    t3 = time.perf_counter()
    w = H @ pol.p - ubar
    err = scaled_kkt_error(pol.p, w, ubar, float(np.max(np.diag(H), initial=0.0)))
    return LCPSolution(pol.p, w, err, pol.rounds, pol.converged, t1 - t0, t2 - t1, t3 - t2)


@dataclass
class SubsetSolution:
    """The exact solution of an LCP found on a proper subset (``exact_solution_on_subset``).

    p         : the solution on the whole problem (zero off ``subset``);
    kkt_error : ``problems.kkt.kkt_check`` of p on the whole problem (<= the certifying tol);
    subset    : the positions (0..n-1) of the last subset solved on;
    rounds    : subset solves it took.
    """

    p: np.ndarray
    kkt_error: float
    subset: np.ndarray
    rounds: int
    multiplier: float | None = None  # Delta under a load equality (None: no load equality)


#: The exact solve on positions T of a QP, with the others held at p = 0: (p on T, the
#: multiplier Delta under a load equality, else None).
SubsetSolve = Callable[[np.ndarray], tuple[np.ndarray, "float | None"]]


def top_half_subset(ubar: np.ndarray) -> np.ndarray:
    """Positions of the largest half of ``ubar`` (sorted; at least one, a proper subset
    for n >= 2): where contact is likeliest."""
    u = np.asarray(ubar, dtype=np.float64)
    keep = max(1, u.size // 2)
    return np.sort(np.argsort(u, kind="stable")[u.size - keep:])


def exact_solution_on_subset(qp: "QP", subset: np.ndarray | None = None, tol: float = CERTIFY_KKT,
                             max_rounds: int = MAX_SUBSET_ROUNDS, solve: SubsetSolve | None = None) -> SubsetSolution:
    """The exact solution of the LCP of ``qp`` (any H positive definite on proper
    subsets: a periodic whole-grid problem) by solves on a growing proper subset T
    (module doc), starting from ``subset`` (positions; default ``top_half_subset``).
    ``solve`` is the exact solve on T (default: ``exact_solution`` of the plain LCP; the
    bounded and load-controlled one: ``mixed_lcp.constrained_solution_on_subset``).
    Certified when the whole-problem scaled KKT error is at most ``tol``; else
    ``UncertifiedSolutionError`` saying why (T would be the whole problem, no point off
    T penetrates yet the check fails, or ``max_rounds`` solves did not do)."""
    u = np.asarray(qp.ubar, dtype=np.float64)
    n = u.size
    T = top_half_subset(u) if subset is None else np.unique(np.asarray(subset, dtype=np.int64))
    if solve is None:
        def solve(T: np.ndarray) -> tuple[np.ndarray, float | None]:
            return exact_solution(qp.H.submatrix(T, T), u[T]).p, None
    err = float("inf")
    for rnd in range(1, max_rounds + 1):
        p_T, delta = solve(T)
        p = np.zeros(n)
        p[T] = p_T
        err = kkt_check(qp, p, delta).kkt_error
        if err <= tol:
            return SubsetSolution(p, err, T, rnd, delta)
        w = qp.H.matvec(p) - u - (delta or 0.0)
        off = np.ones(n, dtype=bool)
        off[T] = False
        missed = np.flatnonzero(off & (w < 0.0))
        if missed.size == 0:
            raise UncertifiedSolutionError(
                f"the solution on {T.size} of {n} points has whole-problem KKT error {err:.2e} > {tol:g} "
                "and no point off the subset penetrates: the subset solve is inexact")
        if T.size + missed.size >= n:
            raise UncertifiedSolutionError(
                f"{missed.size} points off a subset of {T.size} of {n} penetrate: the subset would be the "
                "whole problem, where H may be singular")
        T = np.union1d(T, missed)
    raise UncertifiedSolutionError(f"no certified solution after {max_rounds} subset solves "
                                   f"(last KKT error {err:.2e} > {tol:g} on {T.size} of {n} points)")
