"""A whole number a user writes outside the command line (CONTACTBENCH_FFT_WORKERS) is
read by the command line's rule (``problems.units.plain_int``, the whole-number sibling
of ``plain_float``): ASCII digits with an optional sign, no underscores, no exponent;
anything else, and a thread count below 1 or above ``fft_threads.MAX_THREADS``, is a
one-line ``ProblemInputError`` naming the variable; ``run --threads`` has the same bound."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness.arguments import plain_number
from contactbench.harness.run.plan import RunConfig
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.fft_threads import MAX_THREADS, fft_workers
from contactbench.problems.units import plain_int
from tests.helpers import run_cli

WRITTEN = ["10", "+4", " 3 ", "1_0", "1e1", " 1e1", "1.5", "١٠", "0x10", "ten", ""]


@pytest.mark.parametrize("text", WRITTEN)
def test_a_whole_number_is_read_as_the_command_line_reads_one(text: str) -> None:
    try:
        expected: int | None = plain_number(text, int)
    except ValueError:
        expected = None
    try:
        got: int | None = plain_int(text)
    except ValueError:
        got = None
    assert got == expected


@pytest.mark.parametrize("text, workers", [("10", 10), ("+4", 4), (" 3 ", 3)])
def test_the_fft_threads_take_a_plainly_written_count(text: str, workers: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", text)
    assert fft_workers() == workers


@pytest.mark.parametrize("text", ["1_0", "1e1", " 1e1", "١٠", "0", "-2"])
def test_the_fft_threads_refuse_what_the_command_line_refuses_in_one_line(text: str,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", text)
    with pytest.raises(ProblemInputError, match="CONTACTBENCH_FFT_WORKERS") as refused:
        fft_workers()
    assert "\n" not in str(refused.value)


@pytest.mark.parametrize("text", [str(MAX_THREADS + 1), str(2**64), "1" + "0" * 30])
def test_the_fft_threads_refuse_a_count_above_the_most_threads_in_one_line(text: str,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", text)
    with pytest.raises(ProblemInputError, match=f"CONTACTBENCH_FFT_WORKERS.*from 1 to {MAX_THREADS}") as refused:
        fft_workers()
    assert "\n" not in str(refused.value)


def test_the_fft_threads_take_the_most_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", str(MAX_THREADS))
    assert fft_workers() == MAX_THREADS


@pytest.mark.parametrize("threads", [MAX_THREADS + 1, 2**64, 10**30])
def test_run_threads_above_the_most_threads_is_one_line_exit_2_before_anything_is_written(
        threads: int, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match=rf"--threads.*from 1 to {MAX_THREADS}"):
        RunConfig(threads_per_worker=threads)
    rc, _, err = run_cli(["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "pk", "--reference",
                          "none", "--no-progress", "--threads", str(threads), "--out", "o"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "--threads" in err, (rc, err)
    assert not (in_tmp / "o").exists()
