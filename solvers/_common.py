"""Shared machinery of the paper's solvers (Bemporad & Paggi 2015, section 3).

Not a solver module (leading underscore: the registry does not import it).  It holds

* ``Scales``: the scale-invariant yardsticks every stopping test uses -- a displacement
  scale u_s = ||ubar||_inf and a force scale p_s = u_s / max(diag H) (the force that
  alone indents one element by u_s), the same yardsticks as ``harness.kkt``;
* ``natural_residual``: the KKT residual ||min(p * dmax, w)||_inf / u_s of the LCP
  (zero exactly at the solution; invariant under E -> cE and lengths -> cL);
* ``conjugate_gradient``: CG on an SPD operator (optionally ``a H + c I``), warm
  started from x0, stopping on the scaled residual, a deadline and an iteration cap;
* ``lipschitz_constant``: the Frobenius-norm bound (paper) or a power-iteration estimate;
* ``project_nonneg``, ``Deadline``, ``MatvecTally`` and ``RunRecorder`` (builds the
  ``SolveResult`` with trace, matvecs, status and timing);
* ``matvec_seconds``: a rough cost model for ``time_estimate``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contactbench.problems.instances import QP
from contactbench.problems.operators import ContactOperator, DenseOperator, spectral_norm_estimate

from .base import SolveResult, Solver, SolverSettings, Trace, WarmStart

#: Default relative tolerance of the exact (finite-termination) methods.
EXACT_TOL = 1e-10
#: Default relative tolerance of the first-order methods (GP, ADMM).
FIRST_ORDER_TOL = 1e-6


# ---------------------------------------------------------------------------
# Scales and stopping tests
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Scales:
    """Unit-free yardsticks of one QP: u_s [length], p_s [force], dmax [length/force]."""

    u_s: float
    p_s: float
    dmax: float

    @classmethod
    def of(cls, qp: QP) -> "Scales":
        u_s = float(np.max(np.abs(qp.ubar), initial=0.0)) or 1.0
        dmax = float(np.max(qp.H.diagonal()))
        return cls(u_s=u_s, p_s=u_s / dmax, dmax=dmax)

    def force_tol(self, tol: float) -> float:
        """Absolute force threshold for a relative tolerance."""
        return tol * self.p_s

    def disp_tol(self, tol: float) -> float:
        """Absolute displacement threshold for a relative tolerance."""
        return tol * self.u_s


def natural_residual(p: np.ndarray, w: np.ndarray, sc: Scales) -> float:
    """||min(p dmax, w)||_inf / u_s: the scaled natural-map residual of the LCP
    w = Hp - ubar >= 0, p >= 0, w'p = 0 (zero iff p solves the QP)."""
    if p.size == 0:
        return 0.0
    return float(np.max(np.abs(np.minimum(p * sc.dmax, w)))) / sc.u_s


def project_nonneg(x: np.ndarray) -> np.ndarray:
    """Projection onto p >= 0 (in place)."""
    return np.maximum(x, 0.0, out=x)


# ---------------------------------------------------------------------------
# Time limit, matvec accounting
# ---------------------------------------------------------------------------


class Deadline:
    """settings.time_limit as a cheap predicate."""

    def __init__(self, time_limit: float | None) -> None:
        self.t_end = None if time_limit is None else time.perf_counter() + float(time_limit)

    def expired(self) -> bool:
        return self.t_end is not None and time.perf_counter() > self.t_end


class MatvecTally:
    """Sums matvec_count over the operator and every restriction made from it."""

    def __init__(self) -> None:
        self._ops: list[tuple[ContactOperator, int]] = []

    def track(self, op: ContactOperator) -> ContactOperator:
        self._ops.append((op, op.matvec_count))
        return op

    def total(self) -> int:
        return int(sum(op.matvec_count - c0 for op, c0 in self._ops))


# ---------------------------------------------------------------------------
# Conjugate gradient (warm-started, on an operator or a restriction of it)
# ---------------------------------------------------------------------------


@dataclass
class CGResult:
    x: np.ndarray
    iterations: int
    residual: float  # ||r||_inf, absolute
    converged: bool


def conjugate_gradient(
    op: ContactOperator,
    b: np.ndarray,
    x0: np.ndarray | None,
    atol: float,
    max_iter: int,
    deadline: Deadline | None = None,
    scale: float = 1.0,
    shift: float = 0.0,
) -> CGResult:
    """Solve (scale H + shift I) x = b by conjugate gradients from x0 (Hestenes-Stiefel,
    as in paper Algorithm 1 steps 2.1-2.4), until ||b - A x||_inf <= atol."""
    n = b.size
    if n == 0:
        return CGResult(np.zeros(0), 0, 0.0, True)

    def amul(v: np.ndarray) -> np.ndarray:
        out = op.matvec(v)
        if scale != 1.0:
            out *= scale
        if shift:
            out += shift * v
        return out

    x = np.zeros(n) if x0 is None else np.array(x0, dtype=np.float64, copy=True)
    r = b - amul(x) if np.any(x) else b.copy()
    res = float(np.max(np.abs(r)))
    d = r.copy()
    rr = float(r @ r)
    it = 0
    while res > atol and it < max_iter and not (deadline is not None and deadline.expired()):
        q = amul(d)
        dq = float(d @ q)
        if dq <= 0.0:  # loss of positive definiteness by round-off: stop here
            break
        alpha = rr / dq
        x += alpha * d
        r -= alpha * q
        rr_new = float(r @ r)
        d *= rr_new / rr
        d += r
        rr = rr_new
        res = float(np.max(np.abs(r)))
        it += 1
        if res <= atol:  # confirm on the true residual (recurrence drift)
            r = b - amul(x)
            res = float(np.max(np.abs(r)))
            rr = float(r @ r)
            d = r.copy()
    return CGResult(x, it, res, res <= atol)


