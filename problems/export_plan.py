"""What an export of a scene will write, checked whole before it writes anything.

``plan_export`` checks the scene as ``check_scene`` does and lists every QP of the
export in the order it is written (``PlannedQP``: name, recipe, step, n), raising each
refusal of a single QP in that pass, before the export touches its folder:

* two QPs of one name (``problem_name`` maps characters to ``_``);
* a QP its scene cannot build (e.g. a dense operator over the memory budget,
  ``operators.check_dense_budget``), named;
* a dense H (0 < n <= the dense limit, every format) over the memory budget
  (``check_dense_fits``);
* where a QP over the dense limit is written as its kernel table (problem-dir, hdf5),
  one that has none (``qpfile.problem_payload``'s refusal), named.

The export itself checks the folder's entries that its QPs would be written to against
the plan's names and sizes (``export.check_targets``), with the folder's lock held.

What the check costs: a recipe whose scene tells its steps' sizes from surfaces and loads
(``Scene.validate_sizes``: the ramp scenes, whose ``validate`` computes them anyway) and
whose operator is matrix-free (any kind but "dense": it always has a kernel table, so
every check above follows from n) is not built by the check at all.  Every other QP
(scenes that tell no sizes, such as the synthetic batteries, and a dense operator) is
built by the check and kept for the export while the kept QPs' operators hold at most
``KEEP_SHARE`` of the memory budget (``operators.memory_budget``); a QP past that is
dropped and built again when written.  A scene that tells
its sizes builds each recipe with the operator its params name, at those sizes:
``ExportPlan.built`` refuses a built QP whose n differs from the plan's.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
import contactbench
from typing import Any, Callable, Iterator

from .errors import MemoryBudgetError, ProblemInputError
from .instances import ContactInstance
from .operators import check_dense_budget, memory_budget
from .qpfile import problem_payload
from .scenes import SceneConfig, get_scene
from .scenes.base import InstanceSpec, LoadSequence, StepSizes, check_instance_memory, scene_counts
from .scenes.options import check_config

#: The most QPs (instances x steps) one export may write (``export_scene``'s ``max_qps``),
#: counted before anything is built (``scene_counts``).
MAX_QPS = 100_000

#: The share of the memory budget the QPs the check built may hold until they are written.
KEEP_SHARE = 0.25


@dataclass(frozen=True)
class PlannedQP:
    """One QP an export will write or skip."""

    name: str
    instance: str
    step: int
    n: int
    #: Its recipe's position in ``ExportPlan.specs``.
    spec: int


@dataclass
class ExportPlan:
    """Every QP of an export, in the order it is written, each checked (module doc)."""

    scene: Any
    specs: list[InstanceSpec]
    qps: list[PlannedQP]
    #: Instances the check built, by (recipe, step), kept for the export (module doc).
    kept: dict[tuple[int, int], ContactInstance] = field(default_factory=dict)
    #: The scene options the export uses (``options_record`` of the merged configuration).
    options: dict[str, Any] = field(default_factory=dict)

    def built(self, wanted: Callable[[PlannedQP], bool]) -> Iterator[tuple[PlannedQP, ContactInstance | None]]:
        """(QP, its instance) of every planned QP in order: the instance built where
        ``wanted`` (one load sequence per recipe at a time), None elsewhere.  A built QP
        whose n is not the plan's is a ``RuntimeError`` (the plan's checks would not hold).
        An instance the check kept is handed over once and forgotten."""
        seq: LoadSequence | None = None
        at = -1
        for qp in self.qps:
            kept = self.kept.pop((qp.spec, qp.step), None)
            if not wanted(qp):
                yield qp, None
                continue
            if kept is not None:
                yield qp, kept
                continue
            if seq is None or qp.spec != at:
                seq, at = self.scene.build(self.specs[qp.spec]), qp.spec
            inst = seq.at(qp.step)
            if inst.n != qp.n:
                raise RuntimeError(f"{qp.name}: the plan's n = {qp.n} (its scene's validate_sizes) differs from its "
                                   f"build's n = {inst.n}")
            yield qp, inst


def problem_name(instance: str, step: int) -> str:
    """The exported name of one QP: ``<instance>-step<k>``, file-name safe."""
    return file_safe(f"{instance}-step{step}")


def file_safe(text: str) -> str:
    """``text`` with every character other than letters, digits and ``._-`` as ``_``."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", text)


