"""Which rows and solvers a paper section draws and reads, and which of the claims
ledger's measurements its readings state (sections/paper.py, sections/counterexample.py).

**The paper's methods** are found by ``claim_tables.PAPER_ROLES`` (``resolve_role``): by
the table's ``base_solver`` (registry name) and ``params`` columns, never by the solver's
label; the ledger reads them the same way (``LEDGER_ROLES``, ``by_role``).

**Conditions.**  A results table may hold a scene under several conditions: the
``paper-claims`` study runs the paper's methods on the dense H at profile ``paper`` and
the FFT solvers at ``default`` (the ledger's ``dense`` and ``fft``, harness/report/claims.py).
A paper section never drops one of them for another: ``condition_blocks`` takes, for each
operator (the table's ``operator`` column), the tightest profile its attempted rows ran
under (``core.pick_profile``), and gives one ``Block`` per profile so taken, with the
skipped rows at that profile.  A block is drawn, tabled and read on its own: one solver
at two profiles is never one curve.  A table whose operators all share their tightest
profile (every study but ``paper-claims``) gives one block, drawn as before.

**The ledger's measurements.**  The claims ledger (claims.py, claim_rules.py) is the one
home of the verdicts on the paper's claims, and claim_tables.py / claim_measures.py the
one home of its measurements: a reading states a verdict word only on the ledger's own
measurement, taken by those same functions on the rows as the ledger reads them
(``claim_tables.ledger_rows``) and judged by ``claim_rules.judge_timed`` (``fig5_ledger``,
``fig6_ledger``; Example 1: counterexample.py ``ledger_shares``, which the ledger reads) --
or, for a Fig. 4 ratio, where the ledger reads no other rows for the claim
(``fig4_elsewhere``; never for P&K, P&K as printed or greedy CG, which the ledger reads
on their cold solves only).  Where the section's own number pools otherwise it is given without a
verdict, with the ledger's row named.  A section imports claim_tables.py and
claim_measures.py, never claims.py (which imports the sections).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import pandas as pd

from ..claim_measures import best_k, fig5_measure, k_of, k_sweep_rows, k_sweep_totals, papers_admm
from ..claim_rules import judge_timed
from ..claim_tables import COLD_SCENE, ledger_rows
from ..core import attempted, natural_key, pick_profile, profile_rank
from ..markdown_text import md_code
from .paper_readings import LedgerReading

# ---------------------------------------------------------------------------
# Conditions: one block per operator's tightest profile
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Block:
    """The rows of a scene a paper section draws under one profile: ``rows`` (skipped ones
    included) of the ``operators`` whose tightest profile is ``profile``; ``alone`` when it
    is the scene's only block."""

    profile: str
    operators: tuple[str, ...]
    rows: pd.DataFrame = field(repr=False)
    alone: bool = True

    @property
    def where(self) -> str:
        """"operator `dense`, profile `paper`": the condition in words."""
        ops = [md_code(o) for o in self.operators if o]
        return (f"operator{'s' if len(ops) > 1 else ''} {', '.join(ops)}, " if ops else "") + f"profile `{self.profile}`"

    @property
    def profile_text(self) -> str:
        """"profile `high`" for a scene's only block, else ``where``: what a caption says."""
        return f"profile `{self.profile}`" if self.alone else self.where

    def name(self, base: str) -> str:
        """The figure name of the block: ``base``, with the profile appended where the scene
        has several blocks."""
        return base if self.alone else f"{base}-{self.profile}"

    def lead(self) -> str:
        """The line that opens the block in a scene of several blocks ("" for the only one)."""
        return "" if self.alone else f"**Condition: {self.where}.**\n\n"


def operators_of(rows: pd.DataFrame) -> pd.Series:
    """The ``operator`` of each row as text ("" where none: a skipped row)."""
    return rows["operator"].fillna("").astype(str) if "operator" in rows.columns else pd.Series("", index=rows.index)


