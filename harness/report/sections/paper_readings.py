"""Words for the readings of the paper's figures (sections/paper.py): a measured ratio
against one of the paper's claims, and the timing spread that decides when two times are
a tie.

A ratio is read in this order (``agreement``):

1. no finite ratio: it cannot be checked;
2. a ratio the timing spread cannot tell from 1 -- within [1 / (1 + s), 1 + s], s the
   relative spread of the timings (``Spread``) -- is unresolved: a tie says nothing of
   which way the paper's claim goes;
3. a ratio on the other side of 1 from the paper's points the opposite way, however near
   it lies (the paper says faster, the table says slower, or the reverse);
4. otherwise it is read by the claim's row of the claims ledger (claim_rules.py, the one
   home of the paper's value and of the bands) as the ledger's ``judge`` reads it: a ratio
   whose interval over the timing spread reaches across an edge of the row's bands is
   unresolved; inside the row's holds band it agrees, inside its partly band it is close,
   and beyond that it points the same way, smaller or larger by a factor taken against the
   paper's stated value (``Claim.value``; the nearer end of a range the paper states as a
   range).

A reading gives such a verdict only on the ledger's own measurement of the claim
(sections/paper_conditions.py), or where the ledger reads no other rows for it; the
ledger's verdict on its measurement is worded by ``ledger_words``.

The spread of a timing from one repeat is ``SINGLE_REPEAT_SPREAD``, the claims ledger's
(claim_rules.py); from several repeats it is the relative range of the ratio over the
repeats (``timing_spread``).  "Fastest" is said of a solver only when every other one is
slower by more than the spread (``tied_with``).  The tie rule (``Spread``, ``tied_with``)
and ``k_of`` are the ledger's own (claim_measures.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Hashable
from typing import Callable

import pandas as pd

from ..claim_measures import EXACT, SINGLE, Spread, k_of, tied_with
from ..claim_rules import CLAIMS, SINGLE_REPEAT_SPREAD, Rule, judge, over_repeats
from ..core import fmt_num, fmt_pct, fmt_ratio, per_cell

#: Below this largest trial-set size n fixed per-solve costs dominate the solve times, so a
#: ratio or an optimum the paper measured at its sizes (n up to 35555) need not hold: the
#: readings of Figs. 4 and 6 say so (``SMALL_N_TEXT``), and Fig. 6 reads no disagreement.
SMALL_N = 5000
#: The readings' words for a table whose largest trial set is under ``SMALL_N``.
SMALL_N_TEXT = "At sizes this small fixed per-solve costs dominate, so the paper's ratios need not hold."


def largest_n(rows: pd.DataFrame) -> int:
    """The largest trial-set size n of ``rows`` (column ``n``); 0 when no row has one."""
    return int(rows["n"].max()) if rows["n"].notna().any() else 0


def too_small(n_max: int) -> bool:
    """Whether a table whose largest trial set has ``n_max`` points (``largest_n``; 0:
    unknown) is under ``SMALL_N``, where the paper's ratios need not hold."""
    return n_max < SMALL_N


def timing_spread(rows: pd.DataFrame, statistic: Callable[[pd.DataFrame], float]) -> Spread:
    """The spread of a timed ``statistic`` (a ratio of times) of ``rows``: ``SINGLE`` when
    the rows hold one repeat (column ``repeat``); else the relative range of the statistic
    computed on each repeat's rows alone (``claim_rules.over_repeats``), ``SINGLE_REPEAT_SPREAD``
    where fewer than two repeats give a finite value."""
    n = int(rows["repeat"].nunique()) if "repeat" in rows.columns else 1
    if n < 2:
        return SINGLE
    _, s = over_repeats(rows, statistic)
    return Spread(s if math.isfinite(s) else SINGLE_REPEAT_SPREAD, n)


@dataclass(frozen=True)
class Claim:
    """A ratio claimed by the paper, read with its row ``ledger`` of the claims ledger
    (claim_rules.py ``CLAIMS``, where it is measured under the paper's conditions): ``text``
    its words; the ledger row's rule is the one home of the paper's value and of the bands
    a measured ratio agrees (holds) or is close (partly) within."""

    text: str
    ledger: str

    @property
    def rule(self) -> Rule:
        """The ledger row's rule (a ``ratio``)."""
        return CLAIMS[self.ledger].rule

    @property
    def value(self) -> float:
        """The one number the paper states; NaN for a claim it states as a range."""
        return self.rule.lo if self.rule.lo == self.rule.hi else math.nan

    @property
    def direction(self) -> int:
        """+1: the paper's ratio is above 1 (slower), -1: below 1 (faster), 0: its range
        holds 1."""
        return 1 if self.rule.lo > 1.0 else -1 if self.rule.hi < 1.0 else 0


