"""Harness core: isolation statuses, skips, warm starts, resume after SIGKILL, the
store, the reference cache and the CLI round trip.  Small grids only (8^2-16^2)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import cli
from contactbench.harness.run.plan import PlanError, RunConfig, make_cell_id, plan_run
from contactbench.harness import run_benchmark
from contactbench.harness.run.sequence import map_by_grid_index
from contactbench.harness.table.schema import ALL_COLUMNS, REQUIRED_COLUMNS, STATUSES
from contactbench.harness.table.store import LOCK_FILE, ROWS_FILE, ResultStore, load_table, read_journal
from contactbench.problems.scenes import SceneConfig
from contactbench.solvers import Capabilities, Outcome, Param, SolveContext, Solver, SolverSettings
from tests import helpers
from tests.helpers import REPO

SOLVER_MODULE = helpers.__name__
SMALL = SceneConfig(size=8, steps=2, seeds=(0,))


def run(tmp: Path, solvers: list[str], cfg: SceneConfig = SMALL, scenes: tuple[str, ...] = ("paper-sweep",),
        append: bool = False, **kw: object) -> pd.DataFrame:
    kw.setdefault("reference", "test-exact")
    kw.setdefault("progress", False)
    run_benchmark(list(scenes), cfg, solvers, RunConfig(**kw), tmp, command=["pytest"],  # type: ignore[arg-type]
                  append=append)
    return load_table(tmp)


def by_solver(df: pd.DataFrame) -> dict[str, set[str]]:
    return {s: set(g["status"]) for s, g in df.groupby("solver")}


def test_crash_hang_and_raise_cost_only_their_own_rows(tmp_path: Path) -> None:
    solvers = ["test-crash", "test-exact", "test-hang", "test-raise", "test-warm-pg"]
    df = run(tmp_path, solvers, timeout=1.0)
    assert len(df) == 2 * len(solvers)  # 2 steps x 5 solvers, every row kept
    assert by_solver(df) == {
        "test-crash": {"crashed"},
        "test-hang": {"timeout", "skipped"},
        "test-raise": {"failed"},
        "test-exact": {"solved"},
        "test-warm-pg": {"solved"},
    }
    hang = df[df.solver == "test-hang"].sort_values("step")
    assert list(hang["status"]) == ["timeout", "skipped"]  # the larger step is predicted too slow
    assert "timed out at step 0" in hang.iloc[1]["skip_reason"]
    assert "; it was at tests/helpers.py:" in hang.iloc[0]["error"] and "in iterate" in hang.iloc[0]["error"]
    crash = df[df.solver == "test-crash"].iloc[0]
    assert "SIGABRT" in crash["error"]
    raised = df[df.solver == "test-raise"].iloc[0]["error"]
    assert "deliberate failure" in raised and "[at tests/helpers.py:" in raised and "in iterate" in raised
    ok = df[df.status == "solved"]
    assert (ok["kkt_error"] <= ok["check_tol"]).all()
    assert (ok["p_rel_error"] < 1e-6).all() and (ok["reference_solver"] == "test-exact").all()
    assert set(df["status"]) <= set(STATUSES)
    assert list(df.columns[: len(ALL_COLUMNS)]) == list(ALL_COLUMNS)
    assert df["cell_id"].is_unique


def test_a_solver_raising_keyboardinterrupt_or_exit_is_a_failed_row_not_a_worker_traceback(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """The worker ignores SIGINT, so a KeyboardInterrupt (or SystemExit, GeneratorExit) there
    is the solver's own: it is the row's error, named with where it was raised; the worker
    printed a traceback and died ("worker exited with code 1") before."""
    df = run(tmp_path, ["test-exact", "test-exit", "test-generator-exit", "test-interrupt"])
    assert by_solver(df) == {"test-exact": {"solved"}, "test-exit": {"failed"}, "test-generator-exit": {"failed"},
                             "test-interrupt": {"failed"}}
    for name, kind in (("test-interrupt", "KeyboardInterrupt"), ("test-exit", "SystemExit: 3"),
                       ("test-generator-exit", "GeneratorExit")):
        assert df[df.solver == name]["error"].str.startswith(kind).all()
        assert df[df.solver == name]["error"].str.contains("tests/helpers.py").all()
    assert "Traceback" not in capfd.readouterr().err


def test_a_solve_aborted_status_set_after_construction_is_a_crashed_row(tmp_path: Path) -> None:
    """A run reads a ``SolveAborted``'s status by the class's own rule, as validate does: a
    status set after construction ("solved") makes a crashed row naming the exception's
    message, never a solved one."""
    df = run(tmp_path, ["test-exact", "test-forged-abort"])
    assert by_solver(df) == {"test-exact": {"solved"}, "test-forged-abort": {"crashed"}}
    assert df[df.solver == "test-forged-abort"]["error"].str.contains("forged status").all()


def test_a_solver_whose_skip_raises_has_failed_rows_not_skips(tmp_path: Path) -> None:
    """A ``skip`` (or a memory or time model) that raises -- sys.exit included -- is a defect
    of the solver: its rows are failed, naming the exception, and the other solvers' rows
    are all there.  They read "skipped" before, as if it were a declared capability; a
    sys.exit in ``skip`` ended the run with exit 0 and rows lost, and a raising time model
    refused the run as bad input."""
    df = run(tmp_path, ["test-exact", "test-buggy-skip", "test-skip-exit", "test-time-raise"])
    assert by_solver(df) == {"test-exact": {"solved"}, "test-buggy-skip": {"failed"}, "test-skip-exit": {"failed"},
                             "test-time-raise": {"failed"}}
    errors = df.groupby("solver")["error"].first()
    assert "skip check failed: RuntimeError: a bug in skip" in errors["test-buggy-skip"]
    assert "skip check failed: SystemExit: 2" in errors["test-skip-exit"]  # it ended the run, rows lost, exit 0
    assert "time model failed: RuntimeError: a bug in the time model" in errors["test-time-raise"]  # bad input


def test_a_reference_candidate_whose_skip_raises_is_named_not_passed_over_silently(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A --reference candidate whose skip check raises serves no reference, and the run says
    so in a warning naming it and the exception; it was passed over without a word, and the
    rows read as if the run had no reference."""
    with caplog.at_level("INFO", logger="contactbench"):
        df = run(tmp_path, ["test-warm-pg"], reference="test-buggy-skip")
    assert set(df["status"]) == {"solved"} and (df["reference_solver"].fillna("") == "").all()
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any("reference test-buggy-skip passed over" in m and "a bug in skip" in m for m in warned), warned


