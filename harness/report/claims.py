"""The paper's claims ledger: every quantitative claim of Bemporad & Paggi (2015), its
measured value under each condition that applies, and one verdict.

A *condition* is the operator a row ran with (the table's ``operator`` column):

* ``dense`` -- the paper's: the dense H, the paper's eps = 1e-8 (profile ``paper``), the
  paper's algorithms with the paper's parameters;
* ``fft``   -- ours: FFT operators, each solver's own tolerance, the fast solvers beside.

``ledger(rows)`` computes one ``ClaimRow`` per (claim, condition, size) from a results
table (the ``paper-claims`` study, ``harness/run/studies.py``); ``write_ledger`` writes it as
``claims.csv`` (``LEDGER_COLUMNS``).  Every verdict comes from ``verdict`` with the
claim's ``Rule``; the tolerances the rules are made of are the constants below, in this
one place.  A claim whose measurement is missing, not finite or rests on no evidence is
``unmeasured`` -- never ``holds``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import astuple, dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET

from ..table.files import replace_atomically
from ..table.schema import ANSWERED
from .core import per_cell
from .sections.cmr import cmr_pairs, instance_totals
from .sections.counterexample import seed_readings, violation_counts
from .sections.paper import k_of

#: The file the ledger is written to, in the run folder.
LEDGER_NAME = "claims.csv"
#: The columns of ``claims.csv``, in order.
LEDGER_COLUMNS: tuple[str, ...] = ("claim", "figure", "paper_value", "condition", "measured", "n_or_size", "seeds",
                                   "verdict", "evidence")
#: The conditions, by the table's ``operator`` value.
CONDITIONS: tuple[str, ...] = ("dense", "fft")
#: The verdicts: the first three for a measured claim, the last where nothing was measured.
VERDICTS: tuple[str, ...] = ("holds", "partly", "fails", "unmeasured")

# --- The tolerances every rule is made of ----------------------------------------------
#: A speed ratio the paper states as "about x" holds within this factor of x; pointing the
#: same way (the same side of 1) is "partly".
RATIO_FACTOR = 2.0
#: A share (a fraction of seeds, n_p/n) holds within this absolute distance of the paper's,
#: and is "partly" within twice it.
SHARE_TOL = 0.1
#: A time ratio CMR / direct holds within this absolute distance of the paper's.
CMR_TIME_TOL = 0.15
#: An upper bound the paper states ("error under 2 %") is "partly" up to this factor above it.
BOUND_FACTOR = 2.0
#: "The same load and contact domain": the largest relative spread over the solvers that holds,
#: and the spread up to which it is "partly".
SAME_TOL = 1e-4
SAME_PARTLY = 1e-2
#: Example 1: greedy failing on at least this share of seeds is "partly" (it does fail).
EX1_PARTLY_MIN = 0.05
#: A range the paper states ("0.6-0.7") holds within this factor beyond either end.
RANGE_FACTOR = 1.25
#: Fig. 6: K = 200 "saves nothing more" while its time is at least this share of K = 100's
#: ("partly" down to the second share).
NO_SAVING_SHARE = 0.95
NO_SAVING_PARTLY = 0.8
#: Fig. 6: the best K holds within this factor of 100 ("partly" within the second).
K_FACTOR = 1.5
K_PARTLY_FACTOR = 2.0
#: A time saving the paper states (18 %) holds from this share of it up; any saving is "partly".
SAVING_SHARE = 0.5
#: "Almost no time saved": |saving| within this holds; a saving up to the second is "partly".
NO_SAVING_TOL = 0.1
NO_SAVING_PARTLY_TOL = 0.3
#: "An error of -98 %": a load error at least this large holds; beyond the paper's 2 % is "partly".
LARGE_ERROR = 0.5
#: Fig. 5's ratios are read over steps with at least this trial-set size (below it fixed
#: per-solve costs dominate).
FIG5_MIN_N = 100
INF = math.inf


@dataclass(frozen=True)
class Rule:
    """A claim's verdict rule on its measured value m: ``holds`` when holds[0] <= m <=
    holds[1], else ``partly`` when partly[0] <= m <= partly[1], else ``fails``; ``absolute``:
    the rule reads |m|."""

    holds: tuple[float, float]
    partly: tuple[float, float]
    absolute: bool = False

    def text(self) -> str:
        def band(b: tuple[float, float]) -> str:
            return f"[{b[0]:g}, {b[1]:g}]"
        return f"holds {band(self.holds)}, partly {band(self.partly)}" + (" (on |measured|)" if self.absolute else "")


def about(value: float) -> Rule:
    """A ratio the paper gives as about ``value``: within ``RATIO_FACTOR``; the same side of 1."""
    side = (1.0, INF) if value > 1 else (0.0, 1.0)
    return Rule((value / RATIO_FACTOR, value * RATIO_FACTOR), side)


def at_least(value: float) -> Rule:
    """A ratio the paper gives as at least ``value`` (> 1): down to value / RATIO_FACTOR; above 1."""
    return Rule((value / RATIO_FACTOR, INF), (1.0, INF))


def near(value: float, tol: float, partly: tuple[float, float] | None = None) -> Rule:
    """A share within ``tol`` of ``value``; "partly" within 2 tol (or the band given)."""
    return Rule((value - tol, value + tol), partly or (value - 2 * tol, value + 2 * tol))


def under(bound: float, absolute: bool = True) -> Rule:
    """An error (or time) the paper puts under ``bound``; "partly" up to BOUND_FACTOR x bound."""
    return Rule((-INF if not absolute else 0.0, bound), (0.0, BOUND_FACTOR * bound), absolute)


def verdict(measured: float, rule: Rule, evidence: str, testable: bool = True) -> str:
    """The claim's verdict (``VERDICTS``): ``unmeasured`` when there is no evidence, the
    table cannot test the claim, or ``measured`` is not a finite number; else the rule's."""
    try:
        m = float(measured)
    except (TypeError, ValueError):
        return "unmeasured"
    if not testable or not str(evidence).strip() or not math.isfinite(m):
        return "unmeasured"
    m = abs(m) if rule.absolute else m
    if rule.holds[0] <= m <= rule.holds[1]:
        return "holds"
    if rule.partly[0] <= m <= rule.partly[1]:
        return "partly"
    return "fails"


