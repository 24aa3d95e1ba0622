"""The worker side of a job: typed messages and the handler that lives in the isolated
process (``harness.run.isolation.ChildProcess``).

The parent (``harness.run.job.JobDriver``) sends one message at a time:

``BuildStep(k)``        build step k of the instance (the ``LoadSequence`` is built once
                        from its recipe) -> ``StepInfo``;
``AssembleDense(k)``    assemble the dense H of step k once -> seconds it took;
``ComputeReference``    load the stored reference answer, or solve and store it ->
                        ``ReferenceReply``;
``CheckReference``      whether the stored reference answer holds on its step, within
                        ``max_kkt`` (``Worker.reference_p``) -> bool;
``WarmUp(task)``        an untimed solve (imports, JIT, caches); its answer is dropped
                        -> ``UntimedReply``;
``Solve(task)``         one timed solve, judged by ``harness.judging.judge`` -> ``SolveReply``;
``Regenerate(task)``    recover this solver's warm start after a worker restart or on
                        resume: the previous step's answer as the run kept it on disk
                        (``task.warm_in``), else that step re-solved, untimed -> ``UntimedReply``.

Every solve of a solver is watched for the threads it leaves running (``threads_left``):
Python threads cannot be stopped, so a reply that names any (``threads_left``) tells the
driver not to reuse this worker, and the solve's row is ``failed``/``wrong`` -- an answer
is not judged while the solver's code still runs beside the judge.

Warm starts are kept here, per (variant label, profile, step), as ``WarmState`` and
mapped by ``harness.run.sequence.warm_start_from``; a solve whose answer the next step
starts from also keeps it on disk (``task.warm_out``, the driver's ``warm_path``).  The
table row is built by the parent (``harness.run.rows``) from the reply.
"""

from __future__ import annotations

import concurrent.futures.thread
import contextlib
import copy
import json
import math
import os
import sys
import threading
import time
import zipfile
from time import monotonic, sleep  # (the grace for threads left: not the solve's clock, ``time.perf_counter``)
from types import FrameType
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Iterator, Sequence, Union

import numpy as np

from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET, DenseOperator, set_memory_budget
from contactbench.problems.scenes import InstanceSpec
from contactbench.solvers._answers import account_problems, is_plain_count
from contactbench.solvers.base import ProblemTraits, SolveAborted, SolverSettings, WarmStart
from contactbench.solvers.registry import load_solver

from ..table.fields import save_field
from ..table.files import write_npz_atomic
from .isolation import SOLVER_RAISES, PeakMemory, error_text, exception_message, output_to
from ..judging import ProblemSeal, Verdict, judge
from ..profiles import get_profile
from .sequence import WarmState, warm_start_from
from .studies import REFERENCE_PROFILE

#: A candidate reference whose own scaled KKT error exceeds this is not used.
REFERENCE_MAX_KKT = 1e-6
MAX_TRACE_POINTS = 200
#: Wrong answers on instances up to this size are kept as arrays for the report's plots.
MAX_SAVED_N = 5000
#: How long a worker waits, after a solve, for the threads the solve started to end.
THREAD_GRACE_S = 1.0

# ---------------------------------------------------------------------------
# Messages and replies
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class BuildStep:
    step: int


@dataclass(frozen=True)
class AssembleDense:
    step: int


@dataclass(frozen=True)
class ComputeReference:
    step: int
    base: str
    operator: str
    path: str
    time_limit: float


@dataclass(frozen=True)
class CheckReference:
    step: int
    path: str
    max_kkt: float = REFERENCE_MAX_KKT


@dataclass(frozen=True)
class SolveTask:
    """One solve of one variant on one step."""

    step: int
    base: str
    params: dict[str, Any]
    label: str
    profile: str
    operator: str
    check_tol: float
    time_limit: float
    warm: bool = False
    reference_path: str | None = None
    record_warm: bool = True
    arrays_path: str | None = None  # where a wrong answer on a small instance is kept for the report
    reference_out: str | None = None  # keep this answer as the step's reference here when it passes
    reference_max_kkt: float = REFERENCE_MAX_KKT  # ... with a scaled KKT error at most this (harness.run.job)
    warm_out: str | None = None  # keep this answer here as the next step's warm start, for a resume
    warm_in: str | None = None  # the previous step's answer kept so (``Regenerate`` reads it before re-solving)
    untimed: str = ""  # what this solver's untimed solve before it did to its problem (``UntimedReply.fault``)


