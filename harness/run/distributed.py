"""Sweeps past one machine: the runner's instance jobs on a Dask distributed cluster.

``contactbench run ... --scheduler ADDRESS`` sends the same cells that a local run
would execute to a running Dask scheduler (``dask.distributed.Client(ADDRESS)``).  No
home-made scheduler: Dask places the work, and Dask's worker-loss handling (the
scheduler re-runs a task whose worker died, up to ``distributed.scheduler.
allowed-failures`` times) is the retry mechanism.

Unit of work.  One task = one ``InstanceJob`` of harness/run/plan.py (all the missing
cells of one instance: its load steps x solver variants x profiles x repeats), run on
the worker by the same ``harness.run.job.JobDriver`` as every executor
(``harness.run.executors``) -- so a Dask worker does exactly what a local run does: builds
the instance *on the worker* from its picklable ``InstanceSpec`` recipe (a seed, never
an operator or a surface), isolates every solve in a child process with a hard time
limit, judges every answer (``harness.judging``), warm-starts along the load history.
Only the recipe goes out and only rows come back.

``DaskExecutor`` is the executor; ``run_benchmark_on_dask`` is ``run_benchmark`` with it.

Rows.  The worker returns its rows to the client; the client writes them through the
same resumable store (harness/table/store.py) as a local run, skipping any ``cell_id``
already stored.  Hence:

* a worker that dies mid-job (OOM killer, pre-empted node, a solver that takes the
  worker down) loses nothing: its rows never reached the store, Dask re-runs the job
  on another worker and the client stores each cell once;
* a job whose worker died more often than the scheduler allows (``KilledWorker``) has
  its missing cells stored with status ``crashed`` (and the reason), so the table is
  complete; a job that raised is stored ``failed``;
* the client can be interrupted (Ctrl-C, kill -9) and the same command rerun: only
  cells missing from the store are sent again.

Threads.  Each worker limits BLAS/OpenMP (threadpoolctl) and FFT
(``CONTACTBENCH_FFT_WORKERS``) threads to ``threads_per_worker`` (default 1), so
``--nworkers`` processes do not oversubscribe a node.

Starting a cluster: see docs/distributed.md (``dask scheduler`` + ``dask worker``,
or dask-jobqueue on SLURM / PBS).
"""

from __future__ import annotations

import json
import logging
import multiprocessing as mp
import os
import queue
import tempfile
import time
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig

from .executors import Progress
from .isolation import limit_threads
from .job import JobDriver
from .output_log import OUTPUT_LOG
from .plan import InstanceJob, RunConfig, job_cell_ids
from .runner import RunSummary, run_benchmark
from ..table.store import CACHE_DIR, ResultStore, encode_row

if TYPE_CHECKING:  # pragma: no cover
    from distributed import Client

log = logging.getLogger("contactbench")

#: Environment every Dask worker should have (``dask worker`` inherits it; LocalCluster
#: and the docs set it).  Dask's nanny already sets OMP/MKL/OPENBLAS to 1 by default.
WORKER_ENV: dict[str, str] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "CONTACTBENCH_FFT_WORKERS": "1",
}
#: glibc malloc settings for workers (see ``tune_malloc``).
MALLOC_TRIM_THRESHOLD = 256 * 2**20
MALLOC_MMAP_THRESHOLD = 32 * 2**20


# ---------------------------------------------------------------------------
# The worker side
# ---------------------------------------------------------------------------


@dataclass
class JobResult:
    """What one Dask task sends back: the rows of the cells it ran, and where it ran."""

    instance: str
    rows: list[dict[str, Any]]
    host: str
    pid: int
    elapsed_s: float


def allow_child_processes() -> None:
    """Let this process start child processes.

    Dask's nanny starts worker processes as *daemonic* multiprocessing processes
    (``distributed.worker.daemon: True``), and multiprocessing refuses to start children
    from a daemonic process.  The runner isolates each solve in a child process that is
    killed with its parent (``PR_SET_PDEATHSIG``), which is exactly what the daemon flag
    exists to guarantee, so the flag is lifted for this worker process.  (Equivalently,
    start workers with ``DASK_DISTRIBUTED__WORKER__DAEMON=False``.)"""
    proc = mp.current_process()
    if proc.daemon:
        proc._config["daemon"] = False  # type: ignore[attr-defined]


