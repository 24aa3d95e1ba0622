"""Load sequences: the warm-start mapping, and ``solve_sequence`` for scripts.

Along a load history each solver starts from its *own* previous-step answer, mapped by
grid index (``Geometry.indices``) onto the new trial set: a point present in both keeps
its value, a point new to the trial set starts at 0; w is mapped too for solvers whose
``capabilities.warm_start`` is "primal-dual".  This module is the one place that
mapping lives: the runner's worker (``harness.run.worker``) and ``solve_sequence`` -- which
the benchmark scripts call for their load loops -- both use it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from contactbench.problems.errors import ProblemInputError, check_positive, real_number
from contactbench.problems.instances import ContactInstance
from contactbench.problems.scenes import LoadSequence
from contactbench.solvers.base import Solver, SolveResult, SolverSettings, WarmStart
from contactbench.solvers.registry import load_solver

from ..judging import ProblemSeal, Verdict, judge
from ..profiles import get_profile
from ..table.files import write_npz_atomic


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
    """One solver's answer of one step, by grid index: the next step's warm start."""

    step: int
    indices: np.ndarray
    p: np.ndarray
    w: np.ndarray | None

    @classmethod
    def of(cls, step: int, inst: ContactInstance, p: np.ndarray, w: Any) -> "WarmState | None":
        """The state of answer (p, w) on ``inst`` (None: no grid geometry, or p unusable)."""
        geom = inst.geometry
        p = np.asarray(p, dtype=np.float64).reshape(-1)
        if geom is None or p.shape != (inst.n,) or not np.all(np.isfinite(p)):
            return None
        w_arr = None
        if w is not None:
            w_arr = np.asarray(w, dtype=np.float64).reshape(-1)
            if w_arr.shape != p.shape:
                w_arr = None
        return cls(step, np.asarray(geom.indices), p.copy(), w_arr)

    def save(self, path: str | Path) -> None:
        """Keep this state in ``path`` (npz, no pickles; p as its support and values, the
        grid indices as the instance gives them again), written whole or not at all."""
        support = np.flatnonzero(self.p)
        extra = {} if self.w is None else {"w": self.w}
        write_npz_atomic(path, step=np.int64(self.step), n=np.int64(self.p.size), support=support,
                         values=self.p[support], **extra)

    @classmethod
    def load(cls, path: str | Path, step: int, inst: ContactInstance) -> "WarmState | None":
        """The state ``save`` kept in ``path`` for ``step`` of ``inst``, or None where the file
        is missing, unreadable or holds another step's or another size's answer."""
        try:
            with np.load(path, allow_pickle=False) as f:
                if int(f["step"]) != step or int(f["n"]) != inst.n:
                    return None
                support, p = np.asarray(f["support"], dtype=np.int64), np.zeros(inst.n)
                if support.size and not 0 <= support.min() <= support.max() < inst.n:
                    return None
                p[support] = f["values"]
                w = f["w"] if "w" in f.files else None
        except Exception:  # cut short, not an archive, another layout: not a warm start
            return None
        return cls.of(step, inst, p, w)


def warm_start_from(state: WarmState | None, inst: ContactInstance, step: int, kind: str) -> WarmStart | None:
    """The previous step's answer mapped onto this step's trial set (None if there is
    no previous-step answer, the instance has no grid geometry, or the solver takes no
    warm start)."""
    geom = inst.geometry
    if state is None or state.step != step - 1 or geom is None or kind == "none":
        return None
    p = map_by_grid_index(state.p, state.indices, geom.indices)
    w = None
    if kind == "primal-dual" and state.w is not None:
        w = map_by_grid_index(state.w, state.indices, geom.indices)
    return WarmStart(p=p, w=w)


# ---------------------------------------------------------------------------
# A whole sequence in this process (benchmark scripts)
# ---------------------------------------------------------------------------


@dataclass
class StepSolve:
    """One step of ``solve_sequence``: the solver's result, the seconds around its
    ``solve`` call, whether it was warm-started, and the judge's verdict."""

    step: int
    inst: ContactInstance
    result: SolveResult | None
    seconds: float
    warm_started: bool
    verdict: Verdict | None
    error: str = ""

    @property
    def kkt_error(self) -> float:
        return float("inf") if self.verdict is None else self.verdict.kkt_error


