"""Equilibration, dense-H assembly and the adapter skeleton shared by the QP adapters.

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
    u~ = D ubar / s,   s = max_i |(D ubar)_i|   (so max |u~| = 1; s = 1 where s D
                                              underflows or s overflows),

    min 1/2 p~' H~ p~ - u~' p~,  p~ >= 0,

whose objective is the original one divided by s^2 and whose feasible set is the same
cone (D > 0, s > 0).  Then p = s D p~ and the gap w = Hp - ubar = s D^{-1} w~.  For the
BCC and Love kernels diag(H) is constant, so D is a multiple of the identity and every
scaled figure is order one: H~_ij in (0, 1], u~ in [0, 1], p~ = O(1).

Under load control the relief is not always the problem's length: the judge's
displacement scale u_s (``problems.kkt.constrained_scales``) is then the load's own where
the load is heavy or light for the relief (or the surface flat), and s is max |D ubar|
times u_s / ||ubar||_inf (``equilibration_for``), so w~ and p~ are read in the judge's
scales and the load row below stays order one (on heights at 1e-300 under
P / (E A) = 1e-3 the relief's s put its right-hand side at 1e292, past OSQP's 1e30).

Bounds and a load equality (``problems.constraints``) scale with p: the box 0 <= p <= u
is 0 <= p~ <= u / (s d) (``ScaledQP.ub``) and sum(p) = P is the row d'p~ = P / s,
stated divided by max(d) so that its entries are at most one (``ScaledQP.eq_row``,
``eq_rhs``); a backend states them natively (qpsolvers' ``lb``,
``ub``, ``A``, ``b``; CVXPY's constraints).  The approach Delta (the row's multiplier) is
not read from the backend: the lifecycle fits it from the answer.

The parameter ``scaling=False`` selects the raw mode (d = 1, s = 1: the backend sees H
and ubar exactly as given), kept so stress tests can show what unscaled use does.

The adapter lifecycle (``EquilibratedAdapter.iterate``)
-------------------------------------------------------
1. ``assemble_scaled`` fetches dense H (the operator's own array when ``qp.H`` is a
   ``DenseOperator`` -- the harness shares one per instance -- else ``to_dense`` under
   the memory budget), scales it and the warm start;
2. ``prepare`` converts it into the backend's input (CSC matrix, CVXPY model);
   steps 1-2 are *build* time: ``ctx.mark_setup_done()`` (``SolveResult.setup_time``),
   plus any build work the backend call reports itself (CVXPY's compilation);
3. ``run_backend`` calls the backend with ``Request`` (the tolerance asked, else the
   caller's check ``SolverSettings.check_tol`` -- None when neither is said: the
   backend's own defaults --, iteration and time limits); its setup, factorization and
   iterations are solve time;
4. the labelled ``+polish`` variants repair the point by block principal pivoting
   (``contactbench.problems.lcp.bpp_polish``; under bounds or a load equality
   ``problems.mixed_lcp.box_polish`` on the original problem); plain adapters never polish;
5. unscaling, and an ``Outcome`` whose status is the ``Status`` enum, with the
   backend's own word in ``info["backend_status"]``; a claim of convergence on an
   answer above the caller's check is withdrawn (``checked_claim``: "stalled").
"""

from __future__ import annotations

import importlib
import sys
import time
from abc import abstractmethod
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from contactbench.problems.instances import QP
from contactbench.problems.constraints import Constraints, fit_multiplier
from contactbench.problems.kkt import constrained_kkt_error, constrained_scales
from contactbench.problems.lcp import bpp_polish
from contactbench.problems.mixed_lcp import box_polish
from contactbench.problems.operators import DenseOperator, memory_budget

from .base import Outcome, Param, SolveContext, Solver, Status

#: Bytes of one dense n x n float64 matrix, the unit of every adapter's memory model.
BYTES_PER_ENTRY = 8.0

#: ``default_max_iter`` of an adapter: no limit of ours, the backend keeps its own.
BACKEND_DEFAULT_MAX_ITER = sys.maxsize

SCALING = Param("scaling", bool, True, "Jacobi+rhs equilibration (False: raw SI units)")
BACKEND_OPTIONS = Param("backend_options", dict, {}, "the backend's own options, over the mapped ones")


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


