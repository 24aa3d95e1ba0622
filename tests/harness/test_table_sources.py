"""Which rows a stored table is read from, and that the run lock survives a signal.

* a run folder's results.parquet is read when it was made from its rows.jsonl as it is
  (its stamp), without reading the journal's rows; one copied from another run of the
  same cells is not; an unstamped one only while it holds exactly the cells its rows.jsonl
  names (and is not older by its time): a table older than its journal is
  never read, whatever the files' times say (a copy, an unpacked archive, a run killed after an interrupted one); an
  unreadable one gives way to the journal; a current one is read without parsing the
  journal's rows; reading writes nothing;
* a row without a cell id is of the cell its cell columns and ``repeat`` name: a table
  without cell ids whose rows repeat counts each cell once (the first row), as does a row
  whose cell id was blanked beside its twin;
* SIGINT / SIGTERM during ``RunLock.acquire`` or ``release`` is acted on once the lock
  file is consistent: the signal still stops the caller, and no run.lock is left."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any, Iterator

import pandas as pd
import pytest

from contactbench.harness.table import store as store_module
from contactbench.harness.table.reading import journal_cell_ids
from contactbench.harness.table.store import LOCK_FILE, PARQUET_FILE, ROWS_FILE, ResultStore, RunLock, load_table
from tests.helpers import fabricate_table


def rows(count: int) -> list[dict[str, Any]]:
    """``count`` valid rows of distinct cells, with cell ids c0, c1, ..."""
    table = fabricate_table().head(count)
    return table.assign(cell_id=[f"c{i}" for i in range(count)]).to_dict("records")


def files_of(folder: Path) -> dict[str, tuple[int, int]]:
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.iterdir()}


@pytest.fixture
def stale(tmp_path: Path) -> Path:
    """A run folder whose table holds 3 of its journal's 5 rows, the table's file time the
    newer (as ``cp -r`` or an archive can leave it)."""
    store = ResultStore(tmp_path / "run")
    made = rows(5)
    for r in made[:3]:
        store.append(r)
    store.finalize()
    for r in made[3:]:
        store.append(r)
    future = (store.path.stat().st_mtime + 100,) * 2
    os.utime(store.out / PARQUET_FILE, future)
    return store.out


def test_a_table_older_than_its_journal_is_not_read_whatever_its_time(stale: Path) -> None:
    before = files_of(stale)
    table = load_table(stale)
    assert sorted(table["cell_id"]) == [f"c{i}" for i in range(5)]
    assert files_of(stale) == before  # reading never writes


def test_a_journal_line_torn_or_unreadable_does_not_hide_a_row(stale: Path) -> None:
    with open(stale / ROWS_FILE, "ab") as fh:
        fh.write(b'{"cell_id": "c9", "scene": "x"')  # a kill mid-write: the reader ignores it
    assert "c9" in journal_cell_ids(stale / ROWS_FILE)
    assert sorted(load_table(stale)["cell_id"]) == [f"c{i}" for i in range(5)]
    (stale / PARQUET_FILE).write_bytes(b"not a parquet file")
    assert sorted(load_table(stale)["cell_id"]) == [f"c{i}" for i in range(5)]


def test_a_current_table_is_read_without_parsing_the_journal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    store = ResultStore(tmp_path / "run")
    for r in rows(4):
        store.append(r)
    store.finalize()
    table = pd.read_parquet(store.out / PARQUET_FILE)
    table.assign(host="from-the-table").to_parquet(store.out / PARQUET_FILE, index=False)
    os.utime(store.out / PARQUET_FILE, (store.path.stat().st_mtime,) * 2)  # (a coarse clock: the same time)

    def parsed(path: Path) -> list[dict[str, Any]]:
        raise AssertionError(f"{path} parsed although the table holds its cells")

    monkeypatch.setattr(store_module, "checked_journal", parsed)
    got = load_table(store.out)
    assert len(got) == 4 and set(got["host"]) == {"from-the-table"}


def test_a_table_copied_from_another_run_of_the_same_cells_is_not_read(tmp_path: Path) -> None:
    """Two runs of one command hold the same cell ids; a results.parquet copied from the
    other run (its file time the newer) is not this journal's: the folder's own rows are
    read."""
    ours, theirs = ResultStore(tmp_path / "ours"), ResultStore(tmp_path / "theirs")
    for store, host in ((ours, "our-host"), (theirs, "their-host")):
        for r in rows(3):
            store.append(dict(r, host=host))
        store.finalize()
    (ours.out / PARQUET_FILE).write_bytes((theirs.out / PARQUET_FILE).read_bytes())
    os.utime(ours.out / PARQUET_FILE, (ours.path.stat().st_mtime + 100,) * 2)
    assert set(load_table(ours.out)["host"]) == {"our-host"}


def test_a_stamped_table_is_read_without_reading_the_journal_s_rows(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A results.parquet made from the journal as it is (its stamp: the journal's size and
    tail) is read without scanning or parsing the journal."""
    store = ResultStore(tmp_path / "run")
    for r in rows(4):
        store.append(r)
    store.finalize()

    def scanned(path: Path) -> Any:
        raise AssertionError(f"{path} read although the table was made from it")

    monkeypatch.setattr(store_module, "checked_journal", scanned)
    monkeypatch.setattr(store_module, "journal_cell_ids", scanned)
    assert len(load_table(store.out)) == 4
    monkeypatch.undo()
    store.append(dict(rows(5)[4]))  # one more row: the stamp is stale
    assert len(load_table(store.out)) == 5


