"""What a solver prints during ``run`` goes to the run folder's solver-output log, bounded
(the head of each output kept, what was dropped counted), never to the terminal -- the
output of a solve the run is stopped in (Ctrl-C) too, marked so; the harness's own
messages and the summary stay on the terminal."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from contactbench.harness import cli, run_benchmark
from contactbench.harness.run.executors import PoolExecutor
from contactbench.harness.run.output_log import ENTRY_HEAD_BYTES, OUTPUT_LOG, STOPPED, OutputLog, dropped_line
from contactbench.harness.table.store import PARQUET_FILE
from contactbench.harness.run.plan import RunConfig
from contactbench.problems.scenes import SceneConfig
from contactbench.solvers import Capabilities, Outcome, ProblemTraits, SolveContext, Solver, register, unregister

#: How much the test solver prints to Python's stdout in one solve (over an entry's head).
LOUD_BYTES = 200_000


class Chatty(Solver):
    """Prints through every route a solver has: Python's streams, the descriptors, a child
    process, and its skip check (run in the harness's process); answers p = 0, unclaimed."""

    name = "test-chatty"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}))

    def skip(self, traits: ProblemTraits) -> str | None:
        print("chatty-skip-check")
        return None

    def iterate(self, ctx: SolveContext) -> Outcome:
        print("chatty-stderr", file=sys.stderr, flush=True)
        os.write(1, b"chatty-descriptor\n")
        os.system("echo chatty-child-process")
        sys.stdout.write("y" * LOUD_BYTES)
        return Outcome(np.zeros(ctx.n), 1, False)


@pytest.fixture
def chatty() -> Iterator[str]:
    register(Chatty, replace=True)
    yield Chatty.name
    unregister(Chatty.name)


class Interrupting(Solver):
    """Prints, over an entry's head, then stops the run as Ctrl-C does (SIGINT to the
    harness's process, ``harness_pid``: set before the run, a forked worker inherits it)
    and hangs until its worker is killed."""

    name = "test-interrupting"
    family = "test"
    harness_pid = 0

    def iterate(self, ctx: SolveContext) -> Outcome:
        print("printed-before-the-interrupt")
        sys.stdout.write("y" * LOUD_BYTES)
        sys.stdout.flush()
        os.kill(self.harness_pid, signal.SIGINT)
        time.sleep(60)
        return Outcome(np.zeros(ctx.n), 1, False)


@pytest.fixture
def interrupting() -> Iterator[str]:
    register(Interrupting, replace=True)
    Interrupting.harness_pid = os.getpid()
    yield Interrupting.name
    unregister(Interrupting.name)


def small_run(out: Path, solver: str, **executor: object) -> None:
    run_benchmark(["counterexample"], SceneConfig(size=10, seeds=(0,)), [solver],
                  RunConfig(progress=False, warmup=False, reference="none"), out, command=["pytest"], **executor)


def test_a_solvers_output_goes_to_the_run_log_not_the_terminal(tmp_path: Path, chatty: str,
                                                              capfd: pytest.CaptureFixture[str]) -> None:
    small_run(tmp_path / "r", chatty)
    seen = capfd.readouterr()
    assert "chatty" not in seen.out + seen.err and "yyyy" not in seen.out + seen.err
    text = (tmp_path / "r" / OUTPUT_LOG).read_text()
    for said in ("chatty-stderr", "chatty-descriptor", "chatty-child-process", "chatty-skip-check"):
        assert said in text, said
    assert f"more bytes dropped: an entry keeps the first {ENTRY_HEAD_BYTES}" in text
    assert os.path.getsize(tmp_path / "r" / OUTPUT_LOG) < LOUD_BYTES  # the head only
    assert json.loads((tmp_path / "r" / "meta.json").read_text())["solver_output"] == OUTPUT_LOG


def test_a_pool_process_writes_its_solvers_output_to_the_same_log(tmp_path: Path, chatty: str,
                                                                  capfd: pytest.CaptureFixture[str]) -> None:
    run_benchmark(["counterexample"], SceneConfig(size=10, seeds=(0, 1)), [chatty],
                  RunConfig(progress=False, warmup=False, reference="none", jobs=2), tmp_path / "r",
                  command=["pytest"], executor=PoolExecutor(2))
    seen = capfd.readouterr()
    assert "chatty" not in seen.out + seen.err
    text = (tmp_path / "r" / OUTPUT_LOG).read_text()
    assert text.count("chatty-child-process") == 2 and "n100-s0" in text and "n100-s1" in text


