"""Generic QP solvers through qpsolvers' ``solve_problem`` (Caron et al., qpsolvers).

Every backend qpsolvers knows is registered as ``qp-<backend>`` (available or not: the
registry then says why, "not installed" or "failed to import ..."), plus two
labelled interior-point variants followed by an exact active-set solve,
``qp-clarabel+polish`` and ``qp-piqp+polish`` (see ``solvers._scaling``).

Each backend gets the contact QP  min 1/2 p'Hp - ubar'p, p >= 0  (Bemporad & Paggi 2015,
eq. (6)) as P = H~, q = -u~, lb = 0 after the equilibration of ``solvers._scaling``
(raw mode: params {"scaling": False}).  H is assembled dense (or taken from the shared
DenseOperator); sparse backends get a CSC copy, converted at build time.

A requested tolerance (``Request.tol``: the profile's ``tol`` -- ``low`` 1e-3, ``mid``
1e-6, ``high`` 1e-9 --, else its check, ``SolverSettings.check_tol`` -- the ``default``
profile's 1e-6 --; None only when the caller says neither: the backend's own defaults)
is mapped by each backend's own function below onto that backend's absolute *and*
relative options; relative ones are set to 0 where that is how the solver reaches an
absolute target.  With the backends' defaults ECOS, ProxQP, QPALM and SCS stop at scaled
KKT errors of 2e-6 to 1.1e-4 on a 32^2 rough case; mapped from 1e-6 they reach
8e-9 to 5e-7.  A claim above the caller's check is withdrawn (``_scaling.checked_claim``).  Known traps handled there: OSQP needs
``polishing=True`` to be exact, HiGHS' QP regularization (default 1e-7) caps it near
3e-7 so it is lowered with the tolerance, CVXOPT needs its tolerances at 1e-10 or
below.  PIQP and ProxQP get dense input (10-20x faster at n ~ 3000).

ProxQP is called through proxsuite's own ``proxqp.dense.QP``, posed as qpsolvers poses it
(``proxqp_solve_problem``, ``BackendSpec.call``): qpsolvers' call cannot set its inner
loop's limit ``max_iter_in``, which its ``max_iter`` (outer iterations) leaves at 1500 each.
Its iterations are its outer ones (``PROXQP_ITERATIONS``); a limit bounds both loops.

Iteration limits: ``max_iter`` goes to each backend's own limit (``_limits``); a limit of 0
calls no backend (the lifecycle answers it: ``base.ZERO_LIMIT_NOTE``).  A count the backend never set (refused settings) reads 0 (``_status_of``).

Parameters: ``scaling`` (bool), ``input_format`` ("dense"/"sparse", default the
backend's) and ``backend_options`` (dict of the backend's own options, applied last).
The backend's status string is kept in ``info["backend_status"]``.

Warm start: the primal goes to OSQP, ProxQP, QPALM, SCS and CVXOPT (declared "primal");
Clarabel, PIQP, HiGHS, DAQP, quadprog and ECOS ignore it ("none").
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np
import scipy.sparse as sp

from .base import Capabilities, Param, SolveContext, WarmKind
from .registry import register
from ._scaling import (BACKEND_OPTIONS, SCALING, BackendOutcome, EquilibratedAdapter, Request, ScaledQP,
                       missing_package_message, request_of)

OptionMap = Callable[[Request], dict[str, Any]]


def ipm_gap_target(tol: float) -> float:
    """Interior-point gap/feasibility target for a requested accuracy ``tol``: ten times
    tighter, because on (nearly) degenerate elements p converges only like sqrt(mu); one
    more iteration (measured) brings p and the load, not just the KKT residual, to tol."""
    return 0.1 * tol


def _limits(req: Request, iter_key: str | None, time_key: str | None) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if iter_key and req.max_iter is not None:
        out[iter_key] = int(req.max_iter)
    if time_key and req.time_limit is not None:
        out[time_key] = float(req.time_limit)
    return out


# --- each backend's own tolerance mapping ----------------------------------------


def osqp_options(req: Request) -> dict[str, Any]:
    """ADMM: absolute target with eps_rel = 0, polishing for an exact active set."""
    out = _limits(req, "max_iter", "time_limit")
    if req.tol is not None:
        out.update(eps_abs=req.tol, eps_rel=0.0, polishing=True, polish_refine_iter=10)
        out.setdefault("max_iter", 200_000)
    return out


def clarabel_options(req: Request) -> dict[str, Any]:
    """Interior point: feasibility, gap (absolute and relative) and KT-ratio tolerances."""
    out = _limits(req, "max_iter", "time_limit")
    if req.tol is not None:
        t = ipm_gap_target(req.tol)
        out.update(tol_feas=t, tol_gap_abs=t, tol_gap_rel=t, tol_ktratio=min(1e-6, t),
                   reduced_tol_feas=max(t, 1e-10), reduced_tol_gap_abs=max(t, 1e-10), reduced_tol_gap_rel=max(t, 1e-10))
        out.setdefault("max_iter", 500)
    return out


#: ProxQP's iteration limit when a tolerance is asked and no limit is: on its outer
#: iterations (``PROXQP_ITERATIONS``) and on each inner loop, far above what a converging
#: solve takes; its own limits (10000 outer, 1500 inner each) let a solve that does not
#: converge run 1.5e7 Newton steps.
PROXQP_MAX_ITER = 1000

#: What this module counts as ProxQP's iterations: its outer (proximal multiplier)
#: iterations, ``info.iter_ext``, the unit of its ``max_iter``.  Each runs an inner
#: semi-smooth Newton loop of at most ``max_iter_in`` steps, all of them counted in
#: ``info.iter`` (reported as ``info["inner_iterations"]``).
PROXQP_ITERATIONS = "iter_ext"

#: ``proxqp.dense.QP.init``'s own options (everything else is a ``proxqp.Settings`` field).
PROXQP_INIT_KEYS = ("compute_preconditioner", "rho", "mu_eq", "mu_in", "manual_minimal_H_eigenvalue")


def proxqp_options(req: Request) -> dict[str, Any]:
    """Proximal augmented Lagrangian: eps_abs with eps_rel = 0, plus the duality gap.  A
    limit bounds both of ProxQP's loops (``max_iter`` outer, ``max_iter_in`` each inner
    loop; ``PROXQP_MAX_ITER`` when a tolerance is asked without one), so the outer
    iterations it reports (``PROXQP_ITERATIONS``) are at most the limit and its Newton
    steps at most the limit squared."""
    limit = req.max_iter if req.max_iter is not None else PROXQP_MAX_ITER if req.tol is not None else None
    out: dict[str, Any] = {} if limit is None else {"max_iter": int(limit), "max_iter_in": int(limit)}
    if req.tol is not None:
        out.update(eps_abs=req.tol, eps_rel=0.0, check_duality_gap=True,
                   eps_duality_gap_abs=req.tol, eps_duality_gap_rel=0.0)
    return out


def proxqp_solve_problem(problem: Any, initvals: np.ndarray | None = None, **options: Any) -> Any:
    """ProxQP's dense solver on a qpsolvers ``Problem`` as qpsolvers' own ProxQP interface
    poses it (the box stacked under the inequalities, ``combine_linear_box_inequalities``;
    ``initvals`` the primal warm start), through a ``proxqp.dense.QP`` whose ``settings``
    take every option by ProxQP's own name -- ``max_iter_in`` among them, which the
    ``proxqp.dense.solve`` that qpsolvers calls does not take; ``PROXQP_INIT_KEYS`` go to
    ``init``.  An option ProxQP does not have raises TypeError.  Returns a qpsolvers
    ``Solution``: ``extras`` holds ProxQP's ``info``, its outer iterations as ``iter``
    (``PROXQP_ITERATIONS``) and its Newton steps as ``inner_iterations``."""
    import qpsolvers
    from proxsuite import proxqp
    from qpsolvers.conversions import combine_linear_box_inequalities

    t0 = time.perf_counter()
    P, q, G, h, A, b, lb, ub = problem.unpack()
    n = int(q.shape[0])
    C, u, l = combine_linear_box_inequalities(G, h, lb, ub, n, False)
    qp = proxqp.dense.QP(n, 0 if A is None else int(A.shape[0]), 0 if C is None else int(C.shape[0]))
    init = {key: options.pop(key) for key in PROXQP_INIT_KEYS if key in options}
    for key, value in options.items():
        if not hasattr(qp.settings, key):
            raise TypeError(f"ProxQP has no setting {key!r}")
        setattr(qp.settings, key, value)
    t1 = time.perf_counter()
    qp.init(P, q, A, b, C, l, u, **init)
    qp.solve(initvals, None, None)
    info = qp.results.info
    sol = qpsolvers.Solution(problem)
    sol.extras = {"info": info, "iter": getattr(info, PROXQP_ITERATIONS), "inner_iterations": info.iter}
    sol.found = info.status == proxqp.QPSolverOutput.PROXQP_SOLVED
    sol.x = qp.results.x
    sol.build_time, sol.solve_time = t1 - t0, time.perf_counter() - t1
    return sol


def piqp_options(req: Request) -> dict[str, Any]:
    """Proximal interior point: eps_abs with eps_rel = 0, plus the duality gap."""
    out = _limits(req, "max_iter", None)
    if req.tol is not None:
        t = ipm_gap_target(req.tol)
        out.update(eps_abs=t, eps_rel=0.0, check_duality_gap=True, eps_duality_gap_abs=t, eps_duality_gap_rel=0.0)
        out.setdefault("max_iter", 1000)
    return out


def scs_options(req: Request) -> dict[str, Any]:
    """Operator splitting (homogeneous embedding): eps_abs with eps_rel = 0."""
    out = _limits(req, "max_iters", "time_limit_secs")
    if req.tol is not None:
        out.update(eps_abs=req.tol, eps_rel=0.0)
        out.setdefault("max_iters", 1_000_000)
    return out


def highs_options(req: Request) -> dict[str, Any]:
    """Active-set QP: feasibility/optimality tolerances; its QP regularization
    (default 1e-7) caps accuracy near 3e-7, so it is lowered with the tolerance."""
    out = _limits(req, "qp_iteration_limit", "time_limit")
    if req.tol is not None:
        t = req.tol
        out.update(primal_feasibility_tolerance=t, dual_feasibility_tolerance=t, optimality_tolerance=t,
                   qp_regularization_value=min(1e-7, t * 1e-2))
    return out


def cvxopt_options(req: Request) -> dict[str, Any]:
    """Interior point: abstol/reltol/feastol, at 1e-10 or below for 1e-8 in KKT."""
    out = _limits(req, "maxiters", None)
    if req.tol is not None:
        t = min(ipm_gap_target(req.tol), 1e-10) if req.tol <= 1e-8 else ipm_gap_target(req.tol)
        out.update(abstol=t, reltol=t, feastol=t, refinement=2)
        out.setdefault("maxiters", 200)
    return out


def qpalm_options(req: Request) -> dict[str, Any]:
    """Proximal augmented Lagrangian: eps_abs with eps_rel = 0 (inner tolerances too)."""
    out = _limits(req, "max_iter", "time_limit")
    if req.tol is not None:
        out.update(eps_abs=req.tol, eps_rel=0.0, eps_abs_in=min(1.0, 100 * req.tol), eps_rel_in=0.0)
        out.setdefault("max_iter", 100_000)
    return out


#: DAQP's exit flags (``daqp.solve``), by name: a status a reader can tell apart -- an
#: iteration limit is "iteration limit", not qpsolvers' bare "not found".
DAQP_EXIT = {2: "soft optimal", 1: "optimal", -1: "infeasible", -2: "cycling", -3: "unbounded",
             -4: "iteration limit", -5: "nonconvex", -6: "overdetermined initial active set", -7: "time limit"}


def daqp_solve_problem(problem: Any, initvals: np.ndarray | None = None, **options: Any) -> Any:
    """DAQP on a qpsolvers ``Problem`` with box bounds and equality rows (no general
    inequalities: the contact QP has none): its exit flag named (``DAQP_EXIT``) as the
    status and its iterations counted, and its last iterate kept where it stops short --
    qpsolvers' own DAQP call drops all three.  ``initvals`` is not read (DAQP declares no
    warm start).  Options go to ``daqp.solve`` by DAQP's own names."""
    import daqp
    import qpsolvers

    t0 = time.perf_counter()
    P, q, G, h, A, b, lb, ub = problem.unpack_as_dense()
    if G is not None:
        raise ValueError("daqp_solve_problem poses no general inequalities")
    n = int(q.shape[0])
    rows = np.zeros((0, n)) if A is None else np.asarray(A, dtype=np.float64)
    rhs = np.zeros(0) if b is None else np.asarray(b, dtype=np.float64)
    upper = np.concatenate([np.full(n, 1e30) if ub is None else np.asarray(ub, dtype=np.float64), rhs])
    lower = np.concatenate([np.full(n, -1e30) if lb is None else np.asarray(lb, dtype=np.float64), rhs])
    sense = np.zeros(n + rhs.size, dtype=np.intc)
    sense[n:] = 5  # DAQP's word for an equality
    t1 = time.perf_counter()
    x, _, flag, info = daqp.solve(np.asarray(P, dtype=np.float64), np.asarray(q, dtype=np.float64), rows, upper,
                                  lower, sense, **options)
    sol = qpsolvers.Solution(problem)
    sol.extras = {"status": DAQP_EXIT.get(int(flag), f"exit flag {int(flag)}"), "iter": int(info["iterations"])}
    sol.found = int(flag) > 0
    sol.x = np.asarray(x, dtype=np.float64)
    sol.build_time, sol.solve_time = t1 - t0, time.perf_counter() - t1
    return sol