@dataclass(frozen=True)
class Solve:
    task: SolveTask


@dataclass(frozen=True)
class WarmUp:
    task: SolveTask


@dataclass(frozen=True)
class Regenerate:
    task: SolveTask


Message = Union[BuildStep, AssembleDense, ComputeReference, CheckReference, Solve, WarmUp, Regenerate]


def message_title(msg: Message) -> str:
    """What ``msg`` asks, in a few words (the solver-output log's entry titles)."""
    if isinstance(msg, (Solve, WarmUp, Regenerate)):
        what = {Solve: "timed solve", WarmUp: "warm-up solve", Regenerate: "warm start"}[type(msg)]
        return f"step {msg.task.step} {msg.task.label} [{msg.task.profile}]: {what}"
    if isinstance(msg, ComputeReference):
        return f"step {msg.step}: reference {msg.base}"
    if isinstance(msg, CheckReference):
        return f"step {msg.step}: stored reference"
    return f"step {msg.step}: {'dense H' if isinstance(msg, AssembleDense) else 'build'}"


@dataclass
class StepInfo:
    """What the parent learns of a built step: the skip policy's ``traits`` and the
    row's columns."""

    traits: ProblemTraits
    steps: int
    delta: float
    build_time: float
    sequence_built: bool
    N: int | None
    E: float
    nominal_area: float
    analytic: dict[str, float]
    columns: dict[str, Any] = field(default_factory=dict)  # ContactInstance.problem_columns

    @property
    def n(self) -> int:
        return self.traits.n

    @property
    def operator(self) -> str:  # "dense" or "fft": what the scene built
        return self.traits.operator

    @property
    def kernel(self) -> str:
        return self.traits.kernel

    @property
    def periodic(self) -> bool:
        return self.traits.periodic


@dataclass
class ReferenceReply:
    solver: str
    cached: bool
    error: str = ""
    time: float = float("nan")
    kkt_error: float = float("nan")


@dataclass
class SolverFacts:
    """The solver's own account of a solve (table columns of the same names)."""

    iterations: int
    solver_status: str
    solver_converged: bool
    solver_message: str
    solver_internal_time_s: float
    setup_time_s: float
    matvecs: int
    trace: str


@dataclass
class SolveReply:
    """One timed solve: the seconds around ``solve``, the solver's account, and the
    judge's verdict (None with ``error`` when the solver raised or its p is unusable)."""

    elapsed: float
    warm_start: bool
    peak_mem_mb: float | None = None
    facts: SolverFacts | None = None
    verdict: Verdict | None = None
    error: str = ""
    kept_warm: bool = False
    aborted: str = ""  # "timeout" / "crashed" when the solver raised SolveAborted
    reference_saved: bool = False  # this answer was kept as the step's reference (task.reference_out)
    threads_left: str = ""  # the threads the solve left running ("" none): the worker is not reused


@dataclass
class UntimedReply:
    """One untimed solve (a warm-up, or the re-solve of a warm start): ``ok`` -- it ran
    (``Regenerate``: a warm start is held); ``fault`` -- what it did to the problem it was
    handed ("" nothing: a write the seal found, threads left running), which the timed row
    of the same solver is judged by (``SolveTask.untimed``); ``threads_left`` -- the worker
    is not reused."""

    ok: bool
    fault: str = ""
    threads_left: str = ""


# ---------------------------------------------------------------------------
# The handler
# ---------------------------------------------------------------------------


def instance_operator_kind(inst: ContactInstance) -> str:
    return "dense" if isinstance(inst.qp.H, DenseOperator) else "fft"


