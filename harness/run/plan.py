"""The plan: scene names and options -> picklable instance jobs, validated up front.

``plan_run`` expands each scene name through its study (``harness.run.studies``: solvers,
sweeps, profiles, reference) into ``InstanceJob`` records -- a scene's ``InstanceSpec``
recipe plus the variants and profiles to run on it.  A job is independent of every other
job, so an executor (``harness.run.executors``) may run jobs anywhere.

Planning refuses bad input before anything runs: the scene options against their rules
(``problems.scenes.options``: every value's range and plausibility, an option a scene
would ignore, what an option requires or excludes -- the command line, the API, the
pytest plugin and Dask runs all come through here), a plan too big to run (more cells than
``RunConfig.max_cells``, or an instance whose memory estimate exceeds the memory budget:
``estimate_scene``, computed from sizes and counts before any surface is generated),
every scene's ``validate`` (sizes, surfaces, loads, and -- where a value is outside its
plausible range or the surface is a measured map -- the kernel table and forces they make,
``scenes.core.check_float_range``), a scene whose every cell the solvers'
declared capabilities (bounds or a load equality they cannot pose, ``max_n``, the
operator) or time and memory models reject (``model_rejections``: from the trial-set
sizes the scene tells, ``Scene.validate_sizes``, as the run's skip policy would), a
``--reference`` that would serve none of its steps (``reference_rejection``), a solver list that
names no solver (``names_no_solver``: ``[]``, ``""``, ``","``), every solver name,
profile and reference name.  All problems found
are raised together as one ``PlanError`` (a ``ProblemInputError``), on one line joined
by "; "; the command line turns it into exit status 2 and writes no table.
"""

from __future__ import annotations


import contextlib
import hashlib
import json
import math
import os
import sys
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

from contactbench.problems.constraints import CONTROLS
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.fft_threads import threads_problem
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET
from contactbench.problems.instances import check_operator_kind
from contactbench.problems.operators_gpu import device_misfit
from contactbench.problems.scenes import InstanceSpec, SceneConfig, get_scene
from contactbench.problems.scenes.base import StepSizes, largest_recipe, scene_counts
from contactbench.problems.scenes.options import config_problems
from contactbench.solvers._loading import file_path_hint, user_code
from contactbench.solvers.base import ProblemTraits, Solver, constraint_skip
from contactbench.solvers.registry import (NamedVariant, SolverLoadError, SolverSpec, all_solvers, available_solvers,
                                           check_late_sources,
                                           expand_solver_spec, get_solver, import_user_module, is_import_path,
                                           load_solver, refuse_same_variants, register, split_solver_list,
                                           split_solver_spec)

from ..arguments import check_time_limit
from ..profiles import get_profile
from ..table.files import canonical_json
from ..table.schema import as_finite
from .child_call import ChildEnded, LoadFailed, in_a_child
from .skips import capability_decision, checked_availability, time_decision
from .spelled_out import left_out
from .studies import SolverVariant, Study, expand


#: Default of ``RunConfig.max_cells`` (``--max-cells``).
DEFAULT_MAX_CELLS = 100_000


#: A reference solve's time limit where the run names none (``RunConfig.reference_timeout``
#: None): this many times the limit of one solve (``RunConfig.timeout``).
REFERENCE_TIMEOUT_FACTOR = 5.0