def test_an_error_names_the_dependency_that_raised_it() -> None:
    from scipy.optimize import bisect

    from contactbench.harness.run.isolation import error_text

    try:
        bisect(lambda x: x * x + 1.0, -1.0, 1.0)  # no sign change: raised inside scipy
    except ValueError as exc:
        text = error_text(exc)
    assert text.startswith("ValueError: f(a) and f(b) must have different signs [at scipy/optimize/")
    assert "<- harness/test_harness.py:" in text and "\n" not in text  # and who called it


def test_skips_are_recorded_with_reasons_and_not_attempted(tmp_path: Path) -> None:
    cfg = SceneConfig(size=16, steps=3, seeds=(0,))
    df = run(tmp_path, ["test-tiny", "test-slow-model", "test-missing"], cfg=cfg, timeout=5.0)
    skipped = df[df.status == "skipped"]
    assert skipped["solve_time_s"].isna().all() and skipped["kkt_error"].isna().all()
    reasons = dict(zip(skipped["solver"], skipped["skip_reason"]))
    assert "not installed" in reasons["test-missing"]
    assert "predicted solve time 8.64e+04 s" in reasons["test-slow-model"] and "limit of 5 s" in reasons["test-slow-model"]
    tiny = df[df.solver == "test-tiny"]
    big = tiny[tiny.n > 10]
    assert len(big) > 0 and (big.status == "skipped").all()
    assert big["skip_reason"].str.contains("max_n = 10").all()
    assert (tiny[tiny.n <= 10].status == "solved").all()


def test_observed_step_time_replaces_the_static_time_model(tmp_path: Path) -> None:
    cfg = SceneConfig(size=16, steps=3, seeds=(0,))
    df = run(tmp_path, ["test-pessimist", "test-hang"], cfg=cfg, timeout=1.0).sort_values("step")
    pess = df[df.solver == "test-pessimist"]
    assert pess.iloc[0]["n"] <= 3 < pess.iloc[-1]["n"]
    # its first step ran, so the later ones are predicted from the observed time, not the model
    assert (pess.status == "solved").all()
    hang = df[df.solver == "test-hang"]
    assert list(hang.status) == ["timeout", "skipped", "skipped"]


def test_dense_solver_beyond_the_memory_budget_is_skipped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from contactbench.harness.run import plan

    monkeypatch.setattr(plan, "largest_recipe", lambda specs: ("", 0.0))  # (the plan's own bound: test_run_folder.py)
    monkeypatch.setattr(plan, "model_rejections", lambda *args: "")  # (its refusal: test_option_records.py)
    df = run(tmp_path, ["test-exact"], reference="none", memory_budget=4.0)  # bytes: n = 1 needs 8
    assert (df.status == "skipped").all()
    assert df["skip_reason"].str.contains("needs dense H").all()
    assert df["skip_reason"].str.contains("GiB").all()