def check_scene(scene_name: str, cfg: Any, max_qps: int = MAX_QPS) -> tuple[Any, SceneConfig]:
    """(scene, merged configuration) of an export of ``scene_name`` under ``cfg`` (a
    ``SceneConfig``), its options and inputs checked as the planner does and its QPs
    counted (``scene_counts``): more than ``max_qps`` is a one-line ``ProblemInputError``
    before any recipe of the whole range is made."""
    scene, merged, _, _ = checked_scene(scene_name, cfg, max_qps)
    return scene, merged


def checked_scene(scene_name: str, cfg: Any, max_qps: int = MAX_QPS
                  ) -> tuple[Any, SceneConfig, dict[str, StepSizes], list[InstanceSpec]]:
    """``check_scene``, the sizes of the recipes' steps where the scene tells them
    (``Scene.validate_sizes``, by instance name; its ``validate`` is the same check), and
    the recipes.  A recipe whose instance would not fit the memory budget
    (``scenes.base.check_instance_memory``, ``operators.memory_budget``) is refused before
    any surface is made."""
    scene = get_scene(scene_name)
    check_config(scene_name, [scene], [cfg or SceneConfig()], cfg)
    merged = scene.config(cfg)
    limit = int(max_qps)
    if limit < 1:
        raise ProblemInputError(f"the most QPs an export may write must be >= 1, got {max_qps!r}")
    size = scene_counts(scene, merged)
    if size.steps > limit:
        raise ProblemInputError(f"the export of {scene_name} has {size.steps:,} QPs ({size.instances:,} instance"
                                f"{'' if size.instances == 1 else 's'} x their steps), over the limit of {limit:,}; "
                                "choose fewer --steps or --seeds, or a larger --max-qps")
    specs = list(scene.instances(merged))
    check_instance_memory(specs, memory_budget(), "CONTACTBENCH_MEMORY_BUDGET_GB", f"the export of {scene_name}")
    return scene, merged, scene.validate_sizes(merged), specs


def scene_steps(scene_name: str, cfg: Any, max_qps: int = MAX_QPS) -> Iterator[tuple[str, int, ContactInstance]]:
    """(instance name, step, instance) of every QP of a scene under ``cfg`` (a
    ``SceneConfig``; checked first by ``check_scene``)."""
    scene, merged = check_scene(scene_name, cfg, max_qps)
    for spec in scene.instances(merged):
        seq = scene.build(spec)
        for k in range(len(seq)):
            yield spec.instance, k, seq.at(k)


def plan_export(scene_name: str, cfg: Any, dense_limit: int, *, tables: bool, tol: float | None,
                max_qps: int = MAX_QPS) -> ExportPlan:
    """Every QP of an export of ``scene_name`` under ``cfg``, checked (module doc): the
    scene by ``checked_scene``, then each QP, in the order it is written; the first
    refusal is a one-line ``ProblemInputError`` naming the QP.  ``tables``: whether a QP
    over ``dense_limit`` is written as its kernel table (problem-dir, hdf5) rather than
    skipped (qpbenchmark); ``tol`` as the export writes it.  Writes nothing."""
    scene, merged, sizes, specs = checked_scene(scene_name, cfg, max_qps)
    qps: list[PlannedQP] = []
    names: set[str] = set()
    keep = Keeper(KEEP_SHARE * memory_budget())
    for i, spec in enumerate(specs):
        told = sizes.get(spec.instance)
        if told is not None and matrix_free(spec):
            steps = list(enumerate(told.n))
        else:
            steps = built_sizes(scene, spec, dense_limit if tables else None, tol, lambda k, inst: keep(i, k, inst))
        for k, n in steps:
            qp = PlannedQP(problem_name(spec.instance, k), spec.instance, k, int(n), i)
            if qp.name in names:
                raise ProblemInputError(f"two QPs of the export of {scene_name} are named {qp.name!r}; export them "
                                        "into separate folders")
            names.add(qp.name)
            if 0 < qp.n <= dense_limit:
                check_dense_fits(qp.name, qp.n)
            qps.append(qp)
    return ExportPlan(scene, specs, qps, keep.kept, options_record(merged))


