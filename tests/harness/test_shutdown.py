"""A run stopped by Ctrl-C writes its table from the journal, and a second Ctrl-C while it
is written waits for it: the folder has its results.parquet, with every recorded row
(harness/run/interrupts.py)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import pytest

from contactbench.harness import run_benchmark
from contactbench.harness.run.executors import SerialExecutor
from contactbench.harness.run.interrupts import signals_deferred
from contactbench.harness.run.plan import InstanceJob, RunConfig
from contactbench.harness.table import store as store_module
from contactbench.harness.table.store import (LOCK_FILE, PARQUET_FILE, ROWS_FILE, ResultStore, load_table,
                                              read_journal)
from contactbench.problems.scenes import SceneConfig
from tests import helpers
from tests.helpers import REPO

#: The command, with the table's writing slowed down and announced (a file), so that the
#: test's second SIGINT arrives while it is under way.
SLOW_WRITER = """
import sys, time
from pathlib import Path
from typing import Any, Sequence
from contactbench.harness.table import store
from contactbench.harness import cli

announce, written = Path(sys.argv[1]), store.write_table

def slow_write(*args: Any) -> None:
    announce.touch()
    time.sleep(1.0)
    written(*args)

store.write_table = slow_write
sys.exit(cli.main(sys.argv[2:]))
"""


def wait_for(condition: object, proc: subprocess.Popen[bytes], seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and proc.poll() is None and not condition():  # type: ignore[operator]
        time.sleep(0.02)
    assert condition(), proc.stderr.read().decode() if proc.stderr and proc.poll() is not None else "timed out"  # type: ignore[operator]


@pytest.mark.slow
def test_a_second_ctrl_c_while_the_table_is_written_leaves_the_whole_table(tmp_path: Path) -> None:
    """The command, interrupted in a solve, then again while it writes its table: exit 130,
    one line, and the table holds every row of the journal."""
    out, announce = tmp_path / "run", tmp_path / "writing"
    cmd = [sys.executable, "-c", SLOW_WRITER, str(announce), "run", "counterexample", "--size", "3", "--seeds", "0",
           "--solvers", f"pk,{helpers.__name__}:HangingStub", "--reference", "none", "--no-warmup",
           "--timeout", "600", "--no-progress", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]), "CI": "true"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        wait_for(lambda: (out / ROWS_FILE).exists() and len(read_journal(out / ROWS_FILE)) >= 1, proc)
        time.sleep(0.3)  # (the hanging solve is under way)
        os.kill(proc.pid, signal.SIGINT)
        wait_for(announce.exists, proc)
        os.kill(proc.pid, signal.SIGINT)
        assert proc.wait(timeout=60) == 130
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    err = proc.stderr.read().decode() if proc.stderr else ""
    assert "interrupted: " in err and "Traceback" not in err, err
    assert (out / PARQUET_FILE).exists()
    recorded = {r["cell_id"] for r in read_journal(out / ROWS_FILE)}
    assert recorded and set(load_table(out / PARQUET_FILE)["cell_id"]) == recorded
    assert not (out / LOCK_FILE).exists()


def test_a_signal_held_back_is_acted_on_after_the_block() -> None:
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with signals_deferred():
            signal.raise_signal(signal.SIGINT)
            steps.append("the block ran to its end")
    assert steps == ["the block ran to its end"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


class InterruptedAfterOneJob(SerialExecutor):
    """Runs the first job, then stops as Ctrl-C stops a run."""

    def execute(self, jobs: Sequence[InstanceJob], run: RunConfig, store: ResultStore, statuses: dict[str, str],
                progress: Any, verbose: bool = False) -> None:
        super().execute(jobs[:1], run, store, statuses, progress, verbose)
        raise KeyboardInterrupt


def test_a_run_interrupted_again_while_it_writes_its_table_writes_it_whole(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    written = store_module.write_table

    def interrupted_again(*args: Any) -> None:
        signal.raise_signal(signal.SIGINT)
        written(*args)

    monkeypatch.setattr(store_module, "write_table", interrupted_again)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        run_benchmark(["counterexample"], SceneConfig(size=3, seeds=(0, 1)), ["pk"],
                      RunConfig(progress=False, reference="none"), out, command=["pytest"],
                      executor=InterruptedAfterOneJob())
    recorded = {r["cell_id"] for r in read_journal(out / ROWS_FILE)}
    assert recorded and set(load_table(out / PARQUET_FILE)["cell_id"]) == recorded