@dataclass(frozen=True)
class RunConfig:
    """How to run (the scene options are in ``SceneConfig``).

    profiles          : accuracy profiles (None: the study's profiles).
    repeats           : timed solves per cell group (min and median are reported).
    timeout           : hard wall-clock limit per solve, seconds (at most ``arguments.MAX_TIMEOUT_S``).
    warm              : warm-start along load histories where the solver supports it.
    warmup            : one untimed solve the first time a worker meets a variant, unless
                        the solve is predicted to take longer than ``warmup_limit``
                        seconds (harness.run.job: a big solve is paid once).
    jobs              : instance jobs run concurrently (process pool).
    reference         : "auto", "none" or a solver name.
    reference_timeout : limit for one reference solve (None: ``REFERENCE_TIMEOUT_FACTOR`` x
                        timeout; at most ``arguments.MAX_TIMEOUT_S``).
    build_timeout     : limit for building one instance step in the worker.
    memory_budget     : bytes a solve may use (dense H + the solver's own estimate), and
                        the most one instance may need (``estimate_scene``).
    max_cells         : the most cells a plan may have (``estimate_scene``).
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
    max_cells: int = DEFAULT_MAX_CELLS

    def __post_init__(self) -> None:
        if self.repeats < 1:
            raise ValueError(f"repeats must be >= 1, got {self.repeats}")
        check_time_limit(self.timeout, "timeout", "--timeout")  # (its rows record it: time_limit_s)
        if self.reference_timeout is not None:
            check_time_limit(self.reference_timeout, "reference_timeout", "--reference-timeout")
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {self.jobs}")
        if self.max_cells < 1:
            raise ValueError(f"max_cells must be >= 1, got {self.max_cells}")
        check_memory_budget(self.memory_budget)
        if self.threads_per_worker is not None and threads_problem(self.threads_per_worker):
            raise ValueError(f"threads_per_worker (--threads): {threads_problem(self.threads_per_worker)}")
        for p in self.profiles or ():
            get_profile(p)

    @property
    def ref_timeout(self) -> float:
        return float(self.reference_timeout or REFERENCE_TIMEOUT_FACTOR * self.timeout)

    def worker_threads(self) -> int | None:
        if self.threads_per_worker:
            return int(self.threads_per_worker)
        if self.jobs > 1:
            return max(1, (os.cpu_count() or 1) // self.jobs)
        return None


def check_memory_budget(nbytes: float) -> None:
    """A one-line ``ValueError`` naming ``--memory-budget-gb`` unless ``nbytes`` is a finite
    number of bytes > 0; an infinite one says which sizes in GB overflow to it."""
    if isinstance(nbytes, bool) or not isinstance(nbytes, (int, float)) or not 0 < nbytes < math.inf:
        overflow = (f": a size of {sys.float_info.max / 2**30:.3g} GB or more is more bytes than a float holds"
                    if nbytes == math.inf else "")
        raise ValueError(f"memory_budget (--memory-budget-gb) must be a finite number of bytes > 0, got "
                         f"{nbytes!r}{overflow}")


@dataclass(frozen=True)
class StoredCell:
    """What a resumed job reads back of one stored row of its own cells: the columns the
    skip policy (``harness.run.skips.SkipPolicy``) reads of a row."""

    step: int
    label: str
    profile: str
    n: int | None
    status: str
    seconds: float | None

    @classmethod
    def of(cls, row: dict[str, Any]) -> "StoredCell":
        n, t = as_finite(row.get("n")), as_finite(row.get("solve_time_s"))
        return cls(int(row["step"]), str(row["solver"]), str(row["profile"]), None if n is None else int(n),
                   str(row.get("status", "")), t)


@dataclass(frozen=True)
class InstanceJob:
    """Everything needed to run all cells of one instance (picklable).

    ``stored``: the rows of this job's cells already in the store (``with_stored``), so
    that a resumed job decides its skips from the same rows as an uninterrupted one."""

    spec: InstanceSpec
    variants: tuple[SolverVariant, ...]
    profiles: tuple[str, ...]
    load_history: bool
    reference_candidates: tuple[str, ...]
    steps_hint: int
    stored: tuple[StoredCell, ...] = ()

    def with_stored(self, rows: dict[str, dict[str, Any]], run: "RunConfig") -> "InstanceJob":
        """This job with the stored rows (``cell_id`` -> row) of its own cells attached."""
        cells = tuple(StoredCell.of(rows[c]) for c in job_cell_ids(self, run) if c in rows)
        return replace(self, stored=cells)

    def n_cells(self, repeats: int) -> int:
        return self.steps_hint * len(self.variants) * len(self.profiles) * repeats


@dataclass
class RunPlan:
    """The instance jobs of a run; ``scene_config``: the user's scene options the recipes
    were built from, those that only spell out what is in effect without them taken back
    (``spelled_out.left_out``)."""

    jobs: list[InstanceJob]
    warnings: list[str] = field(default_factory=list)
    scenes: list[str] = field(default_factory=list)
    scene_config: SceneConfig = field(default_factory=SceneConfig)

    def n_cells(self, repeats: int) -> int:
        return sum(j.n_cells(repeats) for j in self.jobs)


class PlanError(ProblemInputError):
    """Bad input found while planning: ``problems``, one per item, and its text those
    joined by "; " (one line: the command line prints it as one)."""

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        super().__init__("; ".join(self.problems))


# ---------------------------------------------------------------------------
# Cell identity
# ---------------------------------------------------------------------------


def make_cell_id(spec: InstanceSpec, step: int, variant: SolverVariant, profile: str, repeat: int, warm: bool) -> str:
    """Stable id of one solve: a hash of everything that names it."""
    key = json.dumps(
        [spec.scene, spec.instance, spec.params_json(), int(step), variant.name, variant.base,
         canonical_json(variant.params), profile, int(repeat), "warm" if warm else "cold"],
        default=str,
    )
    return hashlib.sha1(key.encode("utf-8")).hexdigest()[:20]


def job_cell_ids(job: InstanceJob, run: RunConfig) -> list[str]:
    return [make_cell_id(job.spec, k, v, p, r, run.warm) for k in range(job.steps_hint) for v in job.variants
            for p in job.profiles for r in range(run.repeats)]


# ---------------------------------------------------------------------------
# Solvers
# ---------------------------------------------------------------------------


def names_no_solver(requested: Sequence[str] | str | None) -> bool:
    """Whether ``requested`` (not None: None means the scenes' own solvers) names no
    solver: an empty sequence, or a comma list with no name ("", ",", " , ").  A list the
    registry cannot split is left to ``resolve_solver_names``, which names its fault."""
    if requested is None:
        return False
    if not isinstance(requested, str):
        return not list(requested)
    try:
        return not split_solver_list(requested)
    except ValueError:
        return False


def resolve_solver_names(requested: Sequence[str] | str | None,
                         study_default: Sequence[str] | None) -> list[str | SolverSpec]:
    """The solvers to run: "all" (every registered solver's name, unavailable ones are
    recorded as skipped), an explicit list, or the study's defaults, or every available
    solver's name.  In an explicit list ``module:NAME`` entries are loaded and registered,
    and an entry with parameters, ``name[k=v]`` or ``name[grid]``, comes back as the
    checked ``SolverSpec`` of each variant it names (``expand_solver_spec``), which
    ``Study.variants`` runs as given; a variant named twice (by its label, or as one
    solver with the same parameters once defaults are filled in) is refused
    (``refuse_same_variants``).  A ``module:NAME`` entry's module is imported in a child
    first (``probe_import``)."""
    if isinstance(requested, str):
        requested = split_solver_list(requested)  # commas inside name[k=v,...] stay
    if requested:
        if list(requested) == ["all"]:
            return list(all_solvers())
        names: list[str | SolverSpec] = []
        variants: list[NamedVariant] = []
        for text in requested:
            # an unknown name is a clear KeyError, a module:NAME that does not load one line whatever its module
            # raised (a ProblemInputError); name[k=v] is Param-checked (solvers/registry.py)
            parts = split_solver_spec(text)
            if is_import_path(parts.name):
                probe_import(parts.name)
            specs, solver = expand_solver_spec(text)
            if is_import_path(parts.name):
                refuse_name_clash(text.strip(), solver)
                register(solver, replace=True)  # (the same class again: each worker loads it too)
            if parts.raw or parts.grid:
                names += [SolverSpec(solver.name, spec.params) for spec in specs]
            else:
                names.append(solver.name)
            variants += [NamedVariant(SolverSpec(solver.name, spec.params).label, solver, spec.params) for spec in specs]
        refuse_same_variants(variants, "--solvers")
        return names
    if study_default:  # a study's name[k=v] is kept when its base is registered
        return [s for s in study_default if split_solver_spec(s).name in all_solvers()]
    return list(available_solvers())


def probe_import(name: str) -> None:
    """Import the module of the solver ``name`` (``module:NAME``) once in a forked child
    (``child_call.in_a_child``, ``import_in_child``) before ``run`` imports it in its own
    process: a module whose import ends the process that imports it (``os._exit``, a
    signal, a segfault) is a one-line ``SolverLoadError`` saying how that process ended,
    one that hangs past ``child_call.LOAD_LIMIT_S`` one saying so.  Nothing is forked for a
    module already imported here (one probe per module, however many of its solvers or
    variants are named) nor for a name ``load_named_solver`` refuses unread (a file path,
    ``file_path_hint``).  The probe catches nothing else: what the import raises is left to
    the load in this process, and a module that passes is trusted as any code ``run``
    imports (docs/verdicts.md)."""
    module, attr = name.split(":", 1)
    if module in sys.modules or file_path_hint(module, attr):
        return
    doing = f"importing module {module!r}"
    try:
        in_a_child(import_in_child, module, what=doing)
    except ChildEnded as exc:
        raise SolverLoadError(f"cannot load solver {name!r}: {doing} ended its process ({exc.how})") from None
    except LoadFailed as exc:
        raise SolverLoadError(f"cannot load solver {name!r}: {exc}") from None


def import_in_child(module: str) -> None:
    """Import ``module`` (``registry.import_user_module``) in ``probe_import``'s child.
    What the import raises is dropped there: the load in ``run``'s own process raises it
    again, and ``registry.load_named_solver`` words it."""
    with contextlib.suppress(Exception), user_code(module, f"importing module {module!r}"):
        import_user_module(module)


def refuse_name_clash(text: str, solver: Solver) -> None:
    """A one-line ``ProblemInputError`` when the solver loaded from ``text`` (MODULE:NAME)
    carries the name of a registered solver of another class: it would run in that one's
    place and its rows would read as that one's (external manifests are refused the same
    way, ``solvers.registry``)."""
    known = all_solvers().get(solver.name)
    if known is None or _class_path(known) == _class_path(solver):
        return
    raise ProblemInputError(f"solver {text!r} is named {solver.name!r}, the name of the registered solver "
                            f"{_class_path(known)}; give it a name of its own")


def _class_path(solver: Solver) -> str:
    """module.QualifiedName of a solver's class."""
    cls = type(solver)
    return f"{cls.__module__}.{cls.__qualname__}"