def test_the_output_of_a_solve_stopped_by_ctrl_c_reaches_the_log_marked_interrupted(
        tmp_path: Path, interrupting: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A solve the run is stopped in: its output so far is an entry of the log (the head
    only), its title marked interrupted; a second Ctrl-C while it is written waits for it,
    and the run's table is written."""
    appended = OutputLog.append

    def interrupted_again(log: OutputLog, title: str, source: Path) -> None:
        if title.endswith(STOPPED):
            signal.raise_signal(signal.SIGINT)
        appended(log, title, source)

    monkeypatch.setattr(OutputLog, "append", interrupted_again)
    with pytest.raises(KeyboardInterrupt):
        small_run(tmp_path / "r", interrupting)
    text = (tmp_path / "r" / OUTPUT_LOG).read_text() if (tmp_path / "r" / OUTPUT_LOG).exists() else ""
    title = next((line for line in text.splitlines() if line.startswith("==> ")), "")
    assert STOPPED in title and "printed-before-the-interrupt" in text, text[:500]
    assert f"more bytes dropped: an entry keeps the first {ENTRY_HEAD_BYTES}" in text
    assert os.path.getsize(tmp_path / "r" / OUTPUT_LOG) < LOUD_BYTES  # the head only
    assert (tmp_path / "r" / PARQUET_FILE).exists()


def test_the_output_of_a_pool_solve_stopped_by_ctrl_c_reaches_the_log_marked_interrupted(
        tmp_path: Path, interrupting: str) -> None:
    """With ``--jobs 2``, Ctrl-C stops each pool process's job as a serial run's is
    stopped: the output of the solves it was in joins the log, marked interrupted, and the
    run's table is written."""
    with pytest.raises(KeyboardInterrupt):
        run_benchmark(["counterexample"], SceneConfig(size=10, seeds=(0, 1)), [interrupting],
                      RunConfig(progress=False, warmup=False, reference="none", jobs=2), tmp_path / "r",
                      command=["pytest"], executor=PoolExecutor(2))
    text = (tmp_path / "r" / OUTPUT_LOG).read_text() if (tmp_path / "r" / OUTPUT_LOG).exists() else ""
    titles = [line for line in text.splitlines() if line.startswith("==> ")]
    assert titles and all(STOPPED in title for title in titles), text[:500]
    assert text.count("printed-before-the-interrupt") == len(titles)
    assert (tmp_path / "r" / PARQUET_FILE).exists()


def test_an_entry_keeps_the_head_and_counts_what_it_dropped(tmp_path: Path) -> None:
    source = tmp_path / "out.txt"
    source.write_bytes(b"a" * 100 + b"b" * 50)
    log = OutputLog(tmp_path / "log", entry_head=100, cap=10_000)
    log.append("one", source)
    text = log.path.read_text()
    assert "a" * 100 in text and "b" not in text.replace("bytes", "")
    assert "(150 bytes)" in text and "50 more bytes dropped" in text


def test_a_full_log_takes_no_more_entries_and_counts_them_in_its_last_line(tmp_path: Path) -> None:
    source = tmp_path / "out.txt"
    source.write_bytes(b"z" * 300)
    log = OutputLog(tmp_path / "log", entry_head=400, cap=1000)
    for _ in range(5):
        log.append("again", source)
    data = log.path.read_bytes()
    assert data.count(b"==> again") == 3  # three entries fit under the cap
    assert data.endswith(dropped_line(1000, 600, 2))
    assert len(data) <= 1000 + len(dropped_line(1000, 0, 0))


def test_an_empty_output_adds_no_entry(tmp_path: Path) -> None:
    source = tmp_path / "out.txt"
    source.write_bytes(b"")
    log = OutputLog(tmp_path / "log")
    log.append("quiet", source)
    assert not log.path.exists()


def test_output_that_reads_as_the_full_log_s_last_line_does_not_fill_it(tmp_path: Path) -> None:
    """A solver that prints the log's own "full" line cannot make the log refuse the
    entries after it (other solvers' output included)."""
    forged, plain = tmp_path / "forged.txt", tmp_path / "plain.txt"
    forged.write_bytes(b"hello\n" + dropped_line(10_000, 0, 0))
    plain.write_bytes(b"later\n")
    log = OutputLog(tmp_path / "log", cap=10_000)
    log.append("forger", forged)
    for _ in range(3):
        log.append("after", plain)
    assert log.path.read_bytes().count(b"==> after") == 3


def test_a_log_that_is_a_link_or_a_folder_is_refused_before_anything_runs(tmp_path: Path) -> None:
    """The run never writes its log through a link (to a file that may not be the run's),
    and says so in one line, exit 2, before any solve."""
    victim = tmp_path / "victim.txt"
    victim.write_text("mine\n")
    args = ["run", "counterexample", "--size", "10", "--seeds", "0", "--solvers", "test-exact", "--reference", "none",
            "--no-progress", "--out"]
    for k, make in enumerate((lambda p: p.symlink_to(victim), lambda p: p.mkdir())):
        out = tmp_path / f"run{k}"
        out.mkdir()
        make(out / OUTPUT_LOG)
        assert cli.main([*args, str(out)]) == 2
        assert victim.read_text() == "mine\n" and not (out / "rows.jsonl").exists()
    with pytest.raises(OSError):  # and the writer itself does not follow one
        link = tmp_path / "log-link"
        link.symlink_to(victim)
        source = tmp_path / "out.txt"
        source.write_bytes(b"x\n")
        OutputLog(link).append("t", source)
    assert victim.read_text() == "mine\n"