def daqp_options(req: Request) -> dict[str, Any]:
    """Dual active set (exact up to its feasibility tolerance)."""
    out = _limits(req, "iter_limit", None)
    if req.tol is not None:
        out.update(primal_tol=req.tol, dual_tol=min(1e-12, req.tol))
    return out


#: ECOS' tightest reliable abstol/reltol/feastol (tighter ends in its "not found" at
#: n ~ 100) and how far below a requested scaled KKT error its options must be: its own
#: default 1e-8 leaves 2e-6 to 3e-6, 1e-10 up to 9e-7, 1e-11 5e-9 to 4e-8 (32^2 rough
#: case, Example 1 n = 100; 64^2 sweep).
ECOS_TIGHTEST = 1e-11
ECOS_OPTION_RATIO = 1e-5


def ecos_options(req: Request) -> dict[str, Any]:
    """Interior point on the SOCP reformulation: abstol/reltol/feastol at
    tol x ``ECOS_OPTION_RATIO``, within [``ECOS_TIGHTEST``, 1e-8] (its default).  Even at
    the tightest its KKT error scatters up to ~4e-8: declared accuracy floor 1e-7."""
    out = _limits(req, "max_iters", None)
    if req.tol is not None:
        t = min(1e-8, max(ECOS_OPTION_RATIO * req.tol, ECOS_TIGHTEST))
        out.update(abstol=t, reltol=t, feastol=t)
    return out