# ---------------------------------------------------------------------------
# Planning
# ---------------------------------------------------------------------------


# ---------------------------------------------------------------------------
# Bounds: the size of a plan, from sizes and counts
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneEstimate:
    """A scene's plan size under one configuration, before anything is built: its cells
    and its largest instance's memory (a lower bound, ``instance_nbytes``)."""

    instances: int
    cells: int
    largest_bytes: float
    largest: str


def estimate_scene(scene: Any, cfg: SceneConfig, per_step: int) -> SceneEstimate:
    """The plan size of ``scene`` under ``cfg`` (merged) with ``per_step`` cells per
    instance step (variants x profiles x repeats), counted from the recipes without
    expanding a huge ``--steps`` or ``--seeds`` (``scenes.base.scene_counts``)."""
    count = scene_counts(scene, cfg)
    return _estimate(count.instances, per_step * count.steps, count.specs)


def _estimate(instances: int, cells: int, specs: list[InstanceSpec]) -> SceneEstimate:
    what, nbytes = largest_recipe(specs)
    return SceneEstimate(instances, cells, nbytes, what)


def check_bounds(est: SceneEstimate, run: RunConfig) -> None:
    """Refuse a scene whose plan is beyond ``run.max_cells`` or whose largest instance is
    beyond ``run.memory_budget`` (``ProblemInputError`` with the estimate, its problems
    joined by "; " on one line)."""
    problems = []
    if est.largest_bytes > run.memory_budget:
        problems.append(f"its largest instance ({est.largest}) needs at least {est.largest_bytes / 2**30:.3g} GiB, "
                        f"over the memory budget of {run.memory_budget / 2**30:.3g} GiB (--memory-budget-gb)")
    if est.cells > run.max_cells:
        problems.append(f"the plan has {est.cells:,} cells ({est.instances:,} instance"
                        f"{'' if est.instances == 1 else 's'}), over the limit of "
                        f"{run.max_cells:,} (--max-cells)")
    if problems:
        raise ProblemInputError("; ".join(problems))


