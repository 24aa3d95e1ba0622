"""Safe by default: one writer per results folder, plausible units of a
measured surface, big solves paid once, and a pytest-benchmark item that fails a wrong
answer claimed as converged."""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import read_meta
from contactbench.harness.run.isolation import SCRATCH_PREFIX, ChildProcess, scratch_owner
from contactbench.harness.run.plan import PlanError, RunConfig, plan_run
from contactbench.harness import run_benchmark
from contactbench.harness.table.store import (LOCK_FILE, FolderInUseError, RunLock, load_table, read_run_folder,
                                              write_table)
from contactbench.problems.scenes import SceneConfig
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.problems.units import (
    ImplausibleUnitsError,
    UnitFigures,
    check_plausible_units,
    probable_unit,
)
from contactbench.solvers import Outcome, SolveContext, register, unregister
from contactbench.solvers.registry import get_solver
from tests.helpers import REPO


def child_env(*paths: Path, **extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*map(str, paths), str(REPO), env.get("PYTHONPATH", "")])
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", CONTACTBENCH_FFT_WORKERS="1", CI="true", **extra)
    return env


# ---------------------------------------------------------------------------
# 1. One writer per results folder
# ---------------------------------------------------------------------------

BLOCKING_SOLVER = '''
import os, time
import numpy as np
from contactbench.solvers import Capabilities, Outcome, Solver

class Blocking(Solver):
    """Waits until the test creates the release file (at most 60 s), then gives up honestly."""
    name = "test-blocking"
    family = "test"
    capabilities = Capabilities()

    def iterate(self, ctx):
        deadline = time.monotonic() + 60
        while not os.path.exists({release!r}) and time.monotonic() < deadline:
            time.sleep(0.05)
        return Outcome(np.zeros(ctx.n), 1, False, "released")
'''


