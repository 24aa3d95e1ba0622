"""What the conformance battery runs: its cases, their exact references, and the solves.

* ``conformance_cases`` -- the recipes of the stress battery
  (``contactbench.problems.scenes.stress``) as ``ConformanceCase`` records;
* ``exact_reference`` -- the exact solution of one instance, computed independently of
  the solver registry (a judge must not be a contestant): the known solution where a
  recipe is built from one or certifies one (a periodic whole grid, where H is singular:
  ``contactbench.problems.lcp.exact_solution_on_subset``), else
  ``contactbench.problems.lcp.exact_solution`` (NNLS on the Cholesky factor, polished by
  block principal pivoting), with cond(H);
* ``CaseRunner`` -- one solver's solves, each in a forked worker
  (``harness.run.isolation.ChildProcess``) with a hard wall-clock limit, so that a
  hanging solver cannot hang ``validate``.

The verdicts are ``harness.conformance.battery``'s business, through ``harness.judging``.
"""

from __future__ import annotations

import fnmatch
import time
import traceback
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from contactbench.problems.errors import MemoryBudgetError, ProblemInputError
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes.base import InstanceSpec
from contactbench.problems.scenes.stress import GROUPS, battery_specs, build_battery_spec, condition_number
from contactbench.solvers.base import WITHOUT_ITERATE, SolveAborted, Solver

from ..judging import ProblemSeal, portable_answer
from ..arguments import check_time_limit
from ..profiles import get_profile
from ..run.isolation import SOLVER_FAULTS, exception_message, exception_text
from ..run.skips import Decision, capability_decision
from ..run.worker import aborted_status, instance_operator_kind, problem_traits

#: Default per-solve time limits (s) by battery mode.
DEFAULT_TIMEOUT = {"fast": 20.0, "full": 60.0, "scene": 120.0}


def check_timeout(seconds: float | None) -> float | None:
    """A per-solve time limit: None (the mode's default) or a finite number of seconds
    in (0, a week] (``arguments.check_time_limit``), else ``ValueError`` naming the value."""
    return None if seconds is None else check_time_limit(seconds, "a time limit", "--timeout")


#: Grace beyond the solver's own time limit before its worker is killed: a solver that
#: honours ``time_limit`` returns an honest answer, only a hanging one is killed.
KILL_GRACE = (2.0, 0.25)  # seconds + fraction of the limit
#: Largest n the exact reference (and a dense-only solver) assembles densely.
REFERENCE_MAX_N = 4096
#: What a solve of the battery may use: a dense H at the reference limit plus its copies.
BATTERY_MEMORY_BUDGET = 4 * 8.0 * REFERENCE_MAX_N**2
#: A reference is trusted (used for the error in p) when its scaled KKT error is at most this.
TRUSTED_REFERENCE_KKT = 1e-9
#: Groups in which refusing the case is a legitimate answer (float32 input).
REFUSABLE_GROUPS = ("precision",)


# ---------------------------------------------------------------------------
# Cases
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ConformanceCase:
    """One battery recipe (an InstanceSpec of the stress scenes) with its verdict profile."""

    spec: InstanceSpec

    @property
    def name(self) -> str:
        return self.spec.instance

    @property
    def group(self) -> str:
        return str(self.spec.params["group"])

    @property
    def profile(self) -> str:
        return str(self.spec.params.get("profile", "mid"))

    @property
    def compare(self) -> str:
        return str(self.spec.params.get("compare", "none"))

    def __str__(self) -> str:
        return self.name


def conformance_cases(mode: str = "fast", groups: Sequence[str] | None = None,
                      pattern: str | None = None) -> list[ConformanceCase]:
    """The battery's recipes: ``mode`` "fast" (the test-suite subset, seconds per solver)
    or "full"; optionally only some ``groups`` (each case once, however often its group
    is named) or names matching ``pattern`` (fnmatch, e.g. ``"edge/*"``; a group name
    matches its whole group)."""
    specs = battery_specs(mode, tuple(dict.fromkeys(groups)) if groups else GROUPS, scene="stress")
    cases = [ConformanceCase(s) for s in specs]
    if pattern:
        cases = [c for c in cases if fnmatch.fnmatch(c.name, pattern) or fnmatch.fnmatch(c.group, pattern)]
    return cases