def problem_traits(inst: ContactInstance) -> ProblemTraits:
    """What the skip policy may know of an instance before solving it."""
    geom = inst.geometry
    square = geom is not None and geom.has_surface and geom.grid_shape[0] == geom.grid_shape[1] \
        and geom.surface.delta1 in (None, geom.surface.delta)
    # a rectangular surface has no coarse levels (coarsen.level_strides): it reads as no surface
    return ProblemTraits(n=inst.n, operator=instance_operator_kind(inst), has_geometry=geom is not None,
                         has_surface=square, periodic=bool(inst.periodic), kernel=inst.kernel,
                         surface_side=int(geom.grid_shape[0]) if square else 0,
                         load_control=inst.qp.constraints.load_control, bounded=inst.qp.constraints.bounded,
                         capacity_share=inst.qp.constraints.capacity_share,
                         layer=geom is not None and geom.layer is not None,
                         rectangular=geom is not None and (geom.grid_shape[0] != geom.grid_shape[1]
                                                           or geom.spacing[0] != geom.spacing[1]),
                         whole_periodic_grid=geom is not None and bool(inst.periodic)
                         and inst.n == inst.total_elements)


def thin_trace(trace: Iterable[Sequence[float]], limit: int = MAX_TRACE_POINTS) -> list[list[float]]:
    pts = [[int(t[0]), float(t[1]), float(t[2])] for t in trace]
    if len(pts) <= limit:
        return pts
    keep = np.unique(np.linspace(0, len(pts) - 1, limit).round().astype(int))
    return [pts[i] for i in keep]


def solver_settings(task: SolveTask) -> SolverSettings:
    return get_profile(task.profile).solver_settings(task.time_limit, copy.deepcopy(task.params))


def aborted_status(exc: SolveAborted) -> str | None:
    """The row status ``exc`` carries: its ``status`` where ``SolveAborted`` itself accepts
    it (the class's own rule, asked by building one), else None -- a status set after
    construction ("pass", "solved") is not the solver's to give.  Both the run's solves
    and validate's read it here."""
    status = getattr(exc, "status", None)
    if type(status) is not str:
        return None
    try:
        SolveAborted(status, "")
    except ValueError:
        return None
    return status