def scene_jobs(study: Study, cfg: SceneConfig, solvers: Sequence[str | SolverSpec],
               run: RunConfig) -> tuple[list[InstanceJob], list[str]]:
    """The jobs and warnings of one study on its scene under ``cfg`` (bounded by
    ``check_bounds``, then validated)."""
    scene = get_scene(study.scene)
    merged = scene.config(cfg)
    if merged.operator is not None:
        check_operator_kind(str(merged.operator))  # "gpu" without CuPy or a device: the reason, before anything runs
    variants = tuple(study.variants(solvers, merged.extra))
    profiles = tuple(run.profiles or study.profiles)
    check_bounds(estimate_scene(scene, merged, len(variants) * len(profiles) * run.repeats), run)
    check_height_unit_applied(study.scene, merged, scene)
    sizes = scene.validate_sizes(merged)
    refs = study.reference_candidates(run.reference)
    jobs = [InstanceJob(spec, variants, profiles, bool(scene.load_history), refs, int(spec.params.get("steps") or 1))
            for spec in scene.instances(merged)]
    check_distinct_instances(jobs)
    if merged.operator == "gpu":
        check_device_fit(jobs, sizes)
    rejected = model_rejections(jobs, sizes, run)
    if rejected:
        raise ProblemInputError(f"every cell would be skipped: {rejected}; choose other --solvers, or, where a time or "
                                "memory model is the reason, a smaller --size, a longer --timeout or a larger "
                                "--memory-budget-gb")
    unserved = reference_rejection(run.reference, jobs, sizes, run)
    if unserved:
        raise ProblemInputError(f"--reference {run.reference} would serve no step: {unserved}; choose another "
                                "--reference, 'auto' or 'none'")
    return jobs, [f"{study.scene}: {w}" for w in scene.warnings(merged)]


