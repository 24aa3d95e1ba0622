"""What the conformance battery runs: its cases, their exact references, and the solves.

* ``conformance_cases`` -- the recipes of the stress battery
  (``contactbench.problems.scenes.stress``) as ``ConformanceCase`` records, and the
  battery's own group ``warm-start`` (``WARM_CASES``): a few small cases of it solved again
  from a warm start that is not their answer -- the exact answer of the same H with ubar
  shifted by a fraction of max|ubar| (a lighter load: the previous step of a loading sweep,
  as ``run`` hands it; a heavier one: of an unloading sweep), with that problem's gap as w.
  A solver that takes no warm start (``capabilities.warm_start`` "none") skips them, a
  capability it declares; and its group ``iteration-limit`` (``LIMIT_GROUP``): a few small
  cases of it solved again under the iteration limit ``ITERATION_LIMIT`` (``SolverSettings.
  max_iter``), whose answers report how many iterations the solver ran
  (``CaseAnswer.iterations``, and the stages a limit bounds each of, ``CaseAnswer.stages``);
* ``exact_reference`` -- the exact solution of one instance, computed independently of
  the solver registry (a judge must not be a contestant): the known solution where a
  recipe is built from one or certifies one (a periodic whole grid, where H is singular:
  ``contactbench.problems.lcp.exact_solution_on_subset``), else
  ``contactbench.problems.lcp.exact_solution`` (NNLS on the Cholesky factor, polished by
  block principal pivoting), with cond(H);
* ``CaseRunner`` -- one solver's solves, each in a forked worker
  (``harness.run.isolation.ChildProcess``) with a hard wall-clock limit, so that a
  hanging solver cannot hang ``validate`` (or in-process, ``--no-isolate``); the
  processes a solve starts end with it either way; each skip says whether a capability the
  solver declares made it (``declared_skip``) or the solver's own refinements did (its
  ``skip``, ``skip_params`` or memory model: ``CaseAnswer.own_skip``).

The verdicts are ``harness.conformance.battery``'s business, through ``harness.judging``.
"""

from __future__ import annotations

import fnmatch
import time
import traceback
from dataclasses import dataclass
from functools import partial
from typing import Any, Iterable, Sequence, cast

import numpy as np

from contactbench.problems.errors import MemoryBudgetError, ProblemInputError
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes.base import InstanceSpec
from contactbench.problems.scenes.stress import GROUPS, battery_specs, build_battery_spec, condition_number
from contactbench.solvers._processes import ends_what_it_starts
from contactbench.solvers._loading import one_line
from contactbench.solvers.base import ProblemTraits, SolveAborted, Solver, WarmStart, answered_without_iterate
from contactbench.solvers.registry import load_solver

from ..judging import ProblemSeal, portable_answer
from ..arguments import check_time_limit
from ..profiles import get_profile
from ..run.isolation import SOLVER_FAULTS, SOLVER_RAISES, ChildProcess, exception_message, exception_text
from ..run.skips import Decision, capability_decision
from ..run.worker import aborted_status, instance_operator_kind, problem_traits, running_threads, solver_facts
from ..run.worker import threads_left

#: Default per-solve time limits (s) by battery mode.
DEFAULT_TIMEOUT = {"fast": 20.0, "full": 60.0, "scene": 120.0}


def check_timeout(seconds: float | None) -> float | None:
    """A per-solve time limit: None (the mode's default) or a finite number of seconds
    in (0, a week] (``arguments.check_time_limit``), else ``ValueError`` naming the value."""
    return None if seconds is None else check_time_limit(seconds, "a time limit", "--timeout")


#: Grace beyond the solver's own time limit before its worker is killed: a solver that
#: honours ``time_limit`` returns an honest answer, only a hanging one is killed.
KILL_GRACE = (2.0, 0.25)  # seconds + fraction of the limit


def kill_limit(timeout: float) -> float:
    """Seconds a solve with time limit ``timeout`` may run before it is stopped as a
    timeout: the limit and ``KILL_GRACE``."""
    return timeout + KILL_GRACE[0] + KILL_GRACE[1] * timeout