def test_a_live_lock_is_the_reason_before_the_run_has_written_its_marker(tmp_path: Path) -> None:
    """The window between a run taking its folder's lock and writing its marker: the folder
    holds the lock and other files but no marker.  A second run is told the folder is in
    use (naming the holder), not that it is foreign; once the lock is free, it is foreign."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "_cache").mkdir()
    holder = {"pid": os.getpid(), "host": socket.gethostname(), "started": "now", "started_epoch": 0.0, "command": ""}
    fd = os.open(out / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # another open file description: as another process
        os.write(fd, json.dumps(holder).encode())
        with pytest.raises(FolderInUseError, match=f"in use by another run: PID {os.getpid()} on host"):
            read_run_folder(out, lambda config: config)
        assert sorted(p.name for p in out.iterdir()) == ["_cache", LOCK_FILE]  # nothing written
    finally:
        os.close(fd)  # the lock is released with its descriptor
    with pytest.raises(Exception, match="is not a contactbench run folder"):
        read_run_folder(out, lambda config: config)


@pytest.mark.slow
def test_a_second_run_into_a_live_folder_exits_2_naming_the_first(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    release = tmp_path / "release"
    (tmp_path / "blocking_solver.py").write_text(BLOCKING_SOLVER.format(release=str(release)))
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "run"
    args = ["run", "counterexample", "--size", "3", "--seeds", "0", "--solvers", "blocking_solver:Blocking",
            "--reference", "none", "--no-warmup", "--no-progress", "--out", str(out)]
    first = subprocess.Popen([sys.executable, "-m", "contactbench.harness.cli", *args], env=child_env(tmp_path),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and first.poll() is None and not (out / LOCK_FILE).exists():
            time.sleep(0.05)
        assert first.poll() is None, first.communicate()
        capsys.readouterr()
        assert cli.main(args) == 2  # the second run, while the first is solving
        err = capsys.readouterr().err
        assert f"PID {first.pid} on host {socket.gethostname()}" in err and "in use by another run" in err
        assert not (out / "rows.jsonl").exists() or (out / "rows.jsonl").read_text().count("\n") == 0
    finally:
        release.touch()
        stdout, stderr = first.communicate(timeout=180)
    assert first.returncode == 0, stderr
    table = load_table(out)
    assert len(table) == 1 and (out / "rows.jsonl").read_text().count("\n") == 1  # the work was done once
    assert not (out / LOCK_FILE).exists()  # released at the end


def test_a_lock_left_by_a_dead_process_is_taken_over_with_a_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "run"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(),
                                             "started": "2020-01-01T00:00:00+00:00", "started_epoch": 1.6e9}))
    caplog.set_level("WARNING", logger="contactbench")
    rc = cli.main(["run", "counterexample", "--size", "3", "--seeds", "0", "--solvers", "scipy-nnls",
                   "--reference", "none", "--no-warmup", "--no-progress", "--out", str(out)])
    assert rc == 0
    assert f"taking over the lock of results folder {out} left by PID {dead.pid}" in caplog.text
    assert len(load_table(out)) == 1 and not (out / LOCK_FILE).exists()


def test_a_lock_of_a_live_process_or_another_host_is_refused(tmp_path: Path) -> None:
    lock = tmp_path / LOCK_FILE
    lock.write_text(json.dumps({"pid": os.getppid(), "host": socket.gethostname(), "started": "now",
                                "started_epoch": time.time()}))
    with pytest.raises(FolderInUseError, match=f"PID {os.getppid()} on host"):
        RunLock(tmp_path).acquire()
    lock.write_text(json.dumps({"pid": 1234, "host": "elsewhere.example", "started": "now"}))
    with pytest.raises(FolderInUseError, match="cannot be checked from this host"):
        RunLock(tmp_path).acquire()
    assert lock.exists()  # a refused run leaves the other's lock alone
    with RunLock(tmp_path / "fresh") as held:  # and a held lock refuses a second holder in this process too
        assert json.loads((tmp_path / "fresh" / LOCK_FILE).read_text())["pid"] == os.getpid()
        with pytest.raises(FolderInUseError, match=f"PID {os.getpid()}"):
            RunLock(tmp_path / "fresh").acquire()
        assert held.fd is not None
    assert not (tmp_path / "fresh").exists()  # created by the lock, left empty: removed


def test_concurrent_table_writers_never_share_a_temporary_file(tmp_path: Path) -> None:
    table = pd.DataFrame({"a": np.arange(2000), "b": np.linspace(0, 1, 2000)})
    errors: list[BaseException] = []

    def write_many() -> None:
        try:
            for _ in range(15):
                write_table(table, tmp_path)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=write_many) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert len(pd.read_parquet(tmp_path / "results.parquet")) == 2000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv", "results.parquet"]  # no temporaries left


# ---------------------------------------------------------------------------
# 2. Plausible units
# ---------------------------------------------------------------------------


def micrometre_map(path: Path) -> Path:
    """An RMD surface (rms 1 um on a 100 um side) saved in micrometres, as an instrument would."""
    surface = rmd_surface_n(33, 0.7, length=1e-4, rms_height=1e-6, seed=3)
    np.save(path, surface.heights * 1e6)
    return path


def test_a_micrometre_map_given_as_metres_exits_2_and_runs_with_height_unit_um(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    surface = micrometre_map(tmp_path / "um.npy")
    base = ["run", "paper-sweep", "--surface", str(surface), "--length", "1e-4", "--steps", "1",
            "--solvers", "fast-dual-pccg", "--reference", "none", "--no-progress"]
    bad = tmp_path / "as-metres"
    assert cli.main([*base, "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "rms slope" in err and "heights look like micrometres given as metres" in err
    assert "--height-unit um" in err
    assert not bad.exists()  # refused while planning: nothing written
    good = tmp_path / "as-um"
    assert cli.main([*base, "--height-unit", "um", "--out", str(good)]) == 0
    df = load_table(good)
    assert list(df["status"]) == ["solved"]
    assert read_meta(good)["config"]["scene_config"]["extra"]["height_unit"] == "um"


def test_allow_steep_overrides_the_check_and_is_recorded(tmp_path: Path) -> None:
    surface = micrometre_map(tmp_path / "um.npy")
    cfg = SceneConfig(surface_path=str(surface), length=1e-4, steps=1)
    with pytest.raises(PlanError, match="rms slope"):
        plan_run(["paper-sweep"], cfg, ["fast-dual-pccg"])
    steep = SceneConfig(surface_path=str(surface), length=1e-4, steps=1, extra={"allow_steep": True})
    assert len(plan_run(["paper-sweep"], steep, ["fast-dual-pccg"]).jobs) == 1


def test_a_height_unit_is_refused_where_a_scene_would_not_apply_it(tmp_path: Path) -> None:
    surface = micrometre_map(tmp_path / "um.npy")
    cfg = SceneConfig(surface_path=str(surface), length=1e-4, steps=1, extra={"height_unit": "um"})
    assert len(plan_run(["paper-sweep"], cfg, ["fast-dual-pccg"]).jobs) == 1
    with pytest.raises(PlanError, match="scene 'cmr-cutoff' does not take --height-unit"):  # as the CLI says
        plan_run(["cmr-cutoff"], cfg, ["nnls"])


def test_the_probable_unit_is_the_largest_that_makes_the_surface_plausible() -> None:
    assert probable_unit(UnitFigures(2.0e4, 5e-2, 1e-4)) == "um"  # um as m
    assert probable_unit(UnitFigures(3.0e2, 1e-3, 1e-2)) == "mm"  # mm as m
    assert probable_unit(UnitFigures(50.0, 1e-6, 1e-4), "um") == "nm"  # nm as um
    assert probable_unit(UnitFigures(1e12, 1.0, 1e-6)) is None  # no unit helps: the length is wrong
    flat = Surface(np.zeros((4, 4)) + np.eye(4) * 1e-9, 1e-6)
    assert check_plausible_units(flat).rms_slope < 1
    tall = Surface(np.eye(8) * 1.0, 1.0)  # slope ~0.5 but heights as tall as the side's eighth: fine
    assert check_plausible_units(tall).plausible
    with pytest.raises(ImplausibleUnitsError, match="height range .* exceeds the side length"):
        check_plausible_units(Surface(np.eye(8) * 100.0, 10.0))


# ---------------------------------------------------------------------------
# 3. Big solves paid once
# ---------------------------------------------------------------------------

COUNT_ENV = "CONTACTBENCH_TEST_SOLVE_LOG"
FastDualPCCG = type(get_solver("fast-dual-pccg"))


class CountingPCCG(FastDualPCCG):  # type: ignore[misc, valid-type]
    """fast-dual-pccg that writes one line per solve to $CONTACTBENCH_TEST_SOLVE_LOG and
    declares a time model of ``predicted`` seconds."""

    name = "test-counting-pccg"
    predicted = 30.0

    def iterate(self, ctx: SolveContext) -> Outcome:
        if os.environ.get(COUNT_ENV):
            with open(os.environ[COUNT_ENV], "a", encoding="utf-8") as fh:
                fh.write(self.name + "\n")
        return super().iterate(ctx)

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return self.predicted


class QuickCountingPCCG(CountingPCCG):
    name = "test-counting-pccg-quick"
    predicted = 0.01


class SloppyExact(CountingPCCG):
    """Declared exact, but its answer is 1 % off: it cannot serve as the reference."""

    name = "test-sloppy-exact"
    predicted = 0.01

    def iterate(self, ctx: SolveContext) -> Outcome:
        out = super().iterate(ctx)
        return Outcome(out.p * 1.01, out.iterations, True, "claims convergence")


@pytest.fixture
def counting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    log = tmp_path / "solves.log"
    monkeypatch.setenv(COUNT_ENV, str(log))
    for cls in (CountingPCCG, QuickCountingPCCG, SloppyExact):
        register(cls, replace=True)
    yield log
    for cls in (CountingPCCG, QuickCountingPCCG, SloppyExact):
        unregister(cls.name)


def solve_count(log: Path) -> dict[str, int]:
    names = log.read_text().split() if log.exists() else []
    return {n: names.count(n) for n in set(names)}


def cold_top_step(out: Path, solvers: list[str], size: int = 128) -> pd.DataFrame:
    run_benchmark(["paper-sweep"], SceneConfig(size=size, steps=1), solvers, RunConfig(warm=False, progress=False),
                  out, command=["pytest"])
    return load_table(out)


@pytest.mark.slow
def test_a_big_cold_top_step_is_solved_once_no_warm_up_no_second_reference(tmp_path: Path, counting: Path) -> None:
    # 128^2 stands in for 1024^2: the solver's time model says 30 s, which is what
    # decides (harness/run/job.py predicted_seconds), and the suite stays fast.
    df = cold_top_step(tmp_path / "big", ["test-counting-pccg"])
    assert solve_count(counting) == {"test-counting-pccg": 1}  # no warm-up, no reference solve
    row = df.iloc[0]
    assert row["status"] == "solved" and row["reference_solver"] == "test-counting-pccg@default"
    said = re.search(r"no warm-up solve: predicted ([0-9.]+) s > 5 s", row["warmup"])
    assert said and 20.0 <= float(said.group(1)) <= 45.0, row["warmup"]  # the 30 s model on this step's own grid
    assert row["p_rel_error"] == 0.0
    refs = sorted(p.name for p in (tmp_path / "big" / "_cache").glob("ref-*.npz"))
    assert len(refs) == 1 and "test-counting-pccg_default" in refs[0]  # no other reference was solved
    # a rerun finds everything stored: nothing is solved again
    cold_top_step(tmp_path / "big", ["test-counting-pccg"])
    assert solve_count(counting) == {"test-counting-pccg": 1}


class CountingFast(CountingPCCG):
    """fast-dual-pccg's own time model, counted."""

    name = "test-counting-fast"

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return FastDualPCCG.time_estimate(self, n, operator_kind)