def instances_of(steps: LoadSequence | Iterable[ContactInstance]) -> Iterator[ContactInstance]:
    if isinstance(steps, LoadSequence):
        return (steps.at(k) for k in range(len(steps)))
    return iter(steps)


def solve_sequence(solver: Solver | str, steps: LoadSequence | Iterable[ContactInstance],
                   settings: SolverSettings | None = None, *, warm: bool = True, check_tol: float | None = None,
                   references: Sequence[np.ndarray | None] | None = None, budget_s: float | None = None,
                   on_step: Callable[[StepSolve], None] | None = None) -> list[StepSolve]:
    """Solve the steps of a load sequence in order with one solver.

    Each step warm-starts from the solver's own previous answer (``warm_start_from``,
    when ``warm`` and the solver takes one); each answer is judged by ``judge`` at
    ``check_tol`` (default: the "default" profile's), against ``references[k]`` when
    given (an entry None: that step has none).  Stops after the step that brings the total
    solve time over ``budget_s`` (None: no budget), or at a ``MemoryError`` (recorded as
    that step's ``error``).

    ``budget_s`` must be None or a number > 0, ``check_tol`` None or a finite number > 0,
    and ``references`` None or one entry per step: for ``steps`` with a length (a
    ``LoadSequence``, a list) checked before any solve; for other iterables before the
    solve of a step beyond the references, and once the steps run out short of them.
    Else a one-line ``ProblemInputError``."""
    if budget_s is not None and not real_number("solve_sequence's budget_s", budget_s, "a number > 0") > 0.0:
        raise ProblemInputError(f"solve_sequence's budget_s must be a number > 0 (None: no budget), got {budget_s!r}")
    refs = None if references is None else list(references)
    count = len(steps) if hasattr(steps, "__len__") else None  # type: ignore[arg-type]
    if refs is not None and count is not None and len(refs) != count:
        raise ProblemInputError(f"solve_sequence was given {len(refs)} references for {count} steps")
    s = load_solver(solver)
    settings = settings or SolverSettings()
    tol = get_profile("default").check_tol if check_tol is None else check_positive("solve_sequence's check_tol",
                                                                                    check_tol)
    kind = s.capabilities.warm_start if warm else "none"
    out: list[StepSolve] = []
    state: WarmState | None = None
    total = 0.0
    k = -1
    for k, inst in enumerate(instances_of(steps)):
        if refs is not None and k >= len(refs):
            raise ProblemInputError(f"solve_sequence was given {len(refs)} references for more steps")
        start = warm_start_from(state, inst, k, kind)
        seal = ProblemSeal.of(inst.qp)  # before the clock: hashing a large kernel table is the harness's time
        t0 = time.perf_counter()
        try:
            res = s.solve(inst.qp, replace(settings, params=dict(settings.params), check_tol=tol), start)
        except MemoryError as exc:
            out.append(StepSolve(k, inst, None, time.perf_counter() - t0, start is not None, None, f"memory: {exc}"))
            break
        seconds = time.perf_counter() - t0
        p_ref = None if refs is None else refs[k]
        tampered = seal.broken(inst.qp)
        seal.mend(inst.qp)
        verdict = judge(inst, res.p, bool(res.converged), tol, p_ref=p_ref, tampered=tampered,
                        multiplier=res.multiplier)
        step = StepSolve(k, inst, res, seconds, start is not None, verdict)
        out.append(step)
        if on_step is not None:
            on_step(step)
        state = WarmState.of(k, inst, res.p, res.w)
        total += seconds
        if budget_s is not None and total > budget_s:
            break
    else:
        if refs is not None and len(refs) != k + 1:
            raise ProblemInputError(f"solve_sequence was given {len(refs)} references for {k + 1} steps")
    return out