#: Largest n the exact reference (and a dense-only solver) assembles densely.
REFERENCE_MAX_N = 4096
#: What a solve of the battery may use: a dense H at the reference limit plus its copies.
BATTERY_MEMORY_BUDGET = 4 * 8.0 * REFERENCE_MAX_N**2
#: A reference is trusted (used for the error in p) when its scaled KKT error is at most this.
TRUSTED_REFERENCE_KKT = 1e-9
#: Groups in which refusing the case is a legitimate answer (float32 input).
REFUSABLE_GROUPS = ("precision",)
#: The battery's own group: cases handed a warm start that is not their answer (module doc).
WARM_GROUP = "warm-start"
#: The battery's own group: cases solved under the iteration limit ``ITERATION_LIMIT`` (module doc).
LIMIT_GROUP = "iteration-limit"
#: The ``max_iter`` the cases of ``LIMIT_GROUP`` are solved under: far below what they take.
ITERATION_LIMIT = 2
#: The cases of ``LIMIT_GROUP``: small cases of the fast stress battery, one a step.
LIMIT_CASES: tuple[str, ...] = (
    "random/spd-n30-s0",  # dense H
    "conditioning/bcc-n100-d1",  # the matrix-free (FFT) operator
)
#: Every group of the battery: the stress groups, then ``LIMIT_GROUP`` and ``WARM_GROUP``.
BATTERY_GROUPS: tuple[str, ...] = (*GROUPS, LIMIT_GROUP, WARM_GROUP)
#: The warm-started cases: (a case of the fast stress battery, the shift of ubar, as a
#: fraction of max|ubar|, of the problem whose exact answer is the warm start).
WARM_CASES: tuple[tuple[str, float], ...] = (
    ("random/spd-n30-s0", -0.3),  # dense H; a lighter load: a loading sweep's previous step
    ("random/bcc-n64-d0.5-s0", 0.3),  # a heavier load: contact the answer releases
    ("conditioning/bcc-n100-d1", -0.3),  # the matrix-free (FFT) operator
)


# ---------------------------------------------------------------------------
# Cases
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ConformanceCase:
    """One battery recipe (an InstanceSpec of the stress scenes) with its verdict profile;
    with ``warm_shift``, the recipe solved from the warm start of ``WARM_GROUP``; with
    ``limited``, solved under ``ITERATION_LIMIT`` as a case of ``LIMIT_GROUP`` (module doc;
    not both: ``ValueError``)."""

    spec: InstanceSpec
    warm_shift: float | None = None
    limited: bool = False

    def __post_init__(self) -> None:
        if self.limited and self.warm_shift is not None:
            raise ValueError("a conformance case is warm-started or solved under a limit, not both")

    @property
    def derived(self) -> str | None:
        """The battery's own group the case belongs to (None: a case of the stress groups)."""
        return WARM_GROUP if self.warm_shift is not None else LIMIT_GROUP if self.limited else None

    @property
    def max_iter(self) -> int | None:
        """The iteration limit the case is solved under (None: the solver's own)."""
        return ITERATION_LIMIT if self.limited else None

    @property
    def name(self) -> str:
        return self.spec.instance if self.derived is None else f"{self.derived}/{self.spec.instance}"

    @property
    def group(self) -> str:
        return str(self.spec.params["group"]) if self.derived is None else self.derived

    @property
    def profile(self) -> str:
        return str(self.spec.params.get("profile", "mid"))

    @property
    def compare(self) -> str:
        return str(self.spec.params.get("compare", "none")) if self.derived is None else "none"

    def __str__(self) -> str:
        return self.name


def fast_specs(names: Iterable[str]) -> dict[str, InstanceSpec]:
    """The recipes of the fast stress battery named ``names`` ("group/instance"), by name."""
    wanted = set(names)
    groups = tuple(dict.fromkeys(name.split("/", 1)[0] for name in wanted))
    return {s.instance: s for s in battery_specs("fast", groups, scene="stress") if s.instance in wanted}


def warm_cases() -> list[ConformanceCase]:
    """The cases of ``WARM_GROUP`` (the same in every mode: they are few and small)."""
    specs = fast_specs(name for name, _ in WARM_CASES)
    return [ConformanceCase(specs[name], shift) for name, shift in WARM_CASES]


def limit_cases() -> list[ConformanceCase]:
    """The cases of ``LIMIT_GROUP`` (the same in every mode: they are few and small)."""
    specs = fast_specs(LIMIT_CASES)
    return [ConformanceCase(specs[name], limited=True) for name in LIMIT_CASES]