class SolveServer:
    """Message handler living in the isolated worker: builds the instance from its
    recipe once, steps in order, the dense H once per step, and runs solves.  With
    ``output_path``, what each message prints (descriptors 1 and 2) goes to that file
    (emptied at each message; ``harness.run.output_log``), not to the terminal."""

    def __init__(self, spec: InstanceSpec, memory_budget: float = DEFAULT_MEMORY_BUDGET,
                 output_path: str | None = None) -> None:
        self.spec = spec
        self.memory_budget = memory_budget
        self.output_path = output_path
        set_memory_budget(memory_budget)  # the run's budget for every dense build in this worker
        self.seq: Any = None
        self.steps: dict[int, ContactInstance] = {}
        self.dense: dict[int, DenseOperator] = {}
        self.refs: dict[str, tuple[np.ndarray, float]] = {}  # path -> (p, its scaled KKT error here)
        self.warm: dict[tuple[str, str, int], WarmState] = {}  # (label, profile, step)

    def __call__(self, msg: Message) -> Any:
        with output_to(self.output_path) if self.output_path else contextlib.nullcontext():
            return self.handle(msg)

    def handle(self, msg: Message) -> Any:
        if isinstance(msg, BuildStep):
            return self.step_info(msg.step)
        if isinstance(msg, AssembleDense):
            return self.ensure_dense(msg.step)
        if isinstance(msg, ComputeReference):
            return self.reference(msg)
        if isinstance(msg, CheckReference):
            return self.reference_p(msg.path, self.ensure_step(msg.step)[0], msg.max_kkt) is not None
        if isinstance(msg, Solve):
            return self.solve(msg.task)
        if isinstance(msg, Regenerate):
            return self.regenerate(msg.task)
        if isinstance(msg, WarmUp):
            return self.warmup(msg.task)
        raise TypeError(f"unknown message {msg!r}")

    # -- building ---------------------------------------------------------
    def ensure_step(self, k: int) -> tuple[ContactInstance, float]:
        if k in self.steps:
            return self.steps[k], 0.0
        t0 = time.perf_counter()
        if self.seq is None:
            self.seq = self.spec.build()
        if not 0 <= k < len(self.seq):
            raise IndexError(f"step {k} out of range: the sequence has {len(self.seq)} steps")
        inst = self.seq.at(k)
        for old in [s for s in self.steps if s < k - 1 or s > k]:
            del self.steps[old]
        for old in [s for s in self.dense if s != k]:
            del self.dense[old]
        self.steps[k] = inst
        return inst, time.perf_counter() - t0

    def analytic(self, k: int) -> dict[str, float]:
        if self.seq is None or self.seq.analytic is None:
            return {}
        return {key: float(v) for key, v in self.seq.analytic(k).items()}

    def step_info(self, k: int) -> StepInfo:
        fresh_seq = self.seq is None
        inst, t_build = self.ensure_step(k)
        geom = inst.geometry
        return StepInfo(
            traits=problem_traits(inst), steps=len(self.seq), delta=float(inst.delta), build_time=t_build,
            sequence_built=fresh_seq, N=int(geom.grid_shape[0]) if geom is not None else None, E=float(inst.E),
            nominal_area=float(inst.nominal_area), analytic=self.analytic(k), columns=inst.problem_columns(),
        )

    def ensure_dense(self, k: int) -> float:
        inst, _ = self.ensure_step(k)
        if k in self.dense or instance_operator_kind(inst) == "dense":
            return 0.0
        t0 = time.perf_counter()
        self.dense[k] = DenseOperator(inst.qp.H.to_dense(self.memory_budget))
        return time.perf_counter() - t0

    def qp_for(self, k: int, operator: str) -> QP:
        """The QP a solver is handed: its own copy of ubar (the judge keeps the step's),
        the step's operator (sealed around each timed solve: ``ProblemSeal``)."""
        inst, _ = self.ensure_step(k)
        if operator == "dense" and instance_operator_kind(inst) != "dense":
            self.ensure_dense(k)
            return QP(self.dense[k], inst.qp.ubar.copy(), inst.qp.geometry, inst.qp.constraints)
        return QP(inst.qp.H, inst.qp.ubar.copy(), inst.qp.geometry, inst.qp.constraints)

    def held_problems(self) -> list[Any]:
        """What this worker holds beside the problem a solver is handed -- the judge's
        problems (each built step's ``inst.qp``) and the load sequence the steps after are
        built from: sealed with it, since a solver reaches every object of its process
        (``gc``)."""
        return [inst.qp for inst in self.steps.values()] + ([self.seq] if self.seq is not None else [])

    def forget_problems(self) -> None:
        """Drop every built step and dense H (after a solver wrote into one)."""
        self.seq, self.steps, self.dense = None, {}, {}

    def reference_p(self, path: str | None, inst: ContactInstance,
                    max_kkt: float = REFERENCE_MAX_KKT) -> np.ndarray | None:
        """The stored reference answer of step ``inst`` at ``path`` (``read_reference``),
        held once read; None where there is none to read, or where the judge does not find
        it solved within ``max_kkt`` (at most ``REFERENCE_MAX_KKT``) on this step (a file
        edited by hand, another problem's of the same size, a run's own answer at a looser
        profile than the run's now): what the stored kkt says is not trusted."""
        if not path:
            return None
        if path not in self.refs:
            p = read_reference(path, inst.n)
            verdict = None if p is None else judge(inst, p, True, REFERENCE_MAX_KKT)
            if p is None or verdict is None or verdict.status != "solved":
                return None
            self.refs[path] = (p, verdict.kkt_error)
        p, kkt = self.refs[path]
        return p if kkt <= max_kkt else None

    # -- solving ----------------------------------------------------------
    def reference(self, msg: ComputeReference) -> ReferenceReply:
        """Load the stored reference, or compute it once and store it (over a stored file
        that ``read_reference`` cannot read as this step's)."""
        inst, _ = self.ensure_step(msg.step)
        if self.reference_p(msg.path, inst) is not None:
            return ReferenceReply(msg.base, cached=True)
        qp = self.qp_for(msg.step, msg.operator)
        settings = SolverSettings(tol=get_profile(REFERENCE_PROFILE).tol, time_limit=msg.time_limit)
        t0 = time.perf_counter()
        with process_state_kept():
            res = load_solver(msg.base).solve(qp, settings, None)
        elapsed = time.perf_counter() - t0
        p = np.asarray(res.p, dtype=np.float64).reshape(-1)
        verdict = judge(inst, p, bool(res.converged), REFERENCE_MAX_KKT)
        if verdict.status != "solved":
            return ReferenceReply(msg.base, cached=False, error=f"reference {msg.base} failed its check: "
                                  f"{verdict.message() or verdict.status}", time=elapsed, kkt_error=verdict.kkt_error)
        self.keep_reference(msg.path, p, msg.base, verdict.kkt_error, elapsed)
        return ReferenceReply(msg.base, cached=False, time=elapsed, kkt_error=verdict.kkt_error)

    def keep_reference(self, path: str, p: np.ndarray, solver: str, kkt_error: float, elapsed: float) -> None:
        """Store ``p`` as the step's reference answer (npz, no pickles) and hold it."""
        write_npz_atomic(path, p=p, solver=solver, kkt_error=kkt_error, time=elapsed)
        self.refs[path] = (p, float(kkt_error))

    def serve_as_reference(self, task: SolveTask, p: np.ndarray, verdict: Verdict, elapsed: float) -> bool:
        """Keep a run's own answer as the step's reference (no second solve) when the
        judge found it solved within ``task.reference_max_kkt``; it is then its own
        reference (p_rel_error = load_rel_error = 0)."""
        if not task.reference_out or verdict.status != "solved" or not verdict.kkt_error <= task.reference_max_kkt:
            return False
        self.keep_reference(task.reference_out, p, task.label, verdict.kkt_error, elapsed)
        verdict.figures.update(p_rel_error=0.0, load_rel_error=0.0)
        return True

    def remember(self, task: SolveTask, inst: ContactInstance, p: np.ndarray, w: Any) -> bool:
        state = WarmState.of(task.step, inst, p, w)
        if state is None:
            return False
        key = (task.label, task.profile)
        for old in [s for s in self.warm if s[:2] == key and s[2] < task.step - 1]:
            del self.warm[old]
        self.warm[(*key, task.step)] = state
        return True

    def regenerate(self, task: SolveTask) -> UntimedReply:
        """Recover this solver's warm start: the previous step's answer as the run kept it
        (``task.warm_in``), so a resumed run starts each step where the uninterrupted one
        did; else that step re-solved from p = 0 (untimed)."""
        prev = replace(task, step=task.step - 1, warm=False, reference_path=None)
        inst, _ = self.ensure_step(prev.step)
        kept = WarmState.load(task.warm_in, prev.step, inst) if task.warm_in else None
        if kept is not None:
            return UntimedReply(self.remember(prev, inst, kept.p, kept.w))
        qp = self.qp_for(prev.step, prev.operator)
        reply = UntimedReply(False)
        with self.sealed(qp, "re-solving the step before", reply):
            res = load_solver(prev.base).solve(qp, solver_settings(prev), None)
            reply.ok = True
        if reply.ok:  # (else no warm start: the step runs cold, and its row says so)
            reply.ok = self.remember(prev, inst, res.p, res.w)
        return reply

    @contextlib.contextmanager
    def sealed(self, qp: QP, what: str, reply: UntimedReply) -> Iterator[None]:
        """An untimed solve on ``qp`` (what the solver raises is swallowed: ``reply.ok``
        stays False), sealed (``ProblemSeal``) and watched for the threads it leaves
        (``threads_left``): a problem it wrote into is dropped, so the solves after it get
        the problem rebuilt; what it did is ``reply.fault``, which the timed row of the same
        solver is judged by (``solve``)."""
        seal, threads = ProblemSeal.of(qp, self.held_problems()), running_threads()
        with contextlib.suppress(*SOLVER_RAISES), process_state_kept():
            yield
        reply.threads_left = threads_left(threads)
        broken = seal.broken(qp)
        seal.mend(qp)
        if broken:
            self.forget_problems()
        if broken or reply.threads_left:
            reply.fault = f"{broken or reply.threads_left}, {what}"

    def prepare(self, task: SolveTask) -> tuple[ContactInstance, QP, Any, WarmStart | None]:
        inst, _ = self.ensure_step(task.step)
        qp = self.qp_for(task.step, task.operator)
        solver = load_solver(task.base)
        warm = None
        if task.warm:
            warm = warm_start_from(self.warm.get((task.label, task.profile, task.step - 1)), inst, task.step,
                                   solver.capabilities.warm_start)
        return inst, qp, solver, warm

    def warmup(self, task: SolveTask) -> UntimedReply:
        """The untimed warm-up solve (imports, JIT, caches); its answer is discarded (a
        solver that raises here fails the same way in its timed solve, which records it)."""
        _, qp, solver, warm = self.prepare(task)
        reply = UntimedReply(False)
        with self.sealed(qp, "in its untimed warm-up", reply):
            solver.solve(qp, solver_settings(task), warm)
            reply.ok = True
        return reply

    def solve(self, task: SolveTask) -> SolveReply:
        """One timed solve, judged by the harness (never by the solver's claim)."""
        inst, qp, solver, warm = self.prepare(task)
        settings = solver_settings(task)
        count0 = qp.H.matvec_count
        seal = ProblemSeal.of(qp, self.held_problems())  # untimed: what the solver is handed, and the judge's
        threads = running_threads()
        raised: SolveReply | None = None
        with process_state_kept(), PeakMemory() as mem:  # (the state put back outside the clock)
            t0 = time.perf_counter()
            try:
                res = solver.solve(qp, settings, warm)
            except SolveAborted as exc:  # (a status the class does not allow is a crash: ``aborted_status``)
                raised = SolveReply(time.perf_counter() - t0, warm is not None, error=exception_message(exc),
                                    aborted=aborted_status(exc) or "crashed")
            except SOLVER_RAISES as exc:
                raised = SolveReply(time.perf_counter() - t0, warm is not None, error=error_text(exc))
            elapsed = time.perf_counter() - t0
        left = threads_left(threads)
        if raised is not None:  # (a problem it wrote into before raising is dropped all the same)
            broken = seal.broken(qp)
            seal.mend(qp)
            if broken:
                self.forget_problems()
            raised.error = "; ".join(filter(None, (raised.error, broken, left)))
            raised.threads_left = left
            return raised
        facts = solver_facts(res, qp.H.matvec_count - count0)
        tampered = seal.broken(qp)
        seal.mend(qp)  # (before the judge reads the problem: its products run the sealed code and state)
        if isinstance(facts, str):  # an account no row can hold: the row fails naming it, never stored as given
            if tampered:
                self.forget_problems()
            return SolveReply(elapsed, warm is not None, mem.mb, error="; ".join(filter(None, (facts, tampered, left))),
                              threads_left=left)
        reply = SolveReply(elapsed, warm is not None, mem.mb, facts)
        p_ref = self.reference_p(task.reference_path, inst)
        reply.threads_left = left
        reply.verdict = judge(inst, res.p, bool(res.converged), task.check_tol, p_ref=p_ref,
                              analytic_load=self.analytic(task.step).get("load"),
                              tampered=tampered or left or task.untimed, multiplier=res.multiplier)
        if not reply.verdict.usable:  # no answer (status "failed"): nothing to keep or draw
            reply.error = reply.verdict.message()
            if reply.verdict.tampered:
                self.forget_problems()
            return reply
        p = np.asarray(res.p, dtype=np.float64)
        if p_ref is None:
            reply.reference_saved = self.serve_as_reference(task, p, reply.verdict, elapsed)
        save_wrong_answer(task.arrays_path, inst, p, p_ref, reply.verdict)
        save_field(task.arrays_path, self.spec.scene, self.spec.instance, inst, p, task.step, len(self.seq),
                   task.label, reply.verdict.status)  # the report's field pictures (harness/table/fields.py)
        if task.record_warm:
            reply.kept_warm = self.remember(task, inst, p, res.w)
        if reply.kept_warm and task.warm_out:
            with contextlib.suppress(OSError):  # a full disk costs a resume its exact start, not this row
                self.warm[(task.label, task.profile, task.step)].save(task.warm_out)
        return reply


