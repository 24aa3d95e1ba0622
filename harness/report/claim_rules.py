"""The verdict rules of the paper's claims ledger: one table of kinds, every one able to
fail, and one function, ``judge``, that reads a measured value and its spread.

The verdicts (``VERDICTS``):

* ``holds``      -- the measured value is inside the claim's holds band;
* ``partly``     -- a ratio or a bound outside the holds band but inside the wider band
                    (a yes/no claim is never partly);
* ``fails``      -- outside both bands (for a yes/no claim: the answer is no);
* ``unresolved`` -- the value's interval of repeats, [m / (1 + s), m (1 + s)] with s the
                    relative spread, reaches across a band edge: the repeats cannot tell
                    the verdicts apart (a near-tie is never ``holds``);
* ``unmeasured`` -- no finite measurement, no evidence, or a claim the table cannot test
                    (its ``Rule.reason`` says why).

The kinds of rule (``RULE_KINDS``; docs/claims.md has the table):

* ``ratio``   -- the paper gives a value v or a range [lo, hi] of a positive ratio: holds
                 within a factor f_h of it on a log scale ([lo / f_h, hi f_h]), partly
                 within f_p > f_h, fails outside (a non-positive ratio fails);
* ``bound``   -- the paper gives an upper bound b on a magnitude |m| (an error): holds for
                 |m| <= b, partly up to f_p b, fails beyond;
* ``at-most`` / ``at-least`` -- a yes/no claim, "m <= x" or "m >= x": holds or fails;
* ``band``    -- a share the paper gives as v: holds within +-d_h, partly within +-d_p
                 (absolute, for fractions of seeds or of points); a share the paper puts
                 at "many" is the band reaching 1 (``share_at_least``: holds from x up);
* ``untestable`` -- the table cannot test the claim: always ``unmeasured``, with the reason.

The factors are the constants below, each in this one place; a claim names its kind and
its paper value through the constructors (``ratio``, ``bound``, ``at_most``, ...).  The
spread of a timed statistic over the repeats (``over_repeats``, ``relative_range``, and the
spread a ``Timing`` is judged with, ``judged_spread``) is here too: the ledger and the
report's paper section read a tie with the same rule; so are the readings of two of the
paper's words, ``spread`` ("the same") and ``falls`` ("a rapid decreasing function").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

#: The verdicts, in the order the ledger counts them.
VERDICTS: tuple[str, ...] = ("holds", "partly", "fails", "unresolved", "unmeasured")
#: The kinds of rule (module doc).
RULE_KINDS: tuple[str, ...] = ("ratio", "bound", "at-most", "at-least", "band", "untestable")

#: "About v" (a value the paper states as a number, "26 times", "about 3"): holds within
#: this factor of v either way, partly within the second.
ABOUT_HOLDS = math.sqrt(2.0)
ABOUT_PARTLY = 3.0
#: "Orders of magnitude" (a power of ten): holds within half a decade, partly within one.
ORDER_HOLDS = math.sqrt(10.0)
ORDER_PARTLY = 10.0
#: A range the paper states ("0.6-0.7"): holds within this factor beyond either end,
#: partly within the second.
RANGE_HOLDS = 1.1
RANGE_PARTLY = 1.5
#: A bound the paper states ("under 2 %"): partly up to this factor above it.
BOUND_PARTLY = 2.0
#: The relative spread a timed ratio from a single repeat is judged with (none measured:
#: a solve of milliseconds moves by tens of percent between runs), so a near-tie from one
#: repeat is ``unresolved``, not ``holds``.
SINGLE_REPEAT_SPREAD = 0.1
INF = math.inf
#: The round-off a ``band`` rule forgives at its edges: shares are counts over counts, and
#: |0.3 - 0.4| is 0.10000000000000003 in float64.
BAND_ROUNDOFF = 1e-12


@dataclass(frozen=True)
class Rule:
    """One claim's rule (module doc): ``kind`` and its numbers -- ``lo``/``hi`` the paper's
    value or range (ratio, band centre in ``lo``), the threshold (at-most, at-least, bound
    in ``hi``), ``holds``/``partly`` the factors (ratio, bound) or half-widths (band);
    ``absolute``: the rule reads |m|; ``reason``: why an untestable claim is unmeasured;
    ``partly_above``: a ratio's partly factor above ``hi`` where the paper's words are
    one-sided (NaN: ``partly`` on both sides)."""

    kind: str
    lo: float = math.nan
    hi: float = math.nan
    holds: float = 1.0
    partly: float = 1.0
    absolute: bool = False
    reason: str = ""
    partly_above: float = math.nan

    def __post_init__(self) -> None:
        if self.kind not in RULE_KINDS:
            raise ValueError(f"unknown rule kind {self.kind!r}; one of {', '.join(RULE_KINDS)}")

    @property
    def yes_no(self) -> bool:
        return self.kind in ("at-most", "at-least")

    def at(self, m: float) -> str:
        """holds / partly / fails of a finite value m, no spread."""
        m = abs(m) if self.absolute else m
        if self.kind == "at-most":
            return "holds" if m <= self.hi else "fails"
        if self.kind == "at-least":
            return "holds" if m >= self.lo else "fails"
        if self.kind == "bound":
            return "holds" if m <= self.hi else "partly" if m <= self.hi * self.partly else "fails"
        if self.kind in ("ratio", "band"):
            if self.kind == "ratio" and not m > 0.0:
                return "fails"
            slack = BAND_ROUNDOFF if self.kind == "band" else 0.0  # (a share at a band's edge, 0.3 of 0.4 +- 0.1)
            for verdict in ("holds", "partly"):
                lo, hi = self.interval(verdict)
                if lo - slack <= m <= hi + slack:
                    return verdict
            return "fails"
        return "unmeasured"

    def interval(self, verdict: str) -> tuple[float, float]:
        """The values a ``ratio`` or ``band`` rule reads as ``verdict`` ("holds" or
        "partly"): [lo / f, hi f] of a ratio, [v - d, v + d] of a band."""
        if verdict not in ("holds", "partly") or self.kind not in ("ratio", "band"):
            raise ValueError(f"a {self.kind} rule has no {verdict!r} interval")
        f = self.holds if verdict == "holds" else self.partly
        if self.kind == "band":
            return self.lo - f, self.lo + f
        above = self.partly_above if verdict == "partly" and math.isfinite(self.partly_above) else f
        return self.lo / f, self.hi * above

    def edges(self) -> tuple[float, ...]:
        """The values where the verdict of ``at`` may change (the ends of its bands, its
        threshold), on the measured value's own scale."""
        if self.kind in ("ratio", "band"):
            return (*self.interval("holds"), *self.interval("partly"))
        if self.kind == "bound":
            return (self.hi, self.hi * self.partly, -self.hi, -self.hi * self.partly)
        if self.kind in ("at-most", "at-least"):
            edge = self.hi if self.kind == "at-most" else self.lo
            return (edge, -edge) if self.absolute else (edge,)
        return ()

    def text(self) -> str:
        """The rule in words, for the ledger's rules table."""
        on = "|measured|" if self.absolute else "measured"
        if self.kind == "at-most":
            return f"yes/no: holds if {on} <= {self.hi:g}, else fails"
        if self.kind == "at-least":
            return f"yes/no: holds if {on} >= {self.lo:g}, else fails"
        if self.kind == "ratio":
            val = f"{self.lo:g}" if self.lo == self.hi else f"[{self.lo:g}, {self.hi:g}]"
            (h0, h1), (p0, p1) = self.interval("holds"), self.interval("partly")
            factor = f"x{self.partly:.3g}" + (f" below, x{self.partly_above:.3g} above"
                                              if math.isfinite(self.partly_above) else "")
            return (f"ratio {val}: holds in [{h0:.3g}, {h1:.3g}] (x{self.holds:.3g}), "
                    f"partly in [{p0:.3g}, {p1:.3g}] ({factor}), else fails")
        if self.kind == "bound":
            return f"bound: holds if {on} <= {self.hi:g}, partly <= {self.hi * self.partly:g}, else fails"
        if self.kind == "band":
            (h0, h1), (p0, _) = self.interval("holds"), self.interval("partly")
            if h1 >= 1.0:  # a share's band reaching 1 (``share_at_least``): a lower bound
                return f"share at least {h0:.3g}: holds if measured >= {h0:.3g}, partly if >= {p0:.3g}, else fails"
            return (f"share {self.lo:g}: holds within +-{self.holds:g}, partly within +-{self.partly:g}, "
                    f"else fails")
        return f"untestable here: {self.reason}"


