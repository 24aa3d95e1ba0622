"""The claims ledger's measurements that the report's readings also state (one home each):
claims.py builds its rows from them, and the paper sections (sections/paper_conditions.py,
sections/paper.py) call the same functions on the same rows (``claim_tables.ledger_rows``),
so a reading that gives the ledger's verdict cannot drift from it.

* a tie among timed totals: ``Spread``, ``tied_with`` (a ratio the timing spread cannot
  tell from 1);
* Fig. 5: ``paired_median_ratio`` and ``fig5_measure`` -- per condition and grid size, the
  median over the (instance, step) both solved with n >= ``FIG5_MIN_N`` of t_a / t_b, taken
  on each timed repeat apart, the median over the repeats;
* Fig. 6: ``k_of``, ``k_sweep_rows`` (the K sweep the ledger reads: the cold one of
  ``claim_tables.COLD_SCENE`` where the table has one, else ``gp-k-sweep``),
  ``k_sweep_totals`` and ``best_k`` (the K of least median total, the Ks not told from it
  and the timing it is judged with);
* Fig. 4's ADMM: ``is_papers_admm``, ``papers_admm`` (ADMM as the paper states it, the only
  one the ledger reads).

The totals over repeats and their ratios are claim_tables.py's (``totals``, ``ratio``);
the verdict is claim_rules.py's (``judge_timed``).  This module imports no section."""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .claim_rules import CLAIMS, SINGLE_REPEAT_SPREAD, Timing, judged_spread, over_repeats
from .claim_tables import COLD_SCENE, plays, ratio, repeat_totals, totals
from .core import natural_key, parse_json, per_cell

# ---------------------------------------------------------------------------
# A tie among timed totals
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Spread:
    """The relative spread ``s`` a time ratio is read with, and the number of timed
    ``repeats`` it comes from (1: none measured, ``SINGLE_REPEAT_SPREAD``; 0: no timing)."""

    s: float = 0.0
    repeats: int = 0

    @property
    def source(self) -> str:
        """Where the spread comes from, in words."""
        return "single repeats" if self.repeats <= 1 else f"{self.repeats} repeats"

    def ties(self, ratio: float) -> bool:
        """Whether the spread cannot tell ``ratio`` from 1 (a tie): 1 / (1 + s) <= ratio
        <= 1 + s, for a finite positive ratio and a positive spread."""
        if not (self.s > 0.0 and math.isfinite(ratio) and ratio > 0.0):
            return False
        return abs(math.log(ratio)) <= math.log1p(self.s) * (1.0 + 1e-12)

    def tie_text(self) -> str:
        """The verdict of a tie."""
        return f"unresolved (a tie within the timing spread of {self.source})"


#: The spread of timings from a single repeat (no spread measured).
SINGLE = Spread(SINGLE_REPEAT_SPREAD, 1)
#: No timing spread: a ratio that is not a timing (iterations, a count).
EXACT = Spread()


def tied_with(times: pd.Series, best: Hashable, spread_of: Callable[[Hashable, Hashable], Spread]) -> list[Hashable]:
    """The labels of ``times`` (label -> time) other than ``best`` whose time the spread
    (``spread_of(label, best)``, of the ratio of the label's time to best's) cannot tell
    from ``best``'s, fastest first."""
    t0 = float(times[best])
    out = [(float(t), s) for s, t in times.items()
           if s != best and t0 > 0 and spread_of(s, best).ties(float(t) / t0)]
    return [s for _, s in sorted(out, key=lambda x: x[0])]


@dataclass(frozen=True)
class Measure:
    """One measurement the ledger judges: the ``measured`` value, the number of steps it
    rests on (``count``; 0: none, so no verdict) and its ``timing`` over the repeats."""

    measured: float
    count: int
    timing: Timing


# ---------------------------------------------------------------------------
# Fig. 5: the paired median over the steps both solved
# ---------------------------------------------------------------------------

#: Fig. 5's ratios are read over steps with at least this trial-set size (below it fixed
#: per-solve costs dominate).
FIG5_MIN_N = 100


def paired_median_ratio(cells: pd.DataFrame, a: str | None, b: str | None, min_n: float = 0.0
                        ) -> tuple[float, int, int]:
    """Median over the (instance, step) cells both ``a`` and ``b`` solved (b's time
    positive; trial-set size n at least ``min_n``) of t_a / t_b, the number of those cells,
    and the number of instances they come from; (NaN, 0, 0) when either is None or none is
    common."""
    if a is None or b is None:
        return float("nan"), 0, 0
    ok = cells[cells["solved"] & (cells["n"] >= min_n)] if min_n > 0 else cells[cells["solved"]]
    ka = ok[ok["solver"] == a].set_index(["instance", "step"])["solve_time_s"]
    kb = ok[ok["solver"] == b].set_index(["instance", "step"])["solve_time_s"]
    j = pd.concat([ka.rename("a"), kb.rename("b")], axis=1, join="inner").dropna()
    j = j[j["b"] > 0]
    if not len(j):
        return float("nan"), 0, 0
    return float(np.median(j["a"] / j["b"])), len(j), int(j.index.get_level_values("instance").nunique())