def solver_facts(res: Any, counted: int) -> SolverFacts | str:
    """The solver's own account of a solve (``res``, its ``SolveResult``; ``counted`` the
    products the handed operator counted, its matvecs where the solver reports 0), or why
    no row can take it: a count or time the table cannot hold (``account_problems``, which
    the lifecycle applies too: this is for a solver that overrides ``solve``; a time not
    reported, NaN, is missing in the row), or a result that cannot be read at all."""
    try:
        reported = res.matvecs
        matvecs = counted if is_plain_count(reported) and reported == 0 else reported
        problems = account_problems(res.iterations, matvecs, res.setup_time, res.solve_time, unreported=True)
        if problems:
            return "the solver's result holds what no results table can: " + "; ".join(problems)
        return SolverFacts(
            iterations=int(res.iterations), solver_status=str(res.status), solver_converged=bool(res.converged),
            solver_message=str(res.message)[:500], solver_internal_time_s=float(res.solve_time),
            setup_time_s=float(res.setup_time), matvecs=int(matvecs),
            trace=json.dumps(thin_trace(res.trace)) if res.trace else "",
        )
    except SOLVER_RAISES as exc:  # (a result that is no SolveResult, a field whose conversion raises)
        return f"the solver's result cannot be read: {exception_message(exc)}"


