"""Equilibration, dense-H assembly and active-set polish shared by the QP adapters.

Why scaling matters
-------------------
The contact QP  min 1/2 p'Hp - ubar'p, p >= 0  (Bemporad & Paggi 2015, eq. (6)) is
badly scaled in SI units: H ~ 4e-6 m/N and ubar ~ 1e-6 m give p ~ 1e-1 N, while the
objective is ~1e-7.  Generic QP solvers test absolute tolerances (1e-3 ... 1e-9)
against such numbers, so several of them (OSQP, SCS, QPALM) stop at p ~ 0 and report
success, and others (Clarabel, PIQP, HiGHS) stop 2-3 % off.

The equilibration
-----------------
Every adapter solves, by default, the scaled problem

    p = s D p~,   D = diag(d),  d_i = 1 / sqrt(H_ii),
    H~ = D H D                       (unit diagonal: a symmetric Jacobi scaling),
    u~ = D ubar / s,   s = max_i |(D ubar)_i|   (so max |u~| = 1; s = 1 when ubar = 0),

    min 1/2 p~' H~ p~ - u~' p~,  p~ >= 0,

whose objective is the original one divided by s^2 and whose feasible set is the same
cone (D > 0, s > 0).  Then p = s D p~ and the gap w = Hp - ubar = s D^{-1} w~.  For the
BCC and Love kernels diag(H) is constant, so D is a multiple of the identity and every
scaled figure is order one: H~_ij in (0, 1], u~ in [0, 1], p~ = O(1).

``settings.params["scaling"] = False`` selects the raw mode (d = 1, s = 1: the
backend sees H and ubar exactly as given), kept so stress tests can show what
unscaled use does.

Build vs solve time
-------------------
``assemble_scaled`` fetches dense H (the operator's own array when ``qp.H`` is a
``DenseOperator`` -- the harness shares one per instance -- else ``to_dense`` under the
memory budget) and scales it.  That, and any format conversion an adapter does before
calling its backend, is *build* time (``SolveResult.setup_time``); the backend's own
setup and factorization count toward ``solve_time``.

Active-set polish
-----------------
``active_set_polish`` takes an approximate solution (from an interior-point solver,
which stalls near 1e-5 in p on nearly degenerate elements), guesses the contact set
A = {i : p~_i > w~_i}, solves H~_AA p~_A = u~_A exactly by Cholesky and repairs the
guess by block principal pivoting (Judice & Pires 1994: move negative p_A out of A,
violated w_i < 0 into A; after three rounds without fewer violations fall back to
Murty's single least-index pivot, which terminates).  It is used only by the
explicitly labelled ``+polish`` variants, never inside a plain adapter.
"""

from __future__ import annotations

import time
import importlib
from abc import abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import scipy.linalg as sla

from contactbench.problems.instances import QP
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET, DenseOperator

from .base import SolveResult, Solver, SolverSettings, WarmStart

#: Bytes of one dense n x n float64 matrix, the unit of every adapter's memory model.
BYTES_PER_ENTRY = 8.0


@dataclass(frozen=True)
class Equilibration:
    """p = s * d * p~ (see module doc).  ``enabled`` is False in raw mode (d = 1, s = 1)."""

    d: np.ndarray
    s: float
    enabled: bool

    def scale_matrix(self, H: np.ndarray) -> np.ndarray:
        """H~ = D H D as a new array (H itself, uncopied, in raw mode)."""
        if not self.enabled:
            return H
        d = self.d
        if np.all(d == d[0]):
            return H * float(d[0] * d[0])
        Hs = H * d[:, None]
        Hs *= d[None, :]
        return Hs

    def scale_rhs(self, ubar: np.ndarray) -> np.ndarray:
        return self.d * ubar / self.s

    def to_scaled(self, p: np.ndarray) -> np.ndarray:
        """p~ for a warm start p in original units."""
        return np.asarray(p, dtype=np.float64) / (self.s * self.d)

    def to_original(self, p_scaled: np.ndarray) -> np.ndarray:
        return self.s * self.d * np.asarray(p_scaled, dtype=np.float64)

    def gap_to_original(self, w_scaled: np.ndarray) -> np.ndarray:
        """w = Hp - ubar from w~ = H~p~ - u~."""
        return self.s * np.asarray(w_scaled, dtype=np.float64) / self.d


def equilibration_for(diag_H: np.ndarray, ubar: np.ndarray, enabled: bool = True) -> Equilibration:
    """The Jacobi-plus-rhs equilibration of the module doc (identity when disabled)."""
    n = int(np.asarray(ubar).size)
    if not enabled:
        return Equilibration(np.ones(n), 1.0, False)
    diag_H = np.asarray(diag_H, dtype=np.float64)
    if np.any(~np.isfinite(diag_H)) or np.any(diag_H <= 0.0):
        raise ValueError("H must have a finite positive diagonal to be equilibrated")
    d = 1.0 / np.sqrt(diag_H)
    s = float(np.max(np.abs(d * ubar), initial=0.0))
    return Equilibration(d, s if s > 0.0 else 1.0, True)