def ratio(value: float, hi: float | None = None, holds: float | None = None, partly: float | None = None) -> Rule:
    """A ratio the paper gives as ``value`` ("about": ``ABOUT_*``) or as the range
    [value, hi] (``RANGE_*``); the factors may be given."""
    if hi is None:
        return Rule("ratio", value, value, holds or ABOUT_HOLDS, partly or ABOUT_PARTLY)
    return Rule("ratio", value, hi, holds or RANGE_HOLDS, partly or RANGE_PARTLY)


def orders(value: float) -> Rule:
    """A ratio the paper gives in orders of magnitude (``value`` a power of ten)."""
    return Rule("ratio", value, value, ORDER_HOLDS, ORDER_PARTLY)


def bound(b: float, partly: float = BOUND_PARTLY) -> Rule:
    """A magnitude the paper puts under ``b`` (on |m|)."""
    return Rule("bound", hi=b, partly=partly, absolute=True)


def at_most(x: float, absolute: bool = False) -> Rule:
    """The yes/no claim m <= x."""
    return Rule("at-most", hi=x, absolute=absolute)


def at_least(x: float, absolute: bool = False) -> Rule:
    """The yes/no claim m >= x."""
    return Rule("at-least", lo=x, absolute=absolute)


def band(value: float, holds: float, partly: float) -> Rule:
    """A share the paper gives as ``value``: holds within +-holds, partly within +-partly."""
    return Rule("band", lo=value, holds=holds, partly=partly)