def read_reference(path: str, n: int) -> np.ndarray | None:
    """The reference answer stored at ``path`` for a step of ``n`` unknowns; None where
    there is none to read: no file, a link or anything but a plain file (a run never reads
    through a link), an archive that cannot be read (no pickles) or whose ``p`` is not n
    finite numbers (a file edited by hand, cut short, or another step's)."""
    if os.path.islink(path) or not os.path.isfile(path):
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            p = np.asarray(data["p"], dtype=np.float64)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    return p if p.shape == (n,) and bool(np.all(np.isfinite(p))) else None


def running_threads() -> set[int]:
    """The threads of this process that run Python code (``sys._current_frames``: those
    started by ``threading`` and by ``_thread`` alike), but the calling thread and idle
    pool workers -- a ``concurrent.futures`` worker waiting on an empty queue runs nothing
    until it is given work (the FFT threads' pool, a pool a solver keeps)."""
    here = threading.get_ident()
    return {ident for ident, frame in sys._current_frames().items()
            if ident != here and not idle_pool_worker(frame)}


def idle_pool_worker(frame: FrameType) -> bool:
    """Whether ``frame``, a thread's innermost, is a ``concurrent.futures`` worker
    waiting for work on an empty queue: the library's own code object (not one compiled
    to look like it) on a queue of the library's own type."""
    if frame.f_code is not concurrent.futures.thread._worker.__code__:
        return False
    queue = frame.f_locals.get("work_queue")
    return type(queue) is concurrent.futures.thread.queue.SimpleQueue and queue.empty()