@pytest.mark.slow
def test_the_warm_up_is_decided_on_the_steps_own_grid(tmp_path: Path, counting: Path) -> None:
    """The warm-up is decided on the problem's estimate (the skip policy's
    ``problem_time_estimate``), not the model's typical trial set: on a periodic 512^2
    grid (n = 262,144, a product costs that grid unpadded) a warm-up limit below the typical
    set's estimate still keeps the warm-up, so the first timed solve does not hold the
    one-time costs."""
    typical = get_solver("fast-dual-pccg").time_estimate(512 * 512, "fft")
    register(CountingFast, replace=True)
    try:
        run_benchmark(["paper-sweep"], SceneConfig(size=512, steps=1, periodic=True, kernel="spectral"),
                      ["test-counting-fast"],
                      RunConfig(warm=False, progress=False, reference="none", warmup_limit=typical / 2),
                      tmp_path / "o", command=["pytest"])
    finally:
        unregister(CountingFast.name)
    row = load_table(tmp_path / "o").iloc[0]
    assert row["status"] == "solved" and row["warmup"] == ""
    assert solve_count(counting) == {"test-counting-fast": 2}  # the warm-up and the timed solve


def test_a_quick_solve_keeps_its_warm_up_and_still_serves_as_the_reference(tmp_path: Path, counting: Path) -> None:
    df = cold_top_step(tmp_path / "quick", ["test-counting-pccg-quick"], size=32)
    assert solve_count(counting) == {"test-counting-pccg-quick": 2}  # the warm-up and the timed solve
    assert df.iloc[0]["error"] == "" and df.iloc[0]["reference_solver"] == "test-counting-pccg-quick@default"


