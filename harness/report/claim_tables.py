"""Reading a results table for the claims ledger (``harness.report.claims``) and for the
report's readings that state its verdicts: which label plays each of the paper's methods
(``PAPER_ROLES``, ``LEDGER_ROLES``, ``by_role``), the rows the ledger reads
(``ledger_rows``), the seeds a measurement rests on, a condition's rows, and each solver
label's totals over the steps (``totals``) and their ratios (``ratio``).

This module and claim_measures.py are the one home of these measurements: claims.py and
the report's sections import them; they import no section."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..table.schema import ANSWERED, CELL_COLUMNS
from .claim_rules import Timing, relative_range
from .core import natural_key, parse_json, per_cell

# ---------------------------------------------------------------------------
# The paper's algorithms: found by base_solver and params, never by label
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PaperRole:
    """How to find one of the paper's algorithms in a table: its registry name, the
    paper's parameter values (keys absent from a row's ``params`` take the solver's
    defaults, which are the paper's), and whether the role is the warm-started run.
    ``warm=False``: cold runs first, a warm-started one only when there is no cold one;
    ``warm=True``: warm-started runs only."""

    label: str
    base_solver: str
    params: dict[str, Any] = field(default_factory=dict)
    warm: bool = False


PAPER_ROLES: dict[str, PaperRole] = {
    "nnls-gp": PaperRole("NNLS+GP", "nnls-gp", {"K": 100}),
    "nnls": PaperRole("NNLS", "nnls"),
    "pk": PaperRole("P&K 1999", "pk"),
    "pk-printed": PaperRole("P&K as printed (the paper's Algorithm 2)", "pk-printed"),
    "pk-warm": PaperRole("P&K 1999 + warm start", "pk", warm=True),
    "greedy-cg": PaperRole("greedy CG", "greedy-cg"),
    "greedy-gs": PaperRole("greedy Gauss-Seidel", "greedy-gs"),
    "greedy-chol": PaperRole("greedy Cholesky", "greedy-chol"),
    "admm": PaperRole("ADMM", "admm"),
}


def _params_match(params: Any, wanted: dict[str, Any]) -> bool:
    p = parse_json(params, {})
    return isinstance(p, dict) and all(p.get(k, v) == v for k, v in wanted.items())


def resolve_role(curves: pd.DataFrame, role: str | PaperRole) -> str | None:
    """The ``solver`` label that plays ``role`` (a key of PAPER_ROLES, or a role), or None.

    ``curves`` has one row per label (or more; duplicates are ignored) with columns
    ``solver``, ``base_solver``, ``params`` and, optionally, ``warm`` (the label is a
    warm-started run).  Among the role's base solver's labels the one with the paper's
    parameters wins, then the natural order of the labels."""
    r = PAPER_ROLES[role] if isinstance(role, str) else role
    c = curves[curves["base_solver"] == r.base_solver]
    warm = c["warm"].astype(bool) if "warm" in c.columns else pd.Series(False, index=c.index)
    if r.warm:
        c, warm = c[warm], warm[warm]
    ranked = sorted(((bool(w) != r.warm, not _params_match(p, r.params), natural_key(s), s)
                     for s, p, w in zip(c["solver"], c["params"], warm)))
    return ranked[0][-1] if ranked else None


def paper_roles(curves: pd.DataFrame) -> dict[str, str | None]:
    """Every role of PAPER_ROLES resolved in ``curves`` (see resolve_role)."""
    return {k: resolve_role(curves, k) for k in PAPER_ROLES}


#: The paper's methods as the claims ledger compares them: its algorithms (PAPER_ROLES but
#: the warm-started P&K) and pure accelerated GP; each key is the method's registry name.
LEDGER_ROLES: dict[str, PaperRole] = {**{k: r for k, r in PAPER_ROLES.items() if not r.warm},
                                      "gp": PaperRole("accelerated GP", "gp")}


def by_role(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with, in each scene, the label of each of the paper's methods (``LEDGER_ROLES``,
    found by ``base_solver`` and ``params``: ``resolve_role``, with the paper's parameter
    values only, never another variant) replaced by the role's key, and any other label
    that spells a key marked with its base solver (``"pk (bvls)"``): a label is never taken
    for the method it names."""
    parts = []
    for _, r in rows.groupby("scene", sort=False, dropna=False):
        curves = r.drop_duplicates("solver")
        params = dict(zip(curves["solver"], curves["params"]))
        players = {s: k for k, role in LEDGER_ROLES.items()
                   if (s := resolve_role(curves, role)) is not None and _params_match(params[s], role.params)}
        bases = dict(zip(curves["solver"], curves["base_solver"]))
        name = {s: players.get(s, f"{s} ({bases[s]})" if s in LEDGER_ROLES else s) for s in curves["solver"]}
        parts.append(r.assign(solver=r["solver"].map(name)))
    return pd.concat(parts) if parts else rows


