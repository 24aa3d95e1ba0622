"""``scipy-nnls``: the classical baseline and the harness's default reference solver.

With the Cholesky factor H~ = L L' of the equilibrated matrix (``solvers._scaling``),

    1/2 p'H~p - u~'p = 1/2 || L'p - L^{-1} u~ ||^2 - 1/2 ||L^{-1} u~||^2,

so the contact QP (Bemporad & Paggi 2015, eq. (6)) is the non-negative least-squares
problem  min ||A p - b||, p >= 0  with A = L', b = L^{-1} u~, solved by
``scipy.optimize.nnls`` (the Lawson-Hanson active-set method, Lawson & Hanson 1974,
ch. 23, which the paper's section 4 also relates to).  Lawson-Hanson terminates finitely
with an exact solve on its final active set, hence ``exact=True``.  It is followed by
the same check as the polish variants (``active_set_polish``: one exact solve on the
detected set, repaired if needed) so the reference is at round-off.  No warm start.
"""

from __future__ import annotations

import time
from typing import ClassVar

import numpy as np
import scipy.linalg as sla
from scipy.optimize import nnls

from .base import Capabilities, SolverSettings
from .registry import register
from ._scaling import BackendOutcome, EquilibratedAdapter, ScaledQP, active_set_polish


def nnls_on_cholesky_factor(H: np.ndarray, u: np.ndarray, max_iter: int | None = None) -> tuple[np.ndarray, float, float]:
    """(p, factor seconds, nnls seconds) for min 1/2 p'Hp - u'p, p >= 0 via Lawson-Hanson."""
    t0 = time.perf_counter()
    L = sla.cholesky(H, lower=True, check_finite=False)
    b = sla.solve_triangular(L, u, lower=True, check_finite=False)
    A = np.ascontiguousarray(L.T)
    t1 = time.perf_counter()
    p, _ = nnls(A, b, maxiter=max_iter)
    return p, t1 - t0, time.perf_counter() - t1


@register
class ScipyNNLS(EquilibratedAdapter):
    """Lawson-Hanson NNLS on the Cholesky factor (module doc).  Warm start: none."""

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

    def solve_scaled(self, sqp: ScaledQP, settings: SolverSettings) -> BackendOutcome:
        try:
            p, t_fac, t_nnls = nnls_on_cholesky_factor(sqp.H, sqp.u, settings.max_iter)
        except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
            return BackendOutcome(None, f"error: {type(exc).__name__}: {exc}", False)
        pol = active_set_polish(sqp.H, sqp.u, p)
        return BackendOutcome(
            pol.p, "solved" if pol.converged else "check failed", pol.converged, pol.rounds,
            backend_setup_time=t_fac, backend_solve_time=t_nnls,
            info={"check_rounds": pol.rounds, "check_improved": pol.improved, "active": pol.active},
        )