@dataclass(frozen=True)
class Claim:
    """One claim of the paper: an id, the figure, the paper's words for its value, the rule."""

    id: str
    figure: str
    paper_value: str
    rule: Rule


CLAIMS: dict[str, Claim] = {c.id: c for c in (
    Claim("ex1-greedy-fails", "Example 1", "greedy fails on ~40 % of seeds, any n",
          near(0.40, SHARE_TOL, (EX1_PARTLY_MIN, 1.0))),
    Claim("fig4-pk-cold-over-nnlsgp", "Fig. 4", "t(P&K1999) / t(NNLS+GP K=100) = 26", about(26.0)),
    Claim("fig4-admm-over-nnlsgp", "Fig. 4", "t(ADMM) / t(NNLS+GP) ~ 100 (two orders)", about(100.0)),
    Claim("fig4-greedy-over-nnlsgp", "Fig. 4", "t(greedy CG) / t(NNLS+GP) ~ 100 (two orders)", about(100.0)),
    Claim("fig4-nnlsgp-fastest", "Fig. 4", "NNLS+GP is the fastest: t(NNLS+GP) / t(fastest other) <= 1",
          Rule((0.0, 1.0), (0.0, RATIO_FACTOR))),
    Claim("fig4-same-load", "Fig. 4", "all methods give the same load (round-off): spread 0",
          Rule((0.0, SAME_TOL), (0.0, SAME_PARTLY))),
    Claim("fig4-same-contact", "Fig. 4", "all methods give the same contact domain: spread 0",
          Rule((0.0, SAME_TOL), (0.0, SAME_PARTLY))),
    Claim("fig5-chol-over-cg", "Fig. 5", "t(greedy Cholesky) / t(greedy CG) = 0.6-0.7, any n",
          Rule((0.6 / RANGE_FACTOR, 0.7 * RANGE_FACTOR), (0.0, 1.0))),
    Claim("fig5-chol-memory", "Fig. 5", "Cholesky out of memory above n ~ 20,000 (128 GB machine)",
          Rule((0.0, 20000.0), (0.0, 20000.0))),
    Claim("fig5-gs-over-cg", "Fig. 5", "t(greedy Gauss-Seidel) / t(greedy CG) ~ 3", about(3.0)),
    Claim("fig6-best-k", "Fig. 6", "the total time is least at K = 100",
          Rule((100 / K_FACTOR, 100 * K_FACTOR), (100 / K_PARTLY_FACTOR, 100 * K_PARTLY_FACTOR))),
    Claim("fig6-k200-over-k100", "Fig. 6", "K = 200 saves nothing more: t(K=200) / t(K=100) >= 1",
          Rule((NO_SAVING_SHARE, INF), (NO_SAVING_PARTLY, INF))),
    Claim("fig8-cmr-time", "Fig. 8", "t(CMR) / t(direct) ~ 0.5 at h = 2, any H (worst H)",
          near(0.5, CMR_TIME_TOL, (0.0, 1.0))),
    Claim("fig8-cmr-error", "Fig. 8", "|load error| < 2 % for H > 0.5, h = 2 (90th percentile)", under(0.02)),
    Claim("fig9-np-low-h", "Fig. 9", "n_p/n = 0.4 at h = 1.25", near(0.4, SHARE_TOL)),
    Claim("fig9-np-high-h", "Fig. 9", "n_p/n = 0.8 at h = 3.0", near(0.8, SHARE_TOL)),
    Claim("fig9-time-ratio", "Fig. 9", "t(CMR) / t(direct) tends to 0.6 (h = 3.0)",
          near(0.6, CMR_TIME_TOL, (0.0, 1.0))),
    Claim("fig9-error", "Fig. 9", "|load error| < 1 % at large h (h = 3.0, median)", under(0.01)),
    Claim("real-power-law-error", "Fig. 11", "power-law PSD: load error -0.4 %", under(0.02)),
    Claim("real-power-law-saving", "Fig. 11", "power-law PSD: 18 % of the time saved",
          Rule((SAVING_SHARE * 0.18, 1.0), (0.0, 1.0))),
    Claim("real-cutoff-error", "Fig. 11", "PSD cut-off: load error -98 %", Rule((LARGE_ERROR, INF), (0.02, INF), True)),
    Claim("real-cutoff-saving", "Fig. 11", "PSD cut-off: almost no time saved",
          Rule((-NO_SAVING_TOL, NO_SAVING_TOL), (-INF, NO_SAVING_PARTLY_TOL))),
    Claim("conclusion-greedy", "Conclusion", "NNLS+GP at least two orders of magnitude faster than greedy",
          at_least(100.0)),
    Claim("conclusion-pk", "Conclusion", "NNLS+GP 26x faster than P&K1999", about(26.0)),
)}