def scaling_requested(settings: SolverSettings) -> bool:
    """True unless the caller asked for the raw mode (params {"scaling": False})."""
    return bool(settings.param("scaling", True))


def requested_tolerance(settings: SolverSettings) -> float | None:
    """The tolerance asked for, or None for the ``default`` profile (backend defaults)."""
    return None if settings.tol is None else float(settings.tol)


def dense_matrix(qp: QP, budget: float | None = None) -> np.ndarray:
    """Dense H: the shared array of a DenseOperator (no copy), else assembled from the
    operator under the memory budget (raises MemoryBudgetError with the estimate)."""
    if isinstance(qp.H, DenseOperator):
        return qp.H.H
    return qp.H.to_dense(DEFAULT_MEMORY_BUDGET if budget is None else budget)


@dataclass
class ScaledQP:
    """The (possibly) equilibrated dense problem handed to a backend."""

    H: np.ndarray
    u: np.ndarray
    eq: Equilibration
    build_time: float
    x0: np.ndarray | None = None  # warm start in scaled units

    @property
    def n(self) -> int:
        return int(self.u.size)


def assemble_scaled(qp: QP, settings: SolverSettings, warm_p: np.ndarray | None = None) -> ScaledQP:
    """Dense H, equilibrated (or raw), plus a scaled warm start; timed as build time."""
    t0 = time.perf_counter()
    H = dense_matrix(qp)
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    eq = equilibration_for(np.diag(H), ubar, scaling_requested(settings))
    Hs = eq.scale_matrix(H)
    us = eq.scale_rhs(ubar)
    x0 = None
    if warm_p is not None:
        warm_p = np.asarray(warm_p, dtype=np.float64)
        if warm_p.shape == ubar.shape:
            x0 = np.maximum(eq.to_scaled(warm_p), 0.0)
    return ScaledQP(Hs, us, eq, time.perf_counter() - t0, x0)


def dense_memory_model(n: int, copies: float) -> float:
    """Peak bytes ~ copies * 8 n^2 (dense H, its scaled copy and the backend's copies
    and factors, each counted in units of one dense n x n matrix)."""
    return copies * BYTES_PER_ENTRY * float(n) * float(n)


def power_time_model(n: int, coef: float, exponent: float) -> float:
    """t ~ coef * n^exponent seconds (calibrated by benchmarks/bench_qp_backends.py)."""
    return float(coef * float(n) ** exponent)


# ---------------------------------------------------------------------------
# Active-set polish (for the labelled "+polish" variants only)
# ---------------------------------------------------------------------------


@dataclass
class PolishOutcome:
    p: np.ndarray  # scaled units
    rounds: int
    converged: bool
    active: int
    improved: bool
    history: list[int] = field(default_factory=list)  # violations per round


def scaled_kkt_residual(H: np.ndarray, u: np.ndarray, p: np.ndarray) -> float:
    """max(primal, dual, complementarity) in the (order-one) scaled units."""
    w = H @ p - u
    return float(max(np.max(-p, initial=0.0), np.max(-w, initial=0.0), np.max(np.abs(w * p), initial=0.0)))


def _solve_on_set(H: np.ndarray, u: np.ndarray, active: np.ndarray) -> np.ndarray:
    p = np.zeros_like(u)
    idx = np.flatnonzero(active)
    if idx.size:
        c = sla.cho_factor(H[np.ix_(idx, idx)], lower=True, check_finite=False)
        p[idx] = sla.cho_solve(c, u[idx], check_finite=False)
    return p


def active_set_polish(H: np.ndarray, u: np.ndarray, p0: np.ndarray, max_rounds: int = 50,
                      tol: float = 1e-11) -> PolishOutcome:
    """Exact solve on the contact set detected from ``p0`` plus a check/repair loop
    (block principal pivoting with Murty fallback, see module doc).  Returns the
    polished point only when it is better than ``p0`` by the scaled KKT residual."""
    p0 = np.asarray(p0, dtype=np.float64)
    w0 = H @ p0 - u
    active = p0 > w0
    scale = max(1.0, float(np.max(np.abs(u), initial=0.0)))
    best_viol, stall, history = np.inf, 0, []
    p = p0
    for rnd in range(1, max_rounds + 1):
        p = _solve_on_set(H, u, active)
        w = H @ p - u
        bad_p = active & (p < -tol * scale)
        bad_w = ~active & (w < -tol * scale)
        nviol = int(np.count_nonzero(bad_p) + np.count_nonzero(bad_w))
        history.append(nviol)
        if nviol == 0:
            p = np.where(active, np.maximum(p, 0.0), 0.0)
            return _better_of(H, u, p0, p, rnd, True, int(active.sum()), history)
        if nviol < best_viol:
            best_viol, stall = nviol, 0
        else:
            stall += 1
        if stall < 3:
            active = (active & ~bad_p) | bad_w
        else:  # Murty's least-index rule: finite termination
            j = int(np.flatnonzero(bad_p | bad_w)[0])
            active[j] = not active[j]
    return _better_of(H, u, p0, np.maximum(p, 0.0), max_rounds, False, int(active.sum()), history)