def no_options(req: Request) -> dict[str, Any]:
    """No tolerance to set (finite active-set method, or a backend this module does
    not know: its defaults are used and recorded as such)."""
    return {}


# --- the backends --------------------------------------------------------------


@dataclass(frozen=True)
class BackendSpec:
    """One qpsolvers backend: how to call it and what to declare for it."""

    backend: str  # qpsolvers' name
    package: str  # the Python module it needs
    method: str
    input_format: str  # "dense" or "sparse"
    warm_start: WarmKind
    options: OptionMap
    memory_copies: float  # peak ~ copies * 8 n^2 (see _scaling.dense_memory_model)
    time_coef: float  # t ~ coef * n^exponent seconds, fitted by bench_qp_backends.py
    time_exponent: float = 3.0
    accuracy_floor: float | None = None  # smallest scaled KKT error it reaches, if > 1e-8
    #: how it is called: (problem, initvals, **options) -> qpsolvers Solution; None: qpsolvers.solve_problem
    call: Callable[..., Any] | None = None


BACKENDS: tuple[BackendSpec, ...] = (
    BackendSpec("osqp", "osqp", "ADMM", "sparse", "primal", osqp_options, 5.5, 1.4e-9),
    BackendSpec("clarabel", "clarabel", "interior point", "sparse", "none", clarabel_options, 5.5, 1.7e-9),
    BackendSpec("proxqp", "proxsuite", "proximal augmented Lagrangian", "dense", "primal", proxqp_options, 9.0, 1.5e-9,
                call=proxqp_solve_problem),
    BackendSpec("piqp", "piqp", "proximal interior point", "dense", "none", piqp_options, 6.0, 4e-10),
    BackendSpec("scs", "scs", "operator splitting", "sparse", "primal", scs_options, 5.5, 1e-9),
    BackendSpec("highs", "highspy", "active set", "sparse", "none", highs_options, 5.5, 1e-8),
    BackendSpec("cvxopt", "cvxopt", "interior point", "dense", "primal", cvxopt_options, 6.0, 1.8e-9),
    BackendSpec("qpalm", "qpalm", "proximal augmented Lagrangian", "sparse", "primal", qpalm_options, 5.5, 3.2e-9),
    BackendSpec("daqp", "daqp", "dual active set", "dense", "none", daqp_options, 4.0, 4e-9, call=daqp_solve_problem),
    BackendSpec("quadprog", "quadprog", "dual active set (Goldfarb-Idnani)", "dense", "none", no_options, 4.0, 6.4e-9),
    BackendSpec("ecos", "ecos", "interior point (SOCP)", "sparse", "none", ecos_options, 6.0, 1.4e-8,
                accuracy_floor=1e-7),
)