def ledger_claim(ledger: str, words: str = "") -> Claim:
    """The claim of the ledger row ``ledger``, a ``ratio`` rule: stated "~v x" for one
    value v, "lo-hi" for a range, then ``words``."""
    rule = CLAIMS[ledger].rule
    if rule.kind != "ratio":
        raise ValueError(f"ledger row {ledger!r} is a {rule.kind} rule, not a ratio")
    stated = f"~{rule.lo:g}x" if rule.lo == rule.hi else f"{rule.lo:g}-{rule.hi:g}"
    return Claim(stated + words, ledger)


def _off_by(measured: float, claim: Claim) -> str:
    """"smaller by a factor of 24.5" (against ``claim.value``), or against the nearer end
    of the range the paper states."""
    rule = claim.rule
    smaller = measured < rule.lo
    if math.isfinite(claim.value):
        factor, what = (claim.value / measured if smaller else measured / claim.value), ""
    else:
        factor, what = (rule.lo / measured if smaller else measured / rule.hi), " than its range"
    return f"{'smaller' if smaller else 'larger'}{what} by a factor of {fmt_num(factor, 3)}"


def band_text(claim: Claim, verdict: str) -> str:
    """"18.4x-36.8x": the values the ledger row reads as ``verdict``."""
    lo, hi = claim.rule.interval(verdict)
    return f"{fmt_ratio(lo)}-{fmt_ratio(hi)}"


def agreement(measured: float, claim: Claim, spread: Spread = EXACT) -> str:
    """Words for a measured ratio against the paper's claim, read in the order of the
    module doc: a tie within ``spread`` is unresolved, the direction is checked before
    closeness, closeness is the ledger row's rule (``Rule.at``), and a factor is given
    against the paper's stated value."""
    if not math.isfinite(measured):
        return "cannot be checked from this table"
    if spread.ties(measured):
        return spread.tie_text()
    way = 1 if measured > 1.0 else -1 if measured < 1.0 else 0
    if claim.direction and way != claim.direction:
        side = "shows no difference" if way == 0 else "points the opposite way"
        return (f"{side} under this table's conditions; for the paper's (dense H, eps = 1e-8) see "
                f"row `{claim.ledger}`, condition `dense`, of the claims ledger (`contactbench run paper-claims`, "
                f"claims.md)")
    verdict = judge(measured, claim.rule, claim.ledger, spread.s)
    if verdict == "unresolved":
        return f"unresolved (the timing spread of {spread.source} reaches across an edge of the claims ledger's bands)"
    if verdict == "holds":
        return f"agrees with the paper (the claims ledger's holds band, {band_text(claim, verdict)})"
    if verdict == "partly":
        return f"is close to the paper (the same way, in the claims ledger's partly band, {band_text(claim, verdict)})"
    return f"points the same way as the paper but is {_off_by(measured, claim)}"


def ledger_words(verdict: str, measured: float, claim: Claim, repeats: int) -> str:
    """Words for the claims ledger's ``verdict`` (``claim_rules.judge``) on the ledger's own
    measurement of ``claim``, ``measured`` over ``repeats`` timed repeats: the verdict, then
    why ("fails: it points the opposite way", "holds: agrees with the paper (...)")."""
    if verdict == "holds":
        return f"holds: it agrees with the paper (the claims ledger's holds band, {band_text(claim, verdict)})"
    if verdict == "partly":
        return f"partly: it is close to the paper (the claims ledger's partly band, {band_text(claim, verdict)})"
    if verdict == "unresolved":
        spread = "single repeats" if repeats <= 1 else f"{repeats} repeats"
        return f"unresolved: the timing spread of {spread} reaches across an edge of the claims ledger's bands"
    if verdict == "fails":
        way = 1 if measured > 1.0 else -1 if measured < 1.0 else 0
        if claim.direction and way != claim.direction:
            return "fails: it points the opposite way" if way else "fails: it shows no difference"
        return f"fails: it points the same way as the paper but is {_off_by(measured, claim)}"
    return "unmeasured: no common solved step to read"


def claim_sentence(label: str, measured: float, claim: Claim, spread: Spread = EXACT) -> str:
    """"label: measured 1.06x against the paper's ~26x -- <agreement>."."""
    return (f"{label}: measured {fmt_ratio(measured)} against the paper's {claim.text} -- "
            f"{agreement(measured, claim, spread)}.")


