"""Which profile Fig. 4 (sections/paper.py) draws, for each operator of the sweep.

A sweep may run at several profiles, and not every solver at each: a run of three solvers
at ``low`` and ``mid`` with one more run of P&K alone at ``high``.  Fig. 4 compares its
solvers, so it draws, per operator (the table's ``operator`` column, paper_conditions.py's
conditions), the tightest profile (``core.PROFILE_PREFERENCE``) at which at least
``FIG4_SHARE`` of the most solvers any of its profiles holds ran (attempted a step): the
tightest alone may hold one solver and leave the others "not run under this condition",
while a profile that lacks only a solver or two of the most is still the paper's condition
to draw (the default benchmark's ``high``, where ADMM declines that accuracy).  Its captions name the profile drawn
and the other profiles the operator ran (``other_profiles_note``).
"""

from __future__ import annotations

import pandas as pd

from ..core import attempted, profile_rank
from ..markdown_text import md_code
from .paper_conditions import Block, operators_of


#: The share of the most solvers any profile of an operator holds that the tightest profile
#: Fig. 4 draws must hold (``fig4_profiles``).
FIG4_SHARE = 0.75


def fig4_profiles(rows: pd.DataFrame) -> dict[str, tuple[str, tuple[str, ...]]]:
    """Operator of the attempted ``rows`` -> (the profile Fig. 4 draws: the tightest with at
    least ``FIG4_SHARE`` of the most distinct solvers attempted at any of its profiles; the
    operator's other profiles, tightest first).  Empty where no row was attempted."""
    att = attempted(rows)
    out: dict[str, tuple[str, tuple[str, ...]]] = {}
    for op, g in att.groupby(operators_of(att), sort=True):
        count = g.groupby(g["profile"].astype(str))["solver"].nunique()
        enough = [p for p in sorted(count.index, key=profile_rank) if count[p] >= FIG4_SHARE * count.max()]
        out[str(op)] = enough[0], tuple(p for p in sorted(count.index, key=profile_rank) if p != enough[0])
    return out


def fig4_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of the sweep that Fig. 4 draws: each operator's attempted rows at its
    profile of ``fig4_profiles``, and the skipped rows at one of those profiles (the
    conditions of paper_conditions.py then take one block per profile so chosen).
    ``rows`` unchanged where none was attempted."""
    chosen = {op: p for op, (p, _) in fig4_profiles(rows).items()}
    if not chosen:
        return rows
    prof = rows["profile"].astype(str)
    skipped = rows["status"] == "skipped"
    kept = (~skipped & (prof == operators_of(rows).map(chosen))) | (skipped & prof.isin(set(chosen.values())))
    return rows[kept]


def other_profiles_note(rows: pd.DataFrame, block: Block) -> str:
    """Caption text: the profile ``block`` shows and the other profiles its operators ran
    under in the sweep's ``rows`` (not drawn here; the aggregates compare the solvers at
    each); "" where they ran under that one only."""
    others: set[str] = set()
    for op, (_, rest) in fig4_profiles(rows).items():
        if op in block.operators or not block.operators:
            others.update(rest)
    if not others:
        return ""
    names = ", ".join(md_code(p) for p in sorted(others, key=profile_rank))
    return (f" Shown: profile `{block.profile}`, the tightest at which at least {FIG4_SHARE:.0%} of the most "
            f"solvers any profile holds ran; the sweep also ran at {names}, not drawn here (Aggregates across instances compares the "
            f"solvers at each profile).")
