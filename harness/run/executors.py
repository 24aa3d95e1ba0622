"""Executors: where a plan's instance jobs run.

An executor takes the jobs with missing cells and makes their rows reach the store.
Every executor runs a job the same way -- ``harness.run.job.JobDriver``: the instance is
built from its picklable recipe where the job runs, each solve is isolated with a hard
time limit and judged by the harness -- so the same cells give the same rows wherever
they run.  What the solvers print goes to the run folder's solver-output log
(``harness.run.output_log``), not to the terminal (on Dask: that log where the worker
sees the run folder, else a log in the worker's temporary directory).

* ``SerialExecutor``  -- one job after another in this process (``--jobs 1``);
* ``PoolExecutor``    -- a local ``concurrent.futures`` process pool (``--jobs J``); each
                         pool process appends to the same journal (flock + fsync);
* ``harness.run.distributed.DaskExecutor`` -- a Dask cluster (``--scheduler ADDRESS``).
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, InvalidStateError, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Protocol, Sequence

from .forks import process_context
from .isolation import remove_orphan_scratch, set_parent_death_signal
from .interrupts import STOP_SIGNALS, signals_deferred
from .job import JobDriver, run_instance_job
from .output_log import OUTPUT_LOG
from .plan import InstanceJob, RunConfig
from ..table.store import ResultStore

log = logging.getLogger("contactbench")


class Progress(Protocol):
    def update(self, n: int = 1) -> None: ...


class Executor(Protocol):
    """Runs instance jobs and stores their rows (module doc)."""

    def run_config(self, run: RunConfig) -> RunConfig:
        """The run configuration the jobs actually run under (recorded in meta.json)."""

    def describe(self) -> dict[str, Any]:
        """What meta.json records of the executor."""

    def execute(self, jobs: Sequence[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str],
                progress: Progress, verbose: bool = False) -> None:
        """Run the missing cells of ``jobs``; each stored row counts one on ``progress``."""


@dataclass
class SerialExecutor:
    """One job after another, in this process."""

    def run_config(self, run: RunConfig) -> RunConfig:
        return run

    def describe(self) -> dict[str, Any]:
        return {"kind": "serial"}

    def execute(self, jobs: Sequence[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str],
                progress: Progress, verbose: bool = False) -> None:
        def sink(row: dict[str, Any]) -> None:
            store.append(row)
            progress.update(1)

        for job in jobs:
            n_before = len(store)
            JobDriver(job, run, statuses, store.cache_dir, sink, store.out / OUTPUT_LOG).run()
            if verbose:
                log.info("%s/%s: %d rows", job.spec.scene, job.spec.instance, len(store) - n_before)


#: Seconds ``stop_workers`` gives the pool's processes to stop their jobs -- each kills its
#: solver worker and writes what the solve printed to the log -- before it kills them.
STOP_GRACE_S = 10.0

#: In a pool process: whether a job is running there (``_pool_run``).
_IN_JOB = False


def _pool_init() -> None:
    for sig in STOP_SIGNALS:  # (the command's own handlers are its process's)
        signal.signal(sig, _stop_pool_process)
    set_parent_death_signal()


def _stop_pool_process(signum: int, frame: Any) -> None:
    """A pool process's Ctrl-C or SIGTERM (``stop_workers``): a running job stops as the
    serial run's does (``JobDriver.call``: its solve's output joins the log, marked
    stopped) and the process then exits (``_pool_run``); an idle one exits at once."""
    if _IN_JOB:
        raise KeyboardInterrupt
    os._exit(128 + signum)


def _pool_run(job: InstanceJob, run: RunConfig, out_dir: str, statuses: dict[str, str]) -> int:
    global _IN_JOB
    _IN_JOB = True
    try:
        return run_instance_job(job, run, out_dir, statuses)
    except KeyboardInterrupt:
        os._exit(128 + signal.SIGINT)  # (no other job may start here: the run is stopping)
    finally:
        _IN_JOB = False


class RunStopped(RuntimeError):
    """A run stopped once it ran -- its cells were being solved and stored -- with the rows
    stored so far kept: one line, and the same command resumes (``cli``: exit 1)."""


class PoolProcessLost(RunStopped):
    """A ``--jobs`` process ended abruptly (killed: the out-of-memory killer, ``kill -9``)."""


@dataclass
class PoolExecutor:
    """A local process pool of ``workers`` processes (forked on Linux)."""

    workers: int

    def run_config(self, run: RunConfig) -> RunConfig:
        return run

    def describe(self) -> dict[str, Any]:
        return {"kind": "process-pool", "workers": self.workers}

    def execute(self, jobs: Sequence[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str],
                progress: Progress, verbose: bool = False) -> None:
        ctx = process_context() if sys.platform.startswith("linux") else None
        lines0 = store.count_lines()
        with ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=_pool_init) as pool:
            futures = {pool.submit(_pool_run, j, run, str(store.out), statuses) for j in jobs}
            seen = 0
            try:
                while futures:
                    done, futures = wait(futures, timeout=0.5, return_when=FIRST_COMPLETED)
                    for f in done:
                        f.result()
                    now = store.count_lines() - lines0
                    progress.update(max(0, now - seen))
                    seen = max(seen, now)
            except BaseException as exc:  # an interrupt (or a job's error): no job may run on after it
                for f in futures:
                    f.cancel()
                with signals_deferred():  # (a second Ctrl-C does not leave the pool's processes running)
                    stop_workers(pool)
                if isinstance(exc, BrokenProcessPool):
                    raise PoolProcessLost("a --jobs process ended abruptly (a signal -- the out-of-memory killer, "
                                          "a kill -- or an exit of its own) and the run stopped; the rows stored "
                                          "are kept: the same command resumes the rest") from None
                raise


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """Stop the pool's processes: each is told to stop (SIGTERM: its running job kills its
    solver worker and writes what the solve printed to the log, ``_stop_pool_process``), and
    whichever has not exited within ``STOP_GRACE_S`` is killed -- with the solver workers it
    started (``PR_SET_PDEATHSIG``) -- so that leaving the pool does not wait on a stuck one.
    The rows they stored are kept; a row cut short by the kill is read as never written."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)  # (shutdown drops the pool's reference)
    before = threading.excepthook
    threading.excepthook = _quiet_on_cancelled(before)
    try:
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        end = time.monotonic() + STOP_GRACE_S
        for proc in procs:
            proc.join(max(0.0, end - time.monotonic()))
        for proc in procs:
            if proc.is_alive():
                proc.kill()
        for proc in procs:
            proc.join(5.0)
        pool.shutdown(wait=False, cancel_futures=True)
        if manager is not None:
            manager.join(5.0)
    finally:
        threading.excepthook = before
    remove_orphan_scratch()  # what their solver workers kept in their temporary folders


