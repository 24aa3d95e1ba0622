"""The resumable result store: one JSON line per finished solve, then a tidy table.

Layout of a run directory ``OUT/``::

    rows.jsonl        the journal: one JSON object per row, appended and fsync'ed as
                      each solve finishes (the source of truth)
    results.parquet   the tidy table (harness/schema.py), regenerated from the journal;
                      read it with ``schema.load_table`` (also importable from here)
    results.csv       the same table as CSV
    meta.json         run metadata (harness/meta.py)
    _cache/           reference solutions, one file per instance-step

Crash safety: a row is appended with one ``write`` under an exclusive ``flock`` and
fsync'ed, so concurrent writers (``--jobs``, Dask workers on a shared file system) do not
interleave.  A ``kill -9`` can leave at most a partial last line; it is cut off when
the store is next opened.  Rows are identified by ``cell_id``; reading keeps the first
row of each cell, so a cell is never counted twice.
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from .schema import apply_schema, load_table  # noqa: F401  (re-exported: the one table reader)

ROWS_FILE = "rows.jsonl"
PARQUET_FILE = "results.parquet"
CSV_FILE = "results.csv"

#: Columns that identify a group of repeats (everything that names the solve but ``repeat``).
GROUP_COLUMNS = ("scene", "instance", "step", "solver", "base_solver", "params", "profile", "warm_start", "history")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def encode_row(row: dict[str, Any]) -> str:
    """One journal line (NaN is kept as the JSON extension ``NaN``)."""
    return json.dumps(row, default=_json_default, allow_nan=True) + "\n"


def repair_journal(path: Path) -> int:
    """Cut a partial last line (left by a kill mid-write).  Returns bytes removed."""
    if not path.exists():
        return 0
    with open(path, "rb+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            data = fh.read()
            if not data or data.endswith(b"\n"):
                return 0
            keep = data.rfind(b"\n") + 1
            fh.truncate(keep)
            return len(data) - keep
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def read_journal(path: Path) -> list[dict[str, Any]]:
    """Rows of a journal, first occurrence per cell_id, unparsable lines ignored."""
    rows: list[dict[str, Any]] = []
    seen: set[str] = set()
    if not path.exists():
        return rows
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            line = line.strip()
            if not line:
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            cid = row.get("cell_id")
            if cid in seen:
                continue
            seen.add(cid)
            rows.append(row)
    return rows


class ResultStore:
    """Append-only journal of rows with the set of finished cells."""

    def __init__(self, out_dir: str | os.PathLike[str], load: bool = True) -> None:
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / ROWS_FILE
        self._status: dict[str, str] = {}
        if load:
            repair_journal(self.path)
            for row in read_journal(self.path):
                self._status[row["cell_id"]] = row.get("status", "")

    @property
    def cache_dir(self) -> Path:
        d = self.out / "_cache"
        d.mkdir(parents=True, exist_ok=True)
        return d

    def done(self) -> set[str]:
        return set(self._status)

    def done_statuses(self) -> dict[str, str]:
        """cell_id -> status of every stored row."""
        return dict(self._status)

    def status_of(self, cell_id: str) -> str | None:
        return self._status.get(cell_id)

    def __contains__(self, cell_id: str) -> bool:
        return cell_id in self._status

    def __len__(self) -> int:
        return len(self._status)

    def append(self, row: dict[str, Any]) -> None:
        """Write one row durably (flock + single write + fsync)."""
        line = encode_row(row).encode("utf-8")
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            try:
                os.write(fd, line)
                os.fsync(fd)
            finally:
                fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
        self._status[str(row["cell_id"])] = str(row.get("status", ""))

    def count_lines(self) -> int:
        """Rows in the journal right now (cheap; used for progress across processes)."""
        if not self.path.exists():
            return 0
        with open(self.path, "rb") as fh:
            return sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 20), b""))

    def rows(self) -> list[dict[str, Any]]:
        return read_journal(self.path)

    def finalize(self) -> pd.DataFrame:
        """Regenerate results.parquet and results.csv from the journal."""
        table = tidy_table(self.rows())
        write_table(table, self.out)
        return table


def tidy_table(rows: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """The tidy table: every column of the schema with its dtype, repeat min/median filled."""
    df = apply_schema(pd.DataFrame(list(rows)))
    if len(df):
        fill_repeat_statistics(df)
        df = df.sort_values(["scene", "instance", "step", "solver", "profile", "repeat"], kind="stable")
        df = df.reset_index(drop=True)
    return df


def fill_repeat_statistics(df: pd.DataFrame) -> None:
    """solve_time_min_s / solve_time_median_s over the repeats of each group (rows
    that ran to an answer only: solved or inaccurate)."""
    ran = df["status"].isin(["solved", "inaccurate"]) & df["solve_time_s"].notna()
    keys = [df[c].astype("string").fillna("") for c in GROUP_COLUMNS]
    grouped = df["solve_time_s"].where(ran).groupby(keys, dropna=False)
    df["solve_time_min_s"] = grouped.transform("min")
    df["solve_time_median_s"] = grouped.transform("median")


def write_table(table: pd.DataFrame, out_dir: str | os.PathLike[str]) -> None:
    """results.parquet and results.csv, each written to a temporary file then renamed."""
    out = Path(out_dir)
    tmp_pq = out / (PARQUET_FILE + ".tmp")
    tmp_csv = out / (CSV_FILE + ".tmp")
    table.to_parquet(tmp_pq, index=False)
    table.to_csv(tmp_csv, index=False)
    os.replace(tmp_pq, out / PARQUET_FILE)
    os.replace(tmp_csv, out / CSV_FILE)