def _better_of(H: np.ndarray, u: np.ndarray, p0: np.ndarray, p: np.ndarray, rounds: int, converged: bool,
               active: int, history: list[int]) -> PolishOutcome:
    improved = scaled_kkt_residual(H, u, p) <= scaled_kkt_residual(H, u, p0)
    return PolishOutcome(p if improved else p0, rounds, converged, active, improved, history)


# ---------------------------------------------------------------------------
# The adapter skeleton: build (assemble + scale), run the backend, unscale, record
# ---------------------------------------------------------------------------


@dataclass
class BackendOutcome:
    """What a backend call returns, in scaled units."""

    x: np.ndarray | None
    status: str
    converged: bool
    iterations: int = 0
    convert_time: float = 0.0  # adapter-side format conversion (build time)
    backend_setup_time: float | None = None  # backend's own setup/factorization (solve time)
    backend_solve_time: float | None = None
    warm_started: bool = False
    info: dict[str, Any] = field(default_factory=dict)


def missing_package_message(solver_name: str, package: str) -> str | None:
    """None when ``package`` imports, else why not ("not installed" / "failed to import")."""
    try:
        importlib.import_module(package)
    except ModuleNotFoundError as exc:
        if exc.name and package.split(".")[0] != exc.name.split(".")[0]:
            return f"failed to import {package}: {exc}"
        return f"not installed: pip install {package} to use solver {solver_name!r}"
    except Exception as exc:  # a broken install: say so rather than crash the registry
        return f"failed to import {package}: {type(exc).__name__}: {exc}"
    return None


class EquilibratedAdapter(Solver):
    """Base of every generic-QP adapter: dense H (shared or assembled), equilibration
    (module doc), one backend call in scaled units, optional labelled active-set polish,
    unscaling and a SolveResult carrying the backend's own status.

    Subclasses set ``required_package`` and implement ``solve_scaled``; they own their
    tolerance mapping (``tolerance_options``)."""

    family: ClassVar[str] = "qp"
    required_package: ClassVar[str] = ""
    polish: ClassVar[bool] = False
    #: memory model: peak bytes ~ memory_copies * 8 n^2; time model: t ~ coef * n^exponent.
    memory_copies: ClassVar[float] = 4.0
    time_coef: ClassVar[float] = 1e-9
    time_exponent: ClassVar[float] = 3.0

    def availability(self) -> tuple[bool, str]:
        why = missing_package_message(self.name, self.required_package) if self.required_package else None
        return (False, why) if why else (True, "available")

    def require_available(self) -> None:
        ok, why = self.availability()
        if not ok:
            raise RuntimeError(f"solver {self.name!r} cannot run: {why}")

    def memory_estimate(self, n: int) -> float:
        return dense_memory_model(n, self.memory_copies)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return power_time_model(n, self.time_coef, self.time_exponent)

    @abstractmethod
    def solve_scaled(self, sqp: ScaledQP, settings: SolverSettings) -> BackendOutcome:
        """Run the backend on sqp.H, sqp.u (scaled units) with the settings' tolerance."""

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        self.require_available()
        sqp = assemble_scaled(qp, settings, warm.p if warm is not None else None)
        t0 = time.perf_counter()
        out = self.solve_scaled(sqp, settings)
        backend_wall = time.perf_counter() - t0 - out.convert_time
        info: dict[str, Any] = {
            "scaling": "jacobi+rhs" if sqp.eq.enabled else "raw",
            "scale_s": sqp.eq.s,
            "build_time": sqp.build_time + out.convert_time,
            "backend_setup_time": out.backend_setup_time,
            "backend_solve_time": out.backend_solve_time,
            **out.info,
        }
        x = out.x
        if x is None or x.shape != sqp.u.shape or not np.all(np.isfinite(x)):
            x = np.full(sqp.n, np.nan) if x is None or x.shape != sqp.u.shape else x
            return self._result(sqp, x, out, backend_wall, info, "backend returned no finite solution")
        if self.polish:
            t1 = time.perf_counter()
            pol = active_set_polish(sqp.H, sqp.u, x)
            info.update(polish_time=time.perf_counter() - t1, polish_rounds=pol.rounds,
                        polish_converged=pol.converged, polish_improved=pol.improved, polish_active=pol.active)
            backend_wall += info["polish_time"]
            x = pol.p
        return self._result(sqp, x, out, backend_wall, info, "")

    def _result(self, sqp: ScaledQP, x: np.ndarray, out: BackendOutcome, wall: float, info: dict[str, Any],
                message: str) -> SolveResult:
        w = sqp.H @ x - sqp.u if np.all(np.isfinite(x)) else None
        return SolveResult(
            p=sqp.eq.to_original(x),
            w=None if w is None else sqp.eq.gap_to_original(w),
            iterations=out.iterations,
            converged=out.converged,
            status=out.status,
            message=message or f"{self.name}: backend status {out.status}",
            solve_time=wall,
            setup_time=sqp.build_time + out.convert_time,
            warm_started=out.warm_started,
            info=info,
        )
