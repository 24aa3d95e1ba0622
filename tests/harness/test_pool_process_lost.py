"""A run stopped once it runs -- a ``--jobs`` process killed outright (the out-of-memory
killer, ``kill -9``), a write that fails (a full disk) -- ends in one line, exit 1, its rows
kept and its table written: never a BrokenProcessPool traceback
(``executors.PoolProcessLost``), nor the exit 2 of bad input."""

from __future__ import annotations

import errno
import os
import signal
import sys
from pathlib import Path
from typing import Any

import pytest

from contactbench.harness import cli
from contactbench.harness.run import executors
from contactbench.harness.table.store import PARQUET_FILE, ROWS_FILE, ResultStore

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


def test_a_write_that_fails_once_the_run_runs_stops_it_in_one_line_exit_1(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A full disk mid-run is no bad input: exit 1, one line naming the file, rows kept."""
    real_append = ResultStore.append
    written: list[int] = []

    def full_after_one(self: ResultStore, row: dict[str, Any]) -> None:
        if written:
            raise OSError(errno.ENOSPC, "No space left on device", str(self.path))
        written.append(1)
        real_append(self, row)

    monkeypatch.setattr(ResultStore, "append", full_after_one)
    out = tmp_path / "run"
    serial = [a for a in ARGS if a not in ("--jobs", "2")]
    assert cli.main(["run", *serial, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"contactbench: error: {out / ROWS_FILE}: No space left on device; the run stopped"), err
    assert len(err.splitlines()) == 1
    monkeypatch.undo()
    assert len(ResultStore(out)) == 1
    assert cli.main(["run", *serial, "--out", str(out)]) == 0