def share_at_least(x: float, partly: float) -> Rule:
    """A share the paper puts at "many" (a lower bound): holds for m >= x, partly for
    ``partly`` <= m < x, fails below -- the ``band`` whose holds interval is [x, 1] and
    whose partly interval is [partly, 1 + x - partly] (a share is at most 1)."""
    half = (1.0 - x) / 2.0
    return Rule("band", lo=x + half, holds=half, partly=half + x - partly)


def untestable(reason: str) -> Rule:
    """A claim the table cannot test: always unmeasured, with ``reason``."""
    return Rule("untestable", reason=reason)


def as_float(measured: object) -> float:
    """``measured`` as a float (NaN where it is not a number)."""
    try:
        return float(measured)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def judge(measured: object, rule: Rule, evidence: str, spread: float = 0.0, testable: bool = True) -> str:
    """The verdict (module doc) of ``measured`` under ``rule``, its repeats' relative spread
    ``spread`` (NaN or negative: none known, read as 0; infinite: any value, "unresolved")."""
    m = as_float(measured)
    if rule.kind == "untestable" or not testable or evidence is None or not str(evidence).strip() \
            or not math.isfinite(m):
        return "unmeasured"
    if spread == math.inf:
        return "unresolved"
    s = spread if math.isfinite(spread) and spread > 0.0 else 0.0
    at_m = rule.at(m)
    if s == 0.0:
        return at_m
    lo, hi = sorted((m / (1.0 + s), m * (1.0 + s)))
    seen = {rule.at(x) for x in (lo, hi, *(e for e in rule.edges() if lo < e < hi))}
    return at_m if seen == {at_m} else "unresolved"


# ---------------------------------------------------------------------------
# The claims: one rule each (the ledger's table; docs/claims.md says how to add one)
# ---------------------------------------------------------------------------

