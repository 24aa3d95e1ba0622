"""``cvxpy``: the contact QP through CVXPY's modelling layer (Diamond & Boyd 2016).

CVXPY is no longer a qpsolvers backend, so it has its own adapter.  On the equilibrated
problem of ``solvers._scaling`` it states Bemporad & Paggi 2015, eq. (6) as

* ``form="quad_form"`` (default):  Minimize(0.5 * quad_form(p, psd_wrap(H~)) - u~ @ p),
  p >= 0  (psd_wrap skips CVXPY's eigenvalue check of H~);
* ``form="cholesky"``:  Minimize(0.5 * sum_squares(L' p) - u~ @ p), p >= 0, H~ = L L'.

Default solver: CLARABEL (interior point; chosen because it reaches the ``high``
profile, while CVXPY's own default for QPs, OSQP without polishing, misses 1e-6 in p).
Pick another with params {"solver": "OSQP"}; the one used is recorded in
``info["cvxpy_solver"]`` and CVXPY's status word in ``info["backend_status"]``.
Tolerances are mapped by the same per-backend functions as the qpsolvers adapters
(``solvers.qp_backends``), since CVXPY forwards the solver's own option names.  Building the expression and CVXPY's compilation are build time
(``SolveResult.setup_time``); the solver's time is solve time.  Parameters: ``scaling``,
``solver``, ``form``, ``backend_options``.  Warm start: none with CLARABEL.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from contactbench.problems.lcp import cholesky_factor

from ._params import ParamError
from .base import Capabilities, Param, SolveContext
from .qp_backends import OptionMap, clarabel_options, osqp_options, piqp_options, scs_options
from .registry import register
from ._scaling import BACKEND_OPTIONS, SCALING, BackendOutcome, EquilibratedAdapter, ScaledQP, request_of

DEFAULT_CVXPY_SOLVER = "CLARABEL"
FORMS = ("quad_form", "cholesky")

#: CVXPY solver name -> the tolerance mapping of that backend (others: their defaults).
TOLERANCE_MAPS: dict[str, OptionMap] = {
    "CLARABEL": clarabel_options,
    "OSQP": osqp_options,
    "SCS": scs_options,
    "PIQP": piqp_options,
}


def cvxpy_problem(H: np.ndarray, u: np.ndarray, form: str, ub: np.ndarray | None = None,
                  eq_row: np.ndarray | None = None, eq_rhs: float = 0.0) -> tuple[Any, Any]:
    """(problem, variable) for min 1/2 p'Hp - u'p, p >= 0 in the requested form, with
    p <= ub and eq_row'p = eq_rhs when given."""
    import cvxpy as cp

    p = cp.Variable(u.size)
    if form == "quad_form":
        objective = 0.5 * cp.quad_form(p, cp.psd_wrap(H)) - u @ p
    elif form == "cholesky":
        L = cholesky_factor(H)
        objective = 0.5 * cp.sum_squares(L.T @ p) - u @ p
    else:
        raise ValueError(f"cvxpy form must be one of {', '.join(FORMS)}, got {form!r}")
    constraints = [p >= 0]
    if ub is not None:
        constraints.append(p <= ub)
    if eq_row is not None:
        constraints.append(eq_row @ p == eq_rhs)
    return cp.Problem(cp.Minimize(objective), constraints), p


def installed_backends() -> tuple[str, ...] | None:
    """The solver names CVXPY has installed here (upper case, ``cvxpy.installed_solvers``),
    or None where CVXPY itself does not import (``availability`` then says why)."""
    try:
        import cvxpy as cp
    except Exception:  # (not installed, or broken: the solver's availability names it)
        return None
    return tuple(str(s).upper() for s in cp.installed_solvers())


