"""The runner: scenes x instances x load steps x solver variants x profiles x repeats.

Plan
----
``plan_run`` turns scene names and options into ``InstanceJob`` records (picklable: a
scene's ``InstanceSpec`` recipe plus the variants and profiles to run on it).  A job is
independent of every other job, so jobs run one after another (``jobs=1``), on a local
process pool (``jobs>1``), or elsewhere (the Dask scheduler of a later issue calls
``run_instance_job`` on a worker).

One job
-------
``JobRunner`` drives one long-lived isolated worker process (harness/isolation.py) that
builds the instance's ``LoadSequence`` once from its recipe and builds the steps in
order.  For each step it

1. builds the step in the worker (build time measured there);
2. decides for each variant whether to run it or skip it (``skip_decision``: the
   solver's availability, capabilities, memory and time models -- the reason, with
   the estimate, goes to ``skip_reason``);
3. assembles the dense H at most once for the step, and only if a variant that runs
   needs it (its assembly time is added to that variant's ``build_time_s``);
4. obtains the reference solution: from OUT/_cache/ if stored, else by running the
   scene's tightest exact solver once (``scipy-nnls`` where dense fits, else ``nnls``
   or ``pk`` at the ``high`` profile); a reference whose own KKT check fails is
   not used;
5. runs each (variant, profile): an untimed warm-up solve the first time the worker
   meets the variant, then ``repeats`` timed solves, each under a hard wall-clock
   limit enforced by killing the worker; every answer is judged by
   ``harness.kkt.kkt_check`` (never by the solver's own claim) and compared with the
   reference and, where the scene has one, the analytic load.

Warm starts: along a load history each solver starts from its *own* previous-step
answer, mapped by grid index onto the new trial set (new points start at 0), when its
capabilities allow and the run asks (``RunConfig.warm``); row column ``warm_start``
says which.  After a worker restart (or on resume) the previous step is re-solved,
untimed, to recover that starting point.

Rows are appended to the store as they finish (harness/store.py); rerunning the same
command runs only the cells whose ``cell_id`` is missing.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import math
import os
import socket
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET, DenseOperator
from contactbench.problems.scenes import InstanceSpec, SceneConfig, SolverVariant, get_scene
from contactbench.solvers.base import SolverSettings, WarmStart

from .profiles import get_profile
from contactbench.solvers.registry import get_solver, load_solver, register

from .isolation import IsolatedWorker, Outcome, PeakMemory, set_parent_death_signal
from contactbench.problems.kkt import kkt_check, relative_error, relative_load_error
from .meta import build_meta, now_iso, write_meta
from .schema import ALL_COLUMNS
from .store import ResultStore

log = logging.getLogger("contactbench")

#: Exact solvers tried, in order, for the reference solution of a step.
REFERENCE_CANDIDATES: tuple[str, ...] = ("scipy-nnls", "nnls", "pk")
REFERENCE_PROFILE = "high"
#: A candidate reference whose own scaled KKT error exceeds this is not used.
REFERENCE_MAX_KKT = 1e-6
MAX_TRACE_POINTS = 200
GiB = float(2**30)

# ---------------------------------------------------------------------------
# Configuration and plan
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RunConfig:
    """How to run (the scene options are in ``SceneConfig``).

    profiles          : accuracy profiles (None: the scene's ``default_profiles`` or "default").
    repeats           : timed solves per cell group (min and median are reported).
    timeout           : hard wall-clock limit per solve, seconds.
    warm              : warm-start along load histories where the solver supports it.
    warmup            : one untimed solve the first time a worker meets a variant.
    jobs              : instance jobs run concurrently (process pool).
    reference         : "auto", "none" or a solver name.
    reference_timeout : limit for one reference solve (None: 5 x timeout).
    build_timeout     : limit for building one instance step in the worker.
    memory_budget     : bytes a solve may use (dense H + the solver's own estimate).
    progress          : progress bar (None: on a terminal and not under CI).
    threads_per_worker: BLAS/FFT threads per worker (None: cores // jobs when jobs > 1).
    """

    profiles: tuple[str, ...] | None = None
    repeats: int = 1
    timeout: float = 60.0
    warm: bool = True
    warmup: bool = True
    jobs: int = 1
    reference: str = "auto"
    reference_timeout: float | None = None
    build_timeout: float = 600.0
    memory_budget: float = DEFAULT_MEMORY_BUDGET
    progress: bool | None = None
    threads_per_worker: int | None = None

    def __post_init__(self) -> None:
        if self.repeats < 1:
            raise ValueError(f"repeats must be >= 1, got {self.repeats}")
        if not self.timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds, got {self.timeout}")
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {self.jobs}")
        for p in self.profiles or ():
            get_profile(p)

    @property
    def ref_timeout(self) -> float:
        return float(self.reference_timeout or 5.0 * self.timeout)

    def worker_threads(self) -> int | None:
        if self.threads_per_worker:
            return int(self.threads_per_worker)
        if self.jobs > 1:
            return max(1, (os.cpu_count() or 1) // self.jobs)
        return None


@dataclass(frozen=True)
class InstanceJob:
    """Everything needed to run all cells of one instance (picklable)."""

    spec: InstanceSpec
    variants: tuple[SolverVariant, ...]
    profiles: tuple[str, ...]
    load_history: bool
    reference_candidates: tuple[str, ...]
    steps_hint: int

    def n_cells(self, repeats: int) -> int:
        return self.steps_hint * len(self.variants) * len(self.profiles) * repeats


@dataclass
class RunPlan:
    jobs: list[InstanceJob]
    warnings: list[str] = field(default_factory=list)
    scenes: list[str] = field(default_factory=list)

    def n_cells(self, repeats: int) -> int:
        return sum(j.n_cells(repeats) for j in self.jobs)


def safe_name(name: str) -> str:
    """A file name with only letters, digits, '.', '_', '-', '[', ']', '=' and '+'."""
    return "".join(c if c.isalnum() or c in "._-[]=+" else "_" for c in name)


def params_json(params: dict[str, Any]) -> str:
    return json.dumps(params, sort_keys=True, default=str)


def make_cell_id(spec: InstanceSpec, step: int, variant: SolverVariant, profile: str, repeat: int, warm: bool) -> str:
    """Stable id of one solve: a hash of everything that names it."""
    key = json.dumps(
        [spec.scene, spec.instance, spec.params_json(), int(step), variant.name, variant.base,
         params_json(variant.params), profile, int(repeat), "warm" if warm else "cold"],
        default=str,
    )
    return hashlib.sha1(key.encode("utf-8")).hexdigest()[:20]


def resolve_solver_names(requested: Sequence[str] | str | None, scene_default: Sequence[str] | None) -> list[str]:
    """Registry names to run: "all" (every registered solver, unavailable ones are
    recorded as skipped), an explicit list (``module:NAME`` entries are loaded and
    registered), or the scene's defaults, or every available solver."""
    from contactbench.solvers.registry import all_solvers, available_solvers

    if isinstance(requested, str):
        requested = [s for s in requested.split(",") if s.strip()]
    if requested:
        if list(requested) == ["all"]:
            return list(all_solvers())
        names = []
        for spec in requested:
            spec = spec.strip()
            if ":" in spec:
                solver = load_solver(spec)
                register(solver, replace=True)
                names.append(solver.name)
            else:
                get_solver(spec)  # a clear error for an unknown name
                names.append(spec)
        return names
    if scene_default:
        return [s for s in scene_default if s in all_solvers()]
    return list(available_solvers())


def _expand_scene(name: str, cfg: SceneConfig, solvers: Sequence[str] | str | None,
                  profiles: tuple[str, ...] | None, reference: str,
                  default_solvers: Sequence[str] | None = None) -> tuple[list[InstanceJob], list[str]]:
    scene = get_scene(name)
    parts = getattr(scene, "parts", None)
    if callable(parts):  # a composite scene (e.g. "default"): a mix of other scenes
        jobs: list[InstanceJob] = []
        warnings: list[str] = []
        for sub_name, sub_cfg, sub_solvers, sub_profiles in parts(cfg):
            j, w = _expand_scene(sub_name, sub_cfg, solvers, profiles or sub_profiles, reference,
                                 default_solvers=sub_solvers)
            jobs += j
            warnings += w
        return jobs, warnings
    merged = scene.config(cfg)
    names = resolve_solver_names(solvers, default_solvers or scene.default_solvers)
    variants = tuple(scene.variants(merged, names))
    profs = tuple(profiles or getattr(scene, "default_profiles", None) or ("default",))
    for p in profs:
        get_profile(p)
    if reference == "none":
        refs: tuple[str, ...] = ()
    elif reference == "auto":
        own = getattr(scene, "reference_solver", None)
        refs = tuple(dict.fromkeys(([own] if own else []) + list(REFERENCE_CANDIDATES)))
    else:
        refs = (reference,)
    jobs = [
        InstanceJob(spec, variants, profs, bool(scene.load_history), refs, int(spec.params.get("steps") or 1))
        for spec in scene.instances(merged)
    ]
    warnings = [f"{name}: {w}" for w in scene.warnings(merged)]
    return jobs, warnings


def plan_run(scenes: Sequence[str], cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
             run: RunConfig | None = None) -> RunPlan:
    """Expand scene names into instance jobs."""
    cfg = cfg or SceneConfig()
    run = run or RunConfig()
    plan = RunPlan(jobs=[], scenes=list(scenes))
    for name in scenes:
        jobs, warnings = _expand_scene(name, cfg, solvers, run.profiles, run.reference)
        plan.jobs += jobs
        plan.warnings += warnings
    return plan


# ---------------------------------------------------------------------------
# Skips: availability, capabilities, memory and time models
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Decision:
    """Run the variant with ``operator`` ("fft"/"dense"), or skip it for ``reason``."""

    operator: str = ""
    reason: str = ""

    @property
    def skip(self) -> bool:
        return bool(self.reason)


#: Growth exponent of solve time with n used to extrapolate an observed solve (the
#: floor; with two observed steps the measured exponent is used, up to the cap: dense
#: factorisations grow like n^3, and a single jump between two steps must not condemn
#: a solver -- the paper's NNLS goes 2.3 s -> 29 s -> 38 s -> 78 s -> 114 s at 512^2).
OBSERVED_TIME_EXPONENT = 1.5
OBSERVED_EXPONENT_CAP = 3.0
#: An extrapolated time above this fraction of the limit counts as hopeless.
OBSERVED_SKIP_FRACTION = 1.0

Observation = tuple[int, float]  # (n, solve seconds) of one finished step


def extrapolated_time(history: Sequence[Observation], n: int) -> tuple[float, float]:
    """(predicted seconds at n, exponent used) from the last one or two finished steps of
    the same solver: t_last (n / n_last)^e, with e measured between the last two steps
    when both are long enough to time (> 0.05 s) and n grew, clamped to [1.5, 3]."""
    n1, t1 = history[-1]
    e = OBSERVED_TIME_EXPONENT
    if len(history) >= 2:
        n0, t0 = history[-2]
        if n1 > 1.1 * n0 and t0 > 0.05 and t1 > 0:
            e = min(OBSERVED_EXPONENT_CAP, max(e, math.log(t1 / t0) / math.log(n1 / n0)))
    return t1 * max(1.0, n / n1) ** e, e


def skip_decision(base: str, n: int, instance_operator: str, time_limit: float, memory_budget: float,
                  observed: Sequence[Observation] | Observation | None = None) -> Decision:
    """Ask the solver's availability, capabilities, memory and time models whether it
    can serve a trial set of size n within the limits.  The reason is in words, with
    the estimate.  ``observed`` = the (n', seconds) of the same solver's last one or two
    finished steps of the load sequence: when given it replaces the solver's static time
    model (which cannot know about warm starts), extrapolated by ``extrapolated_time``,
    and the step is skipped when that exceeds the limit."""
    try:
        solver = resolve_solver(base)
    except Exception as exc:
        return Decision(reason=f"solver {base!r} cannot be loaded: {exc}")
    ok, why = solver.availability()
    if not ok:
        return Decision(reason=f"not available: {why}")
    caps = solver.capabilities
    if caps.max_n is not None and n > caps.max_n:
        return Decision(reason=f"trial set n = {n} exceeds the solver's limit max_n = {caps.max_n}")
    wants_dense = caps.needs_dense or "fft" not in caps.operators
    if instance_operator == "dense":
        if "dense" not in caps.operators:
            return Decision(reason="the solver needs the matrix-free FFT operator; this scene builds a dense H")
        operator = "dense"
    else:
        operator = "dense" if wants_dense else "fft"
    dense_bytes = 8.0 * n * n if operator == "dense" and instance_operator != "dense" else 0.0
    try:
        own_bytes = float(solver.memory_estimate(n))
    except Exception as exc:
        return Decision(reason=f"memory model failed: {exc}")
    if dense_bytes > memory_budget:
        return Decision(reason=(f"needs dense H: {n} x {n} float64 = {dense_bytes / GiB:.3g} GiB "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    if dense_bytes + own_bytes > memory_budget:
        return Decision(reason=(f"memory estimate {(dense_bytes + own_bytes) / GiB:.3g} GiB at n = {n} "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    history = [observed] if observed and not isinstance(observed[0], (tuple, list)) else list(observed or [])
    history = [(int(a), float(b)) for a, b in history if a > 0]  # type: ignore[misc]
    if history:
        t_obs, e = extrapolated_time(history, n)
        if t_obs > OBSERVED_SKIP_FRACTION * time_limit:
            n1, t1 = history[-1]
            return Decision(reason=(f"predicted solve time {t_obs:.3g} s at n = {n} from {t1:.3g} s at n = {n1} on "
                                    f"the previous step (time ~ n^{e:.2g}), over the time limit of {time_limit:.3g} s"))
        return Decision(operator=operator)
    try:
        t_est = solver.time_estimate(n, operator)
    except Exception as exc:
        return Decision(reason=f"time model failed: {exc}")
    if t_est is not None and t_est > time_limit:
        return Decision(reason=(f"predicted solve time {t_est:.3g} s at n = {n} ({operator} operator) "
                                f"exceeds the time limit of {time_limit:.3g} s"))
    return Decision(operator=operator)


def resolve_solver(base: str) -> Any:
    return load_solver(base) if ":" in base else get_solver(base)


# ---------------------------------------------------------------------------
# Warm starts
# ---------------------------------------------------------------------------


def map_by_grid_index(values: np.ndarray, from_idx: np.ndarray, to_idx: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """Carry ``values`` (one per grid index in ``from_idx``) over to the positions
    ``to_idx``: a position present in both keeps its value, a new one gets ``fill``."""
    values = np.asarray(values, dtype=np.float64)
    from_idx = np.asarray(from_idx, dtype=np.int64)
    to_idx = np.asarray(to_idx, dtype=np.int64)
    if values.shape != from_idx.shape:
        raise ValueError(f"{values.size} values for {from_idx.size} grid indices")
    order = np.argsort(from_idx, kind="stable")
    sorted_idx = from_idx[order]
    pos = np.searchsorted(sorted_idx, to_idx)
    pos_c = np.minimum(pos, max(sorted_idx.size - 1, 0))
    hit = (pos < sorted_idx.size) & (sorted_idx[pos_c] == to_idx) if sorted_idx.size else np.zeros(to_idx.shape, bool)
    out = np.full(to_idx.shape, fill, dtype=np.float64)
    out[hit] = values[order[pos_c[hit]]]
    return out


@dataclass
class WarmState:
    step: int
    indices: np.ndarray
    p: np.ndarray
    w: np.ndarray | None


def warm_start_from(state: WarmState | None, inst: ContactInstance, step: int, kind: str) -> WarmStart | None:
    """The previous step's answer mapped onto this step's trial set (None if there is
    no previous-step answer or the instance has no grid geometry)."""
    geom = inst.geometry
    if state is None or state.step != step - 1 or geom is None or kind == "none":
        return None
    p = map_by_grid_index(state.p, state.indices, geom.indices)
    w = None
    if kind == "primal-dual" and state.w is not None:
        w = map_by_grid_index(state.w, state.indices, geom.indices)
    return WarmStart(p=p, w=w)


# ---------------------------------------------------------------------------
# The worker side (runs in the isolated process)
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SolveTask:
    step: int
    base: str
    params: dict[str, Any]
    label: str
    profile: str
    operator: str
    check_tol: float
    time_limit: float
    warm: bool = False
    warmup: bool = False
    reference_path: str | None = None
    record_warm: bool = True
    arrays_path: str | None = None  # where a wrong answer on a small instance is kept for the report


@dataclass(frozen=True)
class ReferenceTask:
    step: int
    base: str
    operator: str
    path: str
    time_limit: float


def instance_operator_kind(inst: ContactInstance) -> str:
    return "dense" if isinstance(inst.qp.H, DenseOperator) else "fft"


def thin_trace(trace: Iterable[Sequence[float]], limit: int = MAX_TRACE_POINTS) -> list[list[float]]:
    pts = [[int(t[0]), float(t[1]), float(t[2])] for t in trace]
    if len(pts) <= limit:
        return pts
    keep = np.unique(np.linspace(0, len(pts) - 1, limit).round().astype(int))
    return [pts[i] for i in keep]


def answer_metrics(inst: ContactInstance, p: np.ndarray, check_tol: float, p_ref: np.ndarray | None,
                   analytic: dict[str, float]) -> dict[str, Any]:
    """The harness's own judgement of an answer: KKT figures (recomputed from H and p),
    verdict, load, contact fraction and errors against the reference / closed form."""
    kkt = kkt_check(inst, p)
    load = inst.load(p)
    out: dict[str, Any] = {
        "status": "solved" if kkt.passes(check_tol) else "inaccurate",
        "primal_residual": kkt.primal,
        "dual_residual": kkt.dual,
        "complementarity": kkt.complementarity,
        "complementarity_sum": kkt.complementarity_sum,
        "kkt_error": kkt.kkt_error,
        "objective": kkt.objective,
        "load": load,
        "dim_load": inst.dimensionless_load(p),
        "contact_fraction": inst.contact_fraction(p),
    }
    if p_ref is not None:
        out["p_rel_error"] = relative_error(p, p_ref)
        out["load_rel_error"] = relative_load_error(load, float(np.sum(p_ref)))
    a_load = analytic.get("load")
    if a_load is not None and math.isfinite(a_load):
        out["analytic_load_rel_error"] = relative_load_error(load, a_load)
        if p_ref is None:
            out["load_rel_error"] = out["analytic_load_rel_error"]
    return out


class InstanceWorker:
    """Message handler living in the isolated worker: builds the instance from its
    recipe once, steps in order, the dense H once per step, and runs solves."""

    def __init__(self, spec: InstanceSpec, memory_budget: float = DEFAULT_MEMORY_BUDGET) -> None:
        self.spec = spec
        self.memory_budget = memory_budget
        self.seq: Any = None
        self.seq_time = 0.0
        self.steps: dict[int, ContactInstance] = {}
        self.dense: dict[int, DenseOperator] = {}
        self.refs: dict[str, np.ndarray] = {}
        self.warm: dict[tuple[str, str, int], WarmState] = {}  # (label, profile, step)

    def __call__(self, msg: tuple[str, Any]) -> Any:
        kind, arg = msg
        if kind == "step":
            return self.step_info(int(arg))
        if kind == "dense":
            return self.ensure_dense(int(arg))
        if kind == "reference":
            return self.reference(arg)
        if kind == "solve":
            return self.solve(arg)
        if kind == "regen":
            return self.regenerate(arg)
        if kind == "warmup":
            return self.warmup(arg)
        raise ValueError(f"unknown message {kind!r}")

    # -- building ---------------------------------------------------------
    def ensure_sequence(self) -> Any:
        if self.seq is None:
            t0 = time.perf_counter()
            self.seq = self.spec.build()
            self.seq_time = time.perf_counter() - t0
        return self.seq

    def ensure_step(self, k: int) -> tuple[ContactInstance, float]:
        if k in self.steps:
            return self.steps[k], 0.0
        t0 = time.perf_counter()
        seq = self.ensure_sequence()
        if not 0 <= k < len(seq):
            raise IndexError(f"step {k} out of range: the sequence has {len(seq)} steps")
        inst = seq.at(k)
        for old in [s for s in self.steps if s < k - 1 or s > k]:
            del self.steps[old]
        for old in [s for s in self.dense if s != k]:
            del self.dense[old]
        self.steps[k] = inst
        return inst, time.perf_counter() - t0

    def step_info(self, k: int) -> dict[str, Any]:
        fresh_seq = self.seq is None
        inst, t_build = self.ensure_step(k)
        seq = self.seq
        geom = inst.geometry
        analytic = {}
        if seq.analytic is not None:
            analytic = {key: float(v) for key, v in seq.analytic(k).items()}
        return {
            "steps": len(seq),
            "n": inst.n,
            "delta": float(inst.delta),
            "build_time": t_build,
            "sequence_built": fresh_seq,
            "operator": instance_operator_kind(inst),
            "N": int(geom.grid_shape[0]) if geom is not None else None,
            "E": float(inst.E),
            "kernel": inst.kernel,
            "periodic": bool(inst.periodic),
            "nominal_area": float(inst.nominal_area),
            "analytic": analytic,
        }

    def ensure_dense(self, k: int) -> float:
        inst, _ = self.ensure_step(k)
        if k in self.dense or instance_operator_kind(inst) == "dense":
            return 0.0
        t0 = time.perf_counter()
        self.dense[k] = DenseOperator(inst.qp.H.to_dense(self.memory_budget))
        return time.perf_counter() - t0

    def qp_for(self, k: int, operator: str) -> QP:
        inst, _ = self.ensure_step(k)
        if operator == "dense" and instance_operator_kind(inst) != "dense":
            self.ensure_dense(k)
            return QP(self.dense[k], inst.qp.ubar, inst.qp.geometry)
        return inst.qp

    def reference_p(self, path: str | None) -> np.ndarray | None:
        if not path:
            return None
        if path not in self.refs:
            if not os.path.exists(path):
                return None
            with np.load(path) as data:
                self.refs[path] = np.asarray(data["p"], dtype=np.float64)
        return self.refs[path]

    # -- solving ----------------------------------------------------------
    def reference(self, task: ReferenceTask) -> dict[str, Any]:
        """Load the stored reference, or compute it once and store it."""
        if os.path.exists(task.path):
            self.reference_p(task.path)
            return {"cached": True, "solver": task.base}
        inst, _ = self.ensure_step(task.step)
        qp = self.qp_for(task.step, task.operator)
        solver = resolve_solver(task.base)
        settings = SolverSettings(tol=get_profile(REFERENCE_PROFILE).tol, time_limit=task.time_limit)
        t0 = time.perf_counter()
        res = solver.solve(qp, settings, None)
        elapsed = time.perf_counter() - t0
        p = np.asarray(res.p, dtype=np.float64).reshape(-1)
        if p.shape != (inst.n,):
            return {"error": f"reference {task.base} returned p of size {p.size} for n = {inst.n}"}
        kkt = kkt_check(inst, p)
        if not kkt.passes(REFERENCE_MAX_KKT):
            return {"error": f"reference {task.base} failed its KKT check (kkt_error {kkt.kkt_error:.3g})"}
        tmp = task.path + f".tmp{os.getpid()}"
        with open(tmp, "wb") as fh:
            np.savez(fh, p=p, solver=task.base, kkt_error=kkt.kkt_error, time=elapsed)
        os.replace(tmp, task.path)
        self.refs[task.path] = p
        return {"cached": False, "solver": task.base, "time": elapsed, "kkt_error": kkt.kkt_error}

    def regenerate(self, task: SolveTask) -> bool:
        """Re-solve the previous step (untimed) to recover this solver's warm start."""
        prev = replace(task, step=task.step - 1, warm=False, warmup=False, reference_path=None)
        inst, _ = self.ensure_step(prev.step)
        qp = self.qp_for(prev.step, prev.operator)
        solver = resolve_solver(prev.base)
        res = solver.solve(qp, self.settings(prev), None)
        return self.remember(prev, inst, np.asarray(res.p, dtype=np.float64).reshape(-1), res.w)

    def remember(self, task: SolveTask, inst: ContactInstance, p: np.ndarray, w: Any) -> bool:
        geom = inst.geometry
        if geom is None or p.shape != (inst.n,) or not np.all(np.isfinite(p)):
            return False
        w_arr = None
        if w is not None:
            w_arr = np.asarray(w, dtype=np.float64).reshape(-1)
            if w_arr.shape != p.shape:
                w_arr = None
        key = (task.label, task.profile)
        for old in [s for s in self.warm if s[:2] == key and s[2] < task.step - 1]:
            del self.warm[old]
        self.warm[(*key, task.step)] = WarmState(task.step, np.asarray(geom.indices), p.copy(), w_arr)
        return True

    @staticmethod
    def settings(task: SolveTask) -> SolverSettings:
        return SolverSettings(tol=get_profile(task.profile).tol, time_limit=task.time_limit,
                              params=copy.deepcopy(task.params))

    def _prepare(self, task: SolveTask) -> tuple[ContactInstance, QP, Any, WarmStart | None]:
        inst, _ = self.ensure_step(task.step)
        qp = self.qp_for(task.step, task.operator)
        solver = resolve_solver(task.base)
        warm = None
        if task.warm:
            warm = warm_start_from(self.warm.get((task.label, task.profile, task.step - 1)), inst, task.step,
                                   solver.capabilities.warm_start)
        return inst, qp, solver, warm

    def warmup(self, task: SolveTask) -> bool:
        """The untimed warm-up solve (imports, JIT, caches); its answer is discarded."""
        _, qp, solver, warm = self._prepare(task)
        try:
            solver.solve(qp, self.settings(task), warm)
        except Exception:
            return False  # the timed solve fails the same way and records it
        return True

    def solve(self, task: SolveTask) -> dict[str, Any]:
        """One timed solve, judged by the harness."""
        inst, qp, solver, warm = self._prepare(task)
        settings = self.settings(task)
        count0 = qp.H.matvec_count
        with PeakMemory() as mem:
            t0 = time.perf_counter()
            try:
                res = solver.solve(qp, settings, warm)
            except Exception as exc:
                elapsed = time.perf_counter() - t0
                return {"status": "failed", "solve_time_s": elapsed, "warm_start": warm is not None,
                        "error": f"{type(exc).__name__}: {exc}"}
            elapsed = time.perf_counter() - t0
        matvecs = qp.H.matvec_count - count0
        row: dict[str, Any] = {
            "solve_time_s": elapsed,
            "peak_mem_mb": mem.mb,
            "warm_start": warm is not None,
            "iterations": int(res.iterations),
            "solver_status": str(res.status),
            "solver_converged": bool(res.converged),
            "solver_message": str(res.message)[:500],
            "solver_internal_time_s": float(res.solve_time),
            "setup_time_s": float(res.setup_time),
            "matvecs": int(res.matvecs or matvecs),
            "trace": json.dumps(thin_trace(res.trace)) if res.trace else "",
        }
        p = np.asarray(res.p, dtype=np.float64).reshape(-1)
        if p.shape != (inst.n,):
            row.update(status="failed", error=f"solver returned p of size {p.size} for n = {inst.n}")
            return row
        if not np.all(np.isfinite(p)):
            row.update(status="failed", error="solver returned non-finite values in p")
            return row
        analytic = {}
        if self.seq is not None and self.seq.analytic is not None:
            analytic = self.seq.analytic(task.step)
        row.update(answer_metrics(inst, p, task.check_tol, self.reference_p(task.reference_path), analytic))
        if task.time_limit and elapsed > task.time_limit:
            row.update(status="timeout", error=f"finished after {elapsed:.3g} s, beyond the {task.time_limit:.3g} s limit")
        row["correct_claim"] = bool(res.converged) == (row["status"] == "solved")
        save_wrong_answer(task.arrays_path, inst, p, self.reference_p(task.reference_path), row)
        if task.record_warm:
            self.remember(task, inst, p, res.w)
        return row


#: Wrong answers on instances up to this size are kept as arrays for the report's plots.
MAX_SAVED_N = 5000


def save_wrong_answer(path: str | None, inst: ContactInstance, p: np.ndarray, p_ref: np.ndarray | None,
                      row: dict[str, Any]) -> None:
    """Keep (p, p_ref, ubar, w) of a wrong answer on a small instance as ``path`` (npz, no
    pickles) -- the counterexample figure plots one.  The first one per cell wins."""
    if not path or inst.n > MAX_SAVED_N or p_ref is None or os.path.exists(path):
        return
    wrong = row.get("status") != "solved" or not (float(row.get("p_rel_error", np.nan)) <= 1e-6)
    if not wrong:
        return
    os.makedirs(os.path.dirname(path), exist_ok=True)
    w = inst.qp.H.matvec(p) - inst.qp.ubar
    tmp = path + f".tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        np.savez(fh, p=p, p_ref=p_ref, ubar=inst.qp.ubar, w=w, E=inst.E)
    os.replace(tmp, path)


# ---------------------------------------------------------------------------
# The parent side: one job
# ---------------------------------------------------------------------------


def blank_row() -> dict[str, Any]:
    row: dict[str, Any] = {c: None for c in ALL_COLUMNS}
    row.update(skip_reason="", error="", trace="", reference_solver="", solver_message="", solver_status="")
    return row


@dataclass
class StepContext:
    k: int
    info: dict[str, Any]
    generation: int
    dense_time: float | None = None
    reference_solver: str = ""
    reference_path: str | None = None


class JobRunner:
    """Runs the missing cells of one ``InstanceJob`` in an isolated worker and hands
    each finished row to ``sink``."""

    def __init__(self, job: InstanceJob, run: RunConfig, statuses: dict[str, str], cache_dir: Path,
                 sink: Callable[[dict[str, Any]], None]) -> None:
        self.job = job
        self.run_cfg = run
        self.statuses = dict(statuses)
        self.cache_dir = Path(cache_dir)
        self.sink = sink
        self.worker = IsolatedWorker(partial(InstanceWorker, job.spec, run.memory_budget), threads=run.worker_threads())
        self.warmed: set[tuple[int, str]] = set()
        self.warm_have: set[tuple[int, str, str, int]] = set()  # (generation, label, profile, step) held by the worker
        self._step_error = ""
        self.host = socket.gethostname()
        self.build_times: dict[int, float] = {}
        #: (variant, profile) -> (step, n) of its first timeout: larger steps are skipped.
        self.too_slow: dict[tuple[str, str], tuple[int, int]] = {}
        #: (variant, profile) -> (n, seconds) of its last two finished solves along the
        #: load history: the time prediction for the next step (see skip_decision).
        self.observed: dict[tuple[str, str], list[Observation]] = {}

    # -- cells ------------------------------------------------------------
    def cell_id(self, k: int, v: SolverVariant, profile: str, r: int) -> str:
        return make_cell_id(self.job.spec, k, v, profile, r, self.run_cfg.warm)

    def missing(self, k: int) -> list[tuple[SolverVariant, str, list[int]]]:
        out = []
        for v in self.job.variants:
            for prof in self.job.profiles:
                reps = [r for r in range(self.run_cfg.repeats) if self.cell_id(k, v, prof, r) not in self.statuses]
                if reps:
                    out.append((v, prof, reps))
        return out

    def emit(self, row: dict[str, Any]) -> None:
        self.statuses[row["cell_id"]] = row["status"]
        self.sink(row)

    def row_for(self, ctx: StepContext | None, k: int, v: SolverVariant, profile: str, r: int, **values: Any) -> dict[str, Any]:
        row = blank_row()
        spec = self.job.spec
        info = ctx.info if ctx else {}
        try:
            family = resolve_solver(v.base).family
        except Exception:
            family = ""
        row.update(
            scene=spec.scene, instance=spec.instance, step=k, delta=info.get("delta", float("nan")), n=info.get("n"),
            solver=v.name, base_solver=v.base, params=params_json(v.params), family=family, profile=profile,
            repeat=r, warm_start=False, check_tol=get_profile(profile).check_tol, time_limit_s=self.run_cfg.timeout,
            E=info.get("E"), nominal_area=info.get("nominal_area"), N=info.get("N"), kernel=info.get("kernel", ""),
            periodic=info.get("periodic"), reference_solver=ctx.reference_solver if ctx else "",
            analytic_load=(info.get("analytic") or {}).get("load"), build_time_s=self.build_times.get(k),
            host=self.host, timestamp=now_iso(), cell_id=self.cell_id(k, v, profile, r),
            history="warm" if self.run_cfg.warm else "cold",
        )
        row.update(values)
        return row

    # -- driving ----------------------------------------------------------
    def run(self) -> None:
        try:
            k, n_steps = 0, self.job.steps_hint
            while k < n_steps:
                todo = self.missing(k)
                if todo:
                    ctx = self.prepare_step(k)
                    if ctx is None:
                        self.fail_step(k, todo)
                    else:
                        n_steps = int(ctx.info["steps"])
                        self.run_step(ctx, todo)
                k += 1
        finally:
            self.worker.close()

    def prepare_step(self, k: int) -> StepContext | None:
        out = self.worker.call(("step", k), self.run_cfg.build_timeout)
        if not out.ok:
            self._step_error = f"building step {k} failed ({out.kind}): {out.detail}"
            log.warning("%s %s", self.job.spec.instance, self._step_error)
            return None
        info = out.value
        if k not in self.build_times:
            self.build_times[k] = float(info["build_time"])
        return StepContext(k=k, info=info, generation=self.worker.generation)

    def fail_step(self, k: int, todo: list[tuple[SolverVariant, str, list[int]]]) -> None:
        status = "failed"
        for v, prof, reps in todo:
            for r in reps:
                self.emit(self.row_for(None, k, v, prof, r, status=status, error=self._step_error))

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
        if not self.refresh(ctx):
            return False
        out = self.worker.call(("dense", ctx.k), self.run_cfg.build_timeout)
        if not out.ok:
            return False
        if ctx.dense_time is None:
            ctx.dense_time = float(out.value)
        return True

    def run_step(self, ctx: StepContext, todo: list[tuple[SolverVariant, str, list[int]]]) -> None:
        info = ctx.info
        n, inst_op = int(info["n"]), str(info["operator"])
        decisions = {(v.name, prof): skip_decision(v.base, n, inst_op, self.run_cfg.timeout,
                                                   self.run_cfg.memory_budget, self.observed.get((v.name, prof)))
                     for v, prof, _ in todo}
        if any(not d.skip for d in decisions.values()):
            self.obtain_reference(ctx, n, inst_op)
        for v, prof, reps in todo:
            d = decisions[(v.name, prof)]
            slow = self.too_slow.get((v.name, prof))
            if not d.skip and slow is not None and n >= slow[1]:
                d = Decision(reason=f"predicted over the {self.run_cfg.timeout:g} s limit: it timed out at step "
                                    f"{slow[0]} with n = {slow[1]}, and this step has n = {n}")
            if d.skip:
                for r in reps:
                    self.emit(self.row_for(ctx, ctx.k, v, prof, r, status="skipped", skip_reason=d.reason))
                continue
            self.run_group(ctx, v, prof, reps, d.operator)

    def obtain_reference(self, ctx: StepContext, n: int, inst_op: str) -> None:
        spec = self.job.spec
        for cand in self.job.reference_candidates:
            path = self.reference_path(ctx.k, cand)
            if path.exists():
                ctx.reference_solver, ctx.reference_path = cand, str(path)
                return
        for cand in self.job.reference_candidates:
            d = skip_decision(cand, n, inst_op, self.run_cfg.ref_timeout, self.run_cfg.memory_budget)
            if d.skip:
                continue
            if d.operator == "dense" and inst_op != "dense" and not self.ensure_dense(ctx):
                continue
            if not self.refresh(ctx):
                return
            path = self.reference_path(ctx.k, cand)
            task = ReferenceTask(ctx.k, cand, d.operator, str(path), self.run_cfg.ref_timeout)
            out = self.worker.call(("reference", task), self.run_cfg.ref_timeout * 1.1 + 5.0)
            if out.ok and "error" not in out.value:
                ctx.reference_solver, ctx.reference_path = cand, str(path)
                return
            why = out.value.get("error") if out.ok else f"{out.kind}: {out.detail}"
            log.info("%s step %d: reference %s not usable (%s)", spec.instance, ctx.k, cand, why)

    def reference_path(self, k: int, solver: str) -> Path:
        spec = self.job.spec
        key = json.dumps([spec.scene, spec.instance, spec.params_json(), int(k), solver], default=str)
        digest = hashlib.sha1(key.encode("utf-8")).hexdigest()[:16]
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in f"{spec.scene}-{spec.instance}")[:80]
        return self.cache_dir / f"ref-{safe}-k{k}-{solver}-{digest}.npz"

    def want_warm(self, v: SolverVariant, k: int) -> bool:
        if not (self.run_cfg.warm and self.job.load_history and k > 0):
            return False
        try:
            return resolve_solver(v.base).capabilities.warm_start != "none"
        except Exception:
            return False

    def previous_ok(self, k: int, v: SolverVariant, profile: str) -> bool:
        return self.statuses.get(self.cell_id(k - 1, v, profile, 0)) in ("solved", "inaccurate")

    def ensure_warm_source(self, ctx: StepContext, v: SolverVariant, profile: str, operator: str) -> bool:
        """Make sure the worker holds this solver's answer of the previous step."""
        if (self.worker.generation, v.name, profile, ctx.k - 1) in self.warm_have and self.worker.alive:
            return True
        if not self.previous_ok(ctx.k, v, profile):
            return False
        if not self.refresh(ctx):
            return False
        task = self.solve_task(ctx, v, profile, operator, warm=False, warmup=False)
        out = self.worker.call(("regen", task), self.run_cfg.timeout * 1.1 + 5.0)
        if out.ok and out.value:
            self.warm_have.add((self.worker.generation, v.name, profile, ctx.k - 1))
            return True
        return False

    def solve_task(self, ctx: StepContext, v: SolverVariant, profile: str, operator: str, warm: bool, warmup: bool) -> SolveTask:
        return SolveTask(step=ctx.k, base=v.base, params=dict(v.params), label=v.name, profile=profile,
                         operator=operator, check_tol=get_profile(profile).check_tol, time_limit=self.run_cfg.timeout,
                         warm=warm, warmup=warmup, reference_path=ctx.reference_path,
                         arrays_path=str(self.cache_dir.parent / "arrays" / safe_name(
                             f"{self.job.spec.scene}-{self.job.spec.instance}-{v.name}.npz")))

    def run_group(self, ctx: StepContext, v: SolverVariant, profile: str, reps: list[int], operator: str) -> None:
        lost: tuple[str, str] | None = None  # (status, why) once a repeat timed out or crashed
        for r in reps:
            if lost is not None:
                self.emit(self.row_for(ctx, ctx.k, v, profile, r, status=lost[0], error=f"not attempted: {lost[1]}"))
                continue
            warm = self.want_warm(v, ctx.k) and self.ensure_warm_source(ctx, v, profile, operator)
            # (a regeneration may have restarted the worker: prepare the step again)
            prepared = self.refresh(ctx) and (operator != "dense" or info_dense(ctx) or self.ensure_dense(ctx))
            if not prepared:
                self.emit(self.row_for(ctx, ctx.k, v, profile, r, status="failed",
                                       error=self._step_error or "could not prepare the step (dense H assembly failed)"))
                continue
            task = self.solve_task(ctx, v, profile, operator, warm=warm, warmup=False)
            deadline = self.run_cfg.timeout * 1.1 + 1.0  # the limit plus room for the KKT check and the pipe
            out: Outcome | None = None
            if self.run_cfg.warmup and (self.worker.generation, v.name) not in self.warmed:
                w_out = self.worker.call(("warmup", task), deadline)
                if w_out.kind in ("timeout", "crashed"):
                    w_out.detail = "in the untimed warm-up solve: " + w_out.detail
                    out = w_out
                else:
                    self.warmed.add((self.worker.generation, v.name))
            if out is None:
                out = self.worker.call(("solve", task), deadline)
            build = self.build_times.get(ctx.k) or 0.0
            if operator == "dense" and str(ctx.info["operator"]) != "dense":
                build += ctx.dense_time or 0.0
            row = self.row_for(ctx, ctx.k, v, profile, r, operator=operator, build_time_s=build)
            if out.ok:
                row.update(out.value)
                if "kkt_error" in out.value:  # the worker kept this answer as the next step's warm start
                    self.warm_have.add((self.worker.generation, v.name, profile, ctx.k))
            else:
                status = {"timeout": "timeout", "crashed": "crashed"}.get(out.kind, "failed")
                row.update(status=status, solve_time_s=out.elapsed, warm_start=warm, error=out.detail[-2000:])
                if status in ("timeout", "crashed"):
                    lost = (status, f"repeat {r} ended with {status}")
            if row.get("status") == "timeout":
                self.too_slow.setdefault((v.name, profile), (ctx.k, int(ctx.info["n"])))
            elif row.get("status") in ("solved", "inaccurate") and self.job.load_history:
                seen = self.observed.setdefault((v.name, profile), [])
                seen[:] = (seen + [(int(ctx.info["n"]), float(row["solve_time_s"]))])[-2:]
            self.emit(row)


def info_dense(ctx: StepContext) -> bool:
    return str(ctx.info.get("operator")) == "dense"


def run_instance_job(job: InstanceJob, run: RunConfig, out_dir: str | os.PathLike[str],
                     statuses: dict[str, str] | None = None, sink: Callable[[dict[str, Any]], None] | None = None) -> int:
    """Run one job, appending its rows to OUT/rows.jsonl.  Returns rows written.

    Usable from any process (a pool worker, a Dask worker): it opens the store for
    appending only."""
    store = ResultStore(out_dir, load=statuses is None)
    count = 0

    def write(row: dict[str, Any]) -> None:
        nonlocal count
        store.append(row)
        count += 1
        if sink is not None:
            sink(row)

    known = store.done_statuses() if statuses is None else statuses
    JobRunner(job, run, known, store.cache_dir, write).run()
    return count


def _pool_init() -> None:
    set_parent_death_signal()


def _pool_run(job: InstanceJob, run: RunConfig, out_dir: str, statuses: dict[str, str]) -> int:
    return run_instance_job(job, run, out_dir, statuses)


# ---------------------------------------------------------------------------
# The whole run
# ---------------------------------------------------------------------------


@dataclass
class RunSummary:
    out_dir: str
    rows: int
    new_rows: int
    statuses: dict[str, int]
    elapsed_s: float
    warnings: list[str]

    def line(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
        return f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s: {counts} -> {self.out_dir}"


def under_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes") or not sys.stderr.isatty()


def job_cell_ids(job: InstanceJob, run: RunConfig) -> list[str]:
    return [make_cell_id(job.spec, k, v, p, r, run.warm) for k in range(job.steps_hint) for v in job.variants
            for p in job.profiles for r in range(run.repeats)]


def open_run(scenes: Sequence[str], cfg: SceneConfig | None, solvers: Sequence[str] | str | None, run: RunConfig,
             out_dir: str | os.PathLike[str]) -> tuple[RunPlan, ResultStore]:
    """Plan the cells and open the store (shared by the local and the Dask runs)."""
    plan = plan_run(scenes, cfg, solvers, run)
    for w in plan.warnings:
        log.warning("warning: %s", w)
    return plan, ResultStore(out_dir)


def run_benchmark(scenes: Sequence[str], cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
                  run: RunConfig | None = None, out_dir: str | os.PathLike[str] = "results/run",
                  command: list[str] | None = None) -> RunSummary:
    """Plan, run the missing cells, write the tidy table and meta.json."""
    run = run or RunConfig()
    t0 = time.perf_counter()
    plan, store = open_run(scenes, cfg, solvers, run, out_dir)
    config = {"scenes": list(scenes), "scene_config": asdict(cfg or SceneConfig()), "run": asdict(run),
              "solvers": sorted({v.name for j in plan.jobs for v in j.variants}),
              "profiles": sorted({p for j in plan.jobs for p in j.profiles})}
    write_meta(out_dir, build_meta(command=command, config=config, warnings=plan.warnings))
    before = len(store)
    statuses = store.done_statuses()
    pending = [j for j in plan.jobs if not all(c in statuses for c in job_cell_ids(j, run))]
    total = sum(j.n_cells(run.repeats) for j in pending)
    already = sum(1 for j in pending for c in job_cell_ids(j, run) if c in statuses)
    show_bar = run.progress if run.progress is not None else not under_ci()
    bar = _progress_bar(total, already, show_bar)
    try:
        if run.jobs <= 1 or len(pending) <= 1:
            for job in pending:
                n_before = len(store)
                JobRunner(job, run, statuses, store.cache_dir, lambda row: (store.append(row), bar.update(1))).run()
                if not show_bar:
                    log.info("%s/%s: %d rows", job.spec.scene, job.spec.instance, len(store) - n_before)
        else:
            _run_pool(pending, run, store, statuses, bar)
    finally:
        bar.close()
        store = ResultStore(out_dir)
        table = store.finalize()
    counts = {str(k): int(v) for k, v in table["status"].value_counts().items()} if len(table) else {}
    return RunSummary(str(out_dir), len(table), len(table) - before, counts, time.perf_counter() - t0, plan.warnings)


def _run_pool(pending: list[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str], bar: Any) -> None:
    import multiprocessing as mp

    ctx = mp.get_context("fork") if sys.platform.startswith("linux") else None
    lines0 = store.count_lines()
    with ProcessPoolExecutor(max_workers=run.jobs, mp_context=ctx, initializer=_pool_init) as pool:
        futures = {pool.submit(_pool_run, j, run, str(store.out), statuses) for j in pending}
        seen = 0
        try:
            while futures:
                done, futures = wait(futures, timeout=0.5, return_when=FIRST_COMPLETED)
                for f in done:
                    f.result()
                now = store.count_lines() - lines0
                bar.update(max(0, now - seen))
                seen = max(seen, now)
        except BaseException:
            for f in futures:
                f.cancel()
            raise


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, initial: int, show: bool) -> Any:
    if not show:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, unit="solve", dynamic_ncols=True, smoothing=0.1)