def test_dense_h_is_assembled_once_per_step_and_only_when_needed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from contactbench.problems import operators

    log = tmp_path / "assemblies.log"
    original = operators.ContactOperator.to_dense

    def counting_to_dense(self: operators.ContactOperator, budget: float | None = None) -> np.ndarray:
        with open(log, "a") as fh:
            fh.write(f"{self.n}\n")
        return original(self, budget)

    monkeypatch.setattr(operators.FFTOperator, "to_dense", counting_to_dense)  # inherited by the forked worker
    df = run(tmp_path / "free", ["test-warm-pg"], reference="none")
    assert (df.status == "solved").all() and (df.operator == "fft").all()
    assert not log.exists()  # no dense-H solver in the run: never assembled
    df = run(tmp_path / "dense", ["test-exact", "test-sleepy", "test-warm-pg"], reference="test-exact")
    assert (df.status == "solved").all()
    assert set(df[df.solver != "test-warm-pg"].operator) == {"dense"}
    assert len(log.read_text().split()) == 2  # two steps: one assembly each, shared by 3 users


def test_map_by_grid_index_keeps_shared_points_and_zeroes_new_ones() -> None:
    values = np.array([1.0, 2.0, 3.0])
    from_idx = np.array([7, 2, 5])  # unsorted on purpose
    to_idx = np.array([1, 2, 5, 6, 7, 9])
    out = map_by_grid_index(values, from_idx, to_idx)
    np.testing.assert_array_equal(out, [0.0, 2.0, 3.0, 0.0, 1.0, 0.0])
    assert map_by_grid_index(np.array([]), np.array([], dtype=int), np.array([3])).tolist() == [0.0]
    with pytest.raises(ValueError, match="values for"):
        map_by_grid_index(values, np.array([1, 2]), to_idx)


def test_load_history_warm_starts_from_the_solvers_own_previous_step(tmp_path: Path) -> None:
    cfg = SceneConfig(size=16, steps=3, seeds=(0,), extra={"family": "periodic"})  # the toy warm start gains on it
    warm = run(tmp_path / "warm", ["test-warm-pg", "test-exact"], cfg=cfg, profiles=("high",))
    cold = run(tmp_path / "cold", ["test-warm-pg", "test-exact"], cfg=cfg, profiles=("high",), warm=False)
    pg_w = warm[warm.solver == "test-warm-pg"].sort_values("step")
    pg_c = cold[cold.solver == "test-warm-pg"].sort_values("step")
    assert pg_w["warm_start"].tolist() == [False, True, True]
    assert not pg_c["warm_start"].any()
    assert not warm[warm.solver == "test-exact"]["warm_start"].any()  # no warm-start capability: runs cold
    assert (pg_w.status == "solved").all() and (pg_c.status == "solved").all()
    assert (pg_w["p_rel_error"] < 1e-6).all()
    assert pg_w["iterations"].iloc[1:].sum() < pg_c["iterations"].iloc[1:].sum()
    assert set(warm["cell_id"]).isdisjoint(cold["cell_id"])  # warm and cold are different cells


def test_repeats_give_min_and_median_and_reference_is_cached(tmp_path: Path) -> None:
    df = run(tmp_path, ["test-exact"], repeats=3)
    assert len(df) == 2 * 3
    for _, g in df.groupby("step"):
        assert g["solve_time_min_s"].iloc[0] == pytest.approx(g["solve_time_s"].min())
        assert g["solve_time_median_s"].iloc[0] == pytest.approx(g["solve_time_s"].median())
    refs = sorted((tmp_path / "_cache").glob("ref-*.npz"))
    assert len(refs) == 2  # once per instance-step
    stamps = [r.stat().st_mtime_ns for r in refs]
    df2 = run(tmp_path, ["test-exact", "test-warm-pg"], repeats=3, append=True)  # another solver: added to the folder
    assert [r.stat().st_mtime_ns for r in refs] == stamps  # stored reference not recomputed
    assert len(df2) == 2 * 2 * 3 and df2["cell_id"].is_unique
    assert (df2["p_rel_error"] < 1e-6).all()


def test_analytic_load_columns_on_hertz(tmp_path: Path) -> None:
    cfg = SceneConfig(size=16)
    df = run(tmp_path, ["test-exact"], cfg=cfg, scenes=("hertz",), reference="none")
    row = df.iloc[0]
    assert row.status == "solved" and row.analytic_load > 0
    assert row.load_rel_error == pytest.approx(abs(row.load - row.analytic_load) / row.analytic_load)
    assert row.analytic_load_rel_error == pytest.approx(row.load_rel_error)


