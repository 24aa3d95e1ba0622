"""One job: the missing cells of one instance, run in an isolated worker.

``JobDriver`` drives one long-lived isolated worker process (``harness.run.isolation``)
whose handler (``harness.run.worker.SolveServer``) builds the instance's
``LoadSequence`` once from its recipe and the steps in order.  For each step it

1. builds the step in the worker (build time measured there);
2. decides for each variant whether to run it or skip it (``harness.run.skips``: the
   solver's availability, capabilities, memory and time models, its own
   ``skip(traits)``, and the rows of the earlier steps of the same (variant, profile)
   sequence -- stored ones included, so a resumed job decides as an uninterrupted one);
3. assembles the dense H at most once for the step, and only if a variant that runs
   needs it (its assembly time is added to that variant's ``build_time_s``);
4. obtains the reference solution: from OUT/_cache/ if stored; else, with the automatic
   reference, from the run itself when an exact solver is among the variants that run
   (its group is solved first and its answer serves, if the judge finds it solved to
   ``REFERENCE_MAX_KKT`` and to the tightest profile of the step -- no second solve;
   rows name it ``label@profile`` in ``reference_solver``); else by running the study's
   reference candidates in order (``harness.run.studies``); a reference that fails its own
   check is not used;
5. runs each (variant, profile): an untimed warm-up solve the first time the worker
   meets the variant -- dropped when the solve is predicted to take longer than
   ``RunConfig.warmup_limit`` (``predicted_seconds``; the row's ``warmup`` says so) --
   then ``repeats`` timed solves, each under a hard wall-clock limit enforced by
   killing the worker; every answer is judged by ``harness.judging.judge``.  What an
   untimed solve did to its problem (a write, threads left running: ``UntimedReply.fault``)
   is the next timed row's of the same solver (``SolveTask.untimed``); a solve that left
   threads running (``threads_left``) ends its worker, and the next message starts a fresh
   one (a new ``generation``).

Warm starts: along a load history each solver starts from its own previous-step answer
(``harness.run.sequence``) when its capabilities allow and the run asks.  The answer a
next step starts from is kept in the run's cache folder until that step's cells are
recorded (``warm_path``), so after a worker restart or on resume a step starts from the
same point as in an uninterrupted run; where that file is missing, the previous step is
re-solved, untimed, from p = 0.

Every row goes through ``harness.run.rows.RowFactory`` and then to ``sink``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, ContextManager

from contactbench.solvers._kit import matvec_seconds
from contactbench.solvers.registry import load_solver

from .isolation import ChildProcess, ChildReply
from .output_log import OUTPUT_LOG, OutputLog, SolverOutput
from .plan import InstanceJob, RunConfig, scene_operator
from ..profiles import get_profile
from .rows import RowFactory, answer_columns
from .skips import Decision, SkipPolicy, extrapolated_time, offered_operator, problem_time_estimate, skip_decision
from ..table.aggregates import served_name
from ..table.files import safe_name
from ..table.store import ResultStore
from .studies import SolverVariant
from .worker import (
    REFERENCE_MAX_KKT,
    AssembleDense,
    BuildStep,
    CheckReference,
    ComputeReference,
    Message,
    SolveServer,
    ReferenceReply,
    Regenerate,
    Solve,
    SolveReply,
    SolveTask,
    StepInfo,
    UntimedReply,
    WarmUp,
    message_title,
)

log = logging.getLogger("contactbench")

Todo = list[tuple[SolverVariant, str, list[int]]]  # (variant, profile, repeats still missing)

#: Without a time model or an observed step, a solve is predicted to cost at least this
#: many products with H (``predicted_seconds``; the warm-up rule only): the field's CCGs,
#: which declare none, take hundreds on a cold step (results/perf/cost-law.md: our plain CCGs
#: 85-363 at 256^2-4096^2).  With ``_kit.matvec_seconds`` it keeps the warm-up of such a
#: solve up to 512^2 and drops it from 1024^2 on the paper's trial sets.
MIN_PREDICTED_MATVECS = 150


def row_operator(base: str, scene_operator: str) -> str:
    """The operator ("dense" or "fft") solver ``base`` is given on a step whose scene builds
    ``scene_operator`` (``skips.offered_operator``; the scene's where the solver takes none
    of it).  The operator a skip or planning-failure row names (its
    ``Decision`` carries none), so the report counts it with the solves of the same
    solver on that operator (``report.view.operator_labels``); the scene's where the solver
    cannot be loaded."""
    scene = "dense" if scene_operator == "dense" else "fft"
    try:
        caps = load_solver(base).capabilities
    except Exception:  # (the decision says why it cannot be loaded)
        return scene
    return offered_operator(caps, scene) or scene


@dataclass
class StepContext:
    k: int
    info: StepInfo
    generation: int
    dense_time: float | None = None
    reference_solver: str = ""
    reference_path: str | None = None
    serving: tuple[str, str] | None = None  # (label, profile) whose answer is to serve as the reference
    serve_max_kkt: float = REFERENCE_MAX_KKT

    @property
    def scene_dense(self) -> bool:
        return self.info.operator == "dense"


class JobDriver:
    """Drives one ``InstanceJob`` from the parent process: sends the missing cells'
    solves to an isolated child (``ChildProcess``, whose handler is worker.py's
    ``SolveServer``), serves reference answers, and hands each finished row to ``sink``.
    With ``output_log``, what the solvers print -- in the worker and in the solver code
    the driver runs itself -- goes to that file (``harness.run.output_log``); without it,
    where this process's output goes."""

    def __init__(self, job: InstanceJob, run: RunConfig, statuses: dict[str, str], cache_dir: Path,
                 sink: Callable[[dict[str, Any]], None], output_log: Path | None = None) -> None:
        self.job = job
        self.run_cfg = run
        self.statuses = dict(statuses)
        self.cache_dir = Path(cache_dir)
        self.sink = sink
        self.rows = RowFactory(job, run)
        self.policy = SkipPolicy(run.timeout, run.memory_budget)
        for cell in job.stored:  # a resumed job: the stored rows count as if seen live
            self.policy.note((cell.label, cell.profile), cell.step, cell.n, cell.status, cell.seconds)
        self.output = SolverOutput(OutputLog(Path(output_log))) if output_log is not None else None
        worker_file = str(self.output.worker_file) if self.output is not None else None
        self.worker = ChildProcess(partial(SolveServer, job.spec, run.memory_budget, worker_file),
                                   threads=run.worker_threads(), output_files=(worker_file,) if worker_file else ())
        self.warmed: set[tuple[int, str]] = set()
        self.warm_have: set[tuple[int, str, str, int]] = set()  # (generation, label, profile, step) held by the worker
        self.untimed: dict[str, str] = {}  # label -> what its untimed solve did to its problem (``UntimedReply.fault``)
        self._step_error = ""
        self.build_times: dict[int, float] = {}

    # -- cells ------------------------------------------------------------
    def missing(self, k: int) -> Todo:
        out = []
        for v in self.job.variants:
            for prof in self.job.profiles:
                reps = [r for r in range(self.run_cfg.repeats) if self.rows.cell_id(k, v, prof, r) not in self.statuses]
                if reps:
                    out.append((v, prof, reps))
        return out

    def emit(self, row: dict[str, Any]) -> None:
        """Hand ``row`` to the sink; the skip policy reads it exactly as it would read it
        back from the journal on resume (``SkipPolicy``)."""
        self.statuses[row["cell_id"]] = row["status"]
        self.policy.note((row["solver"], row["profile"]), row["step"], row.get("n"), row["status"],
                         row.get("solve_time_s"))
        self.sink(row)

    def emit_rows(self, ctx: StepContext | None, k: int, v: SolverVariant, profile: str, reps: list[int],
                  **values: Any) -> None:
        """The same row (a skip, a failure) for each of ``reps``."""
        for r in reps:
            self.emit(self.row(ctx, k, v, profile, r, **values))

    def row(self, ctx: StepContext | None, k: int, v: SolverVariant, profile: str, r: int,
            **values: Any) -> dict[str, Any]:
        values.setdefault("build_time_s", self.build_times.get(k))
        return self.rows.row(ctx.info if ctx else None, k, v, profile, r,
                             reference_solver=ctx.reference_solver if ctx else "", **values)

    # -- driving ----------------------------------------------------------
    def run(self) -> None:
        try:
            k, n_steps = 0, self.job.steps_hint
            while k < n_steps:
                todo = self.missing(k)
                if todo:
                    ctx = self.prepare_step(k)
                    if ctx is None:
                        scene_op = scene_operator(self.job.spec.params)
                        for v, prof, reps in todo:
                            self.emit_rows(None, k, v, prof, reps, status="failed", error=self._step_error,
                                           operator=row_operator(v.base, scene_op))
                    else:
                        n_steps = ctx.info.steps
                        self.run_step(ctx, todo)
                k += 1
            self.forget_all_warm(n_steps)
        except BaseException:  # an interrupt: the worker is killed at once, not asked to finish its solve
            self.worker.kill()
            raise
        finally:
            self.worker.close()
            if self.output is not None:
                self.output.close()

    def call(self, msg: Message, timeout: float | None) -> ChildReply:
        """Send ``msg`` to the worker; what it printed joins the solver-output log.  A
        reply that says the solve left threads running ends the worker: the next message
        starts a fresh one.  A run stopped in the message (Ctrl-C, SIGTERM) kills the worker,
        and what it printed so far joins the log, marked so (``collect_stopped``)."""
        try:
            out = self.worker.call(msg, timeout)
        except KeyboardInterrupt:
            self.worker.kill()
            if self.output is not None:
                self.output.collect_stopped(f"{self.where} {message_title(msg)}")
            raise
        if self.output is not None:
            self.output.collect(f"{self.where} {message_title(msg)}{'' if out.ok else f' ({out.kind})'}")
        if out.ok and getattr(out.value, "threads_left", ""):
            log.info("%s %s: %s; the worker is replaced", self.where, message_title(msg), out.value.threads_left)
            self.worker.kill()
        if out.ok and isinstance(out.value, UntimedReply) and out.value.fault and isinstance(msg, (WarmUp, Regenerate)):
            self.untimed[msg.task.label] = out.value.fault
        return out

    def solver_code(self, what: str) -> ContextManager[None]:
        """Around solver code run in this process: its output joins the solver-output log."""
        if self.output is None:
            return contextlib.nullcontext()
        return self.output.captured(f"{self.where} {what} (in the harness's process)")

    @property
    def where(self) -> str:
        return f"{self.job.spec.scene}/{self.job.spec.instance}"

    def forget_all_warm(self, n_steps: int) -> None:
        """The job's cells are all recorded: no kept answer of it is needed any more (one
        may be left where an interruption came between a step's rows and ``forget_warm``),
        nor a part of one an interrupted write left (``.<name>.<pid>.<random>.tmp``)."""
        names = {self.warm_path(k, v, profile).name for k in range(n_steps) for v in self.job.variants
                 for profile in self.job.profiles}
        for name in names:
            forget_file(self.cache_dir / name)
        with contextlib.suppress(OSError):
            for part in self.cache_dir.glob(".warm-*.tmp"):
                if part.name[1:].rsplit(".", 3)[0] in names:
                    forget_file(part)

    def prepare_step(self, k: int) -> StepContext | None:
        out = self.call(BuildStep(k), self.run_cfg.build_timeout)
        if not out.ok:
            self._step_error = f"building step {k} failed ({out.kind}): {out.detail}"
            log.warning("%s %s", self.job.spec.instance, self._step_error)
            return None
        info: StepInfo = out.value
        self.build_times.setdefault(k, float(info.build_time))
        return StepContext(k=k, info=info, generation=self.worker.generation)

    def refresh(self, ctx: StepContext) -> bool:
        """After a worker restart, rebuild the step (and forget per-worker state)."""
        if ctx.generation == self.worker.generation and self.worker.alive:
            return True
        new = self.prepare_step(ctx.k)
        if new is None:
            return False
        ctx.generation = new.generation
        return True

    def ensure_dense(self, ctx: StepContext) -> bool:
        if ctx.scene_dense:
            return True
        if not self.refresh(ctx):
            return False
        out = self.call(AssembleDense(ctx.k), self.run_cfg.build_timeout)
        if not out.ok:
            return False
        if ctx.dense_time is None:
            ctx.dense_time = float(out.value)
        return True

    def run_step(self, ctx: StepContext, todo: Todo) -> None:
        traits = ctx.info.traits
        with self.solver_code(f"step {ctx.k}: skip checks"):
            decisions = {(v.name, prof): self.policy.decide(v.base, (v.name, prof), traits, ctx.k,
                                                               self.job.load_history, v.params)
                         for v, prof, _ in todo}
        running = [(v, prof) for v, prof, _ in todo if not decisions[(v.name, prof)].skip]
        if running:
            self.plan_reference(ctx, running)
        pending = list(todo)
        while pending:  # the group whose answer is to serve as the reference first
            i = next((j for j, (v, prof, _) in enumerate(pending) if (v.name, prof) == ctx.serving), 0)
            v, prof, reps = pending.pop(i)
            d = decisions[(v.name, prof)]
            if d.failed or d.skip:  # a row that ran nothing names the operator it would have been given
                op = d.operator or row_operator(v.base, traits.operator)
                self.emit_rows(ctx, ctx.k, v, prof, reps, operator=op,
                               **({"status": "failed", "error": d.reason} if d.failed
                                  else {"status": "skipped", "skip_reason": d.reason}))
                continue
            self.run_group(ctx, v, prof, reps, d.operator)
            if ctx.serving == (v.name, prof) and ctx.reference_path is None:  # its answer did not serve:
                rest = [(w, p) for w, p, _ in pending if not decisions[(w.name, p)].skip]
                ctx.serving = self.reference_server(rest)  # the next exact solver of the run,
                if ctx.serving is None and rest:
                    self.obtain_reference(ctx)  # else the reference is solved, if any row is left to judge

    # -- the reference ----------------------------------------------------
    def plan_reference(self, ctx: StepContext, running: list[tuple[SolverVariant, str]]) -> None:
        """A stored reference, else a run's own answer to come (module doc, step 4), else
        a reference solve now."""
        auto = self.run_cfg.reference == "auto"
        server = self.reference_server(running) if auto else None
        served = self.served_names(server) if auto else []
        if self.use_stored_reference(ctx, self.job.reference_candidates) or \
                self.use_stored_reference(ctx, served, self.served_max_kkt()):
            return
        if server is not None:
            ctx.serving = server
            ctx.serve_max_kkt = min([REFERENCE_MAX_KKT] + [get_profile(prof).check_tol for _, prof in running])
            return
        self.obtain_reference(ctx)

    def served_names(self, server: tuple[str, str] | None) -> list[str]:
        """The labels under which a run's own answer may have served this step's reference:
        those of every exact (variant, profile) of the job, in the order ``reference_server``
        takes them, then ``server``'s (None: no exact solver left to run).  A resumed step
        finds the answer that served before it was interrupted, as the uninterrupted run
        would have used it (the pairs with a stored row are no longer running)."""
        every = [(v, prof) for v in self.job.variants for prof in self.job.profiles]
        names = []
        while (first := self.reference_server(every)) is not None:
            names.append(served_name(*first))
            every = [(v, prof) for v, prof in every if (v.name, prof) != first]
        return [*dict.fromkeys([*names, *([served_name(*server)] if server else [])])]

    def reference_server(self, running: list[tuple[SolverVariant, str]]) -> tuple[str, str] | None:
        """The (label, profile) of the exact solver in the run whose answer is to serve as
        the reference: the tightest profile first, then the reference candidates' order,
        then the run's order.  None without a reference, or without an exact solver."""
        if not self.job.reference_candidates:
            return None
        order = {name: i for i, name in enumerate(self.job.reference_candidates)}
        exact = [(get_profile(prof).check_tol, order.get(v.base, len(order)), i, (v.name, prof))
                 for i, (v, prof) in enumerate(running) if is_exact(v.base)]
        return min(exact)[-1] if exact else None

    def use_stored_reference(self, ctx: StepContext, names: list[str] | tuple[str, ...],
                             max_kkt: float = REFERENCE_MAX_KKT) -> bool:
        """Take the first of ``names`` whose reference of this step is stored in OUT/_cache/
        and holds on the step within ``max_kkt`` (``stored_reference_holds``); one that does
        not is written over when that reference is obtained again."""
        for name in names:
            path = self.reference_path(ctx.k, name)
            if path.is_file() and not path.is_symlink() and self.stored_reference_holds(ctx, path, max_kkt):
                ctx.reference_solver, ctx.reference_path = name, str(path)
                return True
        return False

    def served_max_kkt(self) -> float:
        """The scaled KKT error a run's own answer stored as a reference must meet to serve
        this job: what a fresh run asks of the answer that serves (``plan_reference``), at
        every profile of the job -- a resumed run takes no looser reference than it would
        have made."""
        return min([REFERENCE_MAX_KKT] + [get_profile(prof).check_tol for prof in self.job.profiles])

    def stored_reference_holds(self, ctx: StepContext, path: Path, max_kkt: float = REFERENCE_MAX_KKT) -> bool:
        """Whether the worker reads the file at ``path`` as this step's answer and the judge
        finds it solved within ``max_kkt`` (``Worker.reference_p``): its stored kkt is not
        trusted."""
        if not self.refresh(ctx):
            return False
        out = self.call(CheckReference(ctx.k, str(path), max_kkt), self.run_cfg.build_timeout)
        return bool(out.ok and out.value is True)

    def obtain_reference(self, ctx: StepContext) -> None:
        if self.use_stored_reference(ctx, self.job.reference_candidates):
            return
        traits = ctx.info.traits
        for cand in self.job.reference_candidates:
            with self.solver_code(f"step {ctx.k}: skip check of reference {cand}"):
                d = skip_decision(cand, traits, self.run_cfg.ref_timeout, self.run_cfg.memory_budget)
            if d.skip:
                self.pass_over_reference(ctx, cand, d)
            elif self.reference_from(ctx, cand, d):
                return

    def pass_over_reference(self, ctx: StepContext, cand: str, d: Decision) -> None:
        """Say why a reference candidate is not asked on this step: a warning where its own
        skip check or model raised (a defect of the solver), else its declared skip."""
        where = (self.job.spec.instance, ctx.k, cand, d.reason)
        if d.failed:
            log.warning("%s step %d: reference %s passed over (%s)", *where)
        else:
            log.info("%s step %d: reference %s skipped (%s)", *where)

    def reference_from(self, ctx: StepContext, cand: str, d: Decision) -> bool:
        if d.operator == "dense" and not self.ensure_dense(ctx):
            return False
        if not self.refresh(ctx):
            return False
        path = self.reference_path(ctx.k, cand)
        msg = ComputeReference(ctx.k, cand, d.operator, str(path), self.run_cfg.ref_timeout)
        out = self.call(msg, self.run_cfg.ref_timeout * 1.1 + 5.0)
        reply: ReferenceReply | None = out.value if out.ok else None
        if reply is not None and not reply.error:
            ctx.reference_solver, ctx.reference_path = cand, str(path)
            return True
        why = reply.error if reply is not None else f"{out.kind}: {out.detail}"
        log.info("%s step %d: reference %s not usable (%s)", self.job.spec.instance, ctx.k, cand, why)
        return False

    def reference_path(self, k: int, solver: str) -> Path:
        spec = self.job.spec
        key = json.dumps([spec.scene, spec.instance, spec.params_json(), int(k), solver], default=str)
        digest = hashlib.sha1(key.encode("utf-8")).hexdigest()[:16]
        safe = safe_name(f"{spec.scene}-{spec.instance}")[:80]
        return self.cache_dir / f"ref-{safe}-k{k}-{safe_name(solver)[:80]}-{digest}.npz"

    # -- warm starts ------------------------------------------------------
    def want_warm(self, v: SolverVariant, k: int) -> bool:
        if not (self.run_cfg.warm and self.job.load_history and k > 0):
            return False
        try:
            return load_solver(v.base).capabilities.warm_start != "none"
        except Exception:
            return False

    def ensure_warm_source(self, ctx: StepContext, v: SolverVariant, profile: str, operator: str) -> bool:
        """Make sure the worker holds this solver's answer of the previous step."""
        if (self.worker.generation, v.name, profile, ctx.k - 1) in self.warm_have and self.worker.alive:
            return True
        previous = self.statuses.get(self.rows.cell_id(ctx.k - 1, v, profile, 0))
        if previous not in ("solved", "inaccurate") or not self.refresh(ctx):
            return False
        task = self.solve_task(ctx, v, profile, operator, warm=False)
        out = self.call(Regenerate(task), self.run_cfg.timeout * 1.1 + 5.0)
        if out.ok and out.value.ok and self.worker.alive:  # (not a worker ended for the threads left)
            self.warm_have.add((self.worker.generation, v.name, profile, ctx.k - 1))
            return True
        return False

    # -- solving ----------------------------------------------------------
    def solve_task(self, ctx: StepContext, v: SolverVariant, profile: str, operator: str, warm: bool) -> SolveTask:
        spec = self.job.spec
        arrays = self.cache_dir.parent / "arrays" / safe_name(f"{spec.scene}-{spec.instance}-{v.name}.npz")
        serve = ctx.serving == (v.name, profile) and ctx.reference_path is None
        keep = self.want_warm(v, ctx.k + 1) and ctx.k + 1 < ctx.info.steps
        return SolveTask(step=ctx.k, base=v.base, params=dict(v.params), label=v.name, profile=profile,
                         operator=operator, check_tol=get_profile(profile).check_tol, time_limit=self.run_cfg.timeout,
                         warm=warm, reference_path=ctx.reference_path, arrays_path=str(arrays),
                         reference_out=str(self.reference_path(ctx.k, served_name(v.name, profile))) if serve else None,
                         reference_max_kkt=ctx.serve_max_kkt,
                         warm_out=str(self.warm_path(ctx.k, v, profile)) if keep else None,
                         warm_in=str(self.warm_path(ctx.k - 1, v, profile)) if ctx.k > 0 else None)

    def warm_path(self, k: int, v: SolverVariant, profile: str) -> Path:
        """Where the answer of step ``k`` of (variant, profile) is kept as the next step's
        warm start (``WarmState.save``) until that step's cells are all recorded: a resumed
        run starts from it, not from a re-solve."""
        spec = self.job.spec
        key = json.dumps([spec.scene, spec.instance, spec.params_json(), v.name, v.params, profile], default=str)
        digest = hashlib.sha1(key.encode("utf-8")).hexdigest()[:16]
        return self.cache_dir / f"warm-{safe_name(spec.instance)[:60]}-{safe_name(v.name)[:60]}-{digest}-k{k}.npz"

    def predicted_seconds(self, ctx: StepContext, v: SolverVariant, profile: str, operator: str) -> float:
        """The predicted time of this solve: extrapolated from the variant's own finished
        steps (``harness.run.skips``), else the solver's time model for this problem (the
        skip policy's ``problem_time_estimate``: the step's own FFT grid and control), else
        at least ``MIN_PREDICTED_MATVECS`` products with H."""
        n = ctx.info.n
        seen = self.policy.observations((v.name, profile), ctx.k) if self.job.load_history else []
        if seen:
            return extrapolated_time(seen, n)[0]
        try:
            with self.solver_code(f"step {ctx.k} {v.name}: time model"):
                t = problem_time_estimate(load_solver(v.base), ctx.info.traits, operator)
        except Exception:
            t = None
        return float(t) if t is not None else MIN_PREDICTED_MATVECS * matvec_seconds(n, operator)

    def timed_solve(self, ctx: StepContext, task: SolveTask, v: SolverVariant) -> tuple[ChildReply, str]:
        """The untimed warm-up (first time this worker meets the variant, unless the solve
        is predicted to be big), then the solve.  Returns (outcome, note on the warm-up)."""
        deadline = self.run_cfg.timeout * 1.1 + 1.0  # the limit plus room for the KKT check and the pipe
        note = ""
        if self.run_cfg.warmup and (self.worker.generation, v.name) not in self.warmed:
            t = self.predicted_seconds(ctx, v, task.profile, task.operator)
            if t > self.run_cfg.warmup_limit:
                note = (f"no warm-up solve: predicted {t:.3g} s > {self.run_cfg.warmup_limit:g} s, so the timed "
                        "solve includes one-time costs")
            else:
                w_out = self.call(WarmUp(task), deadline)
                if w_out.kind in ("timeout", "crashed"):
                    w_out.detail = "in the untimed warm-up solve: " + w_out.detail
                    return w_out, note
            self.warmed.add((self.worker.generation, v.name))
        task = replace(task, untimed=self.untimed.pop(v.name, ""))  # (the row's whatever worker it runs in)
        return self.call(Solve(task), deadline), note

    def run_group(self, ctx: StepContext, v: SolverVariant, profile: str, reps: list[int], operator: str) -> None:
        lost: tuple[str, str] | None = None  # (status, why) once a repeat timed out or crashed
        for r in reps:
            if lost is not None:
                self.emit(self.row(ctx, ctx.k, v, profile, r, status=lost[0], error=f"not attempted: {lost[1]}"))
                continue
            warm = self.want_warm(v, ctx.k) and self.ensure_warm_source(ctx, v, profile, operator)
            # (a regeneration may have restarted the worker: prepare the step again)
            if not (self.refresh(ctx) and (operator != "dense" or self.ensure_dense(ctx))):
                self.emit(self.row(ctx, ctx.k, v, profile, r, status="failed",
                                   error=self._step_error or "could not prepare the step (dense H assembly failed)"))
                continue
            out, note = self.timed_solve(ctx, self.solve_task(ctx, v, profile, operator, warm=warm), v)
            build = self.build_times.get(ctx.k) or 0.0
            if operator == "dense" and not ctx.scene_dense:
                build += ctx.dense_time or 0.0
            if out.ok:
                reply: SolveReply = out.value
                values = answer_columns(reply, self.run_cfg.timeout)
                if reply.kept_warm:
                    self.warm_have.add((self.worker.generation, v.name, profile, ctx.k))
                if reply.reference_saved:  # this answer serves as the step's reference from now on
                    ctx.reference_solver = served_name(v.name, profile)
                    ctx.reference_path = str(self.reference_path(ctx.k, ctx.reference_solver))
            else:
                status = {"timeout": "timeout", "crashed": "crashed"}.get(out.kind, "failed")
                values = dict(status=status, solve_time_s=out.elapsed, warm_start=warm, error=out.detail[-2000:])
                if status in ("timeout", "crashed"):
                    lost = (status, f"repeat {r} ended with {status}")
            if note:
                values["warmup"] = note
            self.emit(self.row(ctx, ctx.k, v, profile, r, operator=operator, build_time_s=build, **values))
        self.forget_warm(ctx, v, profile)

    def forget_warm(self, ctx: StepContext, v: SolverVariant, profile: str) -> None:
        """Step ``ctx.k``'s cells of (variant, profile) are recorded: the previous step's kept
        answer is needed no more, nor this step's on the last step."""
        done = [ctx.k - 1] + ([ctx.k] if ctx.k + 1 >= ctx.info.steps else [])
        for k in done:
            if k >= 0:
                forget_file(self.warm_path(k, v, profile))


