"""The store reads what it wrote, checked: a hand-edited journal or table never slips a
value past the table contract, and a cell is never counted twice.

* a resume of a folder whose rows.jsonl breaks the contract (an unknown status, text in a
  number column) is refused in one line naming rows.jsonl, exit 2, the folder untouched;
  the tables are never rewritten with text read as a missing number;
* journal lines that are JSON but not an object, or that Python cannot read (not UTF-8, nested or
  numbered past its reader), are ignored; a row without
  ``cell_id`` is refused in one line naming rows.jsonl and the line;
* ``load_table`` keeps the first row of each cell of a results.parquet / results.csv, as
  the journal reader does; rows without a cell id are told apart by the cell's columns
  and their repeat (``schema.CELL_COLUMNS``), the first of each kept;
* ``RunLock`` leaves a run.lock that is not a lock record as it is."""

from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from contactbench.harness import cli, run_benchmark
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.table import store as store_module
from contactbench.harness.table.store import LOCK_FILE, ROWS_FILE, ResultStore, RunLock, load_table
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig

SOLVER = "test-exact"
RUN = RunConfig(reference="none", warmup=False, progress=False)
ARGS = ["counterexample", "--size", "3", "--seeds", "0-1", "--solvers", SOLVER, "--reference", "none",
        "--no-warmup", "--no-progress"]