def test_an_exact_solver_whose_answer_fails_does_not_serve(tmp_path: Path, counting: Path) -> None:
    run = ["test-sloppy-exact", "test-counting-pccg-quick"]
    df = cold_top_step(tmp_path / "sloppy", run, size=16).set_index("solver")
    assert solve_count(counting) == {"test-sloppy-exact": 2, "test-counting-pccg-quick": 2}  # warm-up + solve each
    # the first exact solver of the run was the sloppy one: its answer failed the judge, so
    # the next exact solver's answer served, and no reference was solved separately
    assert df.loc["test-sloppy-exact", "status"] == "inaccurate"
    assert df.loc["test-sloppy-exact", "reference_solver"] == "" and np.isnan(df.loc["test-sloppy-exact", "p_rel_error"])
    assert df.loc["test-counting-pccg-quick", "status"] == "solved"
    assert df.loc["test-counting-pccg-quick", "reference_solver"] == "test-counting-pccg-quick@default"
    assert [p.name.startswith("ref-") and "quick" in p.name for p in (tmp_path / "sloppy" / "_cache").iterdir()] == [True]
    # with a solver left that is not exact, the reference is solved from the candidates for it
    df = cold_top_step(tmp_path / "greedy", ["test-sloppy-exact", "greedy-cg"], size=16).set_index("solver")
    assert df.loc["greedy-cg", "reference_solver"] in ("scipy-nnls", "nnls", "pk")
    assert np.isfinite(df.loc["greedy-cg", "p_rel_error"])
    # and with nothing left to judge, no reference is solved at all
    cold_top_step(tmp_path / "alone", ["test-sloppy-exact"], size=16)
    assert not list((tmp_path / "alone" / "_cache").glob("ref-*"))


# ---------------------------------------------------------------------------
# 4. The pytest-benchmark path fails a wrong answer
# ---------------------------------------------------------------------------

BENCH_PLUGIN = '''
import numpy as np
from contactbench.solvers import Capabilities, Outcome, Solver, register


@register(replace=True)
class Liar(Solver):
    """Returns p = 0 and claims convergence: a wrong answer."""
    name = "test-liar"
    family = "test"
    capabilities = Capabilities()

    def iterate(self, ctx):
        return Outcome(np.zeros(ctx.n), 1, True, "converged")


@register(replace=True)
class Honest(Solver):
    """Returns p = 0 and says it did not converge."""
    name = "test-honest"
    family = "test"
    capabilities = Capabilities()

    def iterate(self, ctx):
        return Outcome(np.zeros(ctx.n), 1, False, "gave up after one iteration")
'''


