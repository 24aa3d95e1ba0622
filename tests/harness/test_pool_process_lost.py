"""A ``--jobs`` process killed outright (the out-of-memory killer, ``kill -9``) stops the run
in one line, exit 1, its rows kept and its table written -- never a BrokenProcessPool
traceback (``executors.PoolProcessLost``)."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path
from typing import Any

import pytest

from contactbench.harness import cli
from contactbench.harness.run import executors
from contactbench.harness.table.store import PARQUET_FILE

ARGS = ["counterexample", "--size", "3", "--seeds", "0-3", "--solvers", "test-exact", "--reference", "none",
        "--no-warmup", "--no-progress", "--jobs", "2"]


def killed_on_its_second_job(job: Any, run: Any, out_dir: str, statuses: dict[str, str]) -> int:
    """A pool process's job that kills its process (SIGKILL) on the job of seed 1."""
    if "-s1" in job.spec.instance:
        os.kill(os.getpid(), signal.SIGKILL)
    return executors.run_instance_job(job, run, out_dir, statuses)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the pool forks its processes on Linux")
def test_a_killed_pool_process_stops_the_run_in_one_line_with_its_rows_kept(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(executors, "_pool_run", killed_on_its_second_job)  # (the forked processes inherit it)
    out = tmp_path / "run"
    assert cli.main(["run", *ARGS, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("contactbench: error: a --jobs process ended abruptly") and len(err.splitlines()) == 1, err
    assert (out / PARQUET_FILE).exists()
    monkeypatch.undo()
    assert cli.main(["run", *ARGS, "--out", str(out)]) == 0  # the same command resumes the rest