#: Words of a backend's status saying it refused its settings and ran nothing (PIQP's
#: PIQP_INVALID_SETTINGS): its iteration counter was never set, so it is not read.
REFUSED_STATUS_WORDS = ("invalid",)


def _status_of(sol: Any) -> tuple[str, int]:
    """The backend's own status string and iteration count from a qpsolvers Solution: 0
    where the status says the backend refused its settings (``REFUSED_STATUS_WORDS``) or
    the count is not a number >= 0 (a counter never set)."""
    extras = getattr(sol, "extras", None) or {}
    status: Any = None
    iters: Any = None
    if isinstance(extras, dict):
        status = extras.get("status", extras.get("status_val"))
        iters = extras.get("iter", extras.get("iterations"))
        info = extras.get("info")
        if info is not None and not isinstance(info, (dict, str)):
            status = status if status is not None else getattr(info, "status", None)
            iters = iters if iters is not None else getattr(info, "iter", getattr(info, "iterations", None))
    if status is None:
        status = "found" if getattr(sol, "found", False) else "not found"
    word = str(status).rsplit(".", 1)[-1]  # "Status.PIQP_SOLVED" -> "PIQP_SOLVED"
    try:
        it = int(iters) if iters is not None else 0
    except (TypeError, ValueError):
        it = 0
    if it < 0 or any(w in word.lower() for w in REFUSED_STATUS_WORDS):
        it = 0
    return word, it