@dataclass(frozen=True)
class ClaimRow:
    """One row of ``claims.csv`` (``LEDGER_COLUMNS``)."""

    claim: str
    figure: str
    paper_value: str
    condition: str
    measured: float
    n_or_size: str
    seeds: str
    verdict: str
    evidence: str


def claim_row(claim_id: str, condition: str, measured: float, n_or_size: str, seeds: str, evidence: str,
              testable: bool = True) -> ClaimRow:
    """The ledger row of one measurement, its verdict from the claim's rule."""
    c = CLAIMS[claim_id]
    return ClaimRow(c.id, c.figure, c.paper_value, condition, float(measured), n_or_size, seeds,
                    verdict(measured, c.rule, evidence, testable), evidence)


# ---------------------------------------------------------------------------
# Reading the table
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


def totals(cells: pd.DataFrame) -> pd.DataFrame:
    """Per solver label: summed solve time and operator products (``matvecs``: the time's
    load-independent witness), steps, steps answered and steps solved; a total is
    ``comparable`` when every step of the largest count returned an answer."""
    if cells.empty:
        return pd.DataFrame(columns=["total_s", "matvecs", "steps", "answered", "solved", "comparable"])
    g = cells.groupby("solver")
    mv = g["matvecs"].sum(min_count=1) if "matvecs" in cells.columns else pd.Series(math.nan, index=g.size().index)
    out = pd.DataFrame({"total_s": g["solve_time_s"].sum(min_count=1), "matvecs": mv, "steps": g.size(),
                        "answered": g["status"].agg(lambda s: int(s.isin(ANSWERED).sum())),
                        "solved": g["solved"].sum()})
    out["comparable"] = (out["answered"] == out["steps"]) & (out["steps"] == out["steps"].max())
    return out