# ---------------------------------------------------------------------------
# Exact reference
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Reference:
    """The exact solution of one instance and what it took to trust it."""

    p: np.ndarray
    kkt_error: float
    cond: float
    method: str
    time_s: float = float("nan")  # seconds to compute it (nan: a known solution, not computed)

    @property
    def trusted(self) -> bool:
        return bool(self.kkt_error <= TRUSTED_REFERENCE_KKT)


def exact_reference(inst: ContactInstance) -> Reference:
    """The exact solution of ``inst`` (module doc) and cond(H); ``MemoryBudgetError``
    beyond ``REFERENCE_MAX_N`` unknowns without a known solution."""
    qp = inst.qp
    cond = condition_number(qp.H) if qp.n <= REFERENCE_MAX_N else float("nan")
    if "p_exact" in inst.meta:
        p = np.asarray(inst.meta["p_exact"], dtype=np.float64)
        return Reference(p, kkt_check(qp, p).kkt_error, cond, "known solution")
    if qp.n > REFERENCE_MAX_N:
        raise MemoryBudgetError(f"exact reference for n = {qp.n} (dense limit {REFERENCE_MAX_N})",
                                8.0 * qp.n**2, 8.0 * REFERENCE_MAX_N**2)
    t0 = time.perf_counter()
    if not qp.constraints.plain:  # bounds or a load equality: the certified mixed-LCP solve
        csol = constrained_exact_solution(qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64), qp.constraints)
        elapsed = time.perf_counter() - t0
        return Reference(csol.p, kkt_check(qp, csol.p).kkt_error, cond, "bvls+polish", elapsed)
    sol = exact_solution(qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64))
    elapsed = time.perf_counter() - t0
    return Reference(sol.p, kkt_check(qp, sol.p).kkt_error, cond, "nnls+bpp", elapsed)


_REFERENCES: dict[tuple[str, str, int], Reference] = {}


def cached_reference(spec: InstanceSpec, step: int, inst: ContactInstance) -> Reference | None:
    """References are deterministic per recipe: computed once per process (None: too
    large to compute)."""
    key = (spec.instance, spec.params_json(), step)
    if key not in _REFERENCES:
        try:
            _REFERENCES[key] = exact_reference(inst)
        except MemoryBudgetError:
            return None
    return _REFERENCES[key]


# ---------------------------------------------------------------------------
# Running one solve (in a worker process)
# ---------------------------------------------------------------------------


@dataclass
class CaseAnswer:
    """What one solve produced, as seen from the parent process.

    kind: "ok", "refused", "crashed", "timeout" or "skipped"; ``message`` is one line,
    ``detail`` the traceback of a crash; ``tampered`` what the solver changed in the
    problem it was handed (``harness.judging.ProblemSeal``; "" nothing)."""

    kind: str
    p: np.ndarray | None = None
    converged: bool | None = None
    iterations: int | None = None
    solver_status: str = ""
    message: str = ""
    detail: str = ""
    time_s: float = float("nan")
    tampered: str = ""
    iterated: bool = True  # False: the lifecycle answered without calling the solver (``WITHOUT_ITERATE``)


def adapt_to_solver(inst: ContactInstance, solver: Solver, params: dict[str, Any] | None = None) -> QP | Decision:
    """The QP in a form the solver accepts, or the decision not to solve it: steps 2, 3
    and 5 of ``harness.run.skips`` (max_n, operator kind, the solver's own ``skip`` and
    ``skip_params`` with ``params``; a check that raised is a failed decision); the
    battery applies no time model, so a solver cannot skip its way out of a case."""
    qp = inst.qp
    d = capability_decision(solver, problem_traits(inst), BATTERY_MEMORY_BUDGET, params)
    if d.skip:
        return d
    if d.operator == "dense" and instance_operator_kind(inst) != "dense":
        return QP(DenseOperator(qp.H.to_dense()), qp.ubar, qp.geometry, qp.constraints)
    return qp


def is_refusal(exc: BaseException, group: str) -> bool:
    """A clear refusal (not a crash): the project's input errors, NotImplementedError,
    or, for float32 input, a ValueError/TypeError naming the dtype."""
    if isinstance(exc, (ProblemInputError, MemoryBudgetError, NotImplementedError)):
        return True
    text = exception_message(exc).lower()
    return group in REFUSABLE_GROUPS and isinstance(exc, (ValueError, TypeError)) and any(
        w in text for w in ("float32", "dtype", "precision", "single"))


def first_line(text: str, fallback: str) -> str:
    """The first line of ``text`` with text on it, stripped; ``fallback`` when there is none."""
    return next((line.strip() for line in text.splitlines() if line.strip()), fallback)