def tune_malloc() -> bool:
    """Undo the effect of Dask's ``MALLOC_TRIM_THRESHOLD_=65536`` on numerical work.

    Dask's nanny starts workers with that variable (``distributed.nanny.
    pre-spawn-environ``) so they hand memory back to the OS.  Setting it also freezes
    glibc's mmap threshold at 128 KiB, so every FFT-sized temporary is mmap'ed and
    unmapped again: measured here, solves at 128^2 ran 3-4x slower in a worker (page
    faults, high system time) than in a plain process.  ``mallopt`` restores large
    thresholds for this process and the solve processes it forks.  Linux/glibc only;
    returns whether it applied."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        ok = libc.mallopt(m_mmap_threshold, MALLOC_MMAP_THRESHOLD) == 1
        return bool(libc.mallopt(m_trim_threshold, MALLOC_TRIM_THRESHOLD) == 1 and ok)
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False


def register_solver_specs(specs: Sequence[str]) -> None:
    """Register ``module:NAME`` solvers on this process (a worker does not share the
    client's registry: solvers given on the command line as import paths are loaded
    again here)."""
    from contactbench.solvers.registry import load_solver, register

    for spec in specs:
        register(load_solver(spec), replace=True)


def worker_cache_dir(shared_out: str | None) -> Path:
    """Where a worker keeps reference solutions and the answers a next step starts from:
    the run directory's ``_cache`` when the worker sees it (a shared file system), else a
    per-user temporary directory.  Both are keyed by a hash of the recipe (and variant)
    and the step, so sharing it is safe: another run's file of the same key holds the same
    problem's answer, and one it removed costs a resume a re-solve, not a wrong start."""
    if shared_out and Path(shared_out).is_dir():
        d = Path(shared_out) / CACHE_DIR
    else:
        d = Path(tempfile.gettempdir()) / f"contactbench-cache-{os.getuid()}"
    d.mkdir(parents=True, exist_ok=True)
    return d


def worker_output_log(shared_out: str | None) -> Path:
    """Where a worker's solvers' output goes (``harness.run.output_log``): the run
    directory's log when the worker sees it (a shared file system; appends are locked),
    else a per-user log in the worker's temporary directory."""
    if shared_out and Path(shared_out).is_dir():
        return Path(shared_out) / OUTPUT_LOG
    return Path(tempfile.gettempdir()) / f"contactbench-{os.getuid()}-{OUTPUT_LOG}"


def stream_row(topic: str | None) -> Callable[[dict[str, Any]], None] | None:
    """A sink that sends each finished row to the client at once (a Dask worker event
    on ``topic``), so rows finished before a worker dies are not recomputed-or-lost."""
    if not topic:
        return None
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):  # not inside a Dask worker
        return None
    return lambda row: worker.log_event(topic, encode_row(row))


def run_job_on_worker(job: InstanceJob, run: RunConfig, statuses: dict[str, str],
                      solver_specs: tuple[str, ...] = (), shared_out: str | None = None,
                      topic: str | None = None) -> JobResult:
    """The Dask task: run the missing cells of one instance job and return their rows
    (each row is also streamed to the client on ``topic`` as it finishes).

    The instance is built here from ``job.spec`` (its seed); each solve runs in the
    runner's isolated child process with BLAS/FFT threads limited to
    ``run.threads_per_worker``."""
    import socket

    t0 = time.perf_counter()
    allow_child_processes()
    tune_malloc()
    _limits = limit_threads(run.threads_per_worker)  # noqa: F841 - held for the task
    register_solver_specs(solver_specs)
    rows: list[dict[str, Any]] = []
    stream = stream_row(topic)

    def sink(row: dict[str, Any]) -> None:
        rows.append(row)
        if stream is not None:
            stream(row)

    JobDriver(job, run, statuses, worker_cache_dir(shared_out), sink, worker_output_log(shared_out)).run()
    return JobResult(job.spec.instance, rows, socket.gethostname(), os.getpid(), time.perf_counter() - t0)


# ---------------------------------------------------------------------------
# The client side
# ---------------------------------------------------------------------------