def equilibration_for(diag_H: np.ndarray, ubar: np.ndarray, enabled: bool = True,
                      constraints: Constraints | None = None) -> Equilibration:
    """The Jacobi-plus-rhs equilibration of the module doc (identity when disabled):
    s = max |D ubar| u_s / ||ubar||_inf, the scaled relief with its length put to the
    judge's displacement scale u_s (``kkt.constrained_scales`` of ``constraints``) --
    max |D ubar| itself without a load, where u_s is the relief; the load's own length
    where it sets u_s (a load heavy for the relief, a flat surface: then max(d) u_s),
    so the load row's P / (s max d) is the load in force scales, not P over the relief's
    (1e292 on heights at 1e-300).  s = 1 where s d underflows or s overflows."""
    ubar = np.asarray(ubar, dtype=np.float64)
    n = int(ubar.size)
    if not enabled:
        return Equilibration(np.ones(n), 1.0, False)
    diag_H = np.asarray(diag_H, dtype=np.float64)
    if np.any(~np.isfinite(diag_H)) or np.any(diag_H <= 0.0):
        raise ValueError("H must have a finite positive diagonal to be equilibrated")
    d = 1.0 / np.sqrt(diag_H)
    top = float(np.max(np.abs(ubar), initial=0.0))
    u_s, _ = constrained_scales(ubar, float(np.max(diag_H)), constraints or Constraints(), top)
    relief = float(np.max(np.abs(d * ubar), initial=0.0))
    if u_s == top:  # the relief is the length
        s = relief
    elif relief > 0.0:
        s = relief * (u_s / top)
    else:  # ubar = 0 (a flat surface under a load)
        s = float(np.max(d)) * u_s
    if not (s * float(np.min(d)) >= np.finfo(np.float64).tiny and s < np.inf):  # s d underflows, or s overflows
        s = 1.0
    return Equilibration(d, s, True)


def dense_matrix(qp: QP, budget: float | None = None) -> np.ndarray:
    """Dense H: the shared array of a DenseOperator (no copy), else assembled from the
    operator under the memory budget (raises MemoryBudgetError with the estimate)."""
    if isinstance(qp.H, DenseOperator):
        return qp.H.H
    return qp.H.to_dense(memory_budget() if budget is None else budget)


@dataclass
class ScaledQP:
    """The (possibly) equilibrated dense problem handed to a backend."""

    H: np.ndarray
    u: np.ndarray
    eq: Equilibration
    x0: np.ndarray | None = None  # warm start in scaled units
    ub: np.ndarray | None = None  # upper bounds u / (s d) (None: none)
    eq_row: np.ndarray | None = None  # the load row d / max(d) (None: no load equality)
    eq_rhs: float = 0.0  # P / (s max(d))

    @property
    def n(self) -> int:
        return int(self.u.size)


def assemble_scaled(qp: QP, scaling: bool = True, p0: np.ndarray | None = None) -> ScaledQP:
    """Dense H, equilibrated (or raw), plus the scaled warm start ``p0`` (already
    validated and clipped to p >= 0 by the lifecycle; the scaling keeps its sign)."""
    H = dense_matrix(qp)
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    eq = equilibration_for(np.diag(H), ubar, scaling, qp.constraints)
    Hs = eq.scale_matrix(H)
    us = eq.scale_rhs(ubar)
    x0 = None if p0 is None else eq.to_scaled(p0)
    c = qp.constraints
    ub = None if not c.bounded else eq.to_scaled(c.upper_or_inf(qp.n))
    dmax = float(np.max(eq.d)) if eq.enabled else 1.0
    row = None if c.load is None else (eq.d / dmax if eq.enabled else np.ones(qp.n))
    rhs = 0.0 if c.load is None else float(c.load) / (eq.s * dmax)
    return ScaledQP(Hs, us, eq, x0, ub, row, rhs)


def dense_memory_model(n: int, copies: float) -> float:
    """Peak bytes ~ copies * 8 n^2 (dense H, its scaled copy and the backend's copies
    and factors, each counted in units of one dense n x n matrix)."""
    return copies * BYTES_PER_ENTRY * float(n) * float(n)


def power_time_model(n: int, coef: float, exponent: float) -> float:
    """t ~ coef * n^exponent seconds (calibrated by benchmarks/bench_qp_backends.py)."""
    return float(coef * float(n) ** exponent)


@dataclass(frozen=True)
class Request:
    """What the harness asked for, in the backend-neutral form the option maps read."""

    tol: float | None  # the scaled KKT error to reach (None: the backend's own defaults)
    max_iter: int | None  # None: the backend's own limit
    time_limit: float | None  # seconds left of the solve's one deadline