def tightest_by_operator(rows: pd.DataFrame) -> dict[str, str]:
    """Each operator of the attempted ``rows`` -> the tightest profile it ran under."""
    att = attempted(rows)
    return {str(op): pick_profile(g) for op, g in att.groupby(operators_of(att), sort=True)}


def condition_blocks(rows: pd.DataFrame) -> list[Block]:
    """The blocks of a scene's ``rows`` (module doc), tightest profile first: the attempted
    rows of each operator at its tightest profile, and the skipped rows at that profile of
    the solvers that ran in no other block.  No attempted row: one block of no rows."""
    chosen = tightest_by_operator(rows)
    if not chosen:
        return [Block("", (), rows.iloc[0:0])]
    profiles = sorted(set(chosen.values()), key=profile_rank)
    ops = operators_of(rows)
    skipped = rows["status"] == "skipped"
    kept = ~skipped & (rows["profile"] == ops.map(chosen))
    ran = {p: set(rows.loc[kept & (rows["profile"] == p), "solver"]) for p in profiles}
    blocks = []
    for p in profiles:
        elsewhere = set().union(*(ran[q] for q in profiles if q != p)) - ran[p]
        mine = (kept | (skipped & ~rows["solver"].isin(elsewhere))) & (rows["profile"] == p)
        blocks.append(Block(p, tuple(o for o in sorted(chosen) if chosen[o] == p), rows[mine], len(profiles) == 1))
    return blocks


def absent(table: pd.DataFrame, scene: str, base_solver: str, block: Block) -> str:
    """Where a method of the paper (``base_solver``) that a block lacks did run: "is not in
    this table", "did not run in this scene (its rows are in ...)" or "did not run under
    this condition (...)" -- never "not in this table" of a method the table holds."""
    mine = attempted(table[table["base_solver"] == base_solver])
    if mine.empty:
        return "is not in this table"
    if (mine["scene"] == scene).any():
        return f"did not run under this condition ({block.where}; it ran under another)"
    scenes = ", ".join(md_code(s) for s in sorted(set(mine["scene"]), key=natural_key))
    return f"did not run in this scene (its rows are in {scenes})"


# ---------------------------------------------------------------------------
# Fig. 4: where the ledger reads a ratio on other rows
# ---------------------------------------------------------------------------


#: The paper's methods whose Fig. 4 ratio to NNLS+GP the ledger reads only on their cold
#: solves of ``COLD_SCENE`` (claims.py ``FIG4_RATIOS``, ``top_step_rows``), never on a sweep.
COLD_READ: frozenset[str] = frozenset({"pk", "pk-printed", "greedy-cg"})


def fig4_elsewhere(table: pd.DataFrame, sweep: pd.DataFrame, base_solver: str, operators: Iterable[str]) -> str:
    """Why Fig. 4's reading gives no verdict of its own on the ratio of ``base_solver`` to
    NNLS+GP over the attempted ``sweep`` rows of one block ("" where it may give one).
    The ledger (claims.py ``fig4_rows``) reads each grid size N apart, and reads P&K, P&K as
    printed and greedy CG on their cold solves of ``COLD_SCENE`` at the sweep's instances;
    ``operators``: those the two solvers ran on (the ledger compares within one).  For a
    method of ``COLD_READ`` it is never "": the sweep's solves are not the ledger's cold ones."""
    ops = sorted(set(operators))
    sizes = sorted(int(n) for n in sweep["N"].dropna().unique())
    if len(sizes) > 1:
        return (f"summed over the grid sizes N = {', '.join(map(str, sizes))}, which the claims ledger reads one "
                f"at a time")
    if len(ops) > 1:
        return f"the two ran on different operators ({', '.join(ops)}), which the claims ledger never compares"
    t = attempted(table[(table["scene"] == COLD_SCENE) & (table["base_solver"] == base_solver)])
    cold = t[operators_of(t).isin(ops) & t["N"].isin(sizes) & t["instance"].isin(set(sweep["instance"]))]
    if len(cold):
        return f"the claims ledger reads this claim on {md_code(base_solver)}'s cold solves of `{COLD_SCENE}`"
    if base_solver in COLD_READ:
        return (f"the claims ledger reads this claim on {md_code(base_solver)}'s cold solves of `{COLD_SCENE}` "
                f"(every solve from p = 0), not on this sweep, and this table has none at these instances")
    return ""