def scene_operator(params: dict[str, Any]) -> str:
    """The operator a recipe's steps build ("dense" or "fft"; "fft" where it names none)."""
    return str(params.get("operator") or "fft")


def step_traits(params: dict[str, Any], n: int, side: int) -> ProblemTraits:
    """What the skip policy will know of a step of n unknowns of recipe ``params``
    (``harness.run.worker.problem_traits`` of the built instance)."""
    layer = params.get("thickness") is not None or params.get("thickness_over_L") is not None
    return ProblemTraits(n=int(n), operator=scene_operator(params), has_geometry=True,
                         has_surface=side > 0, periodic=bool(params.get("periodic")), kernel=str(params.get("kernel")),
                         surface_side=side, load_control=params.get("control") == CONTROLS[1],
                         bounded=params.get("hardness") is not None or params.get("hardness_over_ps") is not None,
                         layer=layer)


def planned_solver(base: str) -> tuple[Solver | None, bool]:
    """(solver ``base``, True) when it loads and is available; else (None, whether the run
    should still plan it): an unloadable one is not (the plan names it elsewhere), nor an
    unavailable one, but one whose ``availability()`` raised is, to record its failed rows."""
    try:
        solver = load_solver(base)
    except Exception:  # (the plan names an unloadable solver elsewhere)
        return None, False
    ok, _, failed = checked_availability(solver)
    return (solver, True) if ok else (None, failed)


def model_rejection(base: str, traits: ProblemTraits, run: RunConfig, params: dict[str, Any] | None = None,
                    timeout: float | None = None) -> tuple[bool, str]:
    """(whether solver ``base`` with ``params`` would run on a step with ``traits``, the
    reason when it would be skipped for what it declares: its ``capabilities``
    (``declared_incapacity``: its ``max_n``, the operator, a load equality or bounds it
    cannot pose) or its memory or time model, at ``run.memory_budget`` and ``timeout``
    (None: ``run.timeout``)).  A solver that cannot be loaded, is unavailable or whose own
    ``skip``/``skip_params`` alone skips the step is neither: the run records that skip
    with its reason, as before; one whose availability, model or skip check raised
    (``Decision.failed``) would run, to record its failed rows."""
    solver, runs = planned_solver(base)
    if solver is None:
        return runs, ""
    free = capability_decision(solver, traits, float("inf"), params)
    if free.skip:  # a model or skip check that raised runs, to record its failed rows
        declared = not free.failed and bool(declared_incapacity(solver, traits))
        return free.failed, free.reason if declared else ""
    d = capability_decision(solver, traits, run.memory_budget, params)
    if not d.skip:
        d = time_decision(solver, traits, d.operator, run.timeout if timeout is None else timeout, None)
    if d.skip and not d.failed:
        return False, d.reason
    return True, ""


def declared_rejection(base: str, traits: ProblemTraits) -> tuple[bool, str]:
    """``model_rejection`` where the scene tells no sizes: (whether solver ``base`` may run
    on a step with ``traits``, the reason when its ``declared_incapacity`` alone skips it).
    Only what the recipe tells is read -- the operator, a load equality, bounds; n and the
    grid are unknown (``traits`` carries 0), so neither ``max_n`` nor a time or memory model
    refuses here.  A solver that cannot be loaded or is unavailable: as ``model_rejection``."""
    solver, runs = planned_solver(base)
    if solver is None:
        return runs, ""
    why = declared_incapacity(solver, traits)
    return not why, why