@pytest.fixture(scope="module")
def genuine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished run of two cells (the command line's, so that ``ARGS`` resumes it)."""
    out = tmp_path_factory.mktemp("genuine") / "run"
    assert cli.main(["run", *ARGS, "--out", str(out)]) == 0
    return out


def copy_of(genuine: Path, tmp_path: Path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(genuine, out)
    return out


def journal(out: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (out / ROWS_FILE).read_text().splitlines()]


def write_journal(out: Path, rows: list[Any], extra: str = "") -> None:
    (out / ROWS_FILE).write_text("".join(json.dumps(r) + "\n" for r in rows) + extra)


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(("column", "value", "words"), [("status", "banana", "banana"),
                                                         ("solve_time_s", "fast", "'fast', not a number"),
                                                         ("iterations", True, "True, a true/false value")])
def test_a_resume_of_a_hand_edited_journal_is_refused_untouched(genuine: Path, tmp_path: Path, column: str,
                                                                 value: object, words: str,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = copy_of(genuine, tmp_path)
    rows = journal(out)
    rows[1][column] = value
    write_journal(out, rows)
    untouched = snapshot(out)
    capsys.readouterr()
    assert cli.main(["run", *ARGS, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ROWS_FILE in err and words in err
    assert snapshot(out) == untouched  # no table rewritten, no marker, no lock, no meta.json
    with pytest.raises(ProblemInputError, match=words):  # the API's resume, and the report's reader
        run_benchmark(["counterexample"], SceneConfig(size=3, seeds=(0, 1)), [SOLVER], RUN, out)
    with pytest.raises(ValueError, match=words):
        load_table(out)
    assert snapshot(out) == untouched


def test_finalize_never_reads_text_as_a_missing_number(genuine: Path, tmp_path: Path) -> None:
    out = copy_of(genuine, tmp_path)
    rows = journal(out)
    rows[0]["solve_time_s"] = "fast"
    write_journal(out, rows)
    untouched = snapshot(out)
    with pytest.raises(ProblemInputError, match="'fast', not a number"):
        ResultStore(out, load=False).finalize()
    assert snapshot(out) == untouched


def test_journal_lines_that_are_not_objects_are_ignored(genuine: Path, tmp_path: Path) -> None:
    out = copy_of(genuine, tmp_path)
    rows = journal(out)
    write_journal(out, rows, extra='[1, 2, 3]\n"text"\nNaN\n12\nnull\n')
    assert len(ResultStore(out)) == 2
    table = load_table(out)  # (the journal is newer than the table: it is read)
    assert sorted(table["cell_id"]) == sorted(r["cell_id"] for r in rows)


@pytest.mark.parametrize("line", [b"caf\xe9\n", b"[" * 100_000 + b"\n", b'{"x": 1' + b"0" * 5000 + b"}\n"],
                         ids=["not-utf8", "nested-deep", "number-too-long"])
def test_journal_lines_python_cannot_read_are_ignored_and_resumed_over(genuine: Path, tmp_path: Path,
                                                                        line: bytes) -> None:
    out = copy_of(genuine, tmp_path)
    rows = journal(out)
    with open(out / ROWS_FILE, "ab") as fh:
        fh.write(line)
    assert len(ResultStore(out)) == 2
    assert sorted(load_table(out)["cell_id"]) == sorted(r["cell_id"] for r in rows)
    assert cli.main(["run", *ARGS, "--out", str(out)]) == 0  # (a resume: nothing left to run)
    assert sorted(load_table(out)["cell_id"]) == sorted(r["cell_id"] for r in rows)


@pytest.mark.parametrize("cell_id", [None, "", 7, "drop"])
def test_a_journal_row_without_a_cell_id_is_one_line_naming_it(genuine: Path, tmp_path: Path,
                                                               cell_id: Any) -> None:
    out = copy_of(genuine, tmp_path)
    rows = journal(out)
    odd = dict(rows[0], cell_id=cell_id)
    if cell_id == "drop":
        del odd["cell_id"]
    write_journal(out, [rows[0], odd, rows[1]])
    for read in (lambda: ResultStore(out), lambda: load_table(out)):
        with pytest.raises(ProblemInputError) as info:
            read()
        assert "\n" not in str(info.value) and f"{ROWS_FILE} line 2" in str(info.value)
        assert "cell_id" in str(info.value)


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_load_table_keeps_the_first_row_of_each_cell(genuine: Path, tmp_path: Path, suffix: str) -> None:
    table = load_table(genuine)
    assert set(table["status"]) == {"solved"} and table["cell_id"].nunique() == 2
    failed = table.assign(status="failed", verdict="")  # each cell again, failed: the first row stands
    doubled = pd.concat([table, failed, table], ignore_index=True)
    path = tmp_path / f"results{suffix}"
    doubled.to_parquet(path, index=False) if suffix == ".parquet" else doubled.to_csv(path, index=False)
    got = load_table(path)
    assert len(got) == 2 and set(got["status"]) == {"solved"}
    anonymous = doubled.assign(cell_id="")  # a table without cell ids: told apart by the cells' columns
    path2 = tmp_path / f"anonymous{suffix}"
    anonymous.to_parquet(path2, index=False) if suffix == ".parquet" else anonymous.to_csv(path2, index=False)
    got = load_table(path2)
    assert len(got) == 2 and set(got["status"]) == {"solved"}


def test_a_duplicated_cell_in_a_run_folder_table_counts_once(genuine: Path, tmp_path: Path) -> None:
    out = copy_of(genuine, tmp_path)
    table = pd.read_parquet(out / "results.parquet")
    pd.concat([table, table.assign(status="failed", verdict="")], ignore_index=True).to_parquet(out / "results.parquet")
    got = load_table(out)
    assert len(got) == 2 and set(got["status"]) == {"solved"}


@pytest.mark.parametrize("text", ["my notes\n", "12345"])
def test_run_lock_leaves_a_file_that_is_not_a_lock_record(tmp_path: Path, text: str) -> None:
    folder = tmp_path / "theirs"
    folder.mkdir()
    (folder / LOCK_FILE).write_text(text)
    with pytest.raises(ProblemInputError, match="not a contactbench lock"):
        with RunLock(folder):
            pass
    assert (folder / LOCK_FILE).read_text() == text


def test_a_row_the_disk_takes_only_part_of_is_cut_back_and_the_error_names_the_journal(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk mid-row: the part written is cut back (no torn line for the next row to
    join) and the ``OSError`` names rows.jsonl."""
    store = ResultStore(tmp_path)
    store.append({"cell_id": "a", "status": "skipped", "skip_reason": "x"})
    before = (tmp_path / ROWS_FILE).read_bytes()
    calls: list[int] = []
    real_write = os.write

    def half_then_full(fd: int, data: bytes) -> int:
        calls.append(len(data))
        if len(calls) == 1:
            return real_write(fd, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(store_module.os, "write", half_then_full)
    with pytest.raises(OSError) as full:
        store.append({"cell_id": "b", "status": "skipped", "skip_reason": "x"})
    monkeypatch.undo()
    assert full.value.errno == errno.ENOSPC and full.value.filename == str(tmp_path / ROWS_FILE)
    assert (tmp_path / ROWS_FILE).read_bytes() == before
    store.append({"cell_id": "c", "status": "skipped", "skip_reason": "x"})
    assert [r["cell_id"] for r in ResultStore(tmp_path).rows()] == ["a", "c"]