def check_backend(solver: str, backend: Any) -> None:
    """A one-line ``ParamError`` naming the installed backends unless ``backend`` (the
    ``solver`` parameter of solver ``solver``, case-insensitive) is a CVXPY solver
    installed here; nothing is checked where CVXPY does not import."""
    installed = installed_backends()
    if installed is None or str(backend).upper() in installed:
        return
    raise ParamError(f"solver {solver!r}: parameter 'solver' names the CVXPY backend {backend!r}, which is not "
                     f"installed here; installed: {', '.join(installed) or '(none)'}")


@dataclass
class CVXPYModel:
    """The model built at build time, and what it was built for."""

    problem: Any
    variable: Any
    solver: str
    form: str


@register
class CVXPYAdapter(EquilibratedAdapter):
    """CVXPY model of the equilibrated QP (module doc).  Warm start: none (CLARABEL)."""

    name: ClassVar[str] = "cvxpy"
    description: ClassVar[str] = f"CVXPY quad_form model, solver {DEFAULT_CVXPY_SOLVER} (params: solver, form)"
    capabilities: ClassVar[Capabilities] = Capabilities(
        needs_dense=True, warm_start="none", exact=False, input_format="dense", load_control=True, bounds=True
    )
    params: ClassVar[tuple[Param, ...]] = (
        SCALING,
        Param("solver", str, DEFAULT_CVXPY_SOLVER, "the CVXPY solver name (case-insensitive)"),
        Param("form", str, "quad_form", "how the objective is stated", choices=FORMS),
        BACKEND_OPTIONS,
    )
    required_package: ClassVar[str] = "cvxpy"
    # dense H, scaled copy, CVXPY's constant and its canonical sparse P, the solver's KKT
    memory_copies: ClassVar[float] = 7.0
    time_coef: ClassVar[float] = 2.8e-9
    time_exponent: ClassVar[float] = 3.0

    def resolve_params(self, given: dict[str, Any] | None) -> dict[str, Any]:
        """As the base's; a ``solver`` given that CVXPY has not installed here is a
        ``ParamError`` naming the installed ones (``check_backend``), so that the plan
        refuses it before anything runs.  The default is not checked (its rows say why)."""
        params = super().resolve_params(given)
        if given and "solver" in given:
            check_backend(self.name, params["solver"])
        return params

    def prepare(self, sqp: ScaledQP, ctx: SolveContext) -> CVXPYModel:
        form = str(ctx.params["form"])
        problem, var = cvxpy_problem(sqp.H, sqp.u, form, sqp.ub, sqp.eq_row, sqp.eq_rhs)
        return CVXPYModel(problem, var, str(ctx.params["solver"]).upper(), form)

    def run_backend(self, sqp: ScaledQP, prepared: CVXPYModel, ctx: SolveContext) -> BackendOutcome:
        import cvxpy as cp

        solver, problem = prepared.solver, prepared.problem
        opts = {**TOLERANCE_MAPS.get(solver, lambda r: {})(request_of(ctx)), **ctx.params["backend_options"]}
        info: dict[str, Any] = {"cvxpy_solver": solver, "form": prepared.form, "options": opts}
        t1 = time.perf_counter()
        try:
            problem.solve(solver=solver, **opts)
        except Exception as exc:  # the backend's own failure (SolverError, a numerical error) is a status, not a crash
            return BackendOutcome(None, f"error: {type(exc).__name__}: {exc}", False, info=info)
        wall = time.perf_counter() - t1
        compile_time = float(getattr(problem, "compilation_time", None) or 0.0)
        stats = problem.solver_stats
        var = prepared.variable
        x = None if var.value is None else np.asarray(var.value, dtype=np.float64).ravel()
        return BackendOutcome(
            x, str(problem.status), problem.status == cp.OPTIMAL, int(stats.num_iters or 0),
            late_build_time=compile_time,
            backend_setup_time=stats.setup_time, backend_solve_time=stats.solve_time,
            info={**info, "cvxpy_solver": stats.solver_name or solver,
                  "cvxpy_compile_time": compile_time, "cvxpy_solve_wall": wall - compile_time},
        )