#: The paper's largest problem, Figs. 4-6 (sec. 4, tex 1030-1031: "for the highest
#: indentation we have n = 35555").
PAPER_N = 35_555
#: "Rare": a greedy failure share at most this.
RARE = 0.05
#: "In many cases" (the LCP not solved, tex 601-604): a share of seeds at least this -- one
#: seed in five, four times the most a "rare" failure may reach (``RARE``) and half of
#: Example 1's "approximately 40 %", the failure share the paper itself reports -- partly
#: from ``MANY_PARTLY`` (one in ten, still twice ``RARE``), fails below.
MANY = 0.2
MANY_PARTLY = 0.1
#: "Always" and "in many cases" (tex 601-604, 647-651) are read on at least this many
#: answered seeds -- the fewest on which one seed is a share of ``MANY_PARTLY``, the
#: smallest step the "many" rule tells apart (the paper's Example 1 used 100; the study
#: runs 100 per n).  On fewer the share is no measurement, unless a yes/no claim already
#: fails (one rejected seed refutes "always", whatever the rest would give).
MIN_SEEDS = 10
#: "Significantly reduces": at most this share of the cold iterations.
SIGNIFICANT = 2.0 / 3.0
#: "Slow" (pure GP), "quite far" (greedy Cholesky from NNLS): at least this time ratio.
SLOW = 2.0
#: "Large benefits" (K GP steps before NNLS): t(K = 100) / t(K = 0) at most this.
LARGE_BENEFIT = 0.5
#: "Only a small subset" of the trial set in contact: n_contact / n at most this.
SMALL_SUBSET = 0.5
#: "A rapid decreasing function": the error at the far end at most this share of the near end's,
#: with no rise between (``falls``).
FALLS = 0.5
#: "The same load and contact domain, with small round-off errors": relative spread at most this.
SAME = 1e-6
#: "-98 %": a load error at least this large in magnitude is the paper's "poor accuracy".
LARGE_ERROR = 0.5
#: What the ledger runs as "Algorithm 2 as printed" (solvers/pk_printed.py, ``projection="all"``):
#: step 3.4 (tex 743) projects only the points of I_C, which read literally leaves negative
#: forces outside it; the project's reading projects every point.
PK_PRINTED_READING = ("Algorithm 2 with step 3.4 on every point (read literally, line 743 leaves negative "
                      "forces)")
#: Example 1 and Fig. 9's shares: holds within +-SHARE_HOLDS, partly within +-SHARE_PARTLY.
SHARE_HOLDS = 0.1
SHARE_PARTLY = 0.2


@dataclass(frozen=True)
class Claim:
    """One claim of the paper: an id, where it is (figure or section, and the tex lines of
    the paper's source), the paper's words for its value, its rule, and what the ledger
    measures it on (``measures``, the words of the rules table); ``inexact``: the methods
    (registry names) the claim reads as printed, inexact by design (their own stop, not
    the KKT check): a ratio reads their answers whether or not they pass the check, and
    the evidence says so; any other method's unconverged answer is no measurement."""

    id: str
    figure: str
    tex_lines: str
    paper_value: str
    rule: Rule
    measures: str = ""
    inexact: tuple[str, ...] = ()