def test_a_journal_whose_cell_id_has_escapes_is_matched(tmp_path: Path) -> None:
    store = ResultStore(tmp_path / "run")
    odd = ['quote " here', "back\\slash", "é-ü", "tab\there"]
    for r, cid in zip(rows(4), odd):
        store.append(dict(r, cell_id=cid))
    assert journal_cell_ids(store.path) == set(odd)


def cellless(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=["cell_id"])


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_rows_without_cell_ids_that_repeat_count_once(tmp_path: Path, fmt: str) -> None:
    table = pd.DataFrame(rows(4))
    failed = table.assign(status="failed", verdict="", kkt_error=float("nan"), p_rel_error=float("nan"))
    doubled = cellless(pd.concat([table, failed], ignore_index=True))
    path = tmp_path / f"results.{fmt}"
    doubled.to_parquet(path, index=False) if fmt == "parquet" else doubled.to_csv(path, index=False)
    got = load_table(path)
    assert len(got) == 4 and set(got["status"]) == set(table["status"])  # the first row of each cell stands
    again = cellless(pd.concat([table, table.assign(repeat=1)], ignore_index=True))  # repeats are cells of their own
    again.to_csv(tmp_path / "repeats.csv", index=False)
    assert len(load_table(tmp_path / "repeats.csv")) == 8


def test_a_row_whose_cell_id_is_blank_beside_its_twin_counts_once(tmp_path: Path) -> None:
    table = pd.DataFrame(rows(3))
    blank = table.head(1).assign(cell_id="", status="failed", verdict="")  # cell c0 again, its id blanked
    pd.concat([table, blank], ignore_index=True).to_csv(tmp_path / "after.csv", index=False)
    got = load_table(tmp_path / "after.csv")
    assert sorted(got["cell_id"]) == ["c0", "c1", "c2"] and "failed" not in set(got["status"])
    pd.concat([blank, table], ignore_index=True).to_csv(tmp_path / "before.csv", index=False)
    got = load_table(tmp_path / "before.csv")  # the first row of the cell stands: the blanked one
    assert sorted(got["cell_id"]) == ["", "c1", "c2"] and list(got["status"]).count("failed") == 1


class Stop(Exception):
    """Raised by the test's SIGTERM handler."""


@pytest.fixture
def term_raises_stop() -> Iterator[Any]:
    def handler(signum: int, frame: Any) -> None:
        raise Stop(signum)

    before = signal.signal(signal.SIGTERM, handler)
    try:
        yield handler
    finally:
        signal.signal(signal.SIGTERM, before)


def test_a_signal_while_the_lock_is_taken_leaves_no_lock_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              term_raises_stop: Any) -> None:
    claim = RunLock._claim

    def claim_then_signal(self: RunLock, fd: int) -> bool:
        won = claim(self, fd)  # run.lock now names this process
        signal.raise_signal(signal.SIGTERM)
        return won

    monkeypatch.setattr(RunLock, "_claim", claim_then_signal)
    out = tmp_path / "new"
    lock = RunLock(out)
    with pytest.raises(Stop):
        lock.acquire()
    assert not (out / LOCK_FILE).exists() and not out.exists()  # the folder the lock made is gone too
    assert lock.fd is None and str(out.resolve()) not in store_module._HELD_PATHS
    monkeypatch.setattr(RunLock, "_claim", claim)
    with RunLock(out):
        assert (out / LOCK_FILE).exists()
    assert not out.exists()


def test_a_signal_while_the_lock_is_let_go_leaves_no_lock_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               term_raises_stop: Any) -> None:
    out = tmp_path / "run"
    out.mkdir()
    lock = RunLock(out).acquire()
    current = RunLock._is_current

    def signal_then_check(self: RunLock, fd: int) -> bool:
        signal.raise_signal(signal.SIGTERM)
        return current(self, fd)

    monkeypatch.setattr(RunLock, "_is_current", signal_then_check)
    with pytest.raises(Stop):
        lock.release()
    assert not (out / LOCK_FILE).exists() and lock.fd is None