def request_of(ctx: SolveContext) -> Request:
    """The request of this solve: the tolerance (``ctx.tol``; when none is asked, the
    check the answer will be judged at, ``ctx.check_tol``, so that the backend stops where
    its claim meets the check; None only when neither is said: the backend's defaults),
    the iteration limit asked for (None when it is the adapter's
    ``BACKEND_DEFAULT_MAX_ITER``) and the time left."""
    max_iter = None if ctx.max_iter >= BACKEND_DEFAULT_MAX_ITER else int(ctx.max_iter)
    tol = ctx.tol if ctx.tol is not None else ctx.check_tol
    return Request(tol, max_iter, ctx.deadline.remaining())


def finite_claim(out: Outcome) -> Outcome:
    """``out`` unless it claims convergence with a p that is not finite; that claim is
    withdrawn (FAILED, p kept as it came): an answer past float64's range (ubar / H near
    1e310, or a scaled answer that overflows on the way back to the problem's units) is no
    solution, whatever the solve's own check said of it.  An outcome that claims nothing
    keeps its own status and message."""
    bad = int(np.count_nonzero(~np.isfinite(out.p)))
    if not out.converged or not bad:
        return out
    return replace(out, converged=False, status=Status.FAILED,
                   message=f"{out.message}; the answer has {bad} non-finite entries of {np.size(out.p)} (beyond "
                           "float64's range): not claimed")


def checked_claim(ctx: SolveContext, out: Outcome) -> Outcome:
    """``out`` with its claim of convergence withdrawn: FAILED where its p is not finite
    (``finite_claim``); status "stalled", the backend's word kept in ``info``, when the
    answer's scaled KKT error (``SolveContext.kkt``, the harness's formula) is above the
    check the caller will judge it at (``ctx.check_tol``): a backend's own stopping test is
    in its own norms, so an adapter verifies a claim before making it.  Unchanged
    without a claim, and but for finiteness without a check."""
    out = finite_claim(out)
    if not out.converged or ctx.check_tol is None or out.w is None:
        return out
    kkt = ctx.kkt(out.p, out.w, out.multiplier)
    out.info["claim_kkt"] = kkt
    if kkt <= ctx.check_tol:
        return out
    out.converged, out.status = False, Status.STALLED
    out.message = (f"{out.message}; the backend reports solved, but the answer's scaled KKT error {kkt:.2e} is above "
                   f"the check {ctx.check_tol:.0e}: not claimed")
    return out


@dataclass
class BackendOutcome:
    """What a backend call returns, in scaled units."""

    x: np.ndarray | None
    status: str  # the backend's own word
    converged: bool
    iterations: int = 0
    late_build_time: float = 0.0  # build work inside the backend call (CVXPY's compilation)
    backend_setup_time: float | None = None  # backend's own setup/factorization (solve time)
    backend_solve_time: float | None = None
    info: dict[str, Any] = field(default_factory=dict)