CLAIMS: dict[str, Claim] = {c.id: c for c in (
    Claim("ex1-greedy-fails", "Example 1", "623-628", "greedy wrong on ~40 % of 100 random ubar, for any n",
          band(0.40, SHARE_HOLDS, SHARE_PARTLY), "share of seeds whose greedy-cg answer the judge rejects, per n"),
    Claim("greedy-random-h-fails", "Sec. 3.1", "601-604",
          "random ubar and random SPD H with positive coefficients: in many cases greedy does not solve the LCP",
          share_at_least(MANY, MANY_PARTLY),
          "share of seeds whose greedy-cg answer the judge rejects on random-positive-h (Q = B B'/n, B ~ U(0,1); "
          "\"many\": >= 20 %, partly >= 10 %), per n"),
    Claim("greedy-spacing-2delta", "Sec. 3.1", "647-651", "trial points 2 delta apart: greedy always right",
          at_most(0.0), "share of seeds whose greedy-cg answer the judge rejects on counterexample-2delta (Example 1 "
                        "with its trial elements 2 delta apart; \"always\": none), per n"),
    Claim("greedy-smooth-no-failures", "Sec. 3.1", "651-655", "smooth ubar (sphere, flat punch): greedy never wrong",
          at_most(0.0), "share of greedy-cg solves rejected on hertz and flat-punch"),
    Claim("greedy-rare", "Conclusion", "1332-1334", "greedy's lack of convergence seems a rare phenomenon",
          at_most(RARE), "share of greedy-cg solves rejected on the rough surface's steps (cold)"),
    Claim("pk-criteria-equivalent", "Sec. 3.2", "707-711",
          "P&K's force-based stopping rule and the displacement-based one are completely equivalent",
          untestable("no solver runs P&K's force-based stopping rule beside the displacement-based one")),
    # tex 716-719 speaks of the constrained CG of Algorithm 2 (726-760): read as printed
    # (pk-printed) and as Polonsky & Keer's own (pk), the way Fig. 4 is split; pk-printed is
    # the project's reading of Algorithm 2 (PK_PRINTED_READING)
    Claim("pkprinted-fewer-iterations-than-greedy", "Sec. 3.2, Algorithm 2", "716-719, 726-760",
          "constrained CG converges in fewer iterations than greedy CG, Algorithm 2 as printed (pk-printed)",
          at_most(1.0), f"iterations of pk-printed cold / greedy-cg cold, summed over the steps; pk-printed: "
          f"{PK_PRINTED_READING}", inexact=("pk-printed",)),
    Claim("pk-fewer-iterations-than-greedy", "Sec. 3.2", "716-719",
          "constrained CG converges in fewer iterations than greedy CG, P&K 1999 proper (pk)", at_most(1.0),
          "iterations of pk cold / greedy-cg cold, summed over the steps"),
    Claim("nnls-warm-cuts-iterations", "Sec. 3.3", "793-797",
          "the load history's warm start significantly reduces NNLS's iterations", at_most(SIGNIFICANT),
          "NNLS iterations warm along the history / cold, summed over the steps"),
    Claim("gp-pure-slow", "Sec. 3.4", "856-858", "pure accelerated GP converges slowly", at_least(SLOW),
          "t(gp cold) / t(nnls-gp cold), the same steps"),
    Claim("gp-warm-start-benefit", "Sec. 3.4, Fig. 6", "864-866, 1087-1091",
          "K GP steps give NNLS large benefits: t(K = 100) well below t(K = 0, cold)", at_most(LARGE_BENEFIT),
          "t(nnls-gp K = 100) / t(K = 0), cold"),
    Claim("fig4-pkprinted-over-nnlsgp", "Fig. 4", "1046-1048, 1339-1341",
          "t(P&K1999) / t(NNLS+GP K=100) = 26, P&K as printed (Algorithm 2, pk-printed)", ratio(26.0),
          f"t(pk-printed cold) / t(nnls-gp); pk-printed: {PK_PRINTED_READING}", inexact=("pk-printed",)),
    Claim("fig4-pk-cold-over-nnlsgp", "Fig. 4", "1046-1048, 1339-1341",
          "t(P&K1999) / t(NNLS+GP K=100) = 26, P&K 1999 proper (pk)", ratio(26.0), "t(pk cold) / t(nnls-gp)"),
    Claim("fig4-admm-over-nnlsgp", "Fig. 4", "1028-1029, 1048-1050", "t(ADMM) / t(NNLS+GP) ~ 100 (two orders)",
          orders(100.0), "t(admm as the paper states it) / t(nnls-gp)", inexact=("admm",)),
    Claim("fig4-greedy-over-nnlsgp", "Fig. 4", "1048-1050, 1338-1339",
          "t(greedy CG) / t(NNLS+GP) ~ 100 (two orders; the conclusion: at least two)", orders(100.0),
          "t(greedy-cg cold) / t(nnls-gp)"),
    Claim("fig4-nnlsgp-fastest", "Fig. 4", "1046-1048", "NNLS+GP is the fastest of the paper's methods",
          at_most(1.0), "t(nnls-gp) / t(the fastest other paper method)", inexact=("admm", "pk-printed")),
    Claim("fig4-same-load", "Fig. 4", "1039-1042", "every method gives the same load (round-off)", at_most(SAME),
          "largest relative spread of the top step's load over the answers of every paper method"),
    Claim("fig4-same-contact", "Fig. 4", "1039-1042", "every method gives the same contact domain (round-off)",
          at_most(SAME), "largest relative spread of the top step's contact fraction over every answer"),
    Claim("fig5-chol-over-cg", "Fig. 5", "1068-1071", "t(greedy Cholesky) / t(greedy CG) = 0.6-0.7, any n",
          ratio(0.6, 0.7, partly=0.95 / 0.7),  # "a reduction": partly needs a saving of 5 % at least
          "median over the steps both solve of t(greedy-chol) / t(greedy-cg)"),
    Claim("fig5-chol-far-from-nnls", "Fig. 5", "1071-1073",
          "greedy Cholesky is still quite far from NNLS", at_least(SLOW), "t(greedy-chol cold) / t(nnls)"),
    # "about 20,000": a refusal far below (our own memory budget) is not the paper's limit
    Claim("fig5-chol-memory", "Fig. 5", "1074-1076", "Cholesky out of memory above n ~ 20,000 (128 GB machine)",
          ratio(20000.0), "largest n greedy-chol answered below a failure for memory, tested only where "
          "n > 20,000 was tried"),
    Claim("fig5-gs-over-cg", "Fig. 5", "1077-1079", "t(greedy Gauss-Seidel) / t(greedy CG) ~ 3", ratio(3.0),
          "median over the steps both solve of t(greedy-gs) / t(greedy-cg)"),
    # least at K = 100, and one-sided above it: K = 200 "does not correspond to further
    # savings" (1092-1097), so a least at 200 fails; one at 50 or 150 is partly
    Claim("fig6-best-k", "Fig. 6", "1087-1097", "the total time is least at K = 100",
          Rule("ratio", 100.0, 100.0, ABOUT_HOLDS, 2.0, partly_above=1.5),
          "the K of least total NNLS+GP time"),
    Claim("fig6-k200-over-k100", "Fig. 6", "1092-1097", "K = 200 saves nothing more: t(K=200) / t(K=100) >= 1",
          at_least(1.0), "t(K = 200) / t(K = 100)"),
    Claim("subset-in-contact", "Sec. 5.1", "1112-1115", "at convergence only a small subset of the trial set is in contact",
          at_most(SMALL_SUBSET), "points in contact / n at the top step (nnls)"),
    Claim("lacunarity", "Sec. 5.1", "1120-1130", "the contact area at one displacement falls as delta is refined",
          untestable("no row records one surface's contact area at its coarser levels at one displacement")),
    Claim("cmr-2x-over-nnlsgp", "Abstract", "241-244", "CMR at least 2x faster than NNLS+GP", at_most(0.5),
          "t(cmr+nnls, h = 2 from 16) / t(nnls-gp) over the cmr steps", inexact=("cmr+nnls",)),
    Claim("fig8-cmr-time", "Fig. 8", "1222-1227", "t(CMR) / t(direct) ~ 0.5 at h = 2, almost regardless of H",
          ratio(0.5, partly=1.9), "median t(CMR) / t(direct) per H, the H farthest from 0.5"),
    Claim("fig8-cmr-error", "Conclusion, Fig. 8", "1349-1351",
          "relative errors < 2 % for surfaces with H > 0.5, h = 2",
          bound(0.02), "the largest |error| over the instances with H > 0.5 (h = 2 from 16)"),
    Claim("fig8-error-falls-with-h-exponent", "Fig. 8", "1228-1230", "the load error is a rapidly decreasing function of H",
          at_most(FALLS), "median |error| per H: the largest rise from one H to the next where one rises, "
          "else at the largest H / at the smallest H"),
    Claim("fig9-np-low-h", "Fig. 9", "1238-1241", "n_p/n = 0.4 at h = 1.25", band(0.4, SHARE_HOLDS, SHARE_PARTLY),
          "median n_p/n over seeds"),
    Claim("fig9-np-high-h", "Fig. 9", "1238-1241", "n_p/n = 0.8 at h = 3.0", band(0.8, SHARE_HOLDS, SHARE_PARTLY),
          "median n_p/n over seeds"),
    Claim("fig9-time-ratio", "Fig. 9", "1241-1244", "t(CMR) / t(direct) tends to 0.6 (40 % saved)",
          ratio(0.6, partly=1.6), "median t(CMR) / t(direct) at h = 3"),
    Claim("fig9-error", "Fig. 9", "1235-1237", "|load error| < 1 % at large h", bound(0.01), "median |error| at h = 3"),
    Claim("fig9-error-falls-with-h", "Fig. 9", "1235-1237", "the error falls rapidly as h grows", at_most(FALLS),
          "median |error| per h: the largest rise from one h to the next where one rises, "
          "else at the largest h / at the smallest h"),
    Claim("fig9-error-001pct", "Fig. 9", "1242-1245", "the 40 % saving comes with < 0.01 % relative error",
          bound(1e-4), "median |error| at h = 3"),
    Claim("real-power-law-error", "Fig. 11", "1292-1294", "power-law PSD: load error -0.4 %", bound(0.01),
          "median load error of CMR against its direct solve"),
    Claim("real-power-law-saving", "Fig. 11", "1293-1295", "power-law PSD: 18 % of the time saved (ratio 0.82)",
          ratio(0.82, holds=RANGE_HOLDS, partly=1.2), "median t(CMR) / t(direct)"),
    Claim("real-cutoff-error", "Fig. 11", "1296-1298", "PSD cut-off: load error -98 % (poor accuracy)",
          at_least(LARGE_ERROR, absolute=True), "median |load error| of CMR against its direct solve"),
    Claim("real-cutoff-saving", "Fig. 11", "1297-1298", "PSD cut-off: almost no time saved (ratio ~ 1)",
          ratio(1.0, holds=RANGE_HOLDS, partly=RANGE_PARTLY), "median t(CMR) / t(direct)"),
)}