def fmt_count(v: float) -> str:
    """A count as an integer, "?" where the table has none."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "?"
    return f"{int(x)}" if math.isfinite(x) else "?"


def ratio(tot: pd.DataFrame, a: str, b: str) -> tuple[float, str]:
    """t_a / t_b with the words saying what it rests on (NaN where either is missing or
    incomplete, or t_b is not positive)."""
    missing = [s for s in (a, b) if s not in tot.index]
    if missing:
        return math.nan, f"no rows of {', '.join(missing)}"
    ta, tb = tot.loc[a], tot.loc[b]
    words = (f"{a} {ta['total_s']:.4g} s, {fmt_count(ta.get('matvecs'))} matvecs ({int(ta['solved'])}/"
             f"{int(ta['steps'])} steps pass the KKT check), {b} {tb['total_s']:.4g} s, "
             f"{fmt_count(tb.get('matvecs'))} matvecs ({int(tb['solved'])}/{int(tb['steps'])})")
    if not (ta["comparable"] and tb["comparable"]) or not tb["total_s"] > 0:
        return math.nan, words + "; not every step answered"
    return float(ta["total_s"] / tb["total_s"]), words


def fig4_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 4 and the conclusion, per grid size: NNLS+GP against P&K cold (independent
    steps, ``greedy-linear-solvers``), ADMM and greedy CG; fastest; same load / contact."""
    warm = of_condition(rows, "paper-sweep", condition)
    cold = of_condition(rows, "greedy-linear-solvers", condition)
    out: list[ClaimRow] = []
    for N in sorted(warm["N"].dropna().unique()):
        w = per_cell(warm[warm["N"] == N])
        c = per_cell(cold[(cold["N"] == N) & cold["instance"].isin(set(w["instance"]))])
        c = c.assign(solver=c["solver"] + " cold")
        tot = totals(pd.concat([w, c]))
        n_max = int(w["n"].max())
        size = f"{int(N)}^2, n <= {n_max}"
        seeds = seeds_of(w)
        where = f"results.csv: paper-sweep (warm) and greedy-linear-solvers (cold) N={int(N)} operator {condition}"
        for claim, other in (("fig4-pk-cold-over-nnlsgp", "pk cold"), ("fig4-admm-over-nnlsgp", "admm"),
                             ("fig4-greedy-over-nnlsgp", "greedy-cg cold"), ("conclusion-greedy", "greedy-cg cold"),
                             ("conclusion-pk", "pk cold")):
            if other in tot.index and "nnls-gp" in tot.index:
                m, words = ratio(tot, other, "nnls-gp")
                out.append(claim_row(claim, condition, m, size, seeds, f"{where}; {words}"))
        if "nnls-gp" in tot.index and len(tot) > 1:
            others = tot[(tot.index != "nnls-gp") & tot["comparable"]]
            best = others["total_s"].idxmin() if len(others) else None
            m, words = ratio(tot, "nnls-gp", best) if best is not None else (math.nan, "no other solver answered")
            out.append(claim_row("fig4-nnlsgp-fastest", condition, m, size, seeds,
                                 f"{where}; fastest other: {best}; {words}"))
        top = w[(w["step"] == w["step"].max()) & w["solved"]]
        for claim, col in (("fig4-same-load", "load"), ("fig4-same-contact", "contact_fraction")):
            per_inst = [spread(g[col]) for _, g in top.groupby("instance")]
            m = max(per_inst) if per_inst else math.nan
            solvers = sorted(set(top["solver"]))
            out.append(claim_row(claim, condition, m, size, seeds,
                                 f"{where}; top step, the largest spread over instances among the solvers that "
                                 f"pass the KKT check: {', '.join(solvers)}" if len(solvers) > 1 else ""))
    return out


