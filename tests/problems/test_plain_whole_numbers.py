"""A whole number a user writes outside the command line (CONTACTBENCH_FFT_WORKERS) is
read by the command line's rule (``problems.units.plain_int``, the whole-number sibling
of ``plain_float``): ASCII digits with an optional sign, no underscores, no exponent;
anything else, and a thread count below 1, is a one-line ``ProblemInputError`` naming the
variable."""

from __future__ import annotations

import pytest

from contactbench.harness.arguments import plain_number
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.fft_threads import fft_workers
from contactbench.problems.units import plain_int

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
