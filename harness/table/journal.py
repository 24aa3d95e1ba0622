"""The journal of a results folder, OUT/rows.jsonl (harness/table/store.py's module doc):
one JSON object per row, written by ``encode_row`` (a row that would not read back is
stored as a failed row saying why, ``storable_row``), a partial last line cut by
``repair_journal``, read by ``read_journal`` (the first row of each cell,
``first_of_each_cell``) and checked against the table contract by ``check_journal``, once
per state of the file (``checked_journal``).
"""

from __future__ import annotations

import fcntl
import json
from pathlib import Path
from typing import Any, Iterable

from contactbench.problems.errors import ProblemInputError

import numpy as np
import pandas as pd

from .schema import CHECKED_COLUMNS, COLUMNS, TableError, as_text, check_booleans, check_numbers, check_table


def _json_default(obj: Any) -> Any:
    return obj.tolist() if isinstance(obj, (np.generic, np.ndarray)) else str(obj)


def _line(row: dict[str, Any]) -> str:
    return json.dumps(row, default=_json_default, allow_nan=True) + "\n"


def encode_row(row: dict[str, Any]) -> str:
    """One journal line (NaN is kept as the JSON extension ``NaN``) that the journal's
    readers take: a row that would not read back (``row_problem``) is written as
    ``storable_row`` makes it, never as given, and ``row`` is updated to what the line holds."""
    stored = storable_row(row)
    if stored is not row:
        row.clear()
        row.update(stored)
    return _line(row)


def row_problem(row: dict[str, Any]) -> str:
    """Why ``row``, read back from its journal line, breaks the table contract
    (``schema.check_table``, as ``check_journal`` reads it); "" where it does not."""
    try:
        check_table(pd.DataFrame.from_records([json.loads(_line(row))], columns=list(CHECKED_COLUMNS)), "the row")
    except TableError as exc:
        return str(exc)
    return ""


def _breaks(row: dict[str, Any], name: str) -> bool:
    """Whether column ``name`` of ``row`` (as read back) alone breaks its number or
    true/false rule (``schema.check_numbers``, ``schema.check_booleans``)."""
    col = pd.DataFrame.from_records([json.loads(_line({name: row[name]}))], columns=[name])[name]
    try:
        if COLUMNS[name].dtype == "boolean":
            check_booleans(col, name, "the row")
        else:
            check_numbers(col, name, "the row", whole=COLUMNS[name].dtype == "Int64")
    except TableError:
        return True
    return False


def storable_row(row: dict[str, Any]) -> dict[str, Any]:
    """``row`` itself where it reads back (``row_problem``); else a copy stored as a failed
    row, unjudged (status "failed", verdict ""), its error naming why, each number or
    true/false column that breaks its rule emptied -- and, should the row still not read
    back (a reading its figures contradict), every number and true/false column emptied.
    The harness writes no such row: a value no table can hold came from a solver."""
    why = row_problem(row)
    if not why:
        return row
    checked = [c.name for c in COLUMNS.values() if c.dtype in ("float64", "Int64", "boolean") and c.name in row]
    bad = [name for name in checked if _breaks(row, name)]
    emptied = f" (emptied: {', '.join(bad)})" if bad else ""
    stored = dict(row, status="failed", verdict="", **dict.fromkeys(bad),
                  error="; ".join(filter(None, (f"the row as made would not read back: {why}; stored as failed"
                                                f"{emptied}", as_text(row.get("error"))))))
    if row_problem(stored):
        stored.update(dict.fromkeys(checked))
    return stored


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


class JournalError(TableError, ProblemInputError):
    """A journal row breaks the contract (module doc); the command line exits 2."""


def first_of_each_cell(cell_ids: Iterable[Any]) -> list[bool]:
    """For each row, in order, whether reading keeps it: the first row of each cell id; a
    row with no cell id (missing or "": a table without the column) is always kept."""
    seen: set[str] = set()
    keep = []
    for text in map(as_text, cell_ids):
        keep.append(text == "" or text not in seen)
        seen.add(text)
    return keep


def read_journal(path: Path) -> list[dict[str, Any]]:
    """Rows of a journal, the first of each cell (``first_of_each_cell``); lines that are not
    a JSON object Python reads are ignored (a torn write, a blank line, bytes that are not
    UTF-8, nesting or a number too deep or long to read: their cells run again); a row
    without a text ``cell_id`` is a ``JournalError``."""
    rows: list[dict[str, Any]] = []
    if not path.exists():
        return rows
    with open(path, "rb") as fh:
        for number, line in enumerate(fh, 1):
            try:
                row = json.loads(line.decode("utf-8"))
            except (UnicodeDecodeError, ValueError, RecursionError):  # (JSONDecodeError is a ValueError)
                continue
            if not isinstance(row, dict):
                continue
            cid = row.get("cell_id")
            if not (isinstance(cid, str) and cid):
                raise JournalError(f"{path} line {number}: the row has no cell_id (the text id of its cell, which "
                                   "every row the run writes has); restore the line as the run wrote it")
            rows.append(row)
    return [row for row, keep in zip(rows, first_of_each_cell(r["cell_id"] for r in rows)) if keep]


def check_journal(rows: list[dict[str, Any]], path: Path) -> None:
    """``JournalError`` naming ``path`` for rows against ``schema.check_table`` (text in a
    number column is never read as missing); "row k" counts the rows ``read_journal`` keeps.
    The rows are read as a table of the columns the check reads (``schema.CHECKED_COLUMNS``;
    a column no row has is read as empty, as the table reader does)."""
    try:
        check_table(pd.DataFrame.from_records(rows, columns=list(CHECKED_COLUMNS)), path)
    except TableError as exc:
        raise JournalError(f"{exc}; restore the row as the run wrote it") from None


#: Journal -> the (inode, size, mtime) it had when its rows last passed ``check_journal``.
_CHECKED: dict[Path, tuple[int, int, int]] = {}


def checked_journal(path: Path) -> list[dict[str, Any]]:
    """``read_journal``, the rows checked (``check_journal``, once per state of the file)."""
    st = path.stat() if path.exists() else None  # (stat first: a row appended while reading changes the key)
    key = (st.st_ino, st.st_size, st.st_mtime_ns) if st else (0, 0, 0)
    rows = read_journal(path)
    if _CHECKED.get(path.absolute()) != key:
        check_journal(rows, path)
        _CHECKED[path.absolute()] = key
    return rows
