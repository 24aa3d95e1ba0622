"""Shared pieces of the matrix-free "fast" solvers (solvers/fast_*.py).

* ``scaled_kkt``     -- the harness's scaled KKT error (harness/kkt.py) computed from
                        the solver's own gap g = Hp - ubar, so a solver stops exactly
                        when the harness will accept the answer (unit-invariant).
* ``start_point``    -- warm start p0 >= 0 from ``WarmStart`` (mapped by the harness
                        onto the current trial set), or the cold start p = 0.
* ``GapState``       -- p, g = Hp - ubar and the operator, with the cheap update
                        g += alpha * Hd after a linear step (no extra matvec), a full
                        recomputation when a projection changed p, and a periodic
                        refresh against round-off drift.
* ``fourier_inverse_preconditioner`` -- inverse of the continuous Boussinesq compliance
                        in Fourier space (~ |q| E*/2), applied on the grid and
                        gathered on a set (Vollebregt 2014's idea for BCCG / CG on the
                        active set).
* ``make_result``    -- the SolveResult all fast solvers return.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP
from contactbench.problems.operators import ContactOperator, FFTOperator, fft_workers

from .base import Capabilities, SolveResult, SolverSettings, Trace, WarmStart

#: Tolerance used when the profile sets none (the harness's "high" check is 1e-8).
DEFAULT_TOL = 1e-8

FAST_CAPABILITIES = Capabilities(
    operators=frozenset({"dense", "fft"}), needs_dense=False, warm_start="primal", exact=True
)


def scaled_kkt(p: np.ndarray, g: np.ndarray, ubar: np.ndarray, diag_max: float) -> float:
    """max(primal, dual, complementarity) exactly as harness.kkt.kkt_check scales them:
    u_s = max(|ubar|_inf, |Hp|_inf), p_s = u_s / max diag H."""
    hp = g + ubar
    u_s = max(float(np.max(np.abs(ubar), initial=0.0)), float(np.max(np.abs(hp), initial=0.0)))
    if u_s == 0.0:
        return 0.0
    p_s = u_s / diag_max
    primal = max(0.0, -float(np.min(p, initial=0.0))) / p_s
    dual = max(0.0, -float(np.min(g, initial=0.0))) / u_s
    comp = float(np.max(np.abs(g * p), initial=0.0)) / (u_s * p_s)
    return max(primal, dual, comp)


def check_qp(qp: QP) -> None:
    if qp.ubar.ndim != 1 or qp.ubar.size != qp.H.n:
        raise ProblemInputError(f"ubar has shape {qp.ubar.shape}, the operator has n = {qp.H.n}")
    if not np.all(np.isfinite(qp.ubar)):
        raise ProblemInputError("ubar contains non-finite values")


def start_point(qp: QP, warm: WarmStart | None) -> tuple[np.ndarray, bool]:
    """(p0 >= 0, warm_started)."""
    if warm is not None and warm.p is not None:
        p0 = np.asarray(warm.p, dtype=np.float64)
        if p0.shape != qp.ubar.shape:
            raise ProblemInputError(f"warm-start p has shape {p0.shape}, the problem has n = {qp.n}")
        return np.maximum(np.nan_to_num(p0, nan=0.0), 0.0), True
    return np.zeros(qp.n), False


@dataclass
class GapState:
    """Iterate p (>= 0) and its gap g = Hp - ubar, kept consistent at one matvec per
    linear step (plus one per projection that changes p)."""

    H: ContactOperator
    ubar: np.ndarray
    p: np.ndarray
    refresh_every: int = 50
    g: np.ndarray = field(init=False)
    _since_refresh: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        self.refresh()

    def refresh(self) -> None:
        """Recompute g from scratch (one matvec)."""
        self.g = self.H.matvec(self.p) - self.ubar
        self._since_refresh = 0

    def step(self, alpha: float, d: np.ndarray, Hd: np.ndarray) -> bool:
        """p <- max(p + alpha d, 0); returns True when the projection was active."""
        self.p += alpha * d
        clipped = self.p < 0.0
        if np.any(clipped):
            self.p[clipped] = 0.0
            self.refresh()
            return True
        self.g += alpha * Hd
        self._since_refresh += 1
        if self._since_refresh >= self.refresh_every:
            self.refresh()
        return False


def floored_wavenumbers(shape: tuple[int, int]) -> np.ndarray:
    """|q| on the rfft2 half-spectrum of a grid, |q(0, 0)| floored at the lowest
    non-zero wave number (so the multiplier below is positive definite)."""
    p0, p1 = shape
    q0 = 2.0 * np.pi * sfft.fftfreq(p0)
    q1 = 2.0 * np.pi * sfft.rfftfreq(p1)
    q = np.hypot(q0[:, None], q1[None, :])
    q[0, 0] = min(q0[1] if p0 > 1 else 1.0, q1[1] if q1.size > 1 else 1.0)
    return q


def multiply_by_wavenumbers(q: np.ndarray, shape: tuple[int, int], idx: np.ndarray, r: np.ndarray) -> np.ndarray:
    """gather_idx F^-1[ q F[scatter_idx r] ] on a grid of ``shape`` (flat indices idx)."""
    f = np.zeros(shape)
    f.ravel()[idx] = r
    w = fft_workers()
    F = sfft.rfft2(f, workers=w, overwrite_x=True)
    F *= q
    return sfft.irfft2(F, s=shape, workers=w, overwrite_x=True).ravel()[idx]


def fourier_inverse_preconditioner(qp: QP):
    """M^-1 r = gather_I F^-1[ |q| F[scatter_I r] ]: the inverse of the continuous
    half-space compliance 2/(E* |q|) up to a constant factor (PCG is invariant to it),
    with |q| floored at the lowest non-zero wave number, on the padded grid.  FFT
    operator only; returns None for other operators."""
    H = qp.H
    if not isinstance(H, FFTOperator):
        return None
    shape = H.transform.padded_shape
    q = floored_wavenumbers(shape)
    idx = H.pidx

    def apply(r: np.ndarray) -> np.ndarray:
        return multiply_by_wavenumbers(q, shape, idx, r)

    return apply


def make_result(
    state: GapState,
    *,
    iterations: int,
    kkt: float,
    tol: float,
    trace: Trace,
    matvecs0: int,
    warm_started: bool,
    setup_time: float,
    info: dict | None = None,
) -> SolveResult:
    converged = kkt <= tol
    return SolveResult(
        p=state.p,
        w=state.g,
        iterations=iterations,
        converged=converged,
        status="converged" if converged else "max_iter",
        message=f"scaled KKT error {kkt:.3e} (tol {tol:.1e}) after {iterations} iterations",
        solve_time=trace.elapsed(),
        setup_time=setup_time,
        matvecs=state.H.matvec_count - matvecs0,
        warm_started=warm_started,
        trace=trace.points,
        info=dict(info or {}),
    )


def iteration_limit(settings: SolverSettings, n: int) -> int:
    return int(settings.max_iter) if settings.max_iter else max(1000, 20 * int(np.sqrt(max(n, 1))) + 2000)


def time_left(t0: float, settings: SolverSettings) -> bool:
    return settings.time_limit is None or time.perf_counter() - t0 < float(settings.time_limit)


@dataclass
class FastStart:
    """What every fast solver sets up before iterating (shared prologue)."""

    tol: float
    warm_started: bool
    matvecs0: int
    diag_max: float
    state: "GapState"
    trace: Trace
    setup: float


def begin_fast_solve(qp: QP, settings: SolverSettings, warm: WarmStart | None) -> FastStart:
    """Check the QP, pick the tolerance, take the warm start and compute the first gap."""
    t0 = time.perf_counter()
    check_qp(qp)
    tol = settings.tolerance(DEFAULT_TOL)
    p0, warm_started = start_point(qp, warm)
    m0 = qp.H.matvec_count
    diag_max = float(np.max(qp.H.diagonal()))
    trace = Trace()
    state = GapState(qp.H, qp.ubar, p0)
    return FastStart(tol, warm_started, m0, diag_max, state, trace, time.perf_counter() - t0)