def conformance_cases(mode: str = "fast", groups: Sequence[str] | None = None,
                      pattern: str | None = None) -> list[ConformanceCase]:
    """The battery's recipes: ``mode`` "fast" (the test-suite subset, seconds per solver)
    or "full"; optionally only some ``groups`` (``BATTERY_GROUPS``; one group may be given
    as its name alone; each case once, however often its group is named) or names matching
    ``pattern`` (fnmatch, e.g. ``"edge/*"``; a group name matches its whole group).  An
    unknown group, or a pattern that matches no case, is a one-line ``ProblemInputError``
    (parametrized over nothing, a test would pass vacuously).  Each case reads as its name
    (``str``): ``pytest.mark.parametrize("case", conformance_cases(), ids=str)``."""
    named = (groups,) if isinstance(groups, str) else tuple(groups or ())
    unknown = [g for g in named if g not in BATTERY_GROUPS]
    if unknown:
        raise ProblemInputError(f"unknown battery group(s) {', '.join(map(repr, unknown))}; choose from "
                                f"{', '.join(BATTERY_GROUPS)}")
    chosen = tuple(dict.fromkeys(named)) if named else BATTERY_GROUPS
    stress = tuple(g for g in chosen if g not in (LIMIT_GROUP, WARM_GROUP))
    cases = [ConformanceCase(s) for s in battery_specs(mode, stress, scene="stress")] if stress else []
    if LIMIT_GROUP in chosen:
        cases += limit_cases()
    if WARM_GROUP in chosen:
        cases += warm_cases()
    if pattern:
        cases = [c for c in cases if fnmatch.fnmatch(c.name, pattern) or fnmatch.fnmatch(c.group, pattern)]
        if not cases:
            raise ProblemInputError(f"no case matches {pattern!r} in the groups {', '.join(chosen)}; give a glob "
                                    "such as 'edge/*'")
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
_WARM_STARTS: dict[tuple[str, str, int, float], WarmStart] = {}