def top_step_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 4's P&K1999 / NNLS+GP at the sizes that have no load history in the table: the
    cold solves of ``greedy-linear-solvers`` at a grid size that ``paper-sweep`` did not run
    (the study's top step of the paper's own 512^2 surface, n = 35,218 against the paper's
    35,555), both solvers from p = 0.  A size where either was skipped (a memory budget
    below the dense H) gives ``unmeasured`` rows that carry the skip reason."""
    warm_sizes = set(of_condition(rows, "paper-sweep", condition)["N"].dropna().unique())
    planned = rows[(rows["scene"] == "greedy-linear-solvers") & (rows["operator"] == condition)]
    out: list[ClaimRow] = []
    for N in sorted(set(planned["N"].dropna().unique()) - warm_sizes):
        here = planned[(planned["N"] == N) & planned["solver"].isin(["pk", "nnls-gp"])]
        if here.empty:
            continue
        cells = per_cell(here[here["status"] != "skipped"])
        m, words = ratio(totals(cells), "pk", "nnls-gp")
        skipped = here[here["status"] == "skipped"]
        if len(skipped):
            words += "; skipped: " + "; ".join(f"{s} ({r})" for s, r in zip(skipped["solver"], skipped["skip_reason"]))
        steps = sorted(here["step"].dropna().unique())
        size = f"{int(N)}^2, {len(steps)} step(s) cold, n <= {int(here['n'].max())}"
        where = f"results.csv: greedy-linear-solvers N={int(N)} operator {condition}, pk and nnls-gp from p = 0"
        for claim in ("fig4-pk-cold-over-nnlsgp", "conclusion-pk"):
            out.append(claim_row(claim, condition, m, size, seeds_of(here), f"{where}; {words}"))
    return out


def spread(values: pd.Series) -> float:
    """max |v - median| / |median| over the values (NaN for fewer than two, a NaN value or a
    zero median)."""
    v = pd.to_numeric(values, errors="coerce").to_numpy(float)
    if len(v) < 2 or not np.isfinite(v).all():
        return math.nan
    med = float(np.median(v))
    return float(np.max(np.abs(v - med)) / abs(med)) if med != 0 else math.nan


def paired_median(cells: pd.DataFrame, a: str, b: str) -> tuple[float, int]:
    """Median over the (instance, step) both solved, with n >= FIG5_MIN_N, of t_a / t_b."""
    ok = cells[cells["solved"] & (cells["n"] >= FIG5_MIN_N)]
    ta = ok[ok["solver"] == a].set_index(["instance", "step"])["solve_time_s"]
    tb = ok[ok["solver"] == b].set_index(["instance", "step"])["solve_time_s"]
    j = pd.concat([ta.rename("a"), tb.rename("b")], axis=1, join="inner").dropna()
    j = j[j["b"] > 0]
    return (float(np.median(j["a"] / j["b"])) if len(j) else math.nan), len(j)


def fig5_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 5 per grid size: greedy Cholesky and Gauss-Seidel against greedy CG, and the
    Cholesky memory limit (our n limit from the memory budget)."""
    r = of_condition(rows, "greedy-linear-solvers", condition)
    out: list[ClaimRow] = []
    for N in sorted(r["N"].dropna().unique()):
        cells = per_cell(r[r["N"] == N])
        size = f"{int(N)}^2, n <= {int(cells['n'].max())}"
        seeds = seeds_of(cells)
        for claim, other in (("fig5-chol-over-cg", "greedy-chol"), ("fig5-gs-over-cg", "greedy-gs")):
            if other not in set(cells["solver"]) or "greedy-cg" not in set(cells["solver"]):
                continue
            m, k = paired_median(cells, other, "greedy-cg")
            out.append(claim_row(claim, condition, m, size, seeds,
                                 f"results.csv: greedy-linear-solvers N={int(N)} operator {condition}; median over "
                                 f"{k} steps with n >= {FIG5_MIN_N} both solved" if k else ""))
    chol = rows[(rows["base_solver"] == "greedy-chol") & (rows["operator"] == condition) & (rows["status"] != "skipped")]
    if len(chol):
        answered = chol[chol["status"].isin(ANSWERED)]
        largest = float(answered["n"].max()) if len(answered) else math.nan
        limit = math.isqrt(int(DEFAULT_MEMORY_BUDGET // 8))
        tried = float(chol["n"].max())
        out.append(claim_row("fig5-chol-memory", condition, largest, f"n <= {int(tried)} tried; our dense limit "
                             f"n = {limit} ({DEFAULT_MEMORY_BUDGET / 2**30:g} GiB a matrix: H and its factor "
                             f"{2 * DEFAULT_MEMORY_BUDGET / 2**30:g} GiB)", "",
                             "results.csv: greedy-chol, largest n answered; the claim is tested only where n > "
                             "20000 was tried", testable=tried > 20000))
    return out


def example1_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Example 1: per n, the share of seeds whose greedy-CG answer the judge rejects."""
    r = of_condition(rows, "counterexample", condition)
    r = r[r["base_solver"] == "greedy-cg"]
    if r.empty:
        return []
    out = []
    for _, f in violation_counts(seed_readings(r)).iterrows():
        sub = r[r["n"] == f["n"]]
        seeds = seeds_of(sub)
        out.append(claim_row("ex1-greedy-fails", condition, float(f["fraction"]), f"n = {int(f['n'])}", seeds,
                             f"results.csv: counterexample operator {condition}, greedy-cg rejected on "
                             f"{int(f['violations'])} of {int(f['seeds'])} seeds (wrong {int(f['wrong'])})"))
    return out


def fig6_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 6: the K of least total time, and t(K=200) / t(K=100)."""
    r = of_condition(rows, "gp-k-sweep", condition)
    if r.empty:
        return []
    cells = per_cell(r)
    cells = cells.assign(K=cells.apply(k_of, axis=1))
    tot = totals(cells).join(cells.groupby("solver")["K"].first())
    tot = tot[tot["K"].notna()]
    comp = tot[tot["comparable"]].set_index("K")
    size = f"{int(cells['N'].max())}^2, n <= {int(cells['n'].max())}"
    seeds = seeds_of(cells)
    where = f"results.csv: gp-k-sweep operator {condition}, K = {', '.join(f'{k:g}' for k in sorted(tot['K']))}"
    best = float(comp["total_s"].idxmin()) if len(comp) else math.nan
    out = [claim_row("fig6-best-k", condition, best, size, seeds, where if len(comp) else "")]
    if 100.0 in comp.index and 200.0 in comp.index:
        m = float(comp.loc[200.0, "total_s"] / comp.loc[100.0, "total_s"])
        out.append(claim_row("fig6-k200-over-k100", condition, m, size, seeds, where))
    return out


def cmr_totals(rows: pd.DataFrame, scene: str, condition: str) -> pd.DataFrame:
    """``sections.cmr.instance_totals`` of one CMR scene under one condition (empty if none)."""
    r = of_condition(rows, scene, condition)
    pairs = cmr_pairs(r) if len(r) else pd.DataFrame()
    return instance_totals(pairs) if len(pairs) else pd.DataFrame()


def cmr_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Figs. 8, 9 and 11 from the CMR pairs (CMR against its direct base)."""
    out: list[ClaimRow] = []
    t8 = cmr_totals(rows, "cmr", condition)
    if len(t8):
        t8 = t8[t8["h"] == 2.0]
        size, seeds = f"{int(t8['N'].max())}^2, H = {', '.join(f'{h:g}' for h in sorted(t8['H'].unique()))}", \
            seeds_text(t8["seed"])
        per_h = t8.groupby("H")["ratio"].median()
        worst = float(per_h.iloc[int(np.argmax(np.abs(per_h.to_numpy() - 0.5)))]) if len(per_h) else math.nan
        out.append(claim_row("fig8-cmr-time", condition, worst, size, seeds,
                             "results.csv: cmr, median t(CMR)/t(direct) per H: "
                             + ", ".join(f"H {h:g}: {v:.3g}" for h, v in per_h.items())))
        hi = t8[t8["H"] > 0.5]["err"].abs()
        out.append(claim_row("fig8-cmr-error", condition, float(hi.quantile(0.9)) if len(hi) else math.nan, size,
                             seeds, f"results.csv: cmr, top step, {len(hi)} instances with H > 0.5" if len(hi) else ""))
    t9 = cmr_totals(rows, "cmr-h-sweep", condition)
    if len(t9):
        t9 = t9[t9["coarsest"] == t9["coarsest"].min()]
        size, seeds = f"{int(t9['N'].max())}^2, H = 0.7, top step", seeds_text(t9["seed"])
        med = t9.groupby("h")[["n_p_over_n", "ratio"]].median()
        err = t9.assign(a=t9["err"].abs()).groupby("h")["a"].median()
        where = "results.csv: cmr-h-sweep, median over seeds at h = "
        for claim, h, val in (("fig9-np-low-h", 1.25, med["n_p_over_n"]), ("fig9-np-high-h", 3.0, med["n_p_over_n"]),
                              ("fig9-time-ratio", 3.0, med["ratio"]), ("fig9-error", 3.0, err)):
            m = float(val.get(h, math.nan))
            out.append(claim_row(claim, condition, m, size, seeds, f"{where}{h:g}" if h in val.index else ""))
    cut = of_condition(rows, "cmr-cutoff", condition)
    tc = cmr_pairs(cut) if len(cut) else pd.DataFrame()  # one step per instance: the pairs are the totals
    if len(tc):
        for kind, err_id, save_id in (("power-law", "real-power-law-error", "real-power-law-saving"),
                                      ("rolloff", "real-cutoff-error", "real-cutoff-saving")):
            k = tc[tc["instance"].str.startswith(kind)]
            if k.empty:
                continue
            size = f"{int(k['N'].max())}^2, one step, n <= {int(k['n'].max())}"
            seeds = seeds_of(k)
            where = f"results.csv: cmr-cutoff {kind} surface, h = {', '.join(f'{h:g}' for h in k['h'].unique())}"
            saving = 1.0 - k["solve_time_s"] / k["direct_time_s"]
            out.append(claim_row(err_id, condition, float(k["err"].median()), size, seeds, where))
            out.append(claim_row(save_id, condition, float(saving.median()), size, seeds, where))
    return out


#: The ledger's readers, each of one part of the paper (conditions looped where they apply).
READERS: tuple[Callable[[pd.DataFrame, str], list[ClaimRow]], ...] = (
    example1_rows, fig4_rows, top_step_rows, fig5_rows, fig6_rows, cmr_rows)


def ledger(rows: pd.DataFrame) -> pd.DataFrame:
    """The ledger of a results table: one row per (claim, condition, size), ``LEDGER_COLUMNS``."""
    out: list[ClaimRow] = []
    for cond in CONDITIONS:
        for read in READERS:
            out += read(rows, cond)
    order = {c: i for i, c in enumerate(CLAIMS)}
    out.sort(key=lambda r: (order[r.claim], CONDITIONS.index(r.condition)))
    return pd.DataFrame([astuple(r) for r in out], columns=[f.name for f in fields(ClaimRow)])


def write_ledger(table: pd.DataFrame, out_dir: str | Path) -> Path:
    """Write ``ledger(table)`` to OUT/claims.csv; return its path."""
    path = Path(out_dir) / LEDGER_NAME
    rows = ledger(table)
    replace_atomically(path, lambda tmp: rows.to_csv(tmp, index=False))
    return path
