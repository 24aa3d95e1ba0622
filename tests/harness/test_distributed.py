"""The Dask executor (harness/run/distributed.py) on a real LocalCluster: 2 worker
processes, 1 thread each.  A small population runs on the cluster and serially, and the
two tables agree row for row; a worker killed mid-run (once, or on every attempt) costs
no row: the cell is re-run by Dask or stored as ``crashed``.

The killer solvers below run inside the runner's isolated child of a Dask worker and
SIGKILL their parent -- the Dask worker process itself -- as an OOM killer or a lost
node would."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("distributed")

from distributed import Client  # noqa: E402

from contactbench.harness.run import isolation  # noqa: E402
from contactbench.harness.run.distributed import lost_job_rows, run_benchmark_on_dask, run_jobs_on_dask, start_local_cluster  # noqa: E402
from contactbench.harness.run.plan import RunConfig, plan_run  # noqa: E402
from contactbench.harness import run_benchmark  # noqa: E402
from contactbench.harness.table.schema import STATUSES  # noqa: E402
from contactbench.harness.table.store import ResultStore, load_table  # noqa: E402
from contactbench.problems.instances import QP  # noqa: E402
from contactbench.problems.scenes import SceneConfig  # noqa: E402
from contactbench.solvers.base import Capabilities, Outcome, SolveContext, Solver, SolverSettings  # noqa: E402
from contactbench.solvers.registry import get_solver  # noqa: E402

MARKER_ENV = "CONTACTBENCH_TEST_KILL_DIR"
SOLVER = "fast-ccg"  # exact, matrix-free, warm-startable
POPULATION = SceneConfig(size=32, steps=2, seeds=(0, 1, 2), extra={"hursts": (0.5, 0.9)})  # 6 surfaces
SMALL = SceneConfig(size=16, steps=2, seeds=(0, 1), extra={"hursts": (0.7,)})  # 2 surfaces
RUN = RunConfig(reference="none", warmup=False, progress=False, timeout=60.0)


def seed_of(qp: QP) -> int | None:
    geom = qp.geometry
    return None if geom is None or geom.surface is None else geom.surface.meta.get("seed")


def kill_dask_worker(after_s: float = 0.0) -> None:
    """SIGKILL the process that started this isolated solve process: the Dask worker
    (after ``after_s`` seconds of "solving")."""
    time.sleep(after_s)
    assert isolation.STARTED_BY is not None
    os.kill(isolation.STARTED_BY, signal.SIGKILL)
    time.sleep(30)  # PR_SET_PDEATHSIG ends this process with its parent


def solve_with_base(ctx: SolveContext) -> Outcome:
    """The answer of ``SOLVER`` on the same problem, settings and warm start."""
    res = get_solver(SOLVER).solve(ctx.qp, SolverSettings(tol=ctx.tol, max_iter=ctx.max_iter,
                                                          time_limit=ctx.deadline.remaining()), ctx.warm)
    return Outcome(res.p, res.iterations, res.converged, res.message, w=res.w)


class KillWorkerOnce(Solver):
    """fast-ccg, except that the first solve on surface seed 1 kills the Dask worker."""

    name = "test-kill-worker-once"
    family = "test"
    capabilities = Capabilities(warm_start="primal", exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        if seed_of(ctx.qp) == 1:
            marker = Path(os.environ[MARKER_ENV]) / self.name
            try:
                os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            except FileExistsError:
                pass
            else:
                kill_dask_worker()
        return solve_with_base(ctx)


class KillWorkerAlways(KillWorkerOnce):
    """Kills the Dask worker on every solve of the second load step of surface seed 1."""

    name = "test-kill-worker-always"

    def iterate(self, ctx: SolveContext) -> Outcome:
        if seed_of(ctx.qp) == 1 and ctx.warm is not None:  # step 1 (warm-started from step 0)
            kill_dask_worker(after_s=0.5)  # rows finished before are streamed to the client by then
        return solve_with_base(ctx)


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    os.environ[MARKER_ENV] = str(tmp_path_factory.mktemp("kill-markers"))  # inherited by the workers
    cluster = start_local_cluster(n_workers=2, threads_per_worker=1, allowed_failures=1, silence_logs=40)
    c = Client(cluster)
    try:
        yield c
    finally:
        c.close()
        cluster.close()


def by_cell(df: pd.DataFrame) -> pd.DataFrame:
    return df.set_index("cell_id").sort_index()


def assert_complete(df: pd.DataFrame, n_cells: int) -> None:
    assert len(df) == n_cells and df["cell_id"].is_unique
    assert set(df["status"]) <= set(STATUSES)


@pytest.mark.slow
def test_population_on_dask_matches_the_serial_run_row_for_row(client: Client, tmp_path: Path) -> None:
    run_benchmark(["population"], POPULATION, [SOLVER], RUN, tmp_path / "serial")
    plan = plan_run(["population"], POPULATION, [SOLVER], RUN)
    store = ResultStore(tmp_path / "dask")
    report = run_jobs_on_dask(plan.jobs, client, store, RUN)
    store.finalize()
    serial, dask = by_cell(load_table(tmp_path / "serial")), by_cell(load_table(tmp_path / "dask"))

    assert report.jobs_submitted == 6 and not report.killed_jobs and not report.failed_jobs
    assert os.getpid() not in report.worker_pids and report.worker_pids  # solved on worker processes
    assert report.duplicates_dropped == report.rows_stored == 12  # streamed, then returned again
    assert list(dask.index) == list(serial.index) and len(dask) == 6 * 2
    assert (dask["status"] == "solved").all() and (serial["status"] == "solved").all()
    for col in ("instance", "step", "n", "warm_start", "iterations"):
        assert (dask[col] == serial[col]).all(), col
    for col in ("delta", "load", "contact_fraction", "kkt_error", "dim_load"):
        np.testing.assert_allclose(dask[col].to_numpy(float), serial[col].to_numpy(float), rtol=1e-12, atol=0,
                                   err_msg=col)
    assert (dask["load"] > 0).all() and dask["solve_time_s"].notna().all()

    # resume: nothing left to do, nothing stored twice
    again = run_jobs_on_dask(plan.jobs, client, store, RUN)
    assert again.jobs_submitted == 0 and len(ResultStore(tmp_path / "dask")) == 12


@pytest.mark.slow
def test_a_worker_killed_mid_run_costs_no_row(client: Client, tmp_path: Path) -> None:
    solvers = [SOLVER, f"{__name__}:KillWorkerOnce"]
    summary = run_benchmark_on_dask(["population"], SMALL, solvers, RUN, tmp_path, client, command=["pytest"])
    df = load_table(tmp_path)
    markers = list(Path(os.environ[MARKER_ENV]).glob("test-kill-worker-once"))
    assert markers, "the killer solver never ran"
    assert_complete(df, 2 * 2 * 2)  # 2 surfaces x 2 steps x 2 solvers
    assert (df["status"] == "solved").all(), df[["instance", "solver", "status", "error"]]
    assert summary.rows == 8 and summary.statuses == {"solved": 8}


@pytest.mark.slow
def test_a_worker_that_dies_on_every_attempt_leaves_its_cells_marked_crashed(client: Client, tmp_path: Path) -> None:
    solvers = [SOLVER, f"{__name__}:KillWorkerAlways"]
    plan = plan_run(["population"], SMALL, solvers, RUN)
    store = ResultStore(tmp_path)
    report = run_jobs_on_dask(plan.jobs, client, store, RUN, solver_specs=(f"{__name__}:KillWorkerAlways",))
    df = store.finalize()
    assert_complete(df, 2 * 2 * 2)
    assert report.killed_jobs == ["pop-H0.7-N16-s1-K2"]
    bad = df[df["status"] != "solved"]
    # only the killer's step-1 cell of seed 1 is lost; the cells finished before the
    # worker died were streamed back and kept
    assert set(zip(bad["instance"], bad["solver"], bad["step"], bad["status"])) == {
        ("pop-H0.7-N16-s1-K2", "test-kill-worker-always", 1, "crashed")}
    assert "died on every attempt" in bad.iloc[0]["error"]
    assert (df[df["instance"] == "pop-H0.7-N16-s0-K2"]["status"] == "solved").all()


def test_lost_job_rows_mark_only_the_missing_cells() -> None:
    plan = plan_run(["population"], SMALL, [SOLVER], RUN)
    job = plan.jobs[0]
    rows: list[dict[str, Any]] = lost_job_rows(job, RUN, {}, "crashed", "worker lost")
    assert len(rows) == 2 and {r["status"] for r in rows} == {"crashed"}
    done = {rows[0]["cell_id"]: "solved"}
    again = lost_job_rows(job, RUN, done, "crashed", "worker lost")
    assert [r["cell_id"] for r in again] == [rows[1]["cell_id"]]
    assert again[0]["error"] == "worker lost" and again[0]["scene"] == "population"
