"""``contactbench run --memory-budget-gb`` reaches every dense build of the run's workers
(they are forked from the run's process and build the scene's dense H themselves): a dense
instance over the process's default budget builds under a larger run budget."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from contactbench.problems import operators
from contactbench.problems.errors import ProblemInputError


def run(tmp_path: Path, budget_gb: float, env_gb: str) -> list[dict]:
    out = tmp_path / f"run-{budget_gb}"
    cmd = [sys.executable, "-m", "contactbench.harness.cli", "run", "greedy-linear-solvers", "--size", "32",
           "--steps", "1", "--seeds", "0", "--operator", "dense", "--solvers", "pk", "--reference", "none",
           "--no-progress", "--out", str(out), "--memory-budget-gb", str(budget_gb)]
    env = {**os.environ, "CONTACTBENCH_MEMORY_BUDGET_GB": env_gb}
    subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300, check=False)
    return [json.loads(line) for line in (out / "rows.jsonl").read_text().splitlines() if line.strip()]


@pytest.mark.slow
def test_the_run_budget_reaches_the_workers_dense_build(tmp_path: Path) -> None:
    # the 32^2 top step's dense H is ~1 MiB; a process default of ~1 KiB refuses it, and the
    # run's 1 GiB lets it build
    (row,) = run(tmp_path, 1.0, "0.000001")
    assert row["status"] == "solved", row.get("error")


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "8"])
def test_set_memory_budget_refuses_what_is_not_a_positive_size(bad: object) -> None:
    before = operators.memory_budget()
    with pytest.raises(ProblemInputError):
        operators.set_memory_budget(bad)  # type: ignore[arg-type]
    assert operators.memory_budget() == before


def test_a_budget_scope_restores_the_process_budget_however_it_ends() -> None:
    before = operators.memory_budget()
    with operators.memory_budget_scope(1234.0):
        assert operators.memory_budget() == 1234.0
    assert operators.memory_budget() == before
    with pytest.raises(RuntimeError):
        with operators.memory_budget_scope(99.0):
            raise RuntimeError("a run that fails")
    assert operators.memory_budget() == before
    with operators.memory_budget_scope(None):
        assert operators.memory_budget() == before


@pytest.fixture
def device_of(monkeypatch: pytest.MonkeyPatch):
    """A stand-in device of the given bytes: CuPy reported present, its memory from
    CONTACTBENCH_DEVICE_BYTES (the probe's cache cleared before and after)."""
    from contactbench.problems import instances, operators_gpu

    monkeypatch.setattr(instances, "gpu_unavailable_reason", lambda: None)
    operators_gpu.device_total_bytes.cache_clear()

    def make(nbytes: float) -> None:
        monkeypatch.setenv("CONTACTBENCH_DEVICE_BYTES", str(nbytes))
        operators_gpu.device_total_bytes.cache_clear()

    yield make
    operators_gpu.device_total_bytes.cache_clear()


def test_a_gpu_run_that_does_not_fit_the_device_is_refused_before_it_runs(device_of, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness.cli import main
    from contactbench.problems.operators_gpu import device_model_nbytes

    need = device_model_nbytes((256, 256), periodic=False)
    device_of(need // 2)
    out = tmp_path / "o"
    args = ["run", "paper-sweep", "--size", "256", "--steps", "1", "--seeds", "0", "--operator", "gpu",
            "--solvers", "fast-dual-pccg", "--reference", "none", "--no-progress", "--out", str(out)]
    rc = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "operator 'gpu'" in err[0] and "256 x 256 non-periodic grid needs about" in err[0], err[0]
    assert not (out / "rows.jsonl").exists()


@pytest.mark.parametrize("bad", ["lots", "-5", "0"])
def test_a_device_size_that_is_not_a_positive_number_is_refused(device_of, bad: str) -> None:
    from contactbench.problems.operators_gpu import device_total_bytes

    device_of(bad)
    with pytest.raises(ProblemInputError, match="CONTACTBENCH_DEVICE_BYTES"):
        device_total_bytes()


def test_a_scene_built_dense_counts_its_h_against_the_budget_before_anything_runs(tmp_path: Path) -> None:
    """--operator dense with a budget below the step's dense H: the build failed in the
    worker, every row 'failed' with a traceback, exit 1; the plan now sees the n x n H and
    refuses (every cell would be skipped), in one line, exit 2, writing nothing."""
    out = tmp_path / "dense"
    cmd = [sys.executable, "-m", "contactbench.harness.cli", "run", "paper-sweep", "--size", "65", "--steps", "1",
           "--operator", "dense", "--solvers", "pk", "--memory-budget-gb", "0.002", "--no-progress", "--out", str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 2, res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert "every cell would be skipped" in line and "needs dense H" in line
    assert not out.exists()


def test_a_time_limit_beyond_the_pipes_longest_wait_is_waited_in_parts() -> None:
    """--timeout 1e9 crashed run and validate (OverflowError from the pipe's poll)."""
    from contactbench.harness.run.isolation import ChildProcess

    with ChildProcess(lambda: (lambda msg: msg)) as child:
        reply = child.call("echo", 1e9)
    assert reply.ok and reply.value == "echo"


def test_a_memory_budget_that_overflows_to_infinite_bytes_is_refused_naming_the_option(
        in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness.run.plan import RunConfig
    from tests.helpers import run_cli

    with pytest.raises(ValueError, match="--memory-budget-gb"):
        RunConfig(memory_budget=1e308 * 2**30)
    rc, _, err = run_cli(["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "pk", "--reference",
                          "none", "--no-progress", "--memory-budget-gb", "1e308", "--out", "o"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1, (rc, err)
    assert "--memory-budget-gb" in err and "1.67e+299 GB" in err and not (in_tmp / "o").exists()