@dataclass
class DaskRunReport:
    """Book-keeping of one distributed run."""

    jobs_submitted: int = 0
    rows_stored: int = 0
    duplicates_dropped: int = 0
    killed_jobs: list[str] = field(default_factory=list)  # instances whose worker died too often
    failed_jobs: list[str] = field(default_factory=list)  # instances whose task raised
    workers: int = 0
    hosts: dict[str, int] = field(default_factory=dict)  # host -> rows computed there
    worker_pids: set[int] = field(default_factory=set)  # worker processes that returned a job
    streamed_rows: int = 0  # rows stored as they finished (before their job returned)
    job_seconds: list[float] = field(default_factory=list)  # wall time of each returned job on its worker


#: The protocol of a scheduler address that names none (as Dask reads one).
DEFAULT_PROTOCOL = "tcp"
#: The protocol whose addresses are names within one process, not HOST:PORT.
IN_PROCESS = "inproc"


def check_scheduler_address(address: object) -> str:
    """``address`` (stripped) when it has the form of a Dask scheduler's address:
    [PROTOCOL://]HOST:PORT with a protocol Dask has (``DEFAULT_PROTOCOL`` where none is
    named) and a port in 1..65535, or ``inproc://NAME``; else a one-line
    ``ProblemInputError`` naming it.  Contacts nothing (reaching it is ``connect``'s)."""
    usage = f"--scheduler needs a Dask scheduler address such as tcp://host:8786, got {address!r}"
    if not isinstance(address, str) or not address.strip():
        raise ProblemInputError(usage)
    try:
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import backends
    except ImportError:
        raise ProblemInputError("--scheduler needs dask.distributed, which is not installed here") from None
    text = address.strip()
    try:
        protocol, location = parse_address(text if "://" in text else f"{DEFAULT_PROTOCOL}://{text}")
        if protocol not in backends:
            raise ValueError(f"no Dask protocol {protocol!r} (known: {', '.join(sorted(backends))})")
        if protocol == IN_PROCESS and not location:
            raise ValueError("inproc:// needs a name")
        if protocol != IN_PROCESS and not _is_host_port(location, parse_host_port):
            raise ValueError(f"{location!r} is not HOST:PORT with a port in 1..65535")
    except (ValueError, TypeError) as exc:
        raise ProblemInputError(f"{usage}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    return text


def _is_host_port(location: str, parse: Callable[[str], tuple[str, Any]]) -> bool:
    """Whether ``location`` is HOST:PORT (read by Dask's ``parse``) with a port in 1..65535."""
    try:
        host, port = parse(location)
        return bool(host) and 1 <= int(port) <= 65535
    except (ValueError, TypeError):
        return False


def connect(client_or_address: "Client | str") -> tuple["Client", bool]:
    """A Client for an address (owned: close it when done; its form checked first,
    ``check_scheduler_address``) or the given Client."""
    from distributed import Client

    if isinstance(client_or_address, Client):
        return client_or_address, False
    return Client(check_scheduler_address(client_or_address), timeout="30s"), True


def start_local_cluster(n_workers: int = 2, threads_per_worker: int = 1, allowed_failures: int | None = None,
                        **kw: Any) -> Any:
    """A Dask ``LocalCluster`` of worker *processes* set up for contactbench (tests,
    benchmarks, a laptop): one thread each, BLAS/FFT limited, ``allowed_failures``
    worker deaths tolerated per task before ``KilledWorker`` (None: Dask's default, 3)."""
    import dask
    from distributed import LocalCluster

    settings: dict[str, Any] = {"distributed.worker.daemon": False}
    if allowed_failures is not None:
        settings["distributed.scheduler.allowed-failures"] = int(allowed_failures)
    with dask.config.set(settings):
        return LocalCluster(n_workers=n_workers, threads_per_worker=threads_per_worker, processes=True,
                            dashboard_address=kw.pop("dashboard_address", None), env=dict(WORKER_ENV), **kw)


def solver_import_specs(solvers: Sequence[str] | str | None) -> tuple[str, ...]:
    """The ``module:NAME`` entries of a --solvers list (workers must load them)."""
    if isinstance(solvers, str):
        solvers = solvers.split(",")
    return tuple(s.strip() for s in (solvers or ()) if ":" in s)


def missing_cells_of(job: InstanceJob, run: RunConfig, statuses: dict[str, str]) -> dict[str, str]:
    """The statuses of this job's stored cells (what the worker must not redo)."""
    return {c: statuses[c] for c in job_cell_ids(job, run) if c in statuses}


def lost_job_rows(job: InstanceJob, run: RunConfig, statuses: dict[str, str], status: str,
                  why: str) -> list[dict[str, Any]]:
    """Rows marking every missing cell of a job that never came back (``crashed`` when
    its worker died too often, ``failed`` when the task raised), built by the job's own
    row factory (``harness.run.rows``) so they carry the full schema."""
    runner = JobDriver(job, run, statuses, Path(tempfile.gettempdir()), lambda row: None)
    rows = []
    for k in range(job.steps_hint):
        for v, prof, reps in runner.missing(k):
            rows += [runner.row(None, k, v, prof, r, status=status, error=why[-2000:]) for r in reps]
    return rows


def store_rows(store: ResultStore, rows: Iterable[dict[str, Any]], report: DaskRunReport,
               on_row: Callable[[dict[str, Any]], None] | None = None) -> int:
    """Append rows whose cell is not stored yet; count the duplicates dropped."""
    n = 0
    for row in rows:
        if str(row["cell_id"]) in store:
            report.duplicates_dropped += 1
            continue
        store.append(row)
        n += 1
        report.rows_stored += 1
        host = str(row.get("host") or "")
        report.hosts[host] = report.hosts.get(host, 0) + 1
        if on_row is not None:
            on_row(row)
    return n


def dask_run_config(run: RunConfig) -> RunConfig:
    """The run configuration a worker uses: one job at a time per worker thread, BLAS/FFT
    threads per worker as asked (default 1)."""
    return replace(run, jobs=1, threads_per_worker=run.threads_per_worker or 1)


def run_jobs_on_dask(jobs: Sequence[InstanceJob], client_or_address: "Client | str", store: ResultStore,
                     run: RunConfig, solver_specs: tuple[str, ...] = (), shared_out: bool = True,
                     on_row: Callable[[dict[str, Any]], None] | None = None, poll_s: float = 0.2) -> DaskRunReport:
    """Run the missing cells of ``jobs`` on a Dask cluster, storing rows as they finish.

    One task per job with missing cells.  Rows are streamed back as worker events and
    stored at once; the job's return value carries them again (duplicates are dropped).
    The scheduler re-runs a task whose worker died (up to its ``allowed-failures``),
    after which the job's still-missing cells are stored as ``crashed``; a task that
    raised has them stored as ``failed``.  No cell is stored twice."""
    from distributed import as_completed

    client, owned = connect(client_or_address)
    report = DaskRunReport()
    wrun = dask_run_config(run)
    statuses = store.done_statuses()
    inbox: "queue.SimpleQueue[str]" = queue.SimpleQueue()
    topic = f"contactbench-rows-{uuid.uuid4().hex}"
    futures: dict[Any, InstanceJob] = {}

    def drain() -> None:
        rows = []
        while True:
            try:
                rows.append(json.loads(inbox.get_nowait()))
            except queue.Empty:
                break
        report.streamed_rows += store_rows(store, rows, report, on_row)

    try:
        client.subscribe_topic(topic, lambda event: inbox.put(event[1]))
        report.workers = len(client.scheduler_info().get("workers", {}))
        out = str(store.out.resolve()) if shared_out else None
        for job in jobs:
            done = missing_cells_of(job, wrun, statuses)
            if len(done) == job.n_cells(wrun.repeats):
                continue
            fut = client.submit(run_job_on_worker, job, wrun, done, solver_specs, out, topic, pure=False,
                                key=f"contactbench-{job.spec.scene}-{job.spec.instance}-{uuid.uuid4().hex[:8]}")
            futures[fut] = job
            report.jobs_submitted += 1
        pending = as_completed(list(futures))
        while not pending.is_empty():
            batch = pending.next_batch(block=False)
            drain()
            if not batch:
                time.sleep(poll_s)
                continue
            for fut in batch:
                job = futures.pop(fut)
                store_rows(store, job_rows(fut, job, wrun, store, report), report, on_row)
        drain()
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
    finally:
        try:
            client.unsubscribe_topic(topic)
        except Exception:  # pragma: no cover - the client is already closing
            pass
        if owned:
            client.close()
    return report


def job_rows(fut: Any, job: InstanceJob, run: RunConfig, store: ResultStore, report: DaskRunReport) -> list[dict[str, Any]]:
    """The rows a finished task stands for: its own rows, or -- when its worker died too
    often (KilledWorker) or it raised -- rows marking its missing cells crashed / failed."""
    from distributed.scheduler import KilledWorker

    try:
        result: JobResult = fut.result()
    except KilledWorker as exc:
        report.killed_jobs.append(job.spec.instance)
        why = (f"the Dask worker running this instance died on every attempt ({exc}); "
               "the cells not finished by then are marked crashed")
        log.warning("%s: %s", job.spec.instance, why)
        return lost_job_rows(job, run, store.done_statuses(), "crashed", why)
    except Exception as exc:  # the task itself raised (scene import error, ...)
        report.failed_jobs.append(job.spec.instance)
        why = f"the Dask task raised {type(exc).__name__}: {exc}"
        log.warning("%s: %s", job.spec.instance, why)
        return lost_job_rows(job, run, store.done_statuses(), "failed", why)
    report.worker_pids.add(result.pid)
    report.job_seconds.append(result.elapsed_s)
    return result.rows


@dataclass
class DaskExecutor:
    """The executor (``harness.run.executors``) that sends jobs to a Dask scheduler: an
    address (tcp://host:8786) or a ``distributed.Client``.  ``solver_specs`` are the
    ``module:NAME`` solvers each worker must load."""

    scheduler: "Client | str"
    solver_specs: tuple[str, ...] = ()
    report: DaskRunReport | None = None
    client: "Client | None" = None  # (the scheduler's, once ``connect`` has contacted it)
    owns_client: bool = False

    def connect(self) -> None:
        """Contact the scheduler (a Client for an address; a Client given is used as it
        is): a run calls this once its checks have passed, before it writes anything, so an
        address it cannot reach leaves nothing behind."""
        if self.client is None:
            self.client, self.owns_client = connect(self.scheduler)

    def close(self) -> None:
        """Close the Client ``connect`` made for an address (a Client given stays open)."""
        if self.client is not None and self.owns_client:
            self.client.close()
        self.client, self.owns_client = None, False

    def run_config(self, run: RunConfig) -> RunConfig:
        return dask_run_config(run)

    def describe(self) -> dict[str, Any]:
        s = self.scheduler
        address = s if isinstance(s, str) else getattr(getattr(s, "scheduler", None), "address", "")
        return {"kind": "dask", "scheduler": str(address or "")}

    def execute(self, jobs: Sequence[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str],
                progress: Progress, verbose: bool = False) -> None:
        report = run_jobs_on_dask(jobs, self.client if self.client is not None else self.scheduler, store, run,
                                  self.solver_specs, on_row=lambda row: progress.update(1))
        self.report = report
        log.info("dask: %d jobs on %d workers, %d rows stored (%d duplicates dropped), hosts %s%s",
                 report.jobs_submitted, report.workers, report.rows_stored, report.duplicates_dropped, report.hosts,
                 f", killed: {report.killed_jobs}" if report.killed_jobs else "")


def run_benchmark_on_dask(scenes: Sequence[str], cfg: SceneConfig | None = None,
                          solvers: Sequence[str] | str | None = None, run: RunConfig | None = None,
                          out_dir: str | os.PathLike[str] = "results/run", scheduler: "Client | str" = "",
                          command: list[str] | None = None, append: bool = False) -> RunSummary:
    """``run_benchmark`` with the cells sent to a Dask scheduler (meta.json records the
    scheduler).  An address is checked for its form first (``check_scheduler_address``);
    the plan and the results folder come next, so bad scene options are refused as from
    the command line (``ProblemInputError``) before the scheduler is contacted; the
    scheduler is contacted before the folder is written (``DaskExecutor.connect``), so one
    that cannot be reached leaves nothing there."""
    if isinstance(scheduler, str):
        scheduler = check_scheduler_address(scheduler)
    executor = DaskExecutor(scheduler, solver_import_specs(solvers))
    try:
        return run_benchmark(scenes, cfg, solvers, run, out_dir, command=command, executor=executor, append=append,
                             ready=executor.connect)
    finally:
        executor.close()