def ties_text(times: pd.Series, best: Hashable, tied: list[Hashable], spread: Spread,
              time_of: Callable[[Hashable], str]) -> str:
    """"tied with `b` (0.00404 s, worst kkt ...) at 1.01x (within the timing spread of
    single repeats)" for the ``tied`` labels of ``times`` (``time_of`` words a label's
    time); "" when none."""
    if not tied:
        return ""
    t0 = float(times[best])
    each = ", ".join(f"{time_of(s)} at {fmt_ratio(float(times[s]) / t0)}" for s in tied)
    return f"tied with {each} (within the timing spread of {spread.source})"


# ---------------------------------------------------------------------------
# Fig. 5: paired ratios; Fig. 6: the least total over K
# ---------------------------------------------------------------------------


def paired_count_text(steps: int, instances: int) -> str:
    """What a paired median counts: "median over 4 common solved instances" when each
    instance gives one step, else "median over 5 common solved steps (instance, load
    step) of 2 instances"."""
    if steps == instances:
        return f"median over {steps} common solved instances"
    return (f"median over {steps} common solved steps (instance, load step) of {instances} "
            f"instance{'s' if instances != 1 else ''}")


def k_cells(rows: pd.DataFrame) -> pd.DataFrame:
    """``per_cell`` of ``rows`` with column ``K`` (``k_of``), the cells without a K left out."""
    cells = per_cell(rows)
    if cells.empty:
        return cells.assign(K=pd.Series(dtype=float))
    cells = cells.assign(K=cells.apply(k_of, axis=1))
    return cells[cells["K"].notna()]


def k_totals(cells: pd.DataFrame) -> pd.DataFrame:
    """Per K (column ``K`` of ``cells``, ``per_cell`` rows of one profile): ``total_s``, the
    solve time summed over every step and instance, and ``complete``, every one solved."""
    g = cells.groupby("K")
    return pd.DataFrame({"total_s": g["solve_time_s"].sum(min_count=1), "complete": g["solved"].all()})


#: The K at which the paper finds NNLS+GP's total least (Fig. 6).
PAPER_BEST_K = 100.0


@dataclass(frozen=True)
class LedgerReading:
    """One measurement of a claim as the claims ledger takes it (sections/paper_conditions.py):
    on ``operator`` at grid size ``N`` (0: every size), ``measured`` over ``count`` steps
    and ``repeats`` timed repeats, and the ledger's ``verdict``; ``near`` the values the
    ledger could not tell from ``measured`` (Fig. 6: the Ks tied with the least, or a
    repeat's own least)."""

    operator: str
    N: int
    measured: float
    count: int
    repeats: int
    verdict: str
    near: tuple[float, ...] = ()


def _k_band(verdict: str) -> str:
    lo, hi = CLAIMS["fig6-best-k"].rule.interval(verdict)
    return f"K = {fmt_num(lo)}-{fmt_num(hi)}"


def _fig6_verdict(ledger: LedgerReading, kbest: float, tied: list[float], at_paper: float, n_max: int,
                  comp: pd.DataFrame, spread_of: Callable[[Hashable, Hashable], Spread]) -> str:
    """The verdict part of Fig. 6's reading: the claims ledger's on its own measurement
    ``ledger`` (``fig6-best-k``), worded against the table's least ``kbest``."""
    best, rule = ledger.measured, CLAIMS["fig6-best-k"].rule
    read = ""
    if best != kbest or set(ledger.near) != set(tied) or ledger.repeats > 1:
        near = f", not told from K = {', '.join(f'{int(k)}' for k in ledger.near)}" if ledger.near else ""
        read = (f"as the claims ledger reads it (each repeat's total over the steps, the median over "
                f"{ledger.repeats} repeat{'s' if ledger.repeats != 1 else ''}) the least is at K = {int(best)}{near}: ")
    takes = (f" (K = {int(PAPER_BEST_K)} takes {fmt_ratio(at_paper)} the minimum)"
             if kbest != PAPER_BEST_K and math.isfinite(at_paper) else "")
    if ledger.verdict == "holds":
        return f"{read}this agrees with the paper (the claims ledger's holds band, {_k_band('holds')}){takes}."
    if ledger.verdict == "partly":
        return (f"{read}this is close to the paper (the claims ledger's partly band, {_k_band('partly')}, outside "
                f"its holds band, {_k_band('holds')}){takes}.")
    if ledger.verdict == "unresolved":
        each = "; ".join(f"K = {int(k)}: {rule.at(k)}" for k in sorted({best, *ledger.near}))
        return (f"{read}{Spread(SINGLE_REPEAT_SPREAD, ledger.repeats).tie_text()} -- the Ks not told from the "
                f"least total read differently by the claims ledger's bands ({each}).")
    ledger_word = (f"the claims ledger's row `fig6-best-k` (its rule reads every size alike) reads K = {int(best)} as "
                   f"{ledger.verdict}")
    if not (comp.index.min() <= PAPER_BEST_K <= comp.index.max()):
        return f"{read}{ledger_word}; the sweep does not bracket K = {int(PAPER_BEST_K)}."
    if too_small(n_max):
        return (f"{read}{ledger_word}; the largest trial set has n = {n_max}"
                + (f", where K = {int(PAPER_BEST_K)} takes {fmt_ratio(at_paper)} the minimum"
                   if math.isfinite(at_paper) else f", with no complete total at K = {int(PAPER_BEST_K)}") + ".")
    if math.isfinite(at_paper):
        return (f"{read}this does not agree with the paper: K = {int(PAPER_BEST_K)} takes {fmt_ratio(at_paper)} the "
                f"minimum, beyond the timing spread of {spread_of(PAPER_BEST_K, kbest).source}.")
    return (f"{read}this does not agree with the paper, though the sweep has no complete total at "
            f"K = {int(PAPER_BEST_K)} to compare with.")