def options_record(cfg: SceneConfig) -> dict[str, Any]:
    """A scene configuration (the scene's defaults filled in) as JSON-ready values, as an
    export's manifest records it: every field (null where unset) and ``extra``; a tuple as
    a list, anything else JSON has no value for (a lazy seed range) as its text."""
    doc: dict[str, Any] = json.loads(json.dumps(asdict(cfg), default=str))
    return doc


def package_version() -> str:
    """The installed contactbench version, recorded with an export (``contactbench.__version__``)."""
    return str(contactbench.__version__)


@dataclass
class Keeper:
    """The instances a plan's check built, kept while their operators' bytes
    (``memory_nbytes``) stay within ``allowance``; the first that would pass it and every
    later one are dropped (they are built again when written, in order)."""

    allowance: float
    held: int = 0
    full: bool = False
    kept: dict[tuple[int, int], ContactInstance] = field(default_factory=dict)

    def __call__(self, spec: int, step: int, inst: ContactInstance) -> None:
        size = int(inst.qp.H.memory_nbytes)
        if self.full or self.held + size > self.allowance:
            self.full = True
            return
        self.held += size
        self.kept[(spec, step)] = inst


def matrix_free(spec: InstanceSpec) -> bool:
    """Whether a recipe's operator is matrix-free (its params' ``operator``, "fft" where
    absent; every kind but "dense", ``instances.OPERATOR_KINDS``): its QPs' kernel table is
    their operator's own."""
    return spec.params.get("operator", "fft") != "dense"


def built_sizes(scene: Any, spec: InstanceSpec, table_over: int | None, tol: float | None,
                keep: Callable[[int, ContactInstance], None] = lambda k, inst: None) -> list[tuple[int, int]]:
    """(step, n) of every step of a recipe, each QP built (``build_checked``) and handed to
    ``keep`` (step, instance); with ``table_over``, a QP over it is checked to have a kernel
    table (``check_table``)."""
    seq = scene.build(spec)
    out = []
    for k in range(len(seq)):
        name = problem_name(spec.instance, k)
        inst = build_checked(seq, k, name)
        if table_over is not None and inst.n > table_over:
            check_table(name, inst, table_over, tol)
        out.append((k, int(inst.n)))
        keep(k, inst)
    return out


def build_checked(seq: LoadSequence, k: int, name: str) -> ContactInstance:
    """Step ``k`` of ``seq``; a build over the memory budget is a one-line
    ``ProblemInputError`` naming QP ``name``."""
    try:
        return seq.at(k)
    except MemoryBudgetError as exc:
        raise ProblemInputError(f"{name}: {exc}; choose a smaller scene, --operator fft where the scene takes it, or a "
                                "larger CONTACTBENCH_MEMORY_BUDGET_GB") from None


def check_table(name: str, inst: ContactInstance, dense_limit: int, tol: float | None) -> None:
    """A one-line ``ProblemInputError`` naming QP ``name`` (n over ``dense_limit``) unless
    the problem directory format can hold it without its dense H (``qpfile.problem_payload``:
    a kernel table); nothing dense is made."""
    try:
        problem_payload(inst, tol=tol, time_limit=None, dense_limit=dense_limit)
    except ProblemInputError as exc:
        raise ProblemInputError(f"{name}: {exc}; choose a --dense-limit of at least {inst.n}") from None


def check_dense_fits(name: str, n: int) -> None:
    """A one-line ``ProblemInputError`` unless the dense H of QP ``name`` (n x n float64)
    fits this process's memory budget for dense matrices (``operators.check_dense_budget``,
    ``CONTACTBENCH_MEMORY_BUDGET_GB``); nothing is allocated."""
    try:
        check_dense_budget(n, what=f"the dense H of {name}")
    except MemoryBudgetError as exc:
        raise ProblemInputError(f"{exc}; choose a --dense-limit below {n} (kernel table only, or the QP skipped "
                                "for qpbenchmark) or a larger CONTACTBENCH_MEMORY_BUDGET_GB") from None


__all__ = [
    "ExportPlan",
    "KEEP_SHARE",
    "MAX_QPS",
    "PlannedQP",
    "check_dense_fits",
    "check_scene",
    "checked_scene",
    "plan_export",
    "problem_name",
    "scene_steps",
]
