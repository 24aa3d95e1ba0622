"""The paper's claims ledger: every claim of Bemporad & Paggi (2015), its measured value
under each condition that applies, and one verdict.

A *condition* is the operator a row ran with (the table's ``operator`` column) and the
profile the study runs it at (``claim_tables.CONDITION_PROFILES``; every reader filters on
both, ``claim_tables.under``, and the evidence names them):

* ``dense`` -- the paper's: the dense H, the paper's eps = 1e-8 (profile ``paper``), the
  paper's algorithms with the paper's parameters;
* ``fft``   -- ours: FFT operators, each solver's own tolerance (profile ``default``), the
  fast solvers beside.

``ledger(rows)`` computes one ``ClaimRow`` per (claim, condition, size) from a results
table (the ``paper-claims`` study, ``harness/run/studies.py``); ``write_ledger`` writes it as
``claims.csv`` (``LEDGER_COLUMNS``).  The claims and their rules are one table,
``claim_rules.CLAIMS``; every verdict is ``claim_rules.judge`` of the claim's rule, the
measured value and the relative spread of its timed repeats (``repeats``, ``spread``:
every timed total is the median over repeats, and a verdict whose margin lies inside the
spread is ``unresolved``; a timing from one repeat is judged with
``SINGLE_REPEAT_SPREAD``).  A claim the table holds no measurement of -- an answer
lacking a finite time, load or count is none (``claim_tables.with_numbers``) -- gets one ``unmeasured``
row saying what it needs: never ``holds``, never left out."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import astuple, dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd
from contactbench.problems.operators import DEFAULT_MEMORY_BUDGET
from contactbench.problems.scenes.cmr import POWER_LAW_FAMILY, ROLLOFF_FAMILY
from contactbench.solvers.admm import PAPER_PARAMS
from contactbench.solvers.registry import get_solver

from ..table.files import replace_atomically
from ..table.schema import ANSWERED
from .claim_measures import FIG5_MIN_N, best_k, fig5_measure, k_sweep_rows, k_sweep_totals, papers_admm
from .claim_rules import (CLAIMS, MIN_SEEDS, PAPER_N, PK_PRINTED_READING, VERDICTS, Claim, Timing, falls, judge,
                          judge_timed, over_repeats, spread)
from .claim_tables import (COLD, CONDITION_PROFILES, PAPER_METHODS, condition_words, ledger_rows, nnlsgp_cold, of_condition,
                           paper_labels, playing, ratio, seeds_of, seeds_text, totals, under)
from .core import parse_json, per_cell
from .sections.cmr import cmr_pairs, instance_totals, recorded_families
from .sections.counterexample import ledger_shares

__all__ = ["CLAIMS", "CONDITION_PROFILES", "FIG5_MIN_N", "VERDICTS", "Claim", "falls", "judge", "ratio", "spread"]

#: The file the ledger is written to, in the run folder.
LEDGER_NAME = "claims.csv"
#: The columns of ``claims.csv``, in order.
LEDGER_COLUMNS: tuple[str, ...] = ("claim", "figure", "tex_lines", "paper_value", "condition", "measured",
                                   "n_or_size", "seeds", "repeats", "spread", "verdict", "evidence")
#: The conditions, by the table's ``operator`` value.
CONDITIONS: tuple[str, ...] = ("dense", "fft")


@dataclass(frozen=True)
class ClaimRow:
    """One row of ``claims.csv`` (``LEDGER_COLUMNS``): ``repeats`` the fewest timed repeats
    a measured total rests on (0: not a timing), ``spread`` the measurement's relative
    spread over them (NaN: none known)."""

    claim: str
    figure: str
    tex_lines: str
    paper_value: str
    condition: str
    measured: float
    n_or_size: str
    seeds: str
    repeats: int
    spread: float
    verdict: str
    evidence: str


def inexact(claim_id: str, labels: Iterable[str]) -> list[str]:
    """The labels among ``labels`` of the methods claim ``claim_id`` reads as printed,
    inexact by design (``Claim.inexact``: a label, cold or not, of one of them)."""
    names = CLAIMS[claim_id].inexact
    return [s for s in labels if str(s).removesuffix(COLD) in names]


def claim_ratio(claim_id: str, tot: pd.DataFrame, a: str, b: str, rows: pd.DataFrame, of: str = "total_s"
                ) -> tuple[float, str, Timing]:
    """``claim_tables.ratio`` of a / b for claim ``claim_id`` (``tot``: ``totals`` of ``rows``):
    its inexact methods read as printed where their answers are at their own stop with the
    other side's load (``claim_tables.as_printed_refusal``), any other unconverged side no
    measurement.  A side that is pk-printed names the project's reading of Algorithm 2
    (``claim_rules.PK_PRINTED_READING``)."""
    m, words, timing = ratio(tot, a, b, of, inexact=inexact(claim_id, (a, b)), rows=rows)
    printed = [s for s in (a, b) if s.removesuffix(COLD) == "pk-printed"]
    return m, words + (f"; {printed[0]}: {PK_PRINTED_READING}" if printed else ""), timing


def claim_row(claim_id: str, condition: str, measured: float, n_or_size: str, seeds: str, evidence: str,
              testable: bool = True, timing: Timing = Timing()) -> ClaimRow:
    """The ledger row of one measurement, its verdict from the claim's rule and spread."""
    c = CLAIMS[claim_id]
    return ClaimRow(c.id, c.figure, c.tex_lines, c.paper_value, condition, float(measured), n_or_size, seeds,
                    int(timing.repeats), float(timing.spread),
                    judge_timed(claim_id, measured, evidence, timing, testable), evidence)