def fig6_reading(tot: pd.DataFrame, spread_of: Callable[[Hashable, Hashable], Spread], n_max: int,
                 ledger: LedgerReading | None = None, elsewhere: str = "") -> str:
    """Fig. 6's reading of ``k_totals`` ``tot``: the K of least total time against the
    paper's K = 100, with the Ks whose totals the timing spread cannot tell from the least
    (``spread_of(k1, k2)``: the spread of t(k1) / t(k2)) named as tied.  The verdict is the
    claims ledger's, on its own measurement of the same sweep (``ledger``: the least of each
    repeat's total's median, judged by the ledger's rule ``fig6-best-k`` -- unresolved where
    the Ks it cannot tell from the least read differently); none where the ledger reads
    the claim on other rows (``elsewhere``: why) or where not every K answered every step
    (``ledger`` None).  A failing least is said with the ratio t(K = 100) / t(least) it
    rests on; when the largest trial set ``n_max`` is ``too_small`` the reading says so
    (``SMALL_N_TEXT``) and gives the ledger's verdict with its row named, and no other.  The
    savings it reports beside (K = 0 against the least, the largest K against it) carry no
    verdict word: the ledger rows that judge those claims (``gp-warm-start-benefit``,
    ``fig6-k200-over-k100``) measure other ratios, and are named."""
    comp = tot[tot["complete"]]
    if comp.empty:
        return "**Reading.** No K solved every step, so the minimum cannot be placed.\n"
    times = comp["total_s"]
    kbest = float(times.idxmin())
    tied = [float(k) for k in tied_with(times, kbest, spread_of)]
    sp = spread_of(tied[0], kbest) if tied else spread_of(PAPER_BEST_K, kbest)
    near = (f", tied with {', '.join(f'K = {int(k)} ({fmt_num(times[k])} s)' for k in tied)} within the timing "
            f"spread of {sp.source}" if tied else "")
    head = (f"**Reading.** The total time is smallest at K = {int(kbest)} ({fmt_num(times[kbest])} s){near}; the "
            f"paper finds the minimum at K = {int(PAPER_BEST_K)} (no saving beyond it) -- ")
    at_paper = times.get(PAPER_BEST_K, float("nan")) / times[kbest]
    if elsewhere:
        verdict = f"no verdict here: {elsewhere} (row `fig6-best-k`)."
    elif ledger is None:
        verdict = ("no verdict: not every K answered every step, so the least total over the sweep is not known "
                   "(the claims ledger reads only a sweep whose every K answered).")
    else:
        verdict = _fig6_verdict(ledger, kbest, tied, at_paper, n_max, comp, spread_of)
    parts = [head + verdict] + ([SMALL_N_TEXT] if too_small(n_max) else [])
    if 0.0 in times.index and kbest != 0.0:
        r0 = times[kbest] / times[0.0]
        s0 = spread_of(kbest, 0.0)
        parts.append(f"Going from K = 0 to K = {int(kbest)} saves {fmt_pct(1 - r0)} of the time"
                     + (f", a tie within the timing spread of {s0.source}" if s0.ties(r0) else "")
                     + " (no verdict here: the claims ledger's row `gp-warm-start-benefit` judges the paper's "
                       "K = 100 against a cold K = 0).")
    above = times[times.index > kbest]
    if len(above):
        kmax = float(above.index.max())
        rmax = times[kmax] / times[kbest]
        smax = spread_of(kmax, kbest)
        parts.append(f"At K = {int(kmax)} the total is {fmt_ratio(rmax)} the minimum"
                     + (f", a tie within the timing spread of {smax.source}" if smax.ties(rmax) else "")
                     + " (the paper: more GP steps only add time; no verdict here: the claims ledger's row "
                       "`fig6-k200-over-k100` judges K = 200 against K = 100).")
    return " ".join(parts) + "\n"