def fig5_measure(rows: pd.DataFrame, a: str, b: str) -> Measure | None:
    """Fig. 5's t_a / t_b over the attempted ``rows`` of one condition and grid size: the
    ``paired_median_ratio`` over the steps with n >= ``FIG5_MIN_N`` (``count``: how many),
    taken on each timed repeat's rows apart, the median over them; its timing the fewest
    repeats of a's and b's cells and the repeats' relative range.  None where a or b has no
    row."""
    cells = per_cell(rows)
    if cells.empty or not {a, b} <= set(cells["solver"]):
        return None
    count = paired_median_ratio(cells, a, b, FIG5_MIN_N)[1]
    m, s = over_repeats(rows, lambda g: paired_median_ratio(per_cell(g), a, b, FIG5_MIN_N)[0])
    reps = int(cells[cells["solver"].isin([a, b])]["repeats"].min())
    return Measure(m, count, Timing(reps, s))


# ---------------------------------------------------------------------------
# Fig. 6: the K of least total
# ---------------------------------------------------------------------------

#: The scenes the ledger reads Fig. 6's K sweep on, first found first, and whether the
#: sweep is cold (every K from p = 0, the paper's; ``gp-k-sweep`` is warm along the history).
K_SWEEP_SCENES: tuple[tuple[str, bool], ...] = ((COLD_SCENE, True), ("gp-k-sweep", False))


def k_of(row: pd.Series) -> float:
    """The GP step count K of a variant, from its ``params`` JSON {"K": ...}; NaN when absent."""
    p = parse_json(row.get("params", ""), {})
    try:
        return float(p["K"]) if isinstance(p, dict) and "K" in p else float("nan")
    except (TypeError, ValueError):
        return float("nan")


def k_sweep_rows(rows: pd.DataFrame) -> tuple[pd.DataFrame, bool]:
    """The K sweep the ledger reads Fig. 6 on among the attempted ``rows`` of one condition:
    the NNLS+GP rows with a K (column ``K``: ``k_of``) of the first scene of
    ``K_SWEEP_SCENES`` that has more than one K, and whether that sweep is cold; (no rows,
    False) where none has."""
    for scene, cold in K_SWEEP_SCENES:
        r = rows[(rows["scene"] == scene) & (rows["base_solver"] == "nnls-gp")]
        if r.empty:
            continue
        r = r.assign(K=r.apply(k_of, axis=1))
        r = r[r["K"].notna()]
        if r["K"].nunique() > 1:
            return r, cold
    return rows.iloc[0:0].assign(K=pd.Series(dtype=float)), False


def k_sweep_totals(sweep: pd.DataFrame) -> tuple[pd.DataFrame, pd.Series]:
    """Per label of a ``k_sweep_rows`` sweep: ``claim_tables.totals`` with its ``K``; and
    each label's ``repeat_totals`` (per (label, repeat))."""
    return totals(sweep).join(sweep.groupby("solver")["K"].first()), repeat_totals(sweep)


def k_labels(tot: pd.DataFrame) -> dict[float, str]:
    """K -> its label in ``k_sweep_totals``."""
    return {float(k): str(s) for s, k in zip(tot.index, tot["K"])}


def best_k(tot: pd.DataFrame, per_repeat: pd.Series) -> tuple[float, list[float], Timing] | None:
    """Fig. 6's K of least median total over ``k_sweep_totals`` (``tot``, ``per_repeat``);
    the Ks not told from it: a timed repeat's own least, a K whose ``ratio`` to the least
    its spread cannot tell from 1 (``tied_with``); the timing it is judged with: spread 0
    where they all read one verdict of ``fig6-best-k``'s rule, else infinite (unresolved,
    ``claim_rules.judged_spread``).  None where some K did not answer every step (the
    least is not known)."""
    comp = tot[tot["comparable"]]
    if comp.empty or not set(tot["K"]) <= set(comp["K"]):
        return None
    label = k_labels(comp)
    times = comp.set_index(comp["K"].astype(float))["total_s"]
    best = float(times.idxmin())

    def spread_of(k: Hashable, b: Hashable) -> Spread:
        t = ratio(comp, label[float(k)], label[float(b)])[2]  # type: ignore[arg-type]
        return Spread(judged_spread(t), t.repeats)

    each = per_repeat[per_repeat.index.get_level_values(0).isin(comp.index)].unstack(0).dropna()  # repeat x label
    firsts = [float(comp.loc[s, "K"]) for s in each.idxmin(axis=1)]
    near = sorted({*map(float, tied_with(times, best, spread_of)), *firsts} - {best})
    agree = len({CLAIMS["fig6-best-k"].rule.at(k) for k in (best, *near)}) == 1
    return best, near, Timing(int(comp["repeats"].min()), 0.0 if agree else math.inf)


# ---------------------------------------------------------------------------
# Fig. 4: ADMM as the paper states it
# ---------------------------------------------------------------------------


def is_papers_admm(params: object) -> bool:
    """Whether a row's ``params`` make ADMM as the paper states it (``PAPER_PARAMS``, every
    other parameter at the registry's default): the only ADMM the ledger reads; the
    registry's ``admm`` (rho relative to mean diag H, the KKT stop) is another method."""
    return plays("admm", params)  # (``claim_tables.PAPER_ROLES["admm"]``: the one home of the fact)


def papers_admm(rows: pd.DataFrame) -> str | None:
    """The label of ADMM as the paper states it (``is_papers_admm``) among ``rows`` (columns
    ``solver``, ``base_solver``, ``params``), the first in natural order; None where none."""
    a = rows[rows["base_solver"] == "admm"].drop_duplicates("solver")
    paper = sorted((str(s) for s, p in zip(a["solver"], a["params"]) if is_papers_admm(p)), key=natural_key)
    return paper[0] if paper else None