#: Fig. 4's time ratios: (claim, numerator label, denominator label); "admm" stands for
#: ADMM as the paper states it (``claim_measures.papers_admm``; where the rows hold none,
#: an ``unmeasured`` row says so).
FIG4_RATIOS: tuple[tuple[str, str, str], ...] = (
    ("fig4-pkprinted-over-nnlsgp", "pk-printed" + COLD, "nnls-gp"),
    ("fig4-pk-cold-over-nnlsgp", "pk" + COLD, "nnls-gp"),
    ("fig4-admm-over-nnlsgp", "admm", "nnls-gp"),
    ("fig4-greedy-over-nnlsgp", "greedy-cg" + COLD, "nnls-gp"),
    ("fig5-chol-far-from-nnls", "greedy-chol" + COLD, "nnls"),
)
#: Iteration ratios of the same size: (claim, numerator label, denominator label).
ITERATION_RATIOS: tuple[tuple[str, str, str], ...] = (
    ("pkprinted-fewer-iterations-than-greedy", "pk-printed" + COLD, "greedy-cg" + COLD),
    ("pk-fewer-iterations-than-greedy", "pk" + COLD, "greedy-cg" + COLD),
    ("nnls-warm-cuts-iterations", "nnls", "nnls" + COLD),
)


def fig4_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 4 and the sections it measures, per grid size: NNLS+GP against P&K (printed and
    1999) cold, ADMM, greedy CG; greedy Cholesky against NNLS; pure GP; the fastest paper
    method; the same load / contact over every paper method's answer; iteration ratios;
    the share of the trial set in contact."""
    warm = of_condition(rows, "paper-sweep", condition)
    cold = of_condition(rows, "greedy-linear-solvers", condition)
    out: list[ClaimRow] = []
    for N in sorted(warm["N"].dropna().unique()):
        w = warm[warm["N"] == N]
        c = cold[(cold["N"] == N) & cold["instance"].isin(set(w["instance"]))]
        both = pd.concat([w, c.assign(solver=c["solver"] + COLD)])
        tot = totals(both)
        size = f"{int(N)}^2, n <= {int(w['n'].max())}"
        seeds = seeds_of(w)
        where = (f"results.csv: paper-sweep (warm) and greedy-linear-solvers (cold) N={int(N)} "
                 f"{condition_words(condition)}")
        cold_gp = nnlsgp_cold(tot)
        if cold_gp is None and "gp" + COLD in tot.index:
            out.append(claim_row("gp-pure-slow", condition, math.nan, size, seeds, f"{where}; no nnls-gp (K = 100) "
                                 "from p = 0 at this size: the claim reads t(gp cold) / t(nnls-gp cold), never the "
                                 "warm run", testable=False))
        for claim, a, b in FIG4_RATIOS + (("gp-pure-slow", "gp" + COLD, cold_gp or ""),):
            a = (papers_admm(both[both["solver"].isin(tot.index)]) or "") if a == "admm" else a
            if claim == "fig4-admm-over-nnlsgp" and not a and (both["base_solver"] == "admm").any():
                out.append(claim_row(claim, condition, math.nan, size, seeds, f"{where}; no ADMM as the paper states "
                                     f"it ({PAPER_PARAMS}): the registry's admm (rho relative to mean diag H, the KKT "
                                     "stop) is another method", testable=False))
            if a in tot.index and b in tot.index:
                m, words, timing = claim_ratio(claim, tot, a, b, both)
                who = f"; admm: ADMM as the paper states it ({PAPER_PARAMS})" if claim == "fig4-admm-over-nnlsgp" else ""
                out.append(claim_row(claim, condition, m, size, seeds, f"{where}{who}; {words}", timing=timing))
        for claim, a, b in ITERATION_RATIOS:
            if a in tot.index and b in tot.index:
                m, words, timing = claim_ratio(claim, tot, a, b, both, of="iterations")
                out.append(claim_row(claim, condition, m, size, seeds, f"{where}; iterations: {words}", timing=timing))
        out += fastest_rows(tot, both, paper_labels(tot), condition, size, seeds, where)
        out += agreement_rows(both, condition, size, seeds, where)
    return out


def fastest_rows(tot: pd.DataFrame, rows: pd.DataFrame, labels: list[str], condition: str, size: str,
                 seeds: str, where: str) -> list[ClaimRow]:
    """"NNLS+GP is the fastest": t(nnls-gp) / t(the fastest other paper method that
    answered every step), ``tot`` the ``totals`` of ``rows``.  A paper method that did not
    answer every step is slower only where the time it spent (``spent_s``) already exceeds
    NNLS+GP's whole total: a lower bound of its own.  One that stopped sooner, or one of the
    paper's methods (``PAPER_METHODS``, whatever the table plans) with no row at the size,
    leaves the claim about every method ``unmeasured``, unless a method that answered is
    faster already (``fails``, whatever the others would give)."""
    if "nnls-gp" not in labels or len(labels) < 2:
        return []
    everyone = tot.loc[[s for s in labels if s.removesuffix(COLD) != "nnls-gp"]]
    others = everyone[everyone["comparable"]]
    if others.empty:
        return [claim_row("fig4-nnlsgp-fastest", condition, math.nan, size, seeds, f"{where}; no other paper method "
                          "answered every step")]
    best = str(others["total_s"].idxmin())
    m, words, timing = claim_ratio("fig4-nnlsgp-fastest", tot, "nnls-gp", best, rows)
    own = tot.loc["nnls-gp", "total_s"]
    ran = {s.removesuffix(COLD) for s in tot.index}
    stopped = sorted(str(s) for s, t in everyone[~everyone["comparable"]]["spent_s"].items() if not t > own)
    never = sorted(s for s in PAPER_METHODS if s not in ran)
    unknown = stopped + never
    if unknown:
        words += "".join((f"; stopped short of every step in less time than NNLS+GP's total: {', '.join(stopped)}"
                          if stopped else "", f"; no row at this size of: {', '.join(never)}" if never else "",
                          ": the rest cannot hold 'the fastest'"))
    return [claim_row("fig4-nnlsgp-fastest", condition, m, size, seeds, f"{where}; fastest other paper method: "
                      f"{best}; {words}", timing=timing,
                      testable=not unknown or CLAIMS["fig4-nnlsgp-fastest"].rule.at(m) == "fails")]


def agreement_rows(both: pd.DataFrame, condition: str, size: str, seeds: str, where: str) -> list[ClaimRow]:
    """The same load and contact domain at the top step over every paper method's answer
    (a wrong answer counts: the claim is about the methods, not about the judge).  Where a
    paper method (``PAPER_METHODS``, whatever the table plans) gave no answer at an instance's top step,
    the rest cannot hold a claim about every method: ``unmeasured``, unless they disagree
    (``fails``, whatever the missing ones would give)."""
    r = both[both["base_solver"].isin(PAPER_METHODS)]
    cells = per_cell(r)
    top = cells[(cells["step"] == cells["step"].max()) & cells["status"].isin(ANSWERED)]
    answered = {i: set(g["base_solver"]) for i, g in top.groupby("instance")}
    missing = sorted({s for i in set(both["instance"]) for s in PAPER_METHODS if s not in answered.get(i, set())})
    partial = f"; no top-step answer of {', '.join(missing)}: the rest cannot hold 'every method'" if missing else ""
    out = []
    for claim, col in (("fig4-same-load", "load"), ("fig4-same-contact", "contact_fraction")):
        if col not in top.columns:
            continue
        per_inst = [spread(g[col]) for _, g in top.groupby("instance") if g["solver"].nunique() > 1]
        m = max(per_inst) if per_inst and all(np.isfinite(per_inst)) else math.nan  # (NaN: not the order's pick)
        solvers = sorted(set(top["solver"]))
        out.append(claim_row(claim, condition, m, size, seeds, f"{where}; top step, the largest relative spread "
                             f"over instances among the answers of {', '.join(solvers)}{partial}"
                             if len(solvers) > 1 else "", testable=not missing or CLAIMS[claim].rule.at(m) == "fails"))
    sub = top[top["base_solver"] == "nnls"] if "contact_fraction" in top.columns else top.iloc[0:0]
    if len(sub):
        share = sub["contact_fraction"] * sub["N"] * sub["N"] / sub["n"]
        out.append(claim_row("subset-in-contact", condition, float(share.max()), size, seeds,
                             f"{where}; top step, nnls: contact fraction x N^2 / n, the largest over instances"))
    return out


def top_step_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 4's P&K1999 / NNLS+GP at the sizes that have no load history in the table: the
    cold solves of ``greedy-linear-solvers`` at a grid size that ``paper-sweep`` did not run
    (the study's top step of the paper's own 512^2 surface, n = 35,218 against the paper's
    35,555), every solver from p = 0: P&K as printed (pk-printed) and P&K 1999 (pk), each
    against NNLS+GP.  A size where one was skipped (a memory budget below the dense H)
    gives ``unmeasured`` rows that carry the skip reason."""
    warm_sizes = set(of_condition(rows, "paper-sweep", condition)["N"].dropna().unique())
    planned = under(rows, condition)
    planned = planned[planned["scene"] == "greedy-linear-solvers"]
    out: list[ClaimRow] = []
    for N in sorted(set(planned["N"].dropna().unique()) - warm_sizes):
        for claim, pk in (("fig4-pkprinted-over-nnlsgp", "pk-printed"), ("fig4-pk-cold-over-nnlsgp", "pk")):
            here = planned[(planned["N"] == N) & planned["solver"].isin([pk, "nnls-gp"])]
            if here.empty or pk not in set(here["solver"]):
                continue
            done = here[here["status"] != "skipped"]
            m, words, timing = claim_ratio(claim, totals(done), pk, "nnls-gp", done)
            skipped = here[here["status"] == "skipped"]
            if len(skipped):
                words += "; skipped: " + "; ".join(f"{s} ({r})" for s, r in zip(skipped["solver"],
                                                                               skipped["skip_reason"]))
            steps = sorted(here["step"].dropna().unique())
            size = f"{int(N)}^2, {len(steps)} step(s) cold, n <= {int(here['n'].max())}"
            where = (f"results.csv: greedy-linear-solvers N={int(N)} {condition_words(condition)}, {pk} and nnls-gp "
                     "from p = 0")
            out.append(claim_row(claim, condition, m, size, seeds_of(here), f"{where}; {words}", timing=timing))
    return out