def relative_range(values: pd.Series) -> float:
    """(max - min) / median of the values (NaN for fewer than two or a median <= 0)."""
    v = pd.to_numeric(values, errors="coerce").dropna().to_numpy(float)
    if len(v) < 2:
        return math.nan
    med = float(np.median(v))
    return float((v.max() - v.min()) / med) if med > 0 else math.nan


def over_repeats(rows: pd.DataFrame, statistic: Callable[[pd.DataFrame], float]) -> tuple[float, float]:
    """A timed statistic over the repeats: ``statistic`` computed on each timed repeat's
    rows alone, as (their median, their relative range); (the statistic of all rows, NaN)
    with fewer than two repeats."""
    if "repeat" not in rows.columns or rows["repeat"].nunique() < 2:
        return statistic(rows), math.nan
    values = pd.Series([statistic(g) for _, g in rows.groupby("repeat")], dtype=float)
    return float(values.median()), relative_range(values)


@dataclass(frozen=True)
class Timing:
    """How a measured ratio of times stands over the timed repeats."""

    repeats: int = 0
    spread: float = math.nan


def judged_spread(timing: Timing) -> float:
    """The spread a timing is judged with: ``SINGLE_REPEAT_SPREAD`` for one repeat with none
    measured (NaN), else its own -- an infinite spread (any value: ``unresolved``, as
    ``claim_measures.best_k`` gives it) stays infinite whatever the repeats."""
    return SINGLE_REPEAT_SPREAD if timing.repeats == 1 and math.isnan(timing.spread) else timing.spread