def declared_incapacity(solver: Solver, traits: ProblemTraits) -> str:
    """Why ``solver`` cannot take a step with ``traits`` by its declared ``capabilities``
    alone, which the plan knows as the run does ("" when it can): n over its ``max_n``, a
    dense H where it takes only the FFT operator, a load equality or bounds it cannot pose
    (``constraint_skip``)."""
    caps = solver.capabilities
    if caps.max_n is not None and traits.n > caps.max_n:
        return f"n = {traits.n} exceeds max_n = {caps.max_n}"
    if traits.operator == "dense" and "dense" not in caps.operators:
        return "it needs the FFT operator"
    return constraint_skip(caps, traits.load_control, traits.bounded, solver.name) or ""


def check_device_fit(jobs: Sequence[InstanceJob], sizes: dict[str, StepSizes]) -> None:
    """Refuse a "gpu" run, before anything runs, where an instance's square grid and its
    largest step's trial set do not fit the device by its memory model
    (``operators_gpu.device_misfit``); instances whose sizes the scene does not tell are
    not checked."""
    misfits = []
    for job in jobs:
        size = sizes.get(job.spec.instance)
        if size is None or size.side <= 0:
            continue
        points = max(size.n) if size.n else None
        why = device_misfit((size.side, size.side), bool(job.spec.params.get("periodic")), points)
        if why:
            misfits.append(f"{job.spec.instance}: {why}")
    if misfits:
        more = f" (and {len(misfits) - 3} more)" if len(misfits) > 3 else ""
        raise ProblemInputError("operator 'gpu': " + "; ".join(misfits[:3]) + more + "; choose a smaller --size")


def planned_steps(jobs: Sequence[InstanceJob], sizes: dict[str, StepSizes]
                  ) -> list[tuple[InstanceJob, ProblemTraits]] | None:
    """(job, the traits of a step) for each distinct trial-set size of each recipe of
    ``jobs``, smallest first; None where a recipe's scene tells no sizes."""
    out: list[tuple[InstanceJob, ProblemTraits]] = []
    for job in jobs:
        size = sizes.get(job.spec.instance)
        if size is None:
            return None
        out += [(job, step_traits(job.spec.params, n, size.side)) for n in sorted(set(size.n))]
    return out


def model_rejections(jobs: Sequence[InstanceJob], sizes: dict[str, StepSizes], run: RunConfig) -> str:
    """"" when some cell of ``jobs`` would run; else, where every cell would be skipped for
    what its solver declares (``model_rejection``: a capability, the time or memory model),
    the reason at the smallest step of each solver (one line).  Where the scene tells no
    sizes, each recipe is one step of its params' traits at n = 0, asked of the declared
    capabilities alone (``declared_rejection``)."""
    reasons: dict[str, str] = {}
    steps = planned_steps(jobs, sizes)
    unsized = steps is None
    if steps is None:
        steps = [(job, step_traits(job.spec.params, 0, 0)) for job in jobs]
    for job, traits in steps:
        for v in job.variants:
            runs, why = declared_rejection(v.base, traits) if unsized else model_rejection(v.base, traits, run, v.params)
            if runs:
                return ""
            if why:
                reasons.setdefault(v.name, why)
    if not reasons:
        return ""
    shown = [f"{name}: {why}" for name, why in list(reasons.items())[:3]]
    more = f" (and {len(reasons) - 3} more)" if len(reasons) > 3 else ""
    return "; ".join(shown) + more


def reference_rejection(reference: str, jobs: Sequence[InstanceJob], sizes: dict[str, StepSizes],
                        run: RunConfig) -> str:
    """"" unless ``reference`` names a solver (not "auto" or "none") that would be skipped
    on every step of ``jobs`` (``model_rejection`` at the reference's limit,
    ``RunConfig.ref_timeout``); then the reason at the first step (one line).  A scene
    that tells no sizes, or a reference that cannot be loaded (named elsewhere) or is
    unavailable, is not refused here."""
    steps = planned_steps(jobs, sizes) if reference not in ("auto", "none") else None
    first = ""
    for _, traits in steps or ():
        runs, why = model_rejection(reference, traits, run, timeout=run.ref_timeout)
        if runs or not why:
            return ""
        first = first or why
    return first