def threads_left(before: set[int], grace: float | None = None) -> str:
    """The threads running now that were not before a solve (``running_threads``), after
    waiting up to ``grace`` seconds (default ``THREAD_GRACE_S``) for them to end; "" when
    none is left, else a sentence naming them."""
    end = monotonic() + (THREAD_GRACE_S if grace is None else grace)
    while (left := running_threads() - before) and monotonic() < end:
        sleep(0.01)
    if not left:
        return ""
    names = {t.ident: t.name for t in threading.enumerate()}
    shown = ", ".join(repr(names.get(ident, f"thread {ident}")) for ident in sorted(left))
    return (f"the solver left {len(left)} thread{'s' if len(left) > 1 else ''} running after its solve ({shown}), "
            "which could write into the problem it was handed while it is judged")


@contextlib.contextmanager
def process_state_kept() -> Iterator[None]:
    """The working folder, the environment and NumPy's floating-point error handling put
    back after a solve as they were before it: a solver that changes them (``os.chdir``,
    ``os.environ``, ``np.seterr``) changes them for itself, not for the harness's writes
    (relative to the working folder) or for the solves after it in this worker."""
    cwd, env, errors = os.getcwd(), dict(os.environ), np.geterr()
    try:
        yield
    finally:
        np.seterr(**errors)
        if dict(os.environ) != env:
            os.environ.clear()
            os.environ.update(env)
        with contextlib.suppress(OSError):  # (a folder gone meanwhile: the harness's writes say so)
            os.chdir(cwd)


def save_wrong_answer(path: str | None, inst: ContactInstance, p: np.ndarray, p_ref: np.ndarray | None,
                      verdict: Verdict) -> None:
    """Keep (p, p_ref, ubar, w) of a wrong answer on a small instance as ``path`` (npz, no
    pickles) -- the counterexample figure plots one.  The first one per cell wins."""
    if not path or inst.n > MAX_SAVED_N or p_ref is None or os.path.exists(path):
        return
    p_err = float(verdict.figures.get("p_rel_error", math.nan))
    if verdict.status == "solved" and p_err <= 1e-6:
        return
    os.makedirs(os.path.dirname(path), exist_ok=True)
    w = inst.qp.H.matvec(p) - inst.qp.ubar
    write_npz_atomic(path, p=p, p_ref=p_ref, ubar=inst.qp.ubar, w=w, E=inst.E)
