"""The plan: scene names and options -> picklable instance jobs, validated up front.

``plan_run`` expands each scene name through its study (``harness.studies``: solvers,
sweeps, profiles, reference) into ``InstanceJob`` records -- a scene's ``InstanceSpec``
recipe plus the variants and profiles to run on it.  A job is independent of every other
job, so an executor (``harness.executors``) may run jobs anywhere.

Planning refuses bad input before anything runs: every scene's ``validate`` (sizes,
surfaces, loads), every solver name, profile and reference name.  All problems found
are raised together as one ``PlanError`` (a ``ProblemInputError``), one line each; the
command line turns it into exit status 2 and writes no table.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from typing import Any, Sequence

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET
from contactbench.problems.instances import check_operator_kind
from contactbench.problems.scenes import InstanceSpec, SceneConfig, get_scene
from contactbench.solvers.registry import (SolverSpec, all_solvers, available_solvers, get_solver, parse_solver_spec,
                                           register, split_solver_list)

from .profiles import get_profile
from .studies import SolverVariant, Study, expand


@dataclass(frozen=True)
class RunConfig:
    """How to run (the scene options are in ``SceneConfig``).

    profiles          : accuracy profiles (None: the study's profiles).
    repeats           : timed solves per cell group (min and median are reported).
    timeout           : hard wall-clock limit per solve, seconds.
    warm              : warm-start along load histories where the solver supports it.
    warmup            : one untimed solve the first time a worker meets a variant, unless
                        the solve is predicted to take longer than ``warmup_limit``
                        seconds (harness.job: a big solve is paid once).
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
    warmup_limit: float = 5.0
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


class PlanError(ProblemInputError):
    """Bad input found while planning: one line per problem."""

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


# ---------------------------------------------------------------------------
# Cell identity
# ---------------------------------------------------------------------------


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


def job_cell_ids(job: InstanceJob, run: RunConfig) -> list[str]:
    return [make_cell_id(job.spec, k, v, p, r, run.warm) for k in range(job.steps_hint) for v in job.variants
            for p in job.profiles for r in range(run.repeats)]


# ---------------------------------------------------------------------------
# Solvers
# ---------------------------------------------------------------------------


def resolve_solver_names(requested: Sequence[str] | str | None, study_default: Sequence[str] | None) -> list[str]:
    """Registry names to run: "all" (every registered solver, unavailable ones are
    recorded as skipped), an explicit list (``module:NAME`` entries are loaded and
    registered; ``name[k=v]`` entries come back as the checked label, which
    ``Study.variants`` turns into a variant with those parameters), or the study's
    defaults, or every available solver."""
    if isinstance(requested, str):
        requested = split_solver_list(requested)  # commas inside name[k=v,...] stay
    if requested:
        if list(requested) == ["all"]:
            return list(all_solvers())
        names = []
        for text in requested:
            try:  # an unknown name is a clear KeyError; name[k=v] is Param-checked (solvers/registry.py)
                spec, solver = parse_solver_spec(text)
            except (ImportError, AttributeError, TypeError) as exc:
                raise ProblemInputError(f"cannot load solver {text.strip()!r}: {type(exc).__name__}: {exc}") from None
            if ":" in spec.name:
                register(solver, replace=True)
            names.append(SolverSpec(solver.name, spec.params).label)
        return names
    if study_default:
        return [s for s in study_default if s in all_solvers()]
    return list(available_solvers())


# ---------------------------------------------------------------------------
# Planning
# ---------------------------------------------------------------------------


def scene_jobs(study: Study, cfg: SceneConfig, solvers: list[str],
               run: RunConfig) -> tuple[list[InstanceJob], list[str]]:
    """The jobs and warnings of one study on its scene under ``cfg`` (validated)."""
    scene = get_scene(study.scene)
    merged = scene.config(cfg)
    if merged.operator is not None:
        check_operator_kind(str(merged.operator))  # "gpu" without CuPy or a device: the reason, before anything runs
    check_height_unit_applied(study.scene, merged, scene)
    scene.validate(merged)
    variants = tuple(study.variants(solvers, merged.extra))
    profiles = tuple(run.profiles or study.profiles)
    refs = study.reference_candidates(run.reference)
    jobs = [InstanceJob(spec, variants, profiles, bool(scene.load_history), refs, int(spec.params.get("steps") or 1))
            for spec in scene.instances(merged)]
    return jobs, [f"{study.scene}: {w}" for w in scene.warnings(merged)]


def check_height_unit_applied(name: str, cfg: SceneConfig, scene: Any) -> None:
    """Refuse ``--height-unit`` where a scene's recipes of a measured surface do not carry
    it (the surface would silently be read in metres)."""
    unit = cfg.extra.get("height_unit")
    if unit in (None, "m"):
        return
    if any(s.params.get("surface_path") and s.params.get("height_unit") != unit for s in scene.instances(cfg)):
        raise ProblemInputError(f"--height-unit {unit}: scene {name!r} does not apply a height unit to its "
                                "surface file; convert the file to metres instead")


def plan_run(scenes: Sequence[str], cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
             run: RunConfig | None = None) -> RunPlan:
    """Expand scene names into instance jobs; raise ``PlanError`` listing every bad
    input (module doc) before anything runs."""
    run = run or RunConfig()
    plan = RunPlan(jobs=[], scenes=list(scenes))
    problems: list[str] = []
    for name in scenes:
        for study, part_cfg in expand(name, cfg):
            try:
                names = resolve_solver_names(solvers, study.solvers)
                jobs, warnings = scene_jobs(study, part_cfg, names, run)
            except ProblemInputError as exc:
                problems += [f"{study.scene}: {line}" for line in str(exc).splitlines() if line]
                continue
            plan.jobs += jobs
            plan.warnings += warnings
    if run.reference not in ("auto", "none"):  # after --solvers: a module:NAME list may register it
        try:
            get_solver(run.reference)
        except KeyError as exc:
            problems.append(f"--reference: {exc}")
    if problems:
        raise PlanError(list(dict.fromkeys(problems)))
    return plan