def judge_timed(claim_id: str, measured: float, evidence: str, timing: Timing = Timing(),
                testable: bool = True) -> str:
    """The ledger's verdict on a measurement of the claim ``claim_id`` (``judge`` of its rule),
    its timing judged with ``judged_spread``: what a ledger row and a report reading that
    states the ledger's verdict both call."""
    return judge(measured, CLAIMS[claim_id].rule, evidence, judged_spread(timing), testable)


def spread(values: pd.Series) -> float:
    """The relative spread "the same" (``SAME``) reads: max |v - median| / |median| over
    the values (NaN for fewer than two, a NaN value or a zero median)."""
    v = pd.to_numeric(values, errors="coerce").to_numpy(float)
    if len(v) < 2 or not np.isfinite(v).all():
        return math.nan
    med = float(np.median(v))
    return float(np.max(np.abs(v - med)) / abs(med)) if med != 0 else math.nan


def falls(by: pd.Series) -> float:
    """The measured value of "a rapid(ly) decreasing function" (``FALLS``) of a series, by
    the index's order: where some value rises over the one before it, the largest such
    rise, value over value before (> 1, so never under ``FALLS``: a rise anywhere is not
    a fall); else the last value over the first.  NaN for fewer than two values, a value
    that is not finite or is negative, a first value of 0 or a rise from 0 (no ratio reads
    them)."""
    v = pd.to_numeric(by.sort_index(), errors="coerce").to_numpy(float)
    if len(v) < 2 or not (np.isfinite(v).all() and (v >= 0.0).all() and v[0] > 0.0):
        return math.nan
    rises = [after / before if before > 0.0 else math.nan for before, after in zip(v[:-1], v[1:]) if after > before]
    return float(np.max(rises)) if rises else float(v[-1] / v[0])