def _problem_matrix(sqp: ScaledQP, fmt: str) -> Any:
    """P in the backend's format (a CSC copy for sparse backends)."""
    return sqp.H if fmt == "dense" else sp.csc_matrix(sqp.H)


class QPSolversAdapter(EquilibratedAdapter):
    """qpsolvers.solve_problem on the equilibrated QP (module doc); one instance per
    backend.  Warm start: primal where qpsolvers forwards it (BackendSpec.warm_start)."""

    family: ClassVar[str] = "qp"

    def __init__(self, spec: BackendSpec, polish: bool = False) -> None:
        self.spec = spec
        self.polish = polish  # type: ignore[misc]
        self.name = f"qp-{spec.backend}" + ("+polish" if polish else "")  # type: ignore[misc]
        self.required_package = spec.package  # type: ignore[misc]
        self.memory_copies = spec.memory_copies + (0.5 if polish else 0.0)  # type: ignore[misc]
        self.time_coef = spec.time_coef * (1.3 if polish else 1.0)  # type: ignore[misc]
        self.time_exponent = spec.time_exponent  # type: ignore[misc]
        input_format = Param("input_format", str, spec.input_format, "matrix handed to the backend",
                             choices=("dense", "sparse"))
        self.params = (SCALING, input_format, BACKEND_OPTIONS)  # type: ignore[misc]
        #: smallest scaled KKT error the backend reaches on these instances (None: 1e-8 or better)
        self.accuracy_floor = None if polish else spec.accuracy_floor
        tail = "; then one exact solve on the detected active set (labelled polish variant)" if polish else ""
        self.description = (  # type: ignore[misc]
            f"{spec.backend} ({spec.method}) via qpsolvers on the equilibrated dense QP, "
            f"{spec.input_format} input{tail}"
            + (f"; accuracy floor ~{spec.accuracy_floor:g} (cannot reach the high profile)" if self.accuracy_floor else "")
        )
        self.capabilities = Capabilities(  # type: ignore[misc]
            needs_dense=True,
            warm_start=spec.warm_start,
            exact=False,
            input_format=spec.input_format,
            promise="exact" if self.accuracy_floor is None else self.accuracy_floor,
            load_control=True,
            bounds=True,
        )

    def availability(self) -> tuple[bool, str]:
        why = missing_package_message(self.name, "qpsolvers")
        if why:
            return False, why
        import qpsolvers

        if self.spec.backend in qpsolvers.available_solvers:
            return True, "available"
        why = missing_package_message(self.name, self.spec.package)
        return False, why or f"failed to import: qpsolvers does not list backend {self.spec.backend!r}"

    def prepare(self, sqp: ScaledQP, ctx: SolveContext) -> Any:
        """qpsolvers' Problem(P, -u~, lb=0[, ub=u~][, A=d', b=P/s]) with P in the
        requested input format (``_scaling``: the scaled bounds and load row)."""
        import qpsolvers

        fmt = ctx.params["input_format"]
        P = _problem_matrix(sqp, fmt)
        A = b = None
        if sqp.eq_row is not None:
            A = sqp.eq_row[None, :] if fmt == "dense" else sp.csc_matrix(sqp.eq_row[None, :])
            b = np.array([sqp.eq_rhs])
        return qpsolvers.Problem(P, -sqp.u, A=A, b=b, lb=np.zeros(sqp.n), ub=sqp.ub)

    def run_backend(self, sqp: ScaledQP, prepared: Any, ctx: SolveContext) -> BackendOutcome:
        import qpsolvers

        opts = {**self.spec.options(request_of(ctx)), **ctx.params["backend_options"]}
        info: dict[str, Any] = {"backend": self.spec.backend, "input_format": ctx.params["input_format"],
                                "options": opts}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                if self.spec.call is not None:
                    sol = self.spec.call(prepared, initvals=sqp.x0, **opts)
                else:
                    sol = qpsolvers.solve_problem(prepared, solver=self.spec.backend, initvals=sqp.x0, **opts)
            except Exception as exc:  # the backend's own failure is a status, not a crash
                return BackendOutcome(None, f"error: {type(exc).__name__}: {exc}", False, info=info)
        status, iters = _status_of(sol)
        extras = getattr(sol, "extras", None) or {}
        if isinstance(extras, dict) and "inner_iterations" in extras:
            info["inner_iterations"] = int(extras["inner_iterations"])
        x = None if sol.x is None else np.asarray(sol.x, dtype=np.float64)
        return BackendOutcome(
            x, status, bool(sol.found), iters,
            backend_setup_time=getattr(sol, "build_time", None), backend_solve_time=getattr(sol, "solve_time", None),
            info={**info, "warnings": [str(w.message) for w in caught][:5]},
        )


def _extra_backends() -> tuple[BackendSpec, ...]:
    """Backends qpsolvers can import that this module has no mapping for (defaults)."""
    try:
        import qpsolvers
    except Exception:
        return ()
    known = {b.backend for b in BACKENDS}
    dense = set(getattr(qpsolvers, "dense_solvers", []))
    return tuple(
        BackendSpec(b, b, "unknown", "dense" if b in dense else "sparse", "none", no_options, 6.0, 1e-8)
        for b in qpsolvers.available_solvers if b not in known
    )


POLISHED = ("clarabel", "piqp")

for _spec in BACKENDS + _extra_backends():
    register(QPSolversAdapter(_spec))
    if _spec.backend in POLISHED:
        register(QPSolversAdapter(_spec, polish=True))