def _quiet_on_cancelled(hook: Any) -> Any:
    """``hook``, less the traceback of the pool's manager thread when it marks a future the
    interrupt cancelled as broken (``InvalidStateError``: CPython's executor tells the
    cancelled futures of a pool whose workers were killed so, on its own thread)."""

    def quiet(args: Any) -> None:
        if not isinstance(args.exc_value, InvalidStateError):
            hook(args)

    return quiet


def output_log_name(executor: Executor) -> str | None:
    """The run folder's file that holds what the solvers print (meta.json ``solver_output``)
    where ``executor`` writes one (this module's executors), else None."""
    return OUTPUT_LOG if isinstance(executor, (SerialExecutor, PoolExecutor)) else None


def local_executor(run: RunConfig, jobs: int) -> Executor:
    """Serial for ``--jobs 1`` or a single job, else a process pool of ``--jobs`` processes,
    never more than there are ``jobs`` to run; a warning when ``--jobs`` or ``--threads`` is
    above the CPUs (the workers, or the threads, then share them, and their timings contend)."""
    cpus = os.cpu_count() or 1
    for flag, asked in (("--jobs", run.jobs), ("--threads", run.threads_per_worker or 0)):
        if asked > cpus:
            log.warning("%s %d is above the %d CPUs of this machine: they share them, and the timings contend",
                        flag, asked, cpus)
    if run.jobs <= 1 or jobs <= 1:
        return SerialExecutor()
    return PoolExecutor(min(run.jobs, jobs))
