"""The runner: scenes x instances x load steps x solver variants x profiles x repeats.

``run_benchmark`` is the one path of a run, whatever executes it:

1. plan (``harness.run.plan.plan_run``): scene names -> instance jobs through their studies
   (``harness.run.studies``), every input validated and the plan's size bounded
   (``--max-cells``, ``--memory-budget-gb``) before anything runs;
2. check the results folder (``checked_folder``: no rows of a solver edited since they were
   written; a new folder, or one that records this run's configuration, ``run_identity``, or
   ``append``; no entry it
   reads or writes, the solvers' log included, a link or of the wrong kind:
   ``check_run_entries``), still touching nothing; then take its lock (``harness.table.store.RunLock``), write the marker,
   open the store and write meta.json (``harness.table.meta``);
3. hand the jobs with missing cells to an executor (``harness.run.executors``: serial, a
   process pool, or Dask in ``harness.run.distributed``); each job is run by
   ``harness.run.job.JobDriver``: skip policy (``harness.run.skips``), isolated worker
   (``harness.run.worker``), judge (``harness.judging``), one row per cell (``harness.run.rows``);
4. write the tidy table -- after an interrupt too, with a further Ctrl-C held back until it
   is written (``harness.run.interrupts``).

Rows are appended to the store as they finish; rerunning the same command runs only the
cells whose ``cell_id`` is missing.  Each job carries the stored rows of its own cells
(``InstanceJob.with_stored``), so its skip decisions on resume are those of an
uninterrupted run (``harness.run.skips.SkipPolicy``).  Stored skips are kept, not decided
again: a skip of step k depends only on the rows of steps < k of its sequence, which a
job writes before it (the journal is append-only, and an interruption or a torn last
line loses a suffix of each job's rows only), and on the configuration, which the
folder's marker pins -- so deciding it again would give the same answer.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, replace
from typing import Any, Callable, Iterator, Sequence

from contactbench.problems.scenes import SceneConfig
from contactbench.solvers.registry import get_solver, source_digest

from ..arguments import os_error_line
from .executors import Executor, RunStopped, local_executor, output_log_name
from .interrupts import signals_deferred
from .output_log import OUTPUT_LOG
from ..table.meta import META_FILE, build_meta, listed, read_meta, surface_preprocessing, write_meta
from .plan import REFERENCE_TIMEOUT_FACTOR, RunConfig, RunPlan, job_cell_ids, plan_run
from .spelled_out import given_apart
from ..table.store import (MARKER_FILE, ResultStore, RunFolder, RunFolderError, check_run_entries, fingerprint,
                           holding_lock, read_run_folder, record_run, refuse_unrecorded)

#: The RunConfig fields that are part of a run's configuration (what the folder's marker
#: pins): those that change which cells exist, how they are judged or skipped.  The
#: others (jobs, threads, progress, max_cells) say how a run executes, and a resume may
#: change them.
IDENTITY_RUN_FIELDS = ("profiles", "repeats", "timeout", "warm", "warmup", "warmup_limit", "reference",
                       "reference_timeout", "build_timeout", "memory_budget")

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
        """Rows the judge gave a verdict ("solved" or "inaccurate", harness/judging.py); the
        rest failed, timed out, crashed or were skipped."""
        return sum(self.statuses.get(s, 0) for s in ("solved", "inaccurate"))

    def line(self) -> str:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
        return f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s: {counts} -> {self.out_dir}"


def under_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes") or not sys.stderr.isatty()


def run_config_record(scenes: Sequence[str], cfg: SceneConfig, plan: RunPlan, run: RunConfig,
                      surfaces: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """meta.json's ``config`` (less the executor); ``cells``: how many cells the plan
    has (a report of a folder with fewer says the run is partial); where the run reads
    measured maps, ``surface_sha256``: the raw heights' hashes its recipes pin
    (``surface_hashes``), and ``surface_key``: each map as prepared (``surface_keys`` of
    ``surfaces``, meta.json's ``surface_preprocessing`` records)."""
    hashes, keys, sources = surface_hashes(plan), surface_keys(surfaces or {}), solver_sources(plan)
    return {"scenes": list(scenes), "scene_config": asdict(cfg), "run": asdict(run),
            "solvers": sorted({v.name for j in plan.jobs for v in j.variants}),
            "profiles": sorted({p for j in plan.jobs for p in j.profiles}),
            "cells": plan.n_cells(run.repeats), **({"surface_sha256": hashes} if hashes else {}),
            **({"surface_key": keys} if keys else {}), **({"solver_sources": sources} if sources else {})}


def solver_sources(plan: RunPlan) -> dict[str, str]:
    """The source digest of each solver the plan runs from outside this package
    (``registry.source_digest``), by registry name."""
    digests = {base: source_digest(get_solver(base)) for base in sorted({v.base for j in plan.jobs for v in j.variants})}
    return {base: d for base, d in digests.items() if d is not None}


def checked_folder(out_dir: str | os.PathLike[str], identity: dict[str, Any], append: bool,
                   sources: dict[str, str]) -> RunFolder:
    """The results folder, read once (``read_run_folder``), that this run may write: no
    edited solver's rows (``check_solver_sources``), a meta.json that can be read
    (``MetaError``) and is its own (``refuse_foreign_meta``) and, unless ``append``, this
    run's configuration recorded (``refuse_unrecorded``)."""
    folder = read_run_folder(out_dir, run_identity)
    check_solver_sources(folder, sources)
    refuse_foreign_meta(folder, read_meta(out_dir))
    return refuse_unrecorded(folder, identity, append)


def refuse_foreign_meta(folder: RunFolder, meta: dict[str, Any]) -> None:
    """``RunFolderError`` when meta.json records a run (its config's ``fingerprint``) that
    the folder's marker does not: another folder's record put here, which a run would merge
    for good and a report would read as this folder's.  Records written without a
    fingerprint are not checked."""
    if folder.kind != "marked":
        return
    known = {r.get("fingerprint") for r in folder.runs}
    for inv in listed(meta.get("invocations")) or [meta]:
        config = inv.get("config") if isinstance(inv, dict) else None
        fp = config.get("fingerprint") if isinstance(config, dict) else None
        if isinstance(fp, str) and fp and fp not in known:
            raise RunFolderError(f"results folder {folder.out}: its {META_FILE} records a run its marker "
                                 f"({MARKER_FILE}) does not -- another folder's record? Put this folder's "
                                 f"{META_FILE} back, or remove it (the next run writes it anew); nothing was written")


def check_solver_sources(folder: RunFolder, sources: dict[str, str]) -> None:
    """``RunFolderError`` when a solver of this run from outside this package has another
    source than the one a run recorded in ``folder`` wrote its rows with (``solver_sources``),
    with ``--append`` too: the folder's rows would be read as the edited code's."""
    for run in folder.runs:
        recorded = (run.get("config") or {}).get("solver_sources") or {}
        for name, digest in sorted(sources.items()):
            if name in recorded and recorded[name] != digest:
                raise RunFolderError(f"results folder {folder.out} holds rows of solver {name!r} from another source "
                                     f"(sha256 {recorded[name]}, now {digest}: its file was edited); write the edited "
                                     "solver's rows to another --out, or give it another name (nothing was written)")


def surface_hashes(plan: RunPlan) -> list[str]:
    """The hashes of the measured maps the plan's recipes read (none for generated surfaces)."""
    return sorted({str(j.spec.params["surface_sha256"]) for j in plan.jobs if j.spec.params.get("surface_sha256")})


#: Hex digits of a map's ``MapPreprocessing.key`` in a run's configuration (``surface_keys``).
IDENTITY_KEY_DIGITS = 16


def surface_keys(surfaces: dict[str, dict[str, Any]]) -> list[str]:
    """Each measured map as prepared, "<base name> (key <key>)": its record's ``key`` (the raw
    heights with every option and file-stated fact that makes the problem: the spacing per
    axis, the unit, the channel, the cleaning), so that a map whose file states another
    lateral size is another configuration, and the folder's refusal names the map."""
    return sorted({f"{rec['source']} (key {str(rec['key'])[:IDENTITY_KEY_DIGITS]})" for rec in surfaces.values()
                   if rec.get("key")})


def same_heights(out_dir: str | os.PathLike[str], surfaces: dict[str, dict[str, Any]]) -> list[str]:
    """One warning for each map of this run (``surfaces``: its ``surface_preprocessing``
    records) that the folder ``out_dir`` already holds (its meta.json's records) under
    another base name with the same ``key`` -- the same heights prepared the same way,
    whose rows the report then counts as two maps.  Not a refusal: a user may mean it."""
    earlier = read_meta(out_dir).get("surface_preprocessing")
    recorded: dict[str, set[str]] = {}
    for rec in (earlier.values() if isinstance(earlier, dict) else ()):
        if isinstance(rec, dict) and rec.get("key"):
            recorded.setdefault(str(rec["key"]), set()).add(str(rec.get("source")))
    found = []
    for rec in surfaces.values():
        others = sorted(recorded.get(str(rec.get("key")), set()) - {str(rec.get("source"))})
        if others:
            found.append(f"surface {rec.get('source')!r} has the same heights, prepared the same way (key "
                         f"{str(rec['key'])[:IDENTITY_KEY_DIGITS]}), as {', '.join(map(repr, others))} already in "
                         f"{out_dir}: the report counts them as separate maps")
    return list(dict.fromkeys(found))


def run_identity(config: dict[str, Any]) -> dict[str, Any]:
    """The configuration a results folder pins (its marker), from a meta.json ``config``
    (``run_config_record``, of this run or of a folder written before the marker):
    scenes, scene options (a ``--surface`` path resolved: one file however it is spelled),
    solvers, profiles and ``IDENTITY_RUN_FIELDS``, and the measured maps' contents where it
    reads any (a map edited between two runs, or prepared otherwise, is another run:
    ``surface_sha256``, ``surface_key``); an option that only spells
    out what is in effect without it is left out (``spelled_out.given_apart``, and a
    reference limit that is the one the run applies without it: ``reference_limit_in_effect``)."""
    run = dict(config.get("run") or {})
    if reference_limit_in_effect(run):
        run["reference_timeout"] = None
    if run.get("profiles") is not None and sorted(run["profiles"]) == config.get("profiles"):
        run["profiles"] = None  # (the profiles the study would run: the same cells)
    maps = {k: config[k] for k in ("surface_sha256", "surface_key", "solver_sources") if config.get(k)}
    scene_config = given_apart(config.get("scene_config"), config.get("scenes"))
    if isinstance(scene_config, dict) and isinstance(scene_config.get("surface_path"), str) and scene_config["surface_path"]:
        # one file, however it is spelled (relative, absolute, through a link): its recipe holds the resolved path
        scene_config = {**scene_config, "surface_path": os.path.realpath(scene_config["surface_path"])}
    return {"scenes": config.get("scenes"), "scene_config": scene_config,
            "solvers": config.get("solvers"), "profiles": config.get("profiles"),
            "run": {k: run.get(k) for k in IDENTITY_RUN_FIELDS}, **maps}


def reference_limit_in_effect(run: dict[str, Any]) -> bool:
    """Whether a run record's (``asdict`` of a ``RunConfig``) ``reference_timeout`` changes
    nothing the run does without it: the limit it applies then, ``REFERENCE_TIMEOUT_FACTOR``
    x its ``timeout`` (``RunConfig.ref_timeout``) to rounding, or any limit where the run
    solves no reference (``reference`` "none")."""
    if run.get("reference") == "none":
        return True
    limit, timeout = run.get("reference_timeout"), run.get("timeout")
    if isinstance(limit, bool) or isinstance(timeout, bool) or not isinstance(limit, (int, float)) \
            or not isinstance(timeout, (int, float)):
        return False
    return math.isclose(float(limit), REFERENCE_TIMEOUT_FACTOR * float(timeout), rel_tol=1e-12)


def run_benchmark(scenes: Sequence[str], cfg: SceneConfig | None = None, solvers: Sequence[str] | str | None = None,
                  run: RunConfig | None = None, out_dir: str | os.PathLike[str] = "results/run",
                  command: list[str] | None = None, executor: Executor | None = None,
                  append: bool = False, ready: Callable[[], None] | None = None) -> RunSummary:
    """Plan, check the folder, run the missing cells on ``executor`` (default: serial, or
    a process pool for ``run.jobs > 1``), write the tidy table and meta.json (module doc).

    Refusals (``PlanError``, ``RunFolderError``, ``FolderInUseError``, ``MetaError``: all
    ``ProblemInputError``) come before anything is written; the lock is held only while
    the run writes.  ``append``: add to a folder that holds a run of another
    configuration.  ``ready``: called once every check has passed, before the folder is
    locked or written (a Dask run contacts its scheduler there); what it raises ends the
    run with nothing written."""
    run = run or RunConfig()
    t0 = time.perf_counter()
    plan = plan_run(scenes, cfg, solvers, run)
    cfg = plan.scene_config
    if cfg.seeds is not None:  # (a lazy range of seeds: the plan has bounded it)
        cfg = replace(cfg, seeds=tuple(cfg.seeds))
    surfaces = surface_preprocessing(j.spec for j in plan.jobs)  # (the maps as prepared: their keys are pinned)
    config = run_config_record(scenes, cfg, plan, run, surfaces)
    identity = run_identity(config)
    config["fingerprint"] = fingerprint(identity)  # (the plan a report counts the cells of: ``meta.planned_runs``)
    checked_folder(out_dir, identity, append, config.get("solver_sources", {}))
    check_run_entries(out_dir, {OUTPUT_LOG: False})  # (the solvers' log: never written through a link)
    if ready is not None:
        ready()
    with holding_lock(out_dir):
        folder = checked_folder(out_dir, identity, append, config.get("solver_sources", {}))  # again, locked
        plan = replace(plan, warnings=[*plan.warnings, *same_heights(out_dir, surfaces)])
        for w in plan.warnings:
            log.warning("warning: %s", w)
        with stopped_before_solving():
            record_run(folder, identity)
        store = ResultStore(out_dir)
        return execute_plan(plan, run, store, config, command, executor, t0, surfaces)


@contextlib.contextmanager
def stopped_before_solving() -> Iterator[None]:
    """A write at a run's start (its marker, meta.json) that fails -- a full disk -- as a
    ``RunStopped`` naming the file: a write that failed, not bad input (``cli``: exit 1)."""
    try:
        yield
    except OSError as exc:
        raise RunStopped(f"{os_error_line(exc)}; the run stopped before it solved anything: the same command "
                         "starts it again") from None


def execute_plan(plan: RunPlan, run: RunConfig, store: ResultStore, config: dict[str, Any],
                 command: list[str] | None, executor: Executor | None, t0: float,
                 surfaces: dict[str, dict[str, Any]] | None = None) -> RunSummary:
    """Run the plan's missing cells into ``store`` (its folder locked), meta.json first
    (``surfaces``: the plan's ``surface_preprocessing`` records, read here when None)."""
    before = len(store)
    stored = {r["cell_id"]: r for r in store.rows()}
    statuses = {c: str(r.get("status", "")) for c, r in stored.items()}
    pending = [j.with_stored(stored, run) for j in plan.jobs if not all(c in statuses for c in job_cell_ids(j, run))]
    executor = executor or local_executor(run, len(pending))
    ran = executor.run_config(run)  # (what each solve worker's BLAS/FFT threads are held to: the report's header)
    config = {**config, "run": asdict(ran), "executor": executor.describe(), "worker_threads": ran.worker_threads()}
    log_name = output_log_name(executor)
    with stopped_before_solving():
        write_meta(store.out, build_meta(command=command, config=config, warnings=plan.warnings,
                                         surfaces=surface_preprocessing(j.spec for j in plan.jobs) if surfaces is None
                                         else surfaces,
                                         extra={"solver_output": log_name} if log_name else None))
    total = sum(j.n_cells(run.repeats) for j in pending)
    already = sum(1 for j in pending for c in job_cell_ids(j, run) if c in statuses)
    show_bar = run.progress if run.progress is not None else not under_ci()
    bar = progress_bar(total, already, show_bar)
    try:
        executor.execute(pending, run, store, statuses, bar, verbose=not show_bar)
    except BaseException as exc:  # (an interrupt, a full disk): the table from the rows kept, the first error told
        bar.close()
        with signals_deferred(), contextlib.suppress(Exception):
            ResultStore(store.out).finalize()
        if isinstance(exc, OSError):  # a write that failed as the cells ran: no bad input
            raise RunStopped(f"{os_error_line(exc)}; the run stopped, the rows stored are kept: the same command "
                             "resumes the rest") from None
        raise
    bar.close()
    try:
        with signals_deferred():  # (a second Ctrl-C while the table is written waits for it)
            table = ResultStore(store.out).finalize()
    except OSError as exc:  # every cell ran, the table could not be written: no bad input
        raise RunStopped(f"{os_error_line(exc)}; the table was not written, the rows stored are kept: the same "
                         "command writes it") from None
    counts = {str(k): int(v) for k, v in table["status"].value_counts().items()} if len(table) else {}
    return RunSummary(str(store.out), len(table), len(table) - before, counts, time.perf_counter() - t0, plan.warnings)


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