def forget_file(path: Path) -> None:
    """Remove a kept answer of ours if it is there; what cannot be removed (a folder put in
    its place, a read-only disk) stays, costing nothing but its space."""
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)


def is_exact(base: str) -> bool:
    """Whether solver ``base`` declares itself exact (``Capabilities.exact``)."""
    try:
        return bool(load_solver(base).capabilities.exact)
    except Exception:
        return False


def run_instance_job(job: InstanceJob, run: RunConfig, out_dir: str | os.PathLike[str],
                     statuses: dict[str, str] | None = None,
                     sink: Callable[[dict[str, Any]], None] | None = None) -> int:
    """Run one job, appending its rows to OUT/rows.jsonl and what its solvers print to
    OUT/solver-output.log.  Returns rows written.

    Usable from any process (a pool worker, another scheduler's worker): it opens the
    store for appending only."""
    store = ResultStore(out_dir, load=statuses is None)
    count = 0

    def write(row: dict[str, Any]) -> None:
        nonlocal count
        store.append(row)
        count += 1
        if sink is not None:
            sink(row)

    if statuses is None:
        stored = {r["cell_id"]: r for r in store.rows()}
        known, job = {c: str(r.get("status", "")) for c, r in stored.items()}, job.with_stored(stored, run)
    else:
        known = statuses
    JobDriver(job, run, known, store.cache_dir, write, store.out / OUTPUT_LOG).run()
    return count