def paper_admm(cells: pd.DataFrame) -> tuple[str | None, str | None]:
    """Among ``cells`` (columns ``solver``, ``base_solver``, ``params``), the label of ADMM
    as the paper states it (``claim_measures.papers_admm``) and, where there is none, that of
    another ADMM (None where none)."""
    paper = papers_admm(cells)
    other = sorted(set(cells.loc[cells["base_solver"] == "admm", "solver"]), key=natural_key)
    return paper, (None if paper or not other else other[0])


# ---------------------------------------------------------------------------
# Fig. 5 and Fig. 6 as the ledger reads them
# ---------------------------------------------------------------------------


def fig5_ledger(rows: pd.DataFrame, a: str, b: str, claim: str) -> list[LedgerReading]:
    """claims.py ``fig5_rows`` on the rows of one scene: per operator and grid size N,
    ``claim_measures.fig5_measure`` of the methods ``a`` and ``b`` (keys of
    ``claim_tables.LEDGER_ROLES``) on the ledger's rows, and the verdict of ledger row
    ``claim``.  (The ledger reads every profile of an operator; a block holds one.)"""
    r = ledger_rows(attempted(rows))
    out = []
    for op, ro in r.groupby(operators_of(r), sort=True):
        for N in sorted(ro["N"].dropna().unique()):
            x = fig5_measure(ro[ro["N"] == N], a, b)
            if x is not None:
                verdict = judge_timed(claim, x.measured, "steps" if x.count else "", x.timing)
                out.append(LedgerReading(str(op), int(N), x.measured, x.count, x.timing.repeats, verdict))
    return out


def cold_k_sweep(table: pd.DataFrame, operator: str) -> bool:
    """Whether the ledger reads Fig. 6 under ``operator`` on the cold K sweep of
    ``COLD_SCENE`` (``claim_measures.k_sweep_rows``)."""
    return k_sweep_rows(attempted(table[operators_of(table) == operator]))[1]


def fig6_elsewhere(table: pd.DataFrame, rows: pd.DataFrame, readings: int) -> str:
    """Why Fig. 6's reading of the K sweep ``rows`` gives no verdict ("" where it gives the
    ledger's, on ``readings`` = 1 reading of ``fig6_ledger``): the ledger reads the cold K
    sweep of ``COLD_SCENE`` where the table has one under the operator, and reads each
    operator apart."""
    mine = rows[rows["base_solver"] == "nnls-gp"]
    ops = sorted(set(operators_of(mine)))
    if mine.empty or mine.apply(k_of, axis=1).dropna().nunique() < 2:
        return "one K ran, so there is no least to place"
    if any(cold_k_sweep(table, op) for op in ops):
        return (f"the claims ledger reads this claim on the cold K sweep of `{COLD_SCENE}` (every K from p = 0), "
                f"not on this sweep")
    if readings > 1:
        return f"the K variants ran on several operators ({', '.join(ops)}), which the claims ledger reads apart"
    return ""


def fig6_ledger(rows: pd.DataFrame) -> list[LedgerReading]:
    """claims.py's ``fig6-best-k`` on the rows of one K sweep, per operator: the K of least
    total, the Ks not told from it (``near``) and the verdict, by ``claim_measures.best_k``
    on the ledger's rows.  None for an operator where some K did not answer every step (the
    least is not known) or one K ran."""
    r = ledger_rows(attempted(rows))
    out = []
    for op, ro in r.groupby(operators_of(r), sort=True):
        sweep = k_sweep_rows(ro)[0]
        least = best_k(*k_sweep_totals(sweep)) if len(sweep) else None
        if least is None:
            continue
        best, near, timing = least
        out.append(LedgerReading(str(op), 0, best, len(sweep[["instance", "step"]].drop_duplicates()), timing.repeats,
                                 judge_timed("fig6-best-k", best, "K sweep", timing), tuple(near)))
    return out