def check_height_unit_applied(name: str, cfg: SceneConfig, scene: Any) -> None:
    """Refuse ``--height-unit`` where a scene's recipes of a measured surface do not carry
    it (the surface would silently be read in metres)."""
    unit = cfg.extra.get("height_unit")
    if unit in (None, "m"):
        return
    if any(s.params.get("surface_path") and s.params.get("height_unit") != unit for s in scene.instances(cfg)):
        raise ProblemInputError(f"--height-unit {unit}: scene {name!r} does not apply a height unit to its "
                                "surface file; convert the file to metres instead")


def option_problems(scenes: Sequence[str], cfg: SceneConfig | None) -> list[str]:
    """The problems of the user's scene options ``cfg`` on each named scene or composite
    (``problems.scenes.options.config_problems``; for a composite, an option is refused
    only where none of its parts reads it).  Unknown names are left to the plan."""
    problems: list[str] = []
    for name in scenes:
        try:
            parts = expand(name, cfg)
        except KeyError:
            continue
        problems += config_problems(name, [get_scene(study.scene) for study, _ in parts],
                                    [part for _, part in parts], cfg)
    return list(dict.fromkeys(problems))


def check_distinct_instances(jobs: Sequence[InstanceJob]) -> None:
    """A one-line ``ProblemInputError`` when two recipes of a scene share an instance name
    (the report would read two problems' rows as one cell's repeats): a scene names each
    of its problems once."""
    seen: set[str] = set()
    for job in jobs:
        if job.spec.instance in seen:
            raise ProblemInputError(f"the scene gives two recipes the one instance name {job.spec.instance!r}; a "
                                    "scene must name each of its problems once (its instances())")
        seen.add(job.spec.instance)


def plan_run(scenes: Sequence[str] | str, cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
             run: RunConfig | None = None) -> RunPlan:
    """Expand scene names into instance jobs; raise ``PlanError`` listing every bad
    input (module doc) before anything runs."""
    run = run or RunConfig()
    scenes = [scenes] if isinstance(scenes, str) else list(scenes)  # one scene's name, or several
    if not scenes:
        raise PlanError(["no scene to run: name one or more (contactbench list scenes)"])
    twice = [name for k, name in enumerate(scenes) if name in scenes[:k]]
    if twice:
        raise PlanError([f"scene {twice[0]!r} named twice; name each scene once"])
    if solvers is not None and not isinstance(solvers, str):
        solvers = list(solvers)  # (an iterator is read once)
    if names_no_solver(solvers):
        raise PlanError([f"an empty solver list (--solvers {solvers!r}) names no solver; give names (contactbench "
                         "list solvers) or 'all' (None: the scenes' own)"])
    problems = option_problems(scenes, cfg)
    if problems:  # (each scene's own checks would repeat them)
        raise PlanError(problems)
    check_late_sources()  # (a bad external manifest: refused whichever solvers are named)
    cfg = left_out(cfg or SceneConfig(), scenes)  # (checked as given; planned as the same run without them)
    plan = RunPlan(jobs=[], scenes=scenes, scene_config=cfg)
    for name in scenes:
        try:
            parts = expand(name, cfg)
        except KeyError as exc:  # an unknown scene or mix: named with the closest ones
            problems.append(str(exc.args[0]) if exc.args else str(exc))
            continue
        for study, part_cfg in parts:
            try:
                names = resolve_solver_names(solvers, study.solvers)
                jobs, warnings = scene_jobs(study, part_cfg, names, run)
            except ProblemInputError as exc:
                problems += [f"{study.scene}: {line}" for line in str(exc).splitlines() if line]
                continue
            except MemoryError as exc:
                problems.append(f"{study.scene}: planning ran out of memory ({type(exc).__name__}: {exc}); "
                                "choose a smaller --size, --steps or --seeds")
                continue
            plan.jobs += jobs
            plan.warnings += warnings
    cells = plan.n_cells(run.repeats)
    if cells > run.max_cells and not problems:
        problems.append(f"the plan has {cells:,} cells, over the limit of {run.max_cells:,} (--max-cells)")
    if run.reference not in ("auto", "none"):  # after --solvers: a module:NAME list may register it
        try:
            get_solver(run.reference)
        except KeyError as exc:
            problems.append(f"--reference: {exc}")
    if problems:
        raise PlanError(list(dict.fromkeys(problems)))
    return plan
