"""Reading a results table for the claims ledger (``harness.report.claims``): the seeds a
measurement rests on, a condition's rows, and each solver label's totals over the steps
(``totals``) and their ratios (``ratio``)."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import pandas as pd

from ..table.schema import ANSWERED
from .claim_rules import Timing, relative_range
from .core import per_cell
from .sections.paper import LEDGER_ROLES

def seeds_text(seeds: Iterable[int]) -> str:
    """"5", "0-99" or "0,3,7": the seeds a measurement rests on."""
    s = sorted({int(x) for x in seeds})
    if not s:
        return ""
    if len(s) > 2 and s == list(range(s[0], s[-1] + 1)):
        return f"{s[0]}-{s[-1]}"
    return ",".join(map(str, s))


def seeds_of(rows: pd.DataFrame) -> str:
    """``seeds_text`` of the rows' ``seed`` column (the instance's recipe; "" where the table
    has none)."""
    if "seed" not in rows.columns:
        return ""
    return seeds_text(pd.to_numeric(rows["seed"], errors="coerce").dropna().astype(int))


def of_condition(rows: pd.DataFrame, scene: str, condition: str) -> pd.DataFrame:
    """The attempted rows of ``scene`` under ``condition`` (column ``operator``)."""
    r = rows[(rows["scene"] == scene) & (rows["operator"] == condition)]
    return r[r["status"] != "skipped"]


#: The paper's methods (registry names): "fastest" and "the same load" compare these only.
PAPER_METHODS: frozenset[str] = frozenset(r.base_solver for r in LEDGER_ROLES.values())
#: The suffix of a label read from the independent (cold) solves of ``greedy-linear-solvers``.
COLD = " cold"


def repeat_totals(rows: pd.DataFrame, skipna: bool = False) -> pd.Series:
    """Per (solver, repeat) of the rows: the repeat's total solve time over the steps (NaN
    where a step has none, or, with ``skipna``, the time of the steps that have one; a
    table without ``repeat`` is one repeat, 0)."""
    rep = rows.assign(repeat=rows["repeat"] if "repeat" in rows.columns else 0)
    return rep.groupby(["solver", "repeat"])["solve_time_s"].agg(lambda v: v.sum(skipna=skipna))


def totals(rows: pd.DataFrame) -> pd.DataFrame:
    """Per solver label of the (unfolded) rows: the total solve time over the steps, as the
    median over the timed repeats of each repeat's sum (``repeats``, ``spread``: their count
    and relative range); operator products and iterations (``matvecs``, ``iterations``: the
    time's load-independent witnesses), steps, steps answered and steps solved.  A total is
    ``comparable`` when every step of the largest count returned an answer; ``spent_s`` is
    the median time of the steps that have one, answered or not (a lower bound of the
    total of a solver that stopped)."""
    cols = ["total_s", "spent_s", "repeats", "spread", "matvecs", "iterations", "steps", "answered", "solved",
            "comparable"]
    if rows.empty:
        return pd.DataFrame(columns=cols)
    cells = per_cell(rows)
    g = cells.groupby("solver")
    nan = pd.Series(math.nan, index=g.size().index)
    out = pd.DataFrame({"matvecs": g["matvecs"].sum(min_count=1) if "matvecs" in cells.columns else nan,
                        "iterations": g["iterations"].agg(lambda v: v.sum(skipna=False))
                        if "iterations" in cells.columns else nan,
                        "steps": g.size(), "answered": g["status"].agg(lambda s: int(s.isin(ANSWERED).sum())),
                        "solved": g["solved"].sum()})
    per = repeat_totals(rows).groupby(level=0)
    out["total_s"], out["repeats"], out["spread"] = per.median(), per.size(), per.agg(relative_range)
    out["spent_s"] = repeat_totals(rows, skipna=True).groupby(level=0).median()
    out["comparable"] = (out["answered"] == out["steps"]) & (out["steps"] == out["steps"].max())
    return out[cols]


def fmt_count(v: float) -> str:
    """A count as an integer, "?" where the table has none."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "?"
    return f"{int(x)}" if math.isfinite(x) else "?"


def ratio(tot: pd.DataFrame, a: str, b: str, of: str = "total_s") -> tuple[float, str, Timing]:
    """a / b of column ``of`` (the median total time; or ``iterations``) with the words saying
    what it rests on and its timing (NaN where either is missing or incomplete, or b is not
    positive).  The spread of a time ratio is the sum of the two totals' spreads."""
    missing = [s for s in (a, b) if s not in tot.index]
    if missing:
        return math.nan, f"no rows of {', '.join(missing)}", Timing()
    ta, tb = tot.loc[a], tot.loc[b]

    def one(label: str, t: pd.Series) -> str:
        return (f"{label} {t['total_s']:.4g} s (median of {int(t['repeats'])}), {fmt_count(t.get('matvecs'))} "
                f"matvecs, {fmt_count(t.get('iterations'))} iterations ({int(t['solved'])}/{int(t['steps'])} steps "
                f"pass the KKT check)")

    words = f"{one(a, ta)}, {one(b, tb)}"
    timing = Timing(int(min(ta["repeats"], tb["repeats"])),
                    float(ta["spread"] + tb["spread"]) if of == "total_s" else 0.0)
    if not (ta["comparable"] and tb["comparable"]) or not tb[of] > 0 or not np.isfinite([ta[of], tb[of]]).all():
        return math.nan, words + "; not every step answered", timing
    return float(ta[of] / tb[of]), words, timing


def paper_labels(tot: pd.DataFrame) -> list[str]:
    """The labels of ``tot`` that play one of the paper's methods (``by_role``: the keys of
    ``LEDGER_ROLES``, warm or cold), other variants of theirs left out."""
    return [s for s in tot.index if s.removesuffix(COLD) in LEDGER_ROLES]


def nnlsgp_cold(tot: pd.DataFrame) -> str:
    """The label of NNLS+GP (K = 100) from p = 0 (the cold K sweep), else the warm one."""
    return "nnls-gp" + COLD if "nnls-gp" + COLD in tot.index else "nnls-gp"