def test_store_cuts_a_partial_last_line_and_keeps_first_rows(tmp_path: Path) -> None:
    path = tmp_path / ROWS_FILE
    solved = {"cell_id": "a", "status": "solved", "kkt_error": 1e-10, "check_tol": 1e-8, "solve_time_s": 0.01}
    path.write_text(json.dumps(solved) + "\n"
                    + json.dumps({"cell_id": "a", "status": "failed"}) + "\n" + '{"cell_id": "b", "sta')
    store = ResultStore(tmp_path)
    assert store.done_statuses() == {"a": "solved"}
    store.append({"cell_id": "c", "status": "skipped", "skip_reason": "x"})
    rows = read_journal(path)
    assert [r["cell_id"] for r in rows] == ["a", "c"]
    table = store.finalize()
    assert set(REQUIRED_COLUMNS) <= set(table.columns) and len(table) == 2


def test_cell_ids_are_stable_and_distinct() -> None:
    plan = plan_run(["paper-sweep"], SMALL, ["test-exact", "test-warm-pg"], RunConfig(profiles=("low", "high")))
    job = plan.jobs[0]
    ids = {make_cell_id(job.spec, k, v, p, 0, True) for k in range(2) for v in job.variants for p in job.profiles}
    assert len(ids) == 2 * 2 * 2
    again = plan_run(["paper-sweep"], SMALL, ["test-exact", "test-warm-pg"], RunConfig(profiles=("low", "high"))).jobs[0]
    assert make_cell_id(again.spec, 1, again.variants[0], "low", 0, True) == make_cell_id(job.spec, 1, job.variants[0], "low", 0, True)


def cli_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])  # tests.helpers importable
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", CONTACTBENCH_FFT_WORKERS="1", CI="true")
    return env


