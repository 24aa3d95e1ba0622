"""The runner: scenes x instances x load steps x solver variants x profiles x repeats.

``run_benchmark`` is the one path of a run, whatever executes it:

1. plan (``harness.plan.plan_run``): scene names -> instance jobs through their studies
   (``harness.studies``), every input validated before anything runs;
2. open the store (``harness.store``) and write meta.json (``harness.meta``);
3. hand the jobs with missing cells to an executor (``harness.executors``: serial, a
   process pool, or Dask in ``harness.distributed``); each job is run by
   ``harness.job.JobRunner``: skip policy (``harness.skips``), isolated worker
   (``harness.worker``), judge (``harness.judge``), one row per cell (``harness.rows``);
4. write the tidy table.

Rows are appended to the store as they finish; rerunning the same command runs only the
cells whose ``cell_id`` is missing.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from dataclasses import asdict, dataclass
from typing import Any, Sequence

from contactbench.problems.scenes import SceneConfig

from .executors import Executor, local_executor
from .meta import build_meta, write_meta
from .plan import RunConfig, RunPlan, job_cell_ids, plan_run
from .store import ResultStore

log = logging.getLogger("contactbench")


@dataclass
class RunSummary:
    out_dir: str
    rows: int
    new_rows: int
    statuses: dict[str, int]
    elapsed_s: float
    warnings: list[str]

    @property
    def judged(self) -> int:
        """Rows the judge gave a verdict ("solved" or "inaccurate", harness/judge.py); the
        rest failed, timed out, crashed or were skipped."""
        return sum(self.statuses.get(s, 0) for s in ("solved", "inaccurate"))

    def line(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
        return f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s: {counts} -> {self.out_dir}"


def under_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes") or not sys.stderr.isatty()


def open_run(scenes: Sequence[str], cfg: SceneConfig | None, solvers: Sequence[str] | str | None, run: RunConfig,
             out_dir: str | os.PathLike[str]) -> tuple[RunPlan, ResultStore]:
    """Plan the cells (refusing bad input before anything is written) and open the store."""
    plan = plan_run(scenes, cfg, solvers, run)
    for w in plan.warnings:
        log.warning("warning: %s", w)
    return plan, ResultStore(out_dir)


def run_benchmark(scenes: Sequence[str], cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
                  run: RunConfig | None = None, out_dir: str | os.PathLike[str] = "results/run",
                  command: list[str] | None = None, executor: Executor | None = None) -> RunSummary:
    """Plan, run the missing cells on ``executor`` (default: serial, or a process pool
    for ``run.jobs > 1``), write the tidy table and meta.json."""
    run = run or RunConfig()
    t0 = time.perf_counter()
    plan, store = open_run(scenes, cfg, solvers, run, out_dir)
    before = len(store)
    statuses = store.done_statuses()
    pending = [j for j in plan.jobs if not all(c in statuses for c in job_cell_ids(j, run))]
    executor = executor or local_executor(run, len(pending))
    config = {"scenes": list(scenes), "scene_config": asdict(cfg or SceneConfig()),
              "run": asdict(executor.run_config(run)),
              "solvers": sorted({v.name for j in plan.jobs for v in j.variants}),
              "profiles": sorted({p for j in plan.jobs for p in j.profiles}), "executor": executor.describe()}
    write_meta(out_dir, build_meta(command=command, config=config, warnings=plan.warnings))
    total = sum(j.n_cells(run.repeats) for j in pending)
    already = sum(1 for j in pending for c in job_cell_ids(j, run) if c in statuses)
    show_bar = run.progress if run.progress is not None else not under_ci()
    bar = progress_bar(total, already, show_bar)
    try:
        executor.execute(pending, run, store, statuses, bar, verbose=not show_bar)
    finally:
        bar.close()
        table = ResultStore(out_dir).finalize()
    counts = {str(k): int(v) for k, v in table["status"].value_counts().items()} if len(table) else {}
    return RunSummary(str(out_dir), len(table), len(table) - before, counts, time.perf_counter() - t0, plan.warnings)


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def progress_bar(total: int, initial: int, show: bool) -> Any:
    if not show:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, unit="solve", dynamic_ncols=True, smoothing=0.1)