def warm_start_of(case: ConformanceCase, step: int, inst: ContactInstance) -> WarmStart | None:
    """The warm start of ``case`` at ``step`` (None: a case of the stress groups): the exact
    answer p of H with ubar + shift max|ubar| and its gap w = Hp - that ubar (module doc);
    computed once per process.  It is not the case's answer (``tests`` check its KKT error)."""
    if case.warm_shift is None:
        return None
    key = (case.spec.instance, case.spec.params_json(), step, case.warm_shift)
    if key not in _WARM_STARTS:
        H = inst.qp.H.to_dense()
        ubar = np.asarray(inst.qp.ubar, dtype=np.float64)
        shifted = ubar + case.warm_shift * float(np.max(np.abs(ubar)))
        p = exact_solution(H, shifted).p
        _WARM_STARTS[key] = WarmStart(p=p, w=H @ p - shifted)
    ws = _WARM_STARTS[key]
    return WarmStart(p=np.array(ws.p), w=None if ws.w is None else np.array(ws.w))  # each solve its own copy


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
    problem it was handed (``harness.judging.ProblemSeal``; "" nothing), or the threads it
    left running, which could change it while it is judged (``threads_left``: the worker is
    then not reused)."""

    kind: str
    p: np.ndarray | None = None
    converged: bool | None = None
    iterations: int | None = None
    solver_status: str = ""
    message: str = ""
    detail: str = ""
    time_s: float = float("nan")
    tampered: str = ""
    iterated: bool = True  # False: the lifecycle answered without calling the solver (``answered_without_iterate``)
    stages: int = 1  # what one limit bounds: the stages of ``info["stages"]`` where ``Solver.limit_per_stage``
    own_skip: bool = False  # skipped by the solver's own refinements, not a capability it declares
    threads_left: str = ""  # the threads the solve left running ("" none)
    multiplier: float | None = None  # the approach Delta the solve reports (load control)
    traced: int = 0  # the largest iteration its own trace records (``SolveResult.trace``)


class DeclaredView:
    """A solver as its declaration alone describes it -- its name and ``capabilities``, the
    base class's ``skip`` (constraints, geometry) and memory model -- without the skip,
    skip_params or memory model it refines (what ``declared_skip`` asks)."""

    def __init__(self, solver: Solver) -> None:
        self.solver, self.name, self.capabilities = solver, solver.name, solver.capabilities

    def memory_estimate(self, n: int) -> float:
        return Solver.memory_estimate(self.solver, n)

    def skip(self, traits: ProblemTraits) -> str | None:
        return Solver.skip(self.solver, traits)

    def skip_params(self, traits: ProblemTraits, params: dict[str, Any]) -> str | None:
        return None

    def resolve_params(self, given: dict[str, Any] | None) -> dict[str, Any]:
        return {}


def declared_skip(solver: Solver, traits: ProblemTraits, warm: bool) -> str | None:
    """Why a capability ``solver`` declares keeps it from the case (None: none does): a warm
    start it does not take, or ``capability_decision`` of its ``DeclaredView``."""
    if warm and solver.capabilities.warm_start == "none":
        return f"{solver.name} takes no warm start (capabilities.warm_start is 'none')"
    d = capability_decision(cast(Solver, DeclaredView(solver)), traits, BATTERY_MEMORY_BUDGET)
    return d.reason or None


def adapt_to_solver(inst: ContactInstance, solver: Solver, params: dict[str, Any] | None = None,
                    warm: bool = False) -> QP | Decision:
    """The QP in a form the solver accepts, or the decision not to solve it: a warm start
    it takes none of (``warm``), then steps 2, 3 and 5 of ``harness.run.skips`` (max_n,
    operator kind, the solver's own ``skip`` and ``skip_params`` with ``params``; a check
    that raised is a failed decision); the battery applies no time model, so a solver
    cannot skip its way out of a case."""
    qp = inst.qp
    traits = problem_traits(inst)
    declared = declared_skip(solver, traits, warm)
    if declared:
        return Decision(reason=declared)
    d = capability_decision(solver, traits, BATTERY_MEMORY_BUDGET, params)
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


@dataclass(frozen=True)
class SolveOrder:
    """One solve, as the parent sends it to the worker: the recipe and step, the time
    limit, the parameters, the warm start (None: a cold start) and the iteration limit
    (``SolverSettings.max_iter``; None: the solver's own)."""

    spec: InstanceSpec
    step: int
    time_limit: float | None
    params: dict[str, Any]
    warm: WarmStart | None = None
    max_iter: int | None = None


def solve_case(solver: Solver, msg: SolveOrder, faults: tuple[type[BaseException], ...] = SOLVER_FAULTS
               ) -> dict[str, Any]:
    """Worker side: rebuild the instance from its recipe, solve, report plain data (the
    answer as ``harness.judging.portable_answer`` gives it, so that it can be sent).  A
    solver that raises -- ``SystemExit`` and ``GeneratorExit`` included (``sys.exit`` in a
    solver is a crash, not the end of ``validate``), in its skip check too -- gives a
    "refused" or "crashed" answer, and a ``SolveAborted`` its own status when the class
    allows it ("crashed" otherwise); a ``KeyboardInterrupt`` propagates in-process (the
    user's Ctrl-C) and is a crash in a worker (``faults`` ``SOLVER_RAISES``: the worker
    ignores SIGINT, so it is the solver's own).  Every message is
    one line, whatever the exception's text (empty, or a ``__str__`` that raises).  Whether
    the lifecycle answered without calling the solver is the harness's own reading of the
    problem (``answered_without_iterate``), never what the solver wrote into its result.  A
    result whose own account no results table holds (``harness.run.worker.solver_facts``) is
    "crashed", as in a run.  The solve runs under ``msg.max_iter``; the answer says how many
    times it the iterations may reach (``Solver.limit_stages``)."""
    case = ConformanceCase(msg.spec)
    inst = build_battery_spec(msg.spec).at(msg.step)
    qp = adapt_to_solver(inst, solver, msg.params, warm=msg.warm is not None)
    if isinstance(qp, Decision):  # a skip check that raised is the solver's crash
        own = not qp.failed and declared_skip(solver, problem_traits(inst), msg.warm is not None) is None
        return {"kind": "crashed" if qp.failed else "skipped", "message": qp.reason, "detail": qp.reason,
                "own_skip": own}
    settings = get_profile(case.profile).solver_settings(msg.time_limit, msg.params, msg.max_iter)
    seal, threads = ProblemSeal.of(qp), running_threads()
    lifecycle = answered_without_iterate(qp)
    t0 = time.perf_counter()
    try:
        res = solver.solve(qp, settings, msg.warm)
    except SolveAborted as exc:  # killed at its limit, or died (an external program)
        elapsed, text, status = time.perf_counter() - t0, exception_message(exc), aborted_status(exc)
        if status is None:
            return {"kind": "crashed", "time_s": elapsed, "detail": text,
                    "message": f"raised SolveAborted with status {getattr(exc, 'status', None)!r}, which is not "
                               f"a status SolveAborted may carry: {first_line(text, '(no message)')}"}
        return {"kind": status, "time_s": elapsed, "message": one_line(text) or status, "detail": text}
    except faults as exc:  # a row, not a harness failure (in-process, Ctrl-C still interrupts)
        refused = is_refusal(exc, case.group)
        return {"kind": "refused" if refused else "crashed", "time_s": time.perf_counter() - t0,
                "message": one_line(exception_text(exc)) or type(exc).__name__,  # (an outside program's tail too)
                "detail": "" if refused else traceback.format_exc(limit=6)}
    elapsed = time.perf_counter() - t0
    left = threads_left(threads)
    tampered = seal.broken(qp) or left
    seal.mend(qp)  # (the judge's products, and the next case's in this process, run the sealed code)
    facts = solver_facts(res, 0)
    if isinstance(facts, str):  # (the lifecycle refuses such an account: a solver that overrides ``solve``)
        return {"kind": "crashed", "time_s": elapsed, "message": "; ".join(filter(None, (facts, tampered))),
                "detail": facts, "threads_left": left}
    return {"kind": "ok", "p": portable_answer(res.p, inst.n), "converged": facts.solver_converged,
            "iterations": facts.iterations, "multiplier": res.multiplier,
            "traced": max((int(pt[0]) for pt in res.trace), default=0),
            "solver_status": str(res.status), "message": str(res.message), "time_s": elapsed,
            "tampered": tampered, "iterated": not lifecycle, "threads_left": left,
            "stages": solver.limit_stages(res.info)}


class _SolverHandler:
    """A worker's handler: the solves of ``solver`` (a ``Solver``, or the text ``load_solver``
    reads, loaded here: in the worker, never in the harness's process)."""

    def __init__(self, solver: Solver | str) -> None:
        self.solver = load_solver(solver)

    def __call__(self, msg: Any) -> dict[str, Any]:
        # the worker ignores SIGINT: whatever the solver raises, a KeyboardInterrupt too, is its own
        return solve_case(self.solver, msg, SOLVER_RAISES)


class CaseRunner:
    """Runs the solves of one solver with a hard time limit: in a forked worker
    (``harness.run.isolation``; what the solver prints is captured there) when
    ``isolate``, else in-process -- no time limit, and no protection against a solver that
    ends the process itself (``os._exit``, a signal).  Either way the processes a solve
    starts end with it, one that leaves its group (``setsid``) included: in-process, those
    this process starts or adopts during the solve (``ends_what_it_starts``; its other
    children are left alone)."""

    def __init__(self, solver: Solver | str, timeout: float | None, isolate: bool = True,
                 params: dict[str, Any] | None = None) -> None:
        self.timeout, self.isolate = timeout, isolate
        self.params = dict(params or {})
        self.worker: ChildProcess | None = None
        self.solver: Solver | None = None
        if isolate:  # (a solver named by text is loaded in the worker alone)
            self.worker = ChildProcess(partial(_SolverHandler, solver), capture_output=True)
        else:
            self.solver = load_solver(solver)

    def solve(self, spec: InstanceSpec, step: int, warm: WarmStart | None = None,
              max_iter: int | None = None) -> CaseAnswer:
        """The answer of one solve of step ``step`` of ``spec``, from ``warm`` (None: cold),
        under the iteration limit ``max_iter`` (None: the solver's own)."""
        msg = SolveOrder(spec, step, self.timeout, self.params, warm, max_iter)
        if self.worker is None:
            assert self.solver is not None
            with ends_what_it_starts():
                return CaseAnswer(**solve_case(self.solver, msg))
        out = self.worker.call(msg, None if self.timeout is None else kill_limit(self.timeout))
        if out.kind == "ok":
            answer = CaseAnswer(**out.value)
            if answer.threads_left:  # (its threads may still write: the next case gets a fresh worker)
                self.worker.kill()
            return answer
        kind = "timeout" if out.kind == "timeout" else "crashed"
        return CaseAnswer(kind, message=first_line(str(out.detail), kind), detail=str(out.detail), time_s=out.elapsed)

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()