def solve_case(solver: Solver, msg: tuple[InstanceSpec, int, float | None, dict[str, Any]]) -> dict[str, Any]:
    """Worker side: rebuild the instance from its recipe, solve, report plain data (the
    answer as ``harness.judging.portable_answer`` gives it, so that it can be sent).  A
    solver that raises -- ``SystemExit`` and ``GeneratorExit`` included (``sys.exit`` in a
    solver is a crash, not the end of ``validate``), in its skip check too -- gives a
    "refused" or "crashed" answer, and a ``SolveAborted`` its own status when the class
    allows it ("crashed" otherwise); a ``KeyboardInterrupt`` propagates.  Every message is
    one line, whatever the exception's text (empty, or a ``__str__`` that raises)."""
    spec, step, time_limit, params = msg
    case = ConformanceCase(spec)
    inst = build_battery_spec(spec).at(step)
    qp = adapt_to_solver(inst, solver, params)
    if isinstance(qp, Decision):  # a skip check that raised is the solver's crash
        return {"kind": "crashed" if qp.failed else "skipped", "message": qp.reason, "detail": qp.reason}
    settings = get_profile(case.profile).solver_settings(time_limit, params)
    seal = ProblemSeal.of(qp)
    t0 = time.perf_counter()
    try:
        res = solver.solve(qp, settings, None)
    except SolveAborted as exc:  # killed at its limit, or died (an external program)
        elapsed, text, status = time.perf_counter() - t0, exception_message(exc), aborted_status(exc)
        if status is None:
            return {"kind": "crashed", "time_s": elapsed, "detail": text,
                    "message": f"raised SolveAborted with status {getattr(exc, 'status', None)!r}, which is not "
                               f"a status SolveAborted may carry: {first_line(text, '(no message)')}"}
        return {"kind": status, "time_s": elapsed, "message": first_line(text, status), "detail": text}
    except SOLVER_FAULTS as exc:  # a row, not a harness failure (Ctrl-C still interrupts)
        refused = is_refusal(exc, case.group)
        return {"kind": "refused" if refused else "crashed", "time_s": time.perf_counter() - t0,
                "message": first_line(exception_text(exc), type(exc).__name__),
                "detail": "" if refused else traceback.format_exc(limit=6)}
    elapsed = time.perf_counter() - t0
    tampered = seal.broken(qp)
    seal.mend(qp)  # (the judge's products, and the next case's in this process, run the sealed code)
    return {"kind": "ok", "p": portable_answer(res.p, inst.n), "converged": bool(res.converged),
            "iterations": int(res.iterations),
            "solver_status": str(res.status), "message": str(res.message), "time_s": elapsed,
            "tampered": tampered, "iterated": not res.info.get(WITHOUT_ITERATE)}


class _SolverHandler:
    def __init__(self, solver: Solver) -> None:
        self.solver = solver

    def __call__(self, msg: Any) -> dict[str, Any]:
        return solve_case(self.solver, msg)


class CaseRunner:
    """Runs the solves of one solver with a hard time limit: in a forked worker
    (``harness.run.isolation``; what the solver prints is captured there, and the
    processes it starts end with the worker) when ``isolate``, else in-process -- no time
    limit, and no protection against a solver that ends the process itself (``os._exit``,
    a signal)."""

    def __init__(self, solver: Solver, timeout: float | None, isolate: bool = True,
                 params: dict[str, Any] | None = None) -> None:
        self.solver, self.timeout, self.isolate = solver, timeout, isolate
        self.params = dict(params or {})
        self.worker: Any = None
        if isolate:
            from contactbench.harness.run.isolation import ChildProcess

            self.worker = ChildProcess(lambda: _SolverHandler(solver), capture_output=True)

    def solve(self, spec: InstanceSpec, step: int) -> CaseAnswer:
        msg = (spec, step, self.timeout, self.params)
        if self.worker is None:
            return CaseAnswer(**solve_case(self.solver, msg))
        out = self.worker.call(msg, None if self.timeout is None else
                               self.timeout + KILL_GRACE[0] + KILL_GRACE[1] * self.timeout)
        if out.kind == "ok":
            return CaseAnswer(**out.value)
        kind = "timeout" if out.kind == "timeout" else "crashed"
        return CaseAnswer(kind, message=first_line(str(out.detail), kind), detail=str(out.detail), time_s=out.elapsed)

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()
