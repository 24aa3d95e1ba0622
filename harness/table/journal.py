"""The journal of a results folder, OUT/rows.jsonl (harness/table/store.py's module doc):
one JSON object per row, written by ``encode_row``, a partial last line cut by
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

from .schema import CHECKED_COLUMNS, TableError, as_text, check_table


def _json_default(obj: Any) -> Any:
    return obj.tolist() if isinstance(obj, (np.generic, np.ndarray)) else str(obj)


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