#: The numbers of an answer a claim rests on (``with_numbers``).
MEASURED_COLUMNS: tuple[str, ...] = ("solve_time_s", "iterations", "load", "contact_fraction")


def with_numbers(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with each answered row lacking a finite ``MEASURED_COLUMNS`` number (or with
    a negative time) read as failed: a sum or median over the rest would be a verdict."""
    cols = [c for c in MEASURED_COLUMNS if c in rows.columns]
    values = rows[cols].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    times = values[:, cols.index("solve_time_s")] if "solve_time_s" in cols else np.zeros(len(rows))
    lacking = ~np.isfinite(values).all(axis=1) | (times < 0)
    bad = rows["status"].isin(ANSWERED).to_numpy() & lacking
    return rows.assign(status=rows["status"].mask(bad, "failed"))


def ledger_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows as the claims ledger reads them: ``with_numbers``, then ``by_role`` (the
    paper's methods under their registry names, never by label)."""
    return by_role(with_numbers(rows))


# ---------------------------------------------------------------------------
# Seeds, conditions, totals and ratios
# ---------------------------------------------------------------------------


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
#: The scene of the independent (cold, from p = 0) solves: the ledger reads Fig. 4's P&K, P&K
#: as printed and greedy CG on it, and Fig. 6's K sweep where it has one.
COLD_SCENE = "greedy-linear-solvers"
#: The suffix of a label read from the independent (cold) solves of ``COLD_SCENE``.
COLD = " cold"


def repeat_totals(rows: pd.DataFrame) -> pd.Series:
    """Per (solver, repeat) of the rows: the repeat's total solve time over the steps (NaN
    where a step has none; a table without ``repeat`` is one repeat, 0)."""
    rep = rows.assign(repeat=rows["repeat"] if "repeat" in rows.columns else 0)
    return rep.groupby(["solver", "repeat"])["solve_time_s"].agg(lambda v: v.sum(skipna=False))


def spent_seconds(rows: pd.DataFrame) -> pd.Series:
    """Per solver label of the (unfolded) rows: a lower bound of its total solve time over the
    steps -- per cell (its repeats), the least time of a repeat that answered, else the most
    time a repeat ran before it stopped (a timeout's limit; a row with no time counts 0)."""
    keys = [c for c in CELL_COLUMNS if c in rows.columns]
    t = pd.to_numeric(rows["solve_time_s"], errors="coerce").fillna(0.0)
    r = rows.assign(_t=t, _answered=t.where(rows["status"].isin(ANSWERED)))
    g = r.groupby(keys, sort=False, dropna=False)
    cell = g["_answered"].min().fillna(g["_t"].max())
    return cell.groupby(level="solver").sum()


def totals(rows: pd.DataFrame) -> pd.DataFrame:
    """Per solver label of the (unfolded) rows: the total solve time over the steps, as the
    median over the timed repeats of each repeat's sum (``repeats``, ``spread``: their count
    and relative range); operator products and iterations (``matvecs``, ``iterations``: the
    time's load-independent witnesses), steps, steps answered and steps solved.  A total is
    ``comparable`` when every step of the largest count returned an answer; ``spent_s`` is
    ``spent_seconds``, a lower bound of the total of a solver that stopped."""
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
    out["spent_s"] = spent_seconds(rows)
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
