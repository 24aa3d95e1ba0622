"""What a program writes into its solution directory is read within bounds
(``problems.qpfile.read_solution_dir``): every field of solution.json by its rule, a value
no rule admits a ``SolutionFileError`` naming the field, never another exception; a file is
read through one open file, never past its bound."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from contactbench.problems import qpfile
from contactbench.problems.qpfile import SolutionFileError, read_solution_dir


def solution(d: Path, report: str | None, p: bytes | None = None) -> Path:
    d.mkdir()
    (d / "p.f64").write_bytes(np.ones(3, dtype="<f8").tobytes() if p is None else p)
    if report is not None:
        (d / "solution.json").write_text(report)
    return d


@pytest.mark.parametrize("report, words", [
    ('{"iterations": 1e300}', "iterations 1e+300 is not a whole number from 0 to"),
    ('{"iterations": 1' + "0" * 300 + "}", "iterations 1000"),
    ('{"iterations": 1e400}', "iterations inf is not a whole number"),
    ('{"iterations": -5}', "iterations -5 is not"),
    ('{"iterations": 12.7}', "iterations 12.7 is not"),
    ('{"iterations": true}', "iterations True is not"),
    ('{"iterations": "12"}', "iterations '12' is not"),
    ('{"iterations": NaN}', "iterations nan is not"),
    ('{"time_s": 1' + "0" * 400 + "}", "time_s 1000"),
    ('{"time_s": -1}', "time_s -1 is not a finite number of seconds >= 0"),
    ('{"time_s": Infinity}', "time_s inf is not"),
    ('{"time_s": "fast"}', "time_s 'fast' is not"),
    ('{"multiplier": NaN}', "multiplier nan is not a finite number"),
    ('{"multiplier": [1]}', "multiplier [1] is not"),
    ('{"iterations": 1' + "0" * 5000 + "}", "solution.json is unreadable"),
    ('{"x": ' + "[" * 100_000 + "]" * 100_000 + "}", "nest deeper"),
    ('{"status": "converged", "status": "failed"}', "the key 'status' is given twice"),
])
def test_a_report_field_no_rule_admits_is_named_in_one_line(tmp_path: Path, report: str, words: str) -> None:
    with pytest.raises(SolutionFileError) as err:
        read_solution_dir(solution(tmp_path / "s", report), 3)
    line = str(err.value)
    assert words in line and len(line.splitlines()) == 1 and len(line) < 400, line


def test_whole_counts_and_finite_numbers_are_read(tmp_path: Path) -> None:
    sol = read_solution_dir(solution(tmp_path / "s", '{"iterations": 12.0, "time_s": 0, "multiplier": -2, '
                                                     '"status": "converged"}'), 3)
    assert sol.iterations == 12 and isinstance(sol.iterations, int) and sol.time_s == 0.0
    assert sol.multiplier == -2.0 and sol.claims_converged


def test_a_file_past_its_bound_is_refused_having_read_at_most_one_byte_more(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bound = 8 * (4 * 3 + 1024)
    d = solution(tmp_path / "s", None, p=b"\0" * (bound * 50))
    read: list[int] = []
    real_read = os.read

    def counted(fd: int, size: int) -> bytes:
        chunk = real_read(fd, size)
        read.append(len(chunk))
        return chunk

    monkeypatch.setattr(qpfile.os, "read", counted)
    with pytest.raises(SolutionFileError, match=f"more than the {bound} bytes it may hold"):
        read_solution_dir(d, 3)
    assert sum(read) == bound + 1


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_pipe_or_a_device_in_place_of_p_is_not_read(tmp_path: Path) -> None:
    fifo = tmp_path / "f"
    fifo.mkdir()
    os.mkfifo(fifo / "p.f64")
    with pytest.raises(SolutionFileError, match="not a regular file"):
        read_solution_dir(fifo, 3)  # (opened without waiting for a writer)
    if Path("/dev/zero").exists():
        dev = tmp_path / "d"
        dev.mkdir()
        (dev / "p.f64").symlink_to("/dev/zero")
        with pytest.raises(SolutionFileError, match="not a regular file"):
            read_solution_dir(dev, 3)


@pytest.mark.parametrize("report, words", [
    ('{"stauts": "max_iter"}', "unknown key(s) 'stauts'"),
    ('{"Status": "max_iter"}', "unknown key(s) 'Status'"),
    ('{"result": {"status": "max_iter"}}', "unknown key(s) 'result'"),
    ('{"residual": 1e-9}', "unknown key(s) 'residual'"),
    ('{"status": null}', "status is null"),
    ('{"iterations": null, "status": "max_iter"}', "iterations is null"),
])
def test_a_key_the_protocol_does_not_know_or_a_null_is_named_not_read_as_a_claim(
        tmp_path: Path, report: str, words: str) -> None:
    with pytest.raises(SolutionFileError) as err:
        read_solution_dir(solution(tmp_path / "s", report), 3)
    assert words in str(err.value) and len(str(err.value).splitlines()) == 1, err.value


@pytest.mark.parametrize("n", [3, 4])
@pytest.mark.parametrize("as_written", [False, True])
def test_a_float32_answer_is_named_whatever_the_parity_of_n(tmp_path: Path, n: int, as_written: bool) -> None:
    d = tmp_path / "s"
    d.mkdir()
    (d / "p.f64").write_bytes(np.ones(n, dtype="<f4").tobytes())  # 4 n bytes
    with pytest.raises(SolutionFileError, match=r"looks like float32 \(4 n bytes\); write float64") as err:
        read_solution_dir(d, n, as_written=as_written)
    assert len(str(err.value).splitlines()) == 1


def test_a_report_with_a_utf8_byte_order_mark_is_read(tmp_path: Path) -> None:
    d = solution(tmp_path / "s", None)
    (d / "solution.json").write_bytes(b'\xef\xbb\xbf{"status": "max_iter", "iterations": 4}')
    sol = read_solution_dir(d, 3)
    assert sol.status == "max_iter" and sol.iterations == 4 and not sol.claims_converged


@pytest.mark.parametrize("codec", ["utf-16", "utf-16-be"])
def test_a_utf16_report_is_named_as_such(tmp_path: Path, codec: str) -> None:
    d = solution(tmp_path / "s", None)
    text = '{"status": "max_iter"}'
    (d / "solution.json").write_bytes(("\ufeff" + text).encode(codec) if codec.endswith("be") else text.encode(codec))
    with pytest.raises(SolutionFileError, match="UTF-16"):
        read_solution_dir(d, 3)