# ---------------------------------------------------------------------------
# Lipschitz constant of the gradient Hp - ubar
# ---------------------------------------------------------------------------


def lipschitz_constant(op: ContactOperator, method: str) -> float:
    """"frobenius": ||H||_F (paper Algorithm 4; a safe upper bound of lambda_max);
    "power": lambda_max by power iteration (spectral_norm_estimate, inflated 1 %)."""
    if method == "frobenius":
        return op.frobenius_norm()
    if method == "power":
        return spectral_norm_estimate(op, iters=50, rtol=1e-4)
    raise ValueError(f"lipschitz must be 'frobenius' or 'power', got {method!r}")


# ---------------------------------------------------------------------------
# Result building
# ---------------------------------------------------------------------------


def is_dense(op: ContactOperator) -> bool:
    return isinstance(op, DenseOperator)


def operator_kind(op: ContactOperator) -> str:
    return "dense" if is_dense(op) else "fft"


def warm_primal(warm: WarmStart | None, n: int) -> np.ndarray | None:
    """The warm-start p projected onto p >= 0, or None (absent / wrong length)."""
    if warm is None or warm.p is None:
        return None
    p = np.asarray(warm.p, dtype=np.float64)
    if p.shape != (n,):
        raise ValueError(f"warm-start p has shape {p.shape}, the problem has n = {n}")
    return np.maximum(p, 0.0)


def max_iter_of(settings: SolverSettings, default: int) -> int:
    return int(settings.max_iter) if settings.max_iter is not None else int(default)


@dataclass
class RunRecorder:
    """Collects trace, matvecs and timing of one solve and builds the SolveResult."""

    qp: QP
    settings: SolverSettings
    trace_every: int = 1
    tally: MatvecTally = field(default_factory=MatvecTally)
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.trace = Trace(self.trace_every)
        self.deadline = Deadline(self.settings.time_limit)
        self.tally.track(self.qp.H)
        self.setup_time = 0.0

    def mark_setup_done(self) -> None:
        self.setup_time = self.trace.elapsed()

    def record(self, it: int, residual: float) -> None:
        self.trace.record(it, residual)

    def result(
        self,
        p: np.ndarray,
        iterations: int,
        converged: bool,
        status: str,
        message: str,
        warm_started: bool,
        w: np.ndarray | None = None,
    ) -> SolveResult:
        """Final record.  w is recomputed as Hp - ubar when not supplied (one matvec)."""
        if w is None:
            w = self.qp.H.matvec(p) - self.qp.ubar
        return SolveResult(
            p=p,
            w=w,
            iterations=int(iterations),
            converged=bool(converged),
            status=status,
            message=message,
            solve_time=self.trace.elapsed(),
            setup_time=self.setup_time,
            matvecs=self.tally.total(),
            warm_started=bool(warm_started),
            trace=list(self.trace.points),
            info=dict(self.info),
        )

    def stop_status(self, converged: bool) -> tuple[str, str]:
        if converged:
            return "converged", "converged to tolerance"
        if self.deadline.expired():
            return "time_limit", "time limit reached before convergence"
        return "max_iter", "iteration limit reached before convergence"

    def trivial(self, warm_started: bool) -> SolveResult | None:
        """ubar <= 0 everywhere: p = 0 is the solution (no contact)."""
        if np.max(self.qp.ubar, initial=0.0) > 0.0:
            return None
        p = np.zeros(self.qp.n)
        return self.result(p, 0, True, "converged", "ubar <= 0: no contact, p = 0", warm_started)


# ---------------------------------------------------------------------------
# Rough cost model for time_estimate
# ---------------------------------------------------------------------------

#: Effective dense GEMV throughput (flop/s) and FFT cost per padded point on one core.
DENSE_FLOPS = 2.0e9
FFT_SECONDS_PER_POINT = 4.0e-8
#: Padded FFT grid points per trial-set unknown at the paper's top load step
#: (trial set ~ 14 % of N^2, aperiodic padding x 4).
FFT_POINTS_PER_UNKNOWN = 28.0


def matvec_seconds(n: int, operator_kind_: str) -> float:
    """Rough wall time of one H matvec at size n on one core."""
    if operator_kind_ == "dense":
        return 2.0 * n * n / DENSE_FLOPS
    pts = FFT_POINTS_PER_UNKNOWN * n
    return FFT_SECONDS_PER_POINT * pts * max(1.0, np.log2(pts)) / 10.0


def cholesky_seconds(n: int) -> float:
    return (n**3 / 3.0) / (5.0 * DENSE_FLOPS)


class PrimalWarmSolver(Solver):
    """Shared prologue of the paper's iterative solvers: set up the recorder, take the
    primal warm start, return at once on a trivial problem (ubar <= 0), then ``run``."""

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        rec = RunRecorder(qp, settings)
        p0 = warm_primal(warm, qp.n)
        trivial = rec.trivial(p0 is not None)
        if trivial is not None:
            return trivial
        return self.run(qp, settings, warm, rec, p0)

    def run(self, qp: QP, settings: SolverSettings, warm: WarmStart | None, rec: "RunRecorder",
            p0: np.ndarray | None) -> SolveResult:
        raise NotImplementedError
