"""Reading a results folder's table files (harness/table/store.py's ``load_table``):
results.csv as written (``read_csv``, refusing a cut-short file: ``cut_row``), the cell
ids a journal names, read without parsing its rows (``journal_cell_ids``), which rows of a
table are the first of their cell (``first_rows``), and the journal a results.parquet was
made from (``journal_stamp``, kept in the parquet's metadata by ``write_parquet`` and read
back by ``parquet_stamp``).  Reading never writes.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
from pathlib import Path
from typing import Any

from contactbench.problems.atomic_files import literal_path

import pandas as pd

from .journal import first_of_each_cell
from .schema import CELL_COLUMNS, TableError, columns_of, text_values


def read_csv(path: Path) -> pd.DataFrame:
    """results.csv as written; ``TableError`` naming the file for one whose last row is cut
    short (``cut_row``: a parser error too, where the cut falls inside a quoted field) or
    that cannot be read as such (not text, not CSV)."""
    head: Any = ()
    try:
        text = {c: "string" for c in columns_of("string")}
        head = pd.read_csv(literal_path(path), nrows=0).columns
        df = pd.read_csv(literal_path(path), dtype={c: t for c, t in text.items() if c in head}, keep_default_na=True)
    except (UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        cut = cut_row(path, len(head)) if len(head) and not isinstance(exc, UnicodeDecodeError) else None
        if cut is None:
            lines = str(exc).splitlines()
            raise TableError(f"{path} cannot be read as a results table ({type(exc).__name__}"
                             f"{': ' + lines[0] if lines else ''})") from None
    else:
        cut = cut_row(path, len(head))
        if cut is None:
            return df
    raise TableError(f"{path} ends in the middle of its row {cut} (a truncated table?): "
                     "restore it, or remove it to read the run's rows.jsonl")


def cut_row(path: Path, fields: int) -> int | None:
    """The data row (from 1) the CSV file ends in the middle of: a file that does not end its
    last row with a newline, whose last record has fewer than ``fields`` fields; else None
    (None too for a file the CSV reader cannot read to its end)."""
    with open(path, "rb") as f:
        if f.seek(0, os.SEEK_END) == 0:
            return None
        f.seek(-1, os.SEEK_END)
        if f.read(1) == b"\n":
            return None
    last: list[str] = []
    records = 0
    try:
        with open(path, newline="", encoding="utf-8") as f:
            for records, last in enumerate(csv.reader(f), 1):
                pass
    except (csv.Error, UnicodeDecodeError):  # (no CSV text: not a cut row)
        return None
    return records - 1 if len(last) < fields else None


#: A ``"cell_id": "<JSON string>"`` member in a journal's text.  In JSON text a quoted
#: ``"cell_id"`` followed by a colon can only be a key.
_CELL_ID = re.compile(rb'"cell_id"\s*:\s*"((?:[^"\\\n]|\\.)*)"')


def journal_cell_ids(path: Path) -> set[str]:
    """Every cell id the journal at ``path`` names, found in its bytes (one read, no row
    parsed).  It holds each cell id ``journal.read_journal`` keeps, and may hold more: one
    on a line that reader ignores (a torn write) or of a nested object; so a table whose
    cell ids are exactly this set holds every row of the journal (``store._read_run_dir``)."""
    ids = set()
    for raw in _CELL_ID.findall(path.read_bytes()):
        try:
            ids.add(json.loads(b'"' + raw + b'"') if b"\\" in raw else raw.decode("utf-8"))
        except (ValueError, UnicodeDecodeError):  # (unreadable: no row of read_journal's)
            ids.add("\0unreadable")
    return ids


def cell_keys(df: pd.DataFrame) -> tuple[list[str], list[tuple[str, ...]]]:
    """The columns that name a row's cell (``schema.CELL_COLUMNS`` and ``repeat``, those
    ``df`` has) and, per row, their values as text: two rows are of one cell when they agree."""
    names = [c for c in (*CELL_COLUMNS, "repeat") if c in df.columns]
    return names, list(zip(*(text_values(df[c]) for c in names))) if names else [()] * len(df)


def check_cell_ids(df: pd.DataFrame, where: object) -> None:
    """Refuse (``TableError``) a table two of whose rows share a ``cell_id`` but name other
    cells (their ``schema.CELL_COLUMNS`` or ``repeat`` differ): reading keeps the first row
    of a cell, so the other would vanish unsaid -- a row edited or merged by hand.  Rows of
    one cell that agree (a resumed run's repeat) pass."""
    ids = text_values(df["cell_id"]) if "cell_id" in df.columns else [""] * len(df)
    names, cells = cell_keys(df)
    first: dict[str, tuple[int, tuple[str, ...]]] = {}
    for i, (cid, cell) in enumerate(zip(ids, cells)):
        if not cid:
            continue
        j, seen = first.setdefault(cid, (i, cell))
        if seen != cell:
            apart = next(f"{n} {a!r} against {b!r}" for n, a, b in zip(names, seen, cell) if a != b)
            raise TableError(f"rows {j + 1} and {i + 1} of {where} share cell_id {cid} but name other cells "
                             f"({apart}): edited or merged by hand; give each cell its own id")


def first_rows(df: pd.DataFrame) -> list[bool]:
    """For each row of ``df`` (a table after ``schema.apply_schema``), in order, whether
    reading keeps it: the first row of each cell.  Two rows are of one cell when their
    ``cell_id`` agree, or when one has none (missing or "") and their cell columns
    (``schema.CELL_COLUMNS``) and ``repeat`` agree; so a table without cell ids whose rows
    repeat counts each cell once, as a journal does."""
    ids = text_values(df["cell_id"])
    if all(ids):
        return first_of_each_cell(ids)
    _, cells = cell_keys(df)
    seen_ids: set[str] = set()
    cells_with_id: set[tuple[str, ...]] = set()
    cells_without: set[tuple[str, ...]] = set()
    keep = []
    for cid, cell in zip(ids, cells):
        if cid:
            kept = cid not in seen_ids and cell not in cells_without
            seen_ids.add(cid)
            if kept:
                cells_with_id.add(cell)
        else:
            kept = cell not in cells_without and cell not in cells_with_id
            cells_without.add(cell)
        keep.append(kept)
    return keep


#: The key of a results.parquet's metadata holding the stamp of the journal it was made from.
STAMP_KEY = b"contactbench_journal"
#: The bytes a journal's stamp reads at a time.
STAMP_BLOCK = 1 << 20


def journal_stamp(path: Path) -> str:
    """The journal at ``path`` as it is now: its size and the digest of all its bytes, read
    in blocks of ``STAMP_BLOCK``.  An appended, cut, repaired or hand-edited journal -- one
    edit that keeps its size included -- or another run's, has another stamp."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(STAMP_BLOCK):
            digest.update(block)
        size = f.tell()
    return f"{size}:{digest.hexdigest()[:32]}"


def write_parquet(table: pd.DataFrame, path: str, stamp: str | None) -> None:
    """``table`` as a Parquet file at ``path`` (as ``DataFrame.to_parquet``), with the
    ``stamp`` of the journal it was made from in its metadata (``STAMP_KEY``)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = pa.Table.from_pandas(table, preserve_index=False)
    if stamp is not None:
        t = t.replace_schema_metadata({**(t.schema.metadata or {}), STAMP_KEY: stamp.encode("ascii")})
    pq.write_table(t, path)


def parquet_stamp(path: Path) -> str | None:
    """The journal stamp a results.parquet keeps (``write_parquet``), or None (a table
    written without one, or a file that is not Parquet)."""
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(literal_path(path)).metadata or {}
    except (OSError, ValueError):
        return None
    raw = meta.get(STAMP_KEY)
    return raw.decode("ascii", "replace") if raw is not None else None