def fig5_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 5 per grid size: greedy Cholesky and Gauss-Seidel against greedy CG
    (``claim_measures.fig5_measure``), and the Cholesky memory limit (our n limit from the
    memory budget)."""
    r = of_condition(rows, "greedy-linear-solvers", condition)
    out: list[ClaimRow] = []
    for N in sorted(r["N"].dropna().unique()):
        at_n = r[r["N"] == N]
        cells = per_cell(at_n)
        size = f"{int(N)}^2, n <= {int(cells['n'].max())}"
        seeds = seeds_of(cells)
        for claim, other in (("fig5-chol-over-cg", "greedy-chol"), ("fig5-gs-over-cg", "greedy-gs")):
            x = fig5_measure(at_n, other, "greedy-cg")
            if x is None:
                continue
            out.append(claim_row(claim, condition, x.measured, size, seeds,
                                 f"results.csv: greedy-linear-solvers N={int(N)} {condition_words(condition)}; median over "
                                 f"{x.count} steps with n >= {FIG5_MIN_N} both solved" if x.count else "",
                                 timing=x.timing))
    chol = under(rows, condition)
    chol = playing(chol, "greedy-chol")
    chol = chol[chol["status"] != "skipped"]
    if len(chol):
        out.append(chol_memory_row(chol, condition))
    return out


def chol_memory_row(chol: pd.DataFrame, condition: str) -> ClaimRow:
    """``fig5-chol-memory`` ("out of memory for n > 20000", tex 1074-1076, about 20,000:
    the rule's band) on the attempted greedy-chol rows of one condition.  The limit lies
    between the largest n answered and the smallest n above it that failed for memory
    (that row printed in the evidence; a refusal of our memory budget is said to be ours,
    not the paper's 128 GB machine): measured is that failure's n; where the two ends read
    different verdicts the row is ``unresolved`` (an infinite spread).  A failure above the
    largest answer that is not for memory leaves the claim unmeasured; with no failure
    above, the largest n answered is a lower bound of the limit, judged only where it
    already fails the rule.  Tested only where n > 20,000 was tried."""
    rule = CLAIMS["fig5-chol-memory"].rule
    answered = chol[chol["status"].isin(ANSWERED)]
    largest = float(answered["n"].max()) if len(answered) else 0.0
    limit = math.isqrt(int(DEFAULT_MEMORY_BUDGET // 8))
    above = chol[~chol["status"].isin(ANSWERED) & (chol["n"] > largest)]
    errors = above.get("error", above["status"]).fillna("").astype(str)
    tried = float(chol["n"].max())
    size = (f"n <= {int(tried)} tried; our dense limit n = {limit} ({DEFAULT_MEMORY_BUDGET / 2**30:g} GiB a matrix: "
            f"H and its factor {2 * DEFAULT_MEMORY_BUDGET / 2**30:g} GiB)")
    words = f"results.csv: greedy-chol {condition_words(condition)}, largest n answered {largest:g}"
    testable, timing = tried > 20000, Timing()
    if len(above):
        first = above.sort_values("n").iloc[0]
        err = str(first["error"]) if "error" in above.columns and pd.notna(first["error"]) else ""
        measured = float(first["n"])
        words += f"; the failure above it: n = {int(first['n'])}, status {first['status']}, error {err[:160]!r}"
        if not errors.str.contains("emory").all():
            measured = math.nan  # above the largest answered, a failure that is not the memory's: not the claim
            words += "; a failure above it is not for memory: not the claim"
        elif "budget" in err.lower():
            words += (f"; a refusal of our memory budget ({DEFAULT_MEMORY_BUDGET / 2**30:g} GiB a matrix), not "
                      "the paper's 128 GB machine")
        ends = {rule.at(x) for x in (max(largest, 1.0), measured)} if math.isfinite(measured) else set()
        if len(ends) > 1:
            timing = Timing(0, math.inf)
            words += f"; the limit lies in ({largest:g}, {measured:g}]: its ends read {' and '.join(sorted(ends))}"
    else:
        measured = largest if len(answered) else math.nan
        words += "; no failure above it: the limit is at least this"
        testable = testable and math.isfinite(measured) and rule.at(measured) == "fails"
    return claim_row("fig5-chol-memory", condition, measured, size, "",
                     words + "; the claim is tested only where n > 20000 was tried", testable=testable, timing=timing)


def example1_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Example 1: per n, the share of seeds whose greedy-CG answer the judge rejects."""
    r = playing(of_condition(rows, "counterexample", condition), "greedy-cg")
    if r.empty:
        return []
    out = []
    for _, f in ledger_shares(r).iterrows():  # per solver and n; a crash or timeout is no answer
        sub = r[r["n"] == f["n"]]
        seeds = seeds_of(sub)
        answered = int(f["answered"])
        out.append(claim_row("ex1-greedy-fails", condition, float(f["share"]) if answered else math.nan,
                             f"n = {int(f['n'])}", seeds,
                             f"results.csv: counterexample {condition_words(condition)}, greedy-cg's answer violates the "
                             f"LCP (read wrong) on {int(f['wrong'])} of the {answered} seeds it answered "
                             f"({int(f['violations'])} of {int(f['seeds'])} rejected in all)"))
    return out


#: Section 3.1's words around Example 1, each on its own scene (problems/scenes/example1_variants.py):
#: (claim, scene).
EXAMPLE1_VARIANT_CLAIMS: tuple[tuple[str, str], ...] = (
    ("greedy-random-h-fails", "random-positive-h"), ("greedy-spacing-2delta", "counterexample-2delta"))


def example1_variant_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Example 1's variants (``EXAMPLE1_VARIANT_CLAIMS``): per n, the share of seeds whose
    greedy-CG answer the judge rejects, read as Example 1 is (``ledger_shares``): its
    ``violations`` over ``seeds`` -- "not solved exactly" and "always provides a solution
    satisfying w* >= 0" are both about every seed, so an unconverged answer, a crash or a
    timeout counts as rejected; NaN (unmeasured) where no seed has an answer at all."""
    out = []
    for claim_id, scene in EXAMPLE1_VARIANT_CLAIMS:
        r = playing(of_condition(rows, scene, condition), "greedy-cg")
        for _, f in (ledger_shares(r).iterrows() if not r.empty else ()):
            n, seeds, rejected = int(f["n"]), int(f["seeds"]), int(f["violations"])
            wrong, unconverged, silent = int(f["wrong"]), int(f["unconverged"]), int(f["no answer"])
            which = seeds_of(r[r["n"] == f["n"]])
            m, rule = rejected / seeds if silent < seeds else math.nan, CLAIMS[claim_id].rule
            few = (f"; {seeds - silent} answered seeds, fewer than MIN_SEEDS = {MIN_SEEDS}: no share of 'always' or "
                   "'many cases'" if seeds - silent < MIN_SEEDS else "")
            out.append(claim_row(claim_id, condition, m, f"n = {n}",
                                 which, f"results.csv: {scene} {condition_words(condition)}, greedy-cg rejected by the "
                                 f"judge on {rejected} of {seeds} seeds (n = {n}, seeds {which}): {wrong} wrong "
                                 f"(claimed converged), {unconverged} unconverged, {silent} no answer{few}",
                                 testable=not few or (rule.yes_no and rule.at(m) == "fails")))
    return out


def rejected_share(rows: pd.DataFrame, label: str) -> tuple[float, str]:
    """The share of a solver's solves the judge rejects (attempted, folded over repeats:
    any status but "solved"), with the words."""
    cells = per_cell(rows[rows["solver"] == label])
    if cells.empty:
        return math.nan, ""
    bad = int((~cells["solved"]).sum())
    return bad / len(cells), f"{label} rejected on {bad} of {len(cells)} solves"


def greedy_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Greedy's failures outside Example 1: on the rough surface's independent steps
    ("rare", the conclusion) and on the smooth indenters (hertz, flat-punch)."""
    out: list[ClaimRow] = []
    rough = of_condition(rows, "greedy-linear-solvers", condition)
    rough = rough[rough["solver"] == "greedy-cg"]
    m, words = rejected_share(rough, "greedy-cg")
    if words:
        size = f"N = {', '.join(f'{int(x)}' for x in sorted(rough['N'].dropna().unique()))}"
        out.append(claim_row("greedy-rare", condition, m, size, seeds_of(rough),
                             f"results.csv: greedy-linear-solvers {condition_words(condition)}; {words}"))
    smooth = pd.concat([of_condition(rows, s, condition) for s in ("hertz", "flat-punch")])
    m, words = rejected_share(smooth, "greedy-cg")
    if words:
        size = f"n <= {int(smooth['n'].max())}"
        out.append(claim_row("greedy-smooth-no-failures", condition, m, size, "",
                             f"results.csv: hertz and flat-punch {condition_words(condition)}; {words}"))
    return out


def fig6_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 6 on the K sweep of ``claim_measures.k_sweep_rows``: the K of least total time
    (``best_k``), t(K=200) / t(K=100), and t(K=100) / t(K=0)."""
    here = under(rows, condition)
    sweep, cold = k_sweep_rows(here[here["status"] != "skipped"])
    if sweep.empty:
        return []
    tot, per_repeat = k_sweep_totals(sweep)
    size = f"{int(sweep['N'].max())}^2, n <= {int(sweep['n'].max())}"
    seeds = seeds_of(sweep)
    how = "greedy-linear-solvers (cold: every K from p = 0)" if cold else "gp-k-sweep (warm along the history)"
    where = f"results.csv: {how} {condition_words(condition)}, K = {', '.join(f'{k:g}' for k in sorted(tot['K']))}"
    per_k = "; median total per K: " + ", ".join(
        f"K {k:g}: {t:.4g} s" + ("" if ok else " (not every step answered)")
        for k, t, ok in sorted(zip(tot["K"], tot["total_s"], tot["comparable"])))
    out = []
    label = {float(k): s for s, k in zip(tot.index, tot["K"])}
    least = best_k(tot, per_repeat)  # None: some K did not answer every step, so the least is not known
    if least is not None:
        best, near, rep = least
        words = f"; not told from K = {', '.join(f'{k:g}' for k in near)} (a repeat's least, or tied)" if near else ""
        out.append(claim_row("fig6-best-k", condition, best, size, seeds, where + per_k + words, timing=rep))
    for claim, a, b, testable in (("fig6-k200-over-k100", 200.0, 100.0, True),
                                  ("gp-warm-start-benefit", 100.0, 0.0, cold)):
        if a in label and b in label:
            m, words, timing = ratio(tot, label[a], label[b])
            why = "" if testable else "; K = 0 is warm along the history here, the paper's is cold (p = 0)"
            out.append(claim_row(claim, condition, m, size, seeds, f"{where}; {words}{why}", testable, timing))
    return out


def cmr_totals(rows: pd.DataFrame, scene: str, condition: str) -> pd.DataFrame:
    """``sections.cmr.instance_totals`` of one CMR scene under one condition (empty if none)."""
    r = of_condition(rows, scene, condition)
    pairs = cmr_pairs(r) if len(r) else pd.DataFrame()
    return instance_totals(pairs) if len(pairs) else pd.DataFrame()


def farthest_from_half(per_h: pd.Series) -> float:
    """Fig. 8's time reading: the per-H median ratio farthest from the paper's 0.5."""
    return float(per_h.iloc[int(np.argmax(np.abs(per_h.to_numpy() - 0.5)))]) if len(per_h) else math.nan


#: The paper's CMR set-up (tex 1208-1211): the cascade from 16 heights per side, h = 2.  A
#: CMR variant is found by these params (``is_papers_cmr``), never by its label.
PAPER_CMR: dict[str, float] = {"h": 2.0, "coarsest": 16.0}


def papers_cmr(t: pd.DataFrame) -> pd.DataFrame:
    """The ``instance_totals`` rows (columns ``h``, ``coarsest``) of the paper's CMR set-up."""
    return t[(t["h"] == PAPER_CMR["h"]) & (t["coarsest"] == PAPER_CMR["coarsest"])]


def is_papers_cmr(params: object) -> bool:
    """Whether a CMR row's ``params`` (JSON) are the paper's set-up (``PAPER_CMR``)."""
    p = parse_json(params, {})
    try:
        return isinstance(p, dict) and all(float(p.get(k, math.nan)) == v for k, v in PAPER_CMR.items())
    except (TypeError, ValueError):
        return False


def fig8_per_h(t8: pd.DataFrame) -> pd.Series:
    """Fig. 8's median t(CMR) / t(direct) per H of ``instance_totals`` rows, the paper's set-up
    only (``papers_cmr``)."""
    return papers_cmr(t8).groupby("H")["ratio"].median()


def fig8_time(rows: pd.DataFrame, condition: str) -> float:
    """``farthest_from_half`` of the ``cmr`` rows given (one repeat's, for the spread)."""
    t8 = cmr_totals(rows, "cmr", condition)
    return farthest_from_half(fig8_per_h(t8)) if len(t8) else math.nan


def fig9_time(rows: pd.DataFrame, condition: str, h: float) -> float:
    """Fig. 9's median time ratio at ``h`` over the ``cmr-h-sweep`` rows given, first level
    the smallest."""
    t9 = cmr_totals(rows, "cmr-h-sweep", condition)
    if t9.empty:
        return math.nan
    t9 = t9[(t9["coarsest"] == t9["coarsest"].min()) & (t9["h"] == h)]
    return float(t9["ratio"].median()) if len(t9) else math.nan


def fig8_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 8 (h = 2 per H): the time ratio, the error for H > 0.5 and its fall with H;
    the abstract's "at least 2x faster than NNLS+GP" where the scene ran nnls-gp."""
    t8 = cmr_totals(rows, "cmr", condition)
    if t8.empty:
        return []
    t8 = papers_cmr(t8)
    if t8.empty:
        return []
    size, seeds = f"{int(t8['N'].max())}^2, H = {', '.join(f'{h:g}' for h in sorted(t8['H'].unique()))}", \
        seeds_text(t8["seed"])
    per_h = fig8_per_h(t8)
    r8 = of_condition(rows, "cmr", condition)
    worst, spread_ = over_repeats(r8, lambda g: fig8_time(g, condition))
    reps = Timing(int(per_cell(r8)["repeats"].min()), spread_)
    out = [claim_row("fig8-cmr-time", condition, worst, size, seeds, f"results.csv: cmr {condition_words(condition)}, cmr+nnls {PAPER_CMR}, median t(CMR)/t(direct) per "
                     "H: " + ", ".join(f"H {h:g}: {v:.3g}" for h, v in per_h.items()), timing=reps)]
    # the paper's error is at the maximum normal force (tex 1226-1228): an instance whose top
    # paired step is not the scene's top step has no error to read, and the claims over
    # every instance then rest on the rest only where they already fail
    top, at_top = r8["step"].max(), t8["step"] == r8["step"].max()
    short = sorted(set(r8["instance"]) - set(t8.loc[at_top, "instance"]) | set(t8.loc[~at_top, "instance"]))
    lacking = f"; no CMR and direct answer at the top step {int(top)} of: {', '.join(short)}" if short else ""
    t8 = t8[at_top & ~t8["instance"].isin(short)]
    hi = t8[t8["H"] > 0.5]
    errs = ", ".join(f"{s} H {h:g}: {e:.3g}" for s, h, e in zip(hi["instance"], hi["H"], hi["err"]))
    m = float(hi["err"].abs().max()) if len(hi) else math.nan
    out.append(claim_row("fig8-cmr-error", condition, m, size,
                         seeds, f"results.csv: cmr {condition_words(condition)}, top step, the largest |error| (every error < 2 %: tex 1349-1350) "
                         f"over {len(hi)} instances with H > 0.5: {errs}{lacking}" if len(hi) else "",
                         testable=not short or CLAIMS["fig8-cmr-error"].rule.at(m) == "fails"))
    err_h = t8.assign(a=t8["err"].abs()).groupby("H")["a"].median()
    out.append(claim_row("fig8-error-falls-with-h-exponent", condition, falls(err_h), size, seeds,
                         f"results.csv: cmr {condition_words(condition)}, median |error| per H: " + ", ".join(f"H {h:g}: {v:.3g}"
                                                                               for h, v in err_h.items()) + lacking,
                         testable=not short))
    r = of_condition(rows, "cmr", condition)
    cmr = r[(r["base_solver"] == "cmr+nnls") & r["params"].map(is_papers_cmr)]
    labels = sorted(set(cmr["solver"]))
    if len(labels) > 1:
        out.append(claim_row("cmr-2x-over-nnlsgp", condition, math.nan, size, seeds, f"results.csv: cmr {condition_words(condition)}; more than "
                             f"one cmr+nnls label with the paper's set-up {PAPER_CMR}: {', '.join(labels)}",
                             testable=False))
    elif labels and "nnls-gp" in set(r["solver"]):
        tot = totals(r[r["solver"].isin([labels[0], "nnls-gp"])])
        # (unchecked: CMR's load is approximate by design, judged by fig8-cmr-error)
        m, words, timing = ratio(tot, labels[0], "nnls-gp", inexact=labels)
        out.append(claim_row("cmr-2x-over-nnlsgp", condition, m, size, seeds, f"results.csv: cmr "
                             f"{condition_words(condition)}, cmr+nnls {PAPER_CMR}; {words}", timing=timing))
    return out


def fig9_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 9 (H = 0.7, top step, per h): n_p/n, the time ratio and the error."""
    t9 = cmr_totals(rows, "cmr-h-sweep", condition)
    if t9.empty:
        return []
    t9 = t9[t9["coarsest"] == t9["coarsest"].min()]
    size, seeds = f"{int(t9['N'].max())}^2, H = 0.7, top step", seeds_text(t9["seed"])
    med = t9.groupby("h")[["n_p_over_n", "ratio"]].median()
    err = t9.assign(a=t9["err"].abs()).groupby("h")["a"].median()
    where = f"results.csv: cmr-h-sweep {condition_words(condition)}, median over seeds at h = "
    count = t9.groupby("h")["seed"].nunique()
    out = []
    r9 = of_condition(rows, "cmr-h-sweep", condition)
    timed, spread_ = over_repeats(r9, lambda g: fig9_time(g, condition, 3.0))
    reps = Timing(int(per_cell(r9)["repeats"].min()), spread_)
    for claim, h, val in (("fig9-np-low-h", 1.25, med["n_p_over_n"]), ("fig9-np-high-h", 3.0, med["n_p_over_n"]),
                          ("fig9-time-ratio", 3.0, pd.Series({3.0: timed}).dropna()),
                          ("fig9-error", 3.0, err), ("fig9-error-001pct", 3.0, err)):
        out.append(claim_row(claim, condition, float(val.get(h, math.nan)), size, seeds,
                             f"{where}{h:g} ({int(count.get(h, 0))} seeds): {float(val[h]):.4g}"
                             if h in val.index else "",
                             timing=reps if claim == "fig9-time-ratio" else Timing()))
    if 1.25 in err.index and 3.0 in err.index:
        out.append(claim_row("fig9-error-falls-with-h", condition, falls(err), size, seeds,
                             f"{where}" + ", ".join(f"{h:g} ({v:.3g})" for h, v in err.items())))
    return out


def cutoff_time(rows: pd.DataFrame) -> float:
    """The median t(CMR) / t(direct) of the ``cmr-cutoff`` rows given (one surface's)."""
    tc = cmr_pairs(rows) if len(rows) else pd.DataFrame()
    return float((tc["solve_time_s"] / tc["direct_time_s"]).median()) if len(tc) else math.nan


def real_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Fig. 11: CMR's load error and time ratio on the power-law and the cut-off surface."""
    cut = of_condition(rows, "cmr-cutoff", condition)
    tc = cmr_pairs(cut) if len(cut) else pd.DataFrame()  # one step per instance: the pairs are the totals
    out: list[ClaimRow] = []
    if tc.empty:
        return out
    family = recorded_families(tc)
    for kind, err_id, time_id in ((POWER_LAW_FAMILY, "real-power-law-error", "real-power-law-saving"),
                                  (ROLLOFF_FAMILY, "real-cutoff-error", "real-cutoff-saving")):
        k = tc[family == kind]
        if k.empty:
            continue
        size = f"{int(k['N'].max())}^2, one step, n <= {int(k['n'].max())}"
        where = (f"results.csv: cmr-cutoff {condition_words(condition)}, {kind} surface, h = "
                 f"{', '.join(f'{h:g}' for h in k['h'].unique())}")
        t_ratio, spread_ = over_repeats(cut[cut["instance"].isin(set(k["instance"]))], cutoff_time)
        out.append(claim_row(err_id, condition, float(k["err"].median()), size, seeds_of(k), where))
        out.append(claim_row(time_id, condition, t_ratio, size, seeds_of(k),
                             f"{where}; t(CMR) / t(direct)", timing=Timing(int(k["repeats"].min()), spread_)))
    return out


#: The Fig. 4-5 claims the paper measured up to its n (``PAPER_N``) on the dense H, and the
#: paper's methods each needs there (registry names; read ``paper_size_rows``).
AT_PAPER_N: dict[str, tuple[str, ...]] = {
    "fig4-admm-over-nnlsgp": ("admm",),
    "fig4-greedy-over-nnlsgp": ("greedy-cg",),
    "fig4-nnlsgp-fastest": ("admm", "greedy-cg", "greedy-gs", "greedy-chol"),
    "fig4-same-load": ("admm", "greedy-cg", "greedy-gs", "greedy-chol"),
    "fig4-same-contact": ("admm", "greedy-cg", "greedy-gs", "greedy-chol"),
    "fig5-chol-over-cg": ("greedy-chol", "greedy-cg"),
    "fig5-gs-over-cg": ("greedy-gs", "greedy-cg"),
}
#: A method "ran at the paper's n" when it answered on the dense H at this share of it (our
#: seed's top step has n = 35,218).
PAPER_N_SHARE = 0.9


def model_words(solver: str, n: int) -> str:
    """What the solver's memory and time models say of one dense solve at n (its memory
    beside the dense H's 8 n^2 bytes)."""
    s = get_solver(solver)
    t = s.time_estimate(n, "dense")
    return (f"{solver} {s.memory_estimate(n) / 2**30:.1f} GiB beside the dense H's {8.0 * n * n / 2**30:.1f} GiB"
            + ("" if t is None else f", about {t:.2g} s a solve") + " (its models)")


def paper_size_rows(rows: pd.DataFrame, condition: str) -> list[ClaimRow]:
    """Under the paper's condition (dense), an ``unmeasured`` row at the paper's n for each
    ``AT_PAPER_N`` claim whose methods did not all answer there: which did not, the
    largest n each answered at, and what its memory and time models say a solve at the
    paper's n needs."""
    if condition != "dense":
        return []
    dense = under(rows, "dense")
    dense = dense[dense["status"].isin(ANSWERED)]
    largest = dense.groupby("solver")["n"].max()  # (by role: ``ledger_rows`` names the paper's methods)
    out = []
    for claim, solvers in AT_PAPER_N.items():
        missing = [s for s in solvers if not largest.get(s, 0) >= PAPER_N_SHARE * PAPER_N]
        if not missing:
            continue
        why = "; ".join(f"{model_words(s, PAPER_N)}, largest n answered here {int(largest.get(s, 0))}"
                        for s in missing)
        out.append(claim_row(claim, condition, math.nan, f"n = {PAPER_N} (the paper's)", "",
                             f"not run at the paper's n: {why}", testable=False))
    return out


#: The ledger's readers, each of one part of the paper (conditions looped where they apply).
READERS: tuple[Callable[[pd.DataFrame, str], list[ClaimRow]], ...] = (
    example1_rows, example1_variant_rows, greedy_rows, fig4_rows, top_step_rows, paper_size_rows, fig5_rows, fig6_rows, fig8_rows,
    fig9_rows, real_rows)


def unmeasured_rows(found: set[str]) -> list[ClaimRow]:
    """One ``unmeasured`` row (condition dense) for every claim no reader measured: the
    untestable claim's reason, else what the table lacks."""
    return [claim_row(c.id, "dense", math.nan, "", "", c.rule.reason or f"not in this table: {c.measures}",
                      testable=False) for c in CLAIMS.values() if c.id not in found]


def ledger(rows: pd.DataFrame) -> pd.DataFrame:
    """The ledger of a results table: one row per (claim, condition, size), ``LEDGER_COLUMNS``;
    every claim of ``CLAIMS`` at least once (module doc)."""
    rows = ledger_rows(rows)  # the paper's methods by base_solver and params, never by label
    out: list[ClaimRow] = []
    for cond in CONDITIONS:
        for read in READERS:
            out += read(rows, cond)
    out += unmeasured_rows({r.claim for r in out})
    order = {c: i for i, c in enumerate(CLAIMS)}
    out.sort(key=lambda r: (order[r.claim], CONDITIONS.index(r.condition)))
    return pd.DataFrame([astuple(r) for r in out], columns=[f.name for f in fields(ClaimRow)])


def write_ledger(table: pd.DataFrame, out_dir: str | Path) -> Path:
    """Write ``ledger(table)`` to OUT/claims.csv; return its path."""
    path = Path(out_dir) / LEDGER_NAME
    rows = ledger(table)
    replace_atomically(path, lambda tmp: rows.to_csv(tmp, index=False))
    return path