def status_of(out: BackendOutcome, finite: bool, expired: bool) -> Status:
    """The ``Status`` of a backend's outcome; its own word stays in ``backend_status``."""
    word = out.status.lower()
    if not finite:
        return Status.FAILED
    if out.converged:
        return Status.CONVERGED
    if expired or "time" in word:
        return Status.TIME_LIMIT
    if "iter" in word or "limit" in word:
        return Status.MAX_ITER
    return Status.STALLED


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
    """Base of every generic-QP adapter (module doc, "The adapter lifecycle"): dense H
    (shared or assembled), equilibration, one backend call in scaled units, optional
    labelled polish, unscaling.  ``ctx.tol`` and ``ctx.check_tol`` both None mean the
    backend's own defaults.

    Subclasses set ``required_package``, may override ``prepare`` (build work) and
    implement ``run_backend``; they own their tolerance mapping."""

    family: ClassVar[str] = "qp"
    required_package: ClassVar[str] = ""
    polish: ClassVar[bool] = False
    default_tol: ClassVar[float | None] = None
    params: ClassVar[tuple[Param, ...]] = (SCALING,)
    #: memory model: peak bytes ~ memory_copies * 8 n^2; time model: t ~ coef * n^exponent.
    memory_copies: ClassVar[float] = 4.0
    time_coef: ClassVar[float] = 1e-9
    time_exponent: ClassVar[float] = 3.0
    time_scales_with_grid: ClassVar[bool] = False

    def default_max_iter(self, n: int) -> int:
        return BACKEND_DEFAULT_MAX_ITER

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

    def prepare(self, sqp: ScaledQP, ctx: SolveContext) -> Any:
        """Build work before the backend call (format conversion, modelling); its result
        is handed to ``run_backend``.  Default: nothing to do."""
        return None

    @abstractmethod
    def run_backend(self, sqp: ScaledQP, prepared: Any, ctx: SolveContext) -> BackendOutcome:
        """Run the backend on sqp.H, sqp.u (scaled units) for ``request_of(ctx)``."""

    def iterate(self, ctx: SolveContext) -> Outcome:
        """The equilibrated solve (module doc)."""
        self.require_available()
        t0 = time.perf_counter()
        sqp = assemble_scaled(ctx.qp, bool(ctx.params["scaling"]), ctx.p0)
        prepared = self.prepare(sqp, ctx)
        build_time = time.perf_counter() - t0
        ctx.mark_setup_done()
        out = self.run_backend(sqp, prepared, ctx)
        if out.late_build_time:
            ctx.add_setup_time(out.late_build_time)
        info: dict[str, Any] = {
            "scaling": "jacobi+rhs" if sqp.eq.enabled else "raw",
            "scale_s": sqp.eq.s,
            "build_time": build_time + out.late_build_time,
            "backend_status": out.status,
            "backend_setup_time": out.backend_setup_time,
            "backend_solve_time": out.backend_solve_time,
            **out.info,
        }
        x = out.x
        finite = x is not None and x.shape == sqp.u.shape and bool(np.all(np.isfinite(x)))
        status = status_of(out, finite, ctx.expired())
        if not finite:
            return Outcome(np.full(sqp.n, np.nan), out.iterations, False,
                           f"backend returned no finite solution (backend status: {out.status})", status=status,
                           info=info)
        if self.polish and not ctx.constraints.plain:
            return checked_claim(ctx, self._constrained_polish(sqp, x, ctx, status, info))
        if self.polish:
            t1 = time.perf_counter()
            try:
                pol = bpp_polish(sqp.H, sqp.u, x)
            except np.linalg.LinAlgError as exc:  # a singular block (a periodic grid's whole set): unpolished
                info.update(polish_time=time.perf_counter() - t1, polish_error=str(exc), polish_improved=False)
            else:
                info.update(polish_time=time.perf_counter() - t1, polish_rounds=pol.rounds,
                            polish_converged=pol.converged, polish_improved=pol.improved, polish_active=pol.active)
                x = pol.p
        return checked_claim(ctx, Outcome(
            p=sqp.eq.to_original(x),
            iterations=out.iterations,
            converged=out.converged,
            message=f"{self.name}: backend status {out.status}",
            w=sqp.eq.gap_to_original(sqp.H @ x - sqp.u),
            status=status,
            info=info,
        ))

    def _constrained_polish(self, sqp: ScaledQP, x: np.ndarray, ctx: SolveContext, status: Status,
                            info: dict[str, Any]) -> Outcome:
        """Step 4 under bounds or a load equality: ``box_polish`` on the original dense
        problem from the backend's point, kept when its KKT error is no worse."""
        t1 = time.perf_counter()
        qp, c = ctx.qp, ctx.constraints
        H = dense_matrix(qp)
        p0 = sqp.eq.to_original(x)
        g0 = sqp.eq.gap_to_original(sqp.H @ x - sqp.u)
        d0 = fit_multiplier(g0, p0, c.upper) if c.load_control else 0.0
        try:
            pol = box_polish(H, np.asarray(qp.ubar, dtype=np.float64), c, p0, d0)
        except np.linalg.LinAlgError as exc:  # a singular block: the backend's point stands, unpolished
            info.update(polish_time=time.perf_counter() - t1, polish_error=str(exc), polish_improved=False)
            return Outcome(p=p0, iterations=0, converged=status is Status.CONVERGED,
                           message=f"{self.name}: polish broke down ({exc})", w=g0, status=status, info=info)
        g1 = H @ pol.p - qp.ubar
        better = (ctx.kkt(pol.p, g1, pol.multiplier if c.load_control else None)
                  <= constrained_kkt_error(p0, g0, qp.ubar, ctx.diag_max, c, None))
        info.update(polish_time=time.perf_counter() - t1, polish_rounds=pol.rounds, polish_converged=pol.converged,
                    polish_improved=better)
        p, g = (pol.p, g1) if better else (p0, g0)
        mult = pol.multiplier if better and c.load_control else None
        return Outcome(p=p, iterations=0, converged=status is Status.CONVERGED, message=f"{self.name}: polished",
                       w=g, status=status, info=info, multiplier=mult)
