"""The stored table as the report reads it (``read_table``, ``report_view``): every number a
float, every text a str, the defaults of columns older tables lack, and a solver's label
told apart by operator where one folder holds a solver on two operators at one profile
(``operator_labels``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..table.schema import COLUMNS, as_text, bool_series
from ..table.store import load_table


def read_table(out_dir: str | Path) -> pd.DataFrame:
    """The stored table (``schema.load_table``) as the report reads it: see ``report_view``."""
    return report_view(load_table(out_dir))


def report_view(df: pd.DataFrame) -> pd.DataFrame:
    """Every number as float (NaN for missing), every text as str ('' for missing),
    ``warm_start`` as bool; ``base_solver`` defaults to the label and ``history`` to
    "warm" (tables written before those columns existed); labels by operator where needed
    (``operator_labels``)."""
    d = df.copy()
    for c in COLUMNS.values():
        if c.name not in d.columns:
            d[c.name] = np.nan
        if c.dtype in ("Int64", "float64"):
            d[c.name] = pd.to_numeric(d[c.name], errors="coerce").astype(float)
        elif c.dtype == "string":
            d[c.name] = d[c.name].map(as_text)
    d["warm_start"] = bool_series(d["warm_start"]).fillna(False).astype(bool)
    d["base_solver"] = d["base_solver"].where(d["base_solver"] != "", d["solver"])
    d["history"] = d["history"].map(lambda v: v or "warm")
    d["solver"] = operator_labels(d)
    return d


def operator_labels(d: pd.DataFrame) -> pd.Series:
    """The ``solver`` column, with " [<operator>]" after the label of each row whose solver
    label ran on more than one operator at its profile in the same scene (rows that name no
    operator, skipped before a solve, keep the label; a folder that
    ``--append --operator dense`` added to): the report's tables, aggregates and figures
    then show each operator's solves apart, as the table's cells are
    (``schema.CELL_COLUMNS``).  A study that runs one solver on two operators at two
    profiles (the paper's claims) keeps its labels."""
    given = d["operator"].where(d["operator"] != "")  # (a row that ran nothing names no operator)
    mixed = given.groupby([d["scene"], d["solver"], d["profile"]], dropna=False).transform("nunique") > 1
    mixed &= given.notna()
    if not mixed.any():
        return d["solver"]
    return d["solver"].where(~mixed, d["solver"] + " [" + d["operator"] + "]")