@pytest.mark.slow
def test_the_benchmark_fails_a_wrong_answer_claimed_as_converged(tmp_path: Path) -> None:
    (tmp_path / "bench_liars.py").write_text(BENCH_PLUGIN)
    bench = "benchmarks/test_bench_solvers.py::test_solver"
    items = [f"{bench}[{solver}-{inst}]" for solver in ("test-liar", "test-honest", "scipy-nnls")
             for inst in ("rmd-32-top", "counterexample-100-s1")]
    cmd = [sys.executable, "-m", "pytest", "-p", "bench_liars", "--benchmark-only", "--benchmark-enable",
           "-p", "no:cacheprovider", "-q", "-rfx", *items]
    done = subprocess.run(cmd, cwd=REPO, env=child_env(tmp_path, CONTACTBENCH_BENCH_ROUNDS="1"),
                          capture_output=True, text=True, timeout=300)
    text = done.stdout + done.stderr
    assert done.returncode == 1, text  # a failure
    failed = [line for line in text.splitlines() if line.startswith("FAILED")]
    assert failed and all("test-liar" in line for line in failed), text
    assert "claims convergence but the judge reads the answer as wrong" in text and "kkt_error" in text
    xfailed = [line for line in text.splitlines() if line.startswith("XFAIL")]
    assert xfailed and all("test-honest" in line for line in xfailed), text
    assert "2 failed, 2 passed" in text and "2 xfailed" in text  # scipy-nnls passes on both


def _leave_a_file(_msg: object) -> str:
    """A worker's handler: a file left in its temporary folder, as a killed solve leaves one."""
    fd, path = tempfile.mkstemp(prefix="left-")
    os.close(fd)
    return path


def test_a_workers_temporary_files_go_with_it() -> None:
    """A worker (and what it runs) keeps its temporary files in a folder of its own, which
    the parent removes when the worker ends -- killed or closed."""
    for end in ("kill", "close"):
        child = ChildProcess(lambda: _leave_a_file)
        reply = child.call("go", 30.0)
        assert reply.ok, reply
        left = Path(reply.value)
        assert left.is_file() and left.parent == Path(str(child.scratch))
        getattr(child, end)()
        assert not left.parent.exists(), end


def test_a_killed_owners_worker_folder_is_removed_by_the_next_worker() -> None:
    """The owner of a worker killed before it could remove the worker's temporary folder (a
    pool job killed at Ctrl-C, a runner killed by kill -9): the next worker started on the
    machine removes it, and leaves those of living owners."""
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    tmp = Path(tempfile.gettempdir())
    dead = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{scratch_owner(gone.pid)}-", dir=tmp))
    (dead / "problem.f64").write_bytes(b"left behind")
    alive = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{scratch_owner()}-", dir=tmp))
    # another pid namespace's (a container sharing the folder): its pid means nothing here
    other = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}1{scratch_owner(gone.pid)}-", dir=tmp))
    try:
        child = ChildProcess(lambda: _leave_a_file)
        assert child.call("go", 30.0).ok
        child.close()
        assert not dead.exists() and alive.is_dir() and other.is_dir()
    finally:
        for d in (dead, alive, other):
            shutil.rmtree(d, ignore_errors=True)


def test_a_pool_never_has_more_processes_than_jobs_and_too_many_is_warned(caplog: pytest.LogCaptureFixture) -> None:
    """--jobs 100000 on four instance jobs starts four processes (a pool starts every worker
    at once), with a warning that --jobs is above the machine's CPUs; one job runs serially;
    --threads above the CPUs is warned too."""
    from contactbench.harness.run.executors import PoolExecutor, SerialExecutor, local_executor
    from contactbench.harness.run.plan import RunConfig
    from contactbench.problems.fft_threads import MAX_THREADS

    pool = local_executor(RunConfig(jobs=100_000), 4)
    assert isinstance(pool, PoolExecutor) and pool.workers == 4 and pool.describe()["workers"] == 4
    assert "--jobs 100000 is above the" in caplog.text
    assert isinstance(local_executor(RunConfig(jobs=100_000), 1), SerialExecutor)
    caplog.clear()
    assert local_executor(RunConfig(jobs=2), 9).workers == 2  # type: ignore[attr-defined]
    assert "above the" not in caplog.text or (os.cpu_count() or 1) < 2
    local_executor(RunConfig(threads_per_worker=MAX_THREADS), 1)  # (the most --threads takes)
    assert f"--threads {MAX_THREADS} is above the" in caplog.text or (os.cpu_count() or 1) >= MAX_THREADS