@pytest.mark.slow
def test_sigkill_mid_run_then_rerun_gives_exactly_the_full_table(tmp_path: Path) -> None:
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "contactbench.harness.cli", "run", "counterexample", "--size", "3", "--seeds", "0-5",
           "--solvers", f"{SOLVER_MODULE}:SleepyStub,test-exact", "--reference", "test-exact",
           "--no-warmup", "--out", str(out)]
    proc = subprocess.Popen(cmd, env=cli_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    journal = out / ROWS_FILE
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.exists() and journal.read_text().count("\n") >= 3:
            break
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {r["cell_id"]: r for r in read_journal(journal)}
    assert 3 <= len(before) < 12
    done = subprocess.run(cmd, env=cli_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    table = load_table(out)
    assert len(table) == 12 and table["cell_id"].is_unique
    assert journal.read_text().count("\n") == 12  # nothing appended twice
    assert set(table["status"]) == {"solved"}
    after = {r["cell_id"]: r for r in read_journal(journal)}
    for cid, row in before.items():  # rows written before the kill are kept as they were
        assert after[cid]["timestamp"] == row["timestamp"]
        assert after[cid]["solve_time_s"] == row["solve_time_s"]


@pytest.mark.slow
@pytest.mark.parametrize("sig, code, word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
def test_ctrl_c_stops_a_parallel_run_without_waiting_for_its_jobs(tmp_path: Path, sig: int, code: int,
                                                                  word: str) -> None:
    """SIGINT to the runner of --jobs 2 (the process alone, as a signal from another shell)
    stops it at once: the jobs its pool is running are killed with their solvers, not
    waited for (each hangs for five minutes here), and it exits 130.  SIGTERM (a batch
    scheduler's) stops it the same way, exit 143.  Either way one line says so, with no
    traceback (not even the pool's own thread's), and the folder's lock is released."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "contactbench.harness.cli", "run", "counterexample", "--size", "3", "--seeds", "0-3",
           "--solvers", f"{SOLVER_MODULE}:HangingStub", "--reference", "none", "--no-warmup", "--jobs", "2",
           "--timeout", "600", "--no-progress", "--out", str(out)]
    proc = subprocess.Popen(cmd, env=cli_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list(out.glob("_cache"))) == 0 and proc.poll() is None:
            time.sleep(0.05)
        time.sleep(2.0)  # the pool's jobs are in their solves
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        os.kill(proc.pid, sig)
        assert proc.wait(timeout=60) == code
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    err = proc.stderr.read().decode() if proc.stderr else ""
    assert f"{word}: " in err and "Traceback" not in err, err
    assert not (out / LOCK_FILE).exists()


def test_cli_run_then_report_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli"
    rc = cli.main(["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "test-exact,test-warm-pg",
                   "--profile", "low,high", "--reference", "test-exact", "--out", str(out), "--no-progress"])
    assert rc == 0
    assert "8 rows (8 new)" in capsys.readouterr().out
    for name in ("results.parquet", "results.csv", "meta.json", ROWS_FILE):
        assert (out / name).exists()
    meta = json.loads((out / "meta.json").read_text())
    assert meta["command"][:3] == ["contactbench", "run", "paper-sweep"]
    assert meta["machine"]["logical_cores"] and "numpy" in meta["packages"]
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 8 and set(REQUIRED_COLUMNS) <= set(csv.columns)
    try:
        import contactbench.harness.report.core  # noqa: F401
    except ImportError:
        pytest.skip("harness/report/core.py is not in this checkout yet")
    assert cli.main(["report", str(out)]) == 0
    assert (out / "report.md").exists()


def test_cli_lists_and_rejects_bad_input(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["list", "scenes"]) == 0
    listed = capsys.readouterr().out
    for scene in ("default", "gp-k-sweep", "greedy-linear-solvers", "paper-sweep"):
        assert scene in listed
    assert cli.main(["list", "solvers"]) == 0
    listed = capsys.readouterr().out
    assert "test-missing" in listed and "nonexistent-backend" in listed and "needs-dense-H" in listed
    assert cli.main(["run", "no-such-scene"]) == 2
    assert "unknown scene" in capsys.readouterr().err
    assert cli.parse_seeds("0-2,7") == (0, 1, 2, 7)
    with pytest.raises(SystemExit):
        cli.main(["run", "paper-sweep", "--seeds", "3-1"])


def test_cli_refuses_an_unreadable_surface_before_running(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    missing = tmp_path / "missing.npy"
    assert cli.main(["run", "paper-sweep", "--surface", str(missing), "--length", "1e-4", "--out", str(out)]) == 2
    assert f"cannot use surface file '{missing}'" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    assert cli.main(["run", "paper-sweep", "--surface", str(bad), "--length", "1e-4", "--out", str(out)]) == 2
    assert "non-numeric value 'a'" in capsys.readouterr().err
    assert not out.exists()  # nothing was planned or recorded


def test_jobs_pool_gives_the_same_table_as_serial(tmp_path: Path) -> None:
    cfg = SceneConfig(size=3, seeds=(0, 1, 2))
    kw = dict(scenes=("counterexample",), cfg=cfg, warmup=False)
    serial = run(tmp_path / "serial", ["test-exact", "test-warm-pg"], **kw)  # type: ignore[arg-type]
    pooled = run(tmp_path / "pool", ["test-exact", "test-warm-pg"], jobs=2, **kw)  # type: ignore[arg-type]
    assert len(pooled) == len(serial) == 6 and pooled["cell_id"].is_unique
    assert pooled["cell_id"].tolist() == serial["cell_id"].tolist()
    np.testing.assert_allclose(pooled["load"], serial["load"], rtol=1e-12)
    assert pooled["status"].tolist() == serial["status"].tolist()


def test_plugin_fixtures(contact_instance, run_harness) -> None:  # type: ignore[no-untyped-def]
    inst = contact_instance("counterexample", n=9, seed=0)
    assert inst.n == 9
    df = run_harness(["counterexample"], solvers=["test-exact"], size=3, seeds=(0,), reference="none")
    assert df["status"].tolist() == ["solved"]


def test_step_time_extrapolation_uses_the_measured_growth() -> None:
    """Measured on the 512^2 paper run: the cascade over NNLS took 6.5 s then 70 s and then
    timed out at n = 36,242 under the fixed n^1.5 extrapolation (it predicted 92 s); the
    measured growth (capped at n^3) predicts it over the 120 s limit.  The paper's NNLS
    (29 s at n = 16,147 after 2.3 s at n = 10,274, then 38 s at n = 22,458) must still run."""
    from contactbench.harness.run.skips import extrapolated_time, skip_decision
    from contactbench.solvers.base import ProblemTraits

    t_fixed, e_fixed = extrapolated_time([(29202, 70.3)], 36242)
    assert e_fixed == 1.5 and t_fixed < 120.0
    t, e = extrapolated_time([(22458, 6.5), (29202, 70.3)], 36242)
    assert e == 3.0 and t > 120.0  # measured ~9, capped
    t, e = extrapolated_time([(10274, 2.29), (16147, 29.2)], 22458)
    assert e == 3.0 and t < 120.0
    assert extrapolated_time([(100, 0.01), (200, 1.0)], 400)[1] == 1.5  # too short to time: the floor
    t, e = extrapolated_time([(10274, 18.7), (16147, 48.3)], 22458)
    assert 2.0 < e < 2.2 and 90.0 < t < 120.0
    budget = 8 * 2**30
    big, mid = ProblemTraits(36242, "fft", has_surface=True), ProblemTraits(22458, "fft", has_surface=True)
    d = skip_decision("fast-ccg", big, 120.0, budget, [(22458, 6.5), (29202, 70.3)])
    assert d.skip and "n^3" in d.reason and "time limit of 120 s" in d.reason
    assert not skip_decision("fast-ccg", mid, 120.0, budget, [(10274, 2.29), (16147, 29.2)]).skip
    assert not skip_decision("fast-ccg", mid, 120.0, budget, [(16147, 2.0)]).skip  # one (n, t) pair


# ---------------------------------------------------------------------------
# Planning refuses bad input up front; studies; the one skip interpreter; judge
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("size, why", [("1000", "2^k"), ("1", "2^k")])
def test_bad_size_exits_2_with_one_line_and_writes_no_table(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                            size: str, why: str) -> None:
    out = tmp_path / "run"
    assert cli.main(["run", "paper-sweep", "--size", size, "--solvers", "test-exact", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("contactbench: error: paper-sweep:") and why in err[0]
    assert f"N = {size}" in err[0]
    assert not out.exists()  # nothing planned, run or recorded


def test_flat_surface_is_refused_before_anything_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    flat = tmp_path / "flat.npy"
    np.save(flat, np.zeros((16, 16)))
    out = tmp_path / "run"
    rc = cli.main(["run", "paper-sweep", "--surface", str(flat), "--length", "1e-4", "--solvers", "test-exact",
                   "--out", str(out)])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is flat" in err[0] and "no step makes contact" in err[0]
    assert not out.exists()
    with pytest.raises(PlanError, match="is flat"):  # the same check through the Python API
        plan_run(["cmr"], SceneConfig(surface_path=str(flat), length=1e-4), ["test-exact"])


def test_every_bad_input_is_reported_once(tmp_path: Path) -> None:
    with pytest.raises(PlanError) as info:  # ten seeds of one bad size: one problem; a bad reference: another
        plan_run(["paper-sweep", "counterexample"], SceneConfig(size=1, seeds=tuple(range(10))), ["test-exact"],
                 RunConfig(reference="no-such-reference"))
    problems = info.value.problems
    assert len(problems) == 3, problems
    assert problems[0].startswith("paper-sweep:") and "2^k" in problems[0] and "N = 1" in problems[0]
    assert problems[1].startswith("counterexample:")
    assert problems[2].startswith("--reference: unknown solver 'no-such-reference'")


def test_studies_keep_the_variants_and_cells_of_the_scenes() -> None:
    from contactbench.harness.run.studies import COMPOSITES, study_for

    cmr = study_for("cmr").variants(["nnls", "cmr+nnls"], {})
    assert [v.name for v in cmr] == ["nnls", "cmr+nnls coarse=subsample h=2 from 16", "cmr+nnls coarse=mean h=2 from 16"]
    assert cmr[1].params == {"h": 2.0, "coarsest": 16, "coarse": "subsample"}
    sweep = study_for("cmr-h-sweep").variants(["cmr+fast-dual-pccg"], {"levels": [16, 32]})
    assert [v.name for v in sweep][:2] == ["cmr+fast-dual-pccg coarse=subsample h=1.25 from 16",
                                           "cmr+fast-dual-pccg coarse=subsample h=1.5 from 16"] and len(sweep) == 20
    assert sweep[15].params == {"h": 3.0, "coarsest": 16, "coarse": "mean", "levels": [16, 32]}
    gp = study_for("gp-k-sweep").variants(["nnls-gp", "pk"], {})
    assert [v.name for v in gp] == [f"nnls-gp[K={k}]" for k in (0, 10, 25, 50, 100, 150, 200)] + ["pk"]  # Fig. 6
    assert study_for("gp-k-sweep").variants(["nnls-gp"], {"K": (5,)})[0].params == {"K": 5}
    assert study_for("stress-edge").solvers is None  # a scene with no record: every available solver
    default = plan_run(["default"], None, None, RunConfig())
    assert {j.spec.scene for j in default.jobs} == {s.study.scene for s in COMPOSITES["default"].parts}
    # the cell id of one stored cell of `make bench` (results/default) does not move
    job = next(j for j in default.jobs if j.spec.instance == "n100-s0")
    pk = next(v for v in job.variants if v.name == "pk")
    assert make_cell_id(job.spec, 0, pk, "default", 0, True) == make_cell_id(
        job.spec, 0, type(pk)("pk"), "default", 0, True)


def test_a_sweep_reads_the_solvers_declared_grid() -> None:
    from contactbench.harness.run.studies import Study, Sweep
    from contactbench.solvers.registry import register, unregister

    class Gridded(helpers.ExactStub):
        name = "test-gridded"
        params = (*helpers.ExactStub.params, Param("K", int, 1, low=0))
        grid = {"K": (3, 7)}

    register(Gridded, replace=True)
    try:
        study = Study("paper-sweep", sweeps=(Sweep("test-gridded", "K", kind=int),))
        assert [(v.name, v.params) for v in study.variants(["test-gridded"])] == [
            ("test-gridded[K=3]", {"K": 3}), ("test-gridded[K=7]", {"K": 7})]
    finally:
        unregister("test-gridded")


class NeedsSurfaceStub(helpers.ExactStub):
    """A solver that needs the instance's surface (as the CMR wrappers do)."""

    name = "test-needs-surface"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True, needs_geometry=True,
                                input_format="dense")


def test_a_solver_needing_a_surface_is_skipped_with_its_reason_on_the_counterexample(tmp_path: Path) -> None:
    from contactbench.solvers.registry import register, unregister

    register(NeedsSurfaceStub, replace=True)
    try:
        df = run(tmp_path / "ce", ["test-needs-surface", "test-exact"], cfg=SceneConfig(size=3, seeds=(0,)),
                 scenes=("counterexample",))
        surf = run(tmp_path / "ps", ["test-needs-surface"], reference="none")
    finally:
        unregister("test-needs-surface")
    row = df[df.solver == "test-needs-surface"].iloc[0]
    assert row.status == "skipped" and "needs the instance's surface" in row.skip_reason
    assert pd.isna(row.solve_time_s)
    assert (df[df.solver == "test-exact"].status == "solved").all()
    assert (surf.status == "solved").all()  # a rough surface has one: it runs


def test_cmr_wrappers_are_skipped_with_a_reason_on_the_counterexample(tmp_path: Path) -> None:
    df = run(tmp_path, ["cmr+nnls", "cmr+pk"], cfg=SceneConfig(size=3, seeds=(0,)), scenes=("counterexample",),
             reference="none", warmup=False)
    assert (df.status == "skipped").all(), df[["solver", "status", "error"]]
    assert df["skip_reason"].str.contains("surface").all()


def test_run_rows_carry_the_judges_verdict(tmp_path: Path) -> None:
    from contactbench.harness.judging import judge
    from contactbench.problems.scenes import get_scene
    from contactbench.solvers.registry import get_solver

    cfg = SceneConfig(size=8, steps=2, seeds=(0,))
    df = run(tmp_path, ["test-warm-pg"], cfg=cfg, profiles=("low",), warm=False, reference="none")
    scene = get_scene("paper-sweep")
    seq = scene.instances(scene.config(cfg))[0].build()
    for _, row in df.sort_values("step").iterrows():
        inst = seq.at(int(row.step))
        res = get_solver("test-warm-pg").solve(inst.qp, SolverSettings(tol=1e-3))
        v = judge(inst, res.p, res.converged, float(row.check_tol))
        assert (row.status, row.verdict) == (v.status, v.reading)
        assert row.kkt_error == pytest.approx(v.figures["kkt_error"], rel=1e-9)
        assert bool(row.correct_claim) == v.correct_claim


class JacobiStub(Solver):
    """One projected Jacobi step p = max(ubar / diag H, 0): not the answer.  The liar
    claims convergence, the honest one does not."""

    name = "test-jacobi-liar"
    family = "test"
    claims = True

    def iterate(self, ctx: SolveContext) -> Outcome:
        p = np.maximum(ctx.qp.ubar / ctx.qp.H.diagonal(), 0.0)
        return Outcome(p, 1, self.claims, "one Jacobi step")


class HonestJacobiStub(JacobiStub):
    name = "test-jacobi-honest"
    claims = False


def test_run_and_validate_give_the_same_verdict_on_the_same_solve(tmp_path: Path) -> None:
    from contactbench.harness.conformance.battery import validate
    from contactbench.problems.scenes import get_scene
    from contactbench.solvers.registry import register, unregister

    cfg = SceneConfig(extra={"mode": "fast"})
    scene = get_scene("stress-random")
    specs = [spec for spec in scene.instances(scene.config(cfg)) if spec.params["family"] == "bcc"][:2]
    stubs = (JacobiStub, HonestJacobiStub)
    for stub in stubs:
        register(stub, replace=True)
    try:
        df = run(tmp_path, ["test-exact", "test-jacobi-liar", "test-jacobi-honest"], cfg=cfg,
                 scenes=("stress-random",), profiles=("mid",), reference="none", warmup=False)
        tables = {name: validate(name, specs, isolate=False) for name in ("test-exact", "test-jacobi-liar",
                                                                            "test-jacobi-honest")}
    finally:
        for stub in stubs:
            unregister(stub.name)
    as_validate = {"pass": "pass", "wrong": "WRONG", "unconverged": "unconverged"}
    seen = set()
    for name, table in tables.items():
        for vrow in table.rows:
            row = df[(df.solver == name) & (df.instance == vrow.case) & (df.step == vrow.step)].iloc[0]
            assert as_validate[row.verdict] == vrow.status, (name, vrow.case, row.verdict, vrow.status)
            assert row.kkt_error == pytest.approx(vrow.kkt_error, rel=1e-12)
            seen.add(row.verdict)
    assert seen == {"pass", "wrong", "unconverged"}


def test_solve_sequence_warm_starts_by_grid_index_and_judges_each_step() -> None:
    from contactbench.harness import solve_sequence
    from contactbench.problems.scenes import get_scene

    scene = get_scene("paper-sweep")
    cfg = SceneConfig(size=16, steps=3, seeds=(0,), extra={"family": "periodic"})
    seq = scene.instances(scene.config(cfg))[0].build()
    warm = solve_sequence("test-warm-pg", seq, SolverSettings(tol=1e-9), check_tol=1e-8)
    cold = solve_sequence("test-warm-pg", seq, SolverSettings(tol=1e-9), check_tol=1e-8,
                          warm=False)
    assert [s.warm_started for s in warm] == [False, True, True] and not any(s.warm_started for s in cold)
    assert all(s.verdict is not None and s.verdict.status == "solved" for s in warm + cold)
    iterations = [sum(s.result.iterations for s in run[1:] if s.result) for run in (warm, cold)]
    assert iterations[0] < iterations[1]
    np.testing.assert_allclose([s.inst.load(s.result.p) for s in warm], [s.inst.load(s.result.p) for s in cold],
                               rtol=1e-6)


def test_list_solvers_params_prints_declared_parameters_and_grid(capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.solvers.base import Param
    from contactbench.solvers.registry import register, unregister

    class Declared(helpers.ExactStub):
        name = "test-declared"
        params = (Param("K", int, 10, "gradient steps", low=0),)
        grid = {"K": (0, 10)}

    register(Declared, replace=True)
    try:
        assert cli.main(["list", "solvers", "--params"]) == 0
    finally:
        unregister("test-declared")
    out = capsys.readouterr().out
    block = out[out.index("test-declared"):].splitlines()[:4]
    assert any("param K: int = 10 in [0, inf)  (gradient steps)" in line for line in block), block
    assert any("grid  K = 0, 10" in line for line in block), block


def test_validate_forwards_every_argument_to_the_conformance_module() -> None:
    assert cli.forwarded_validate(["validate", "--list"]) == ["--list"]
    assert cli.forwarded_validate(["-v", "validate", "--all", "--quiet"]) == ["--all", "--quiet"]
    assert cli.forwarded_validate(["run", "validate"]) is None


def test_the_api_reads_one_scene_name_and_refuses_empty_lists_and_unknown_names(tmp_path: Path) -> None:
    """run_benchmark("hertz") walked the string letter by letter ("unknown scene 'h'"), an
    empty solver list ran every solver, no scene wrote an empty folder, and an unknown
    scene was a bare KeyError: one scene's name is read as that scene, the rest are
    ``PlanError``s (``ProblemInputError``) naming the problem, and nothing is written."""
    from contactbench.harness.run.plan import PlanError, plan_run

    cfg = SceneConfig(size=8)
    assert [j.spec.scene for j in plan_run("hertz", cfg, ["test-exact"]).jobs] == ["hertz"]
    for scenes, solvers, words in ((["hertz"], [], "empty solver list"), ([], ["test-exact"], "no scene"),
                                   (["hertzz"], ["test-exact"], "hertz")):
        with pytest.raises(PlanError, match=words):
            run_benchmark(scenes, cfg, solvers, RunConfig(progress=False), tmp_path / "o", command=["pytest"])
    assert not (tmp_path / "o").exists()


def test_backfill_rebuilds_a_map_run_from_another_folder_and_names_what_it_cannot(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A --surface run given a relative path, backfilled from another folder: rebuilt from
    the path the run resolved; the map changed since: the instance is named, exit 1 (it was
    silently dropped); bad usage: one line, exit 2."""
    import shutil

    from contactbench.harness.run.backfill import main as backfill

    work = tmp_path / "work"
    work.mkdir()
    z = np.random.default_rng(3).normal(0.0, 1e-6, (16, 16))
    np.save(work / "m.npy", z)
    monkeypatch.chdir(work)
    run_benchmark(["paper-sweep"], SceneConfig(surface_path="m.npy", length=1e-4, steps=2), ["test-exact"],
                  RunConfig(reference="none", progress=False, warmup=False), "o", command=["pytest"])
    shutil.rmtree(work / "o" / "arrays")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert backfill([str(work / "o"), "test-exact"]) == 0
    assert list((work / "o" / "arrays").glob("field-*.npz"))
    np.save(work / "m.npy", 1.5 * z)
    capsys.readouterr()
    assert backfill([str(work / "o"), "test-exact"]) == 1
    assert "not rebuilt: paper-sweep/file-m.npy-" in capsys.readouterr().err
    assert backfill([]) == 2 and capsys.readouterr().err.count("\n") == 1
