"""The paper sections' readings (harness/report/sections/paper.py, paper_readings.py) say
no more than the table shows: the direction of a ratio is read before its closeness, a
time ratio the timing spread of single repeats cannot tell from 1 is unresolved, a
"fastest" solver is named only when every other one is slower by more than that spread,
and a factor "smaller by" is taken against the number the paper's claim states.

The tables are small fabricated sweeps: each solver's time per step is given, and a
section is called directly on a report context over the written table.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from contactbench.harness.report import core as rp
from contactbench.harness.report.view import read_table
from contactbench.harness.report.claim_measures import SINGLE, Spread
from contactbench.harness.report.claim_rules import CLAIMS, SINGLE_REPEAT_SPREAD
from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.report.sections.counterexample import share_verdict
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row, write_out


def _section(tmp_path: Path, df: pd.DataFrame, scene: str) -> str:
    """The reading of the paper section of ``scene`` over the table ``df`` (figures not saved)."""
    return section_body(tmp_path, df, scene).split("**Reading.**")[1]


def section_body(tmp_path: Path, df: pd.DataFrame, scene: str) -> str:
    """The body of the paper section of ``scene`` over the table ``df`` (figures not saved)."""
    out = write_out(tmp_path, df)
    ctx = rp.ReportContext(out, read_table(out), META)

    def keep(fig: Any, name: str, on_page: bool = False) -> str:
        return f"figures/{name}.png"

    ctx.save_figure = keep  # type: ignore[method-assign]
    section = {"paper-sweep": rpp.fig4_section, "greedy-linear-solvers": rpp.fig5_section,
               "gp-k-sweep": rpp.fig6_section}[scene]
    sec = section(ctx, ctx.rows(scene))
    assert sec is not None
    return sec.body


def sweep(times: dict[str, list[float]], repeats: int = 1, drift: float = 0.0) -> pd.DataFrame:
    """A one-instance paper-sweep at profile "high": solver -> its time at each load step,
    every step solved, timed ``repeats`` times (repeat r takes the times x (1 + r drift))."""
    rows = []
    for s, ts in times.items():
        for k, t in enumerate(ts):
            for r in range(repeats):
                rows.append(report_row(scene="paper-sweep", instance="i0", step=k, n=100 * (k + 1), N=64, solver=s,
                                       profile="high", repeat=r, solve_time_s=t * (1 + r * drift),
                                       dim_load=1e-4 * (k + 1), warm_start=False))
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def sentence(reading: str, start: str) -> str:
    """The sentence of ``reading`` that begins with ``start``."""
    return start + reading.split(start, 1)[1].split(". ")[0]


# ---------------------------------------------------------------------------
# The direction comes before closeness
# ---------------------------------------------------------------------------


def test_a_ratio_on_the_other_side_of_1_is_never_close() -> None:
    """The paper's greedy Cholesky is 30-40 % faster than CG (0.6-0.7); a measured 1.1x
    or 1.3x, slower, points the opposite way and is never read as close."""
    chol = rpp.ledger_claim("fig5-chol-over-cg")
    for measured in (1.1, 1.3):
        words = rpp.agreement(measured, chol)
        assert words.startswith("points the opposite way") and "close" not in words, words
    slower = rpp.ledger_claim("fig5-gs-over-cg")
    assert rpp.agreement(0.8, slower).startswith("points the opposite way")
    assert rpp.agreement(0.65, chol).startswith("agrees with the paper")
    assert rpp.agreement(0.45, chol).startswith("is close to the paper")  # faster, as the paper: close


READING_WORDS = {"agrees with the paper": "holds", "is close to the paper": "partly", "points the same way": "fails"}


@pytest.mark.parametrize("ledger", ["fig4-pkprinted-over-nnlsgp", "fig4-pk-cold-over-nnlsgp",
                                    "fig4-greedy-over-nnlsgp", "fig4-admm-over-nnlsgp", "fig5-chol-over-cg",
                                    "fig5-gs-over-cg"])
@given(log_ratio=st.floats(min_value=-6.0, max_value=6.0))
@settings(max_examples=60, deadline=None)
def test_the_paper_section_reads_a_ratio_as_the_ledger_does(ledger: str, log_ratio: float) -> None:
    """Every ratio on the paper's side of 1 gets the paper section's words of the ledger
    row's verdict: agrees <-> holds, close <-> partly, the same way but off <-> fails."""
    claim = rpp.ledger_claim(ledger)
    measured = float(10.0 ** log_ratio)
    assume(claim.direction * (1 if measured > 1.0 else -1 if measured < 1.0 else 0) > 0)
    words = rpp.agreement(measured, claim)
    read = [v for k, v in READING_WORDS.items() if words.startswith(k)]
    assert read == [claim.rule.at(measured)], (measured, words)


def test_fig5_reads_a_slower_cholesky_as_the_opposite_of_the_paper_and_counts_steps(tmp_path: Path) -> None:
    """Cholesky 1.3x CG's time on every step of two instances (three steps each): the
    reading points the opposite way, and it says its median is over 6 steps of 2
    instances, not over 6 instances."""
    rows = []
    for inst in ("a", "b"):
        for k in range(3):
            n = 50 * (k + 1)
            for s, f in (("greedy-cg", 1.0), ("greedy-chol", 1.3), ("greedy-gs", 3.0)):
                rows.append(report_row(scene="greedy-linear-solvers", instance=inst, step=k, n=n, N=16, solver=s,
                                       solve_time_s=1e-3 * f * (k + 1), dim_load=1e-3))
    reading = _section(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)), "greedy-linear-solvers")
    chol = sentence(reading, "greedy Cholesky / greedy CG time")
    assert "median over 6 common solved steps (instance, load step) of 2 instances" in chol
    assert "measured 1.3x" in chol and "points the opposite way" in chol and "close" not in chol


# ---------------------------------------------------------------------------
# Ties within the timing spread of single repeats
# ---------------------------------------------------------------------------


def test_a_single_repeat_ratio_near_1_is_unresolved(tmp_path: Path) -> None:
    """P&K 1.06x NNLS+GP's time from one repeat: not "the same way as the paper" (~26x)
    but a tie the timing spread cannot resolve; and the warm sweep's reading gives no verdict
    of its own on the claim, which the ledger reads on P&K's cold solves."""
    words = rpp.agreement(1.06, rpp.ledger_claim("fig4-pk-cold-over-nnlsgp"), SINGLE)
    assert "unresolved (a tie within the timing spread of single repeats)" in words
    assert "points the same way" not in words
    reading = _section(tmp_path, sweep({"nnls-gp": [1.0] * 4, "pk": [1.06] * 4}), "paper-sweep")
    pk = sentence(reading, "P&K 1999 / NNLS+GP")
    assert "measured 1.06x" in pk and "no verdict here" in pk and "`fig4-pk-cold-over-nnlsgp`" in pk


def test_a_fastest_within_the_spread_of_single_repeats_is_a_tie(tmp_path: Path) -> None:
    """Two solvers 1 % apart from one repeat: neither is named the fastest; at 1.5x apart
    the faster one is."""
    tied = _section(tmp_path / "tie", sweep({"nnls-gp": [1.0] * 4, "bvls": [1.01] * 4}), "paper-sweep")
    assert "fastest solver over the whole sweep here is" not in tied
    assert "No solver is the fastest over the whole sweep here" in tied and "tied with `bvls`" in tied
    assert "<= 1e-10: `nnls-gp` (4 s, worst kkt 1.0e-10), tied with `bvls`" in tied
    apart = _section(tmp_path / "apart", sweep({"nnls-gp": [1.0] * 4, "bvls": [1.5] * 4}), "paper-sweep")
    assert "The fastest solver over the whole sweep here is `nnls-gp`" in apart and "tied with" not in apart


def test_repeats_that_agree_resolve_a_small_ratio() -> None:
    """The same 1.06x from two repeats whose ratio does not move (spread 0) in place of the
    single-repeat spread: the ratio is read, not tied."""
    words = rpp.agreement(1.06, rpp.ledger_claim("fig4-pk-cold-over-nnlsgp"), Spread(0.0, 2))
    assert "unresolved" not in words
    assert "points the same way as the paper but is smaller by a factor of 24.5" in words  # 26 / 1.06


def test_fig6_a_least_total_tied_with_k100_is_unresolved(tmp_path: Path) -> None:
    """K = 25 least by 3 % over K = 100, from one repeat: not "does not agree", but a tie."""
    rows = []
    for K, t in ((0, 3.0), (25, 1.0), (100, 1.03), (200, 2.0)):
        for k in range(3):
            rows.append(report_row(scene="gp-k-sweep", instance="i0", step=k, n=100 * (k + 1), N=32,
                                   solver=f"nnls-gp-K{K}", base_solver="nnls-gp", params=json.dumps({"K": K}),
                                   solve_time_s=t, dim_load=1e-4 * (k + 1)))
    reading = _section(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)), "gp-k-sweep")
    assert "does not agree" not in reading
    assert "tied with K = 100" in reading and "unresolved (a tie within the timing spread of single repeats)" in reading


def test_a_tie_is_decided_by_the_ledgers_single_repeat_spread() -> None:
    """The readings' single-repeat spread is the ledger's SINGLE_REPEAT_SPREAD: a ratio just
    inside 1 + spread is a tie, one just outside is not."""
    from contactbench.harness.report.sections import paper_readings as pr

    assert pr.SINGLE.s == SINGLE_REPEAT_SPREAD and pr.SINGLE.repeats == 1
    inside, outside = 1 + 0.99 * SINGLE_REPEAT_SPREAD, 1 + 1.01 * SINGLE_REPEAT_SPREAD
    assert pr.SINGLE.ties(inside) and pr.SINGLE.ties(1 / inside)
    assert not pr.SINGLE.ties(outside) and not pr.SINGLE.ties(1 / outside)
    assert not pr.EXACT.ties(1.0001)


# ---------------------------------------------------------------------------
# "Smaller by a factor of" the number the claim states
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("ratio", [1.5, 2.0, 5.0])
def test_the_factor_is_taken_against_the_stated_value(ratio: float) -> None:
    """P&K at ``ratio`` x NNLS+GP's time, far from the paper's ~26x: the words give a
    factor that, times the measured ratio, gives the paper's stated value."""
    words = rpp.agreement(ratio, rpp.ledger_claim("fig4-pk-cold-over-nnlsgp"))
    stated = CLAIMS["fig4-pk-cold-over-nnlsgp"].rule.lo
    factor = float(words.split("smaller by a factor of ")[1].split(" ")[0])
    assert factor * ratio == pytest.approx(stated, rel=5e-3)


def test_a_range_gives_its_factor_against_the_nearer_end() -> None:
    """A claim stated as a range (no one value): the factor is against the range's nearer
    end, and the words say so."""
    words = rpp.agreement(0.2, rpp.ledger_claim("fig5-chol-over-cg"))
    assert words.endswith("smaller than its range by a factor of 3")


@given(share=st.floats(min_value=0.0, max_value=1.0))
@settings(max_examples=80, deadline=None)
def test_the_counterexample_share_is_read_as_the_ledger_reads_it(share: float) -> None:
    """Greedy CG's share of rejected seeds against the paper's ~40 %: the section's words
    follow the ledger row ``ex1-greedy-fails`` (0.27 and 0.52 are close, not agreeing)."""
    words = share_verdict(share)
    expected = CLAIMS["ex1-greedy-fails"].rule.at(share)
    assert words.startswith({"holds": "agrees", "partly": "is close", "fails": "is "}[expected])
    assert (expected == "fails") == (not words.startswith(("agrees", "is close")))


def test_shares_near_the_old_band_edges_are_close_not_agreeing() -> None:
    assert share_verdict(0.27).startswith("is close") and share_verdict(0.52).startswith("is close")
    assert share_verdict(0.4).startswith("agrees") and share_verdict(0.1).startswith("is below")


def test_a_share_at_a_band_s_edge_is_inside_it() -> None:
    """0.3 of the paper's 0.4 +- 0.1 holds (|0.3 - 0.4| is 0.10000000000000003 in float64)."""
    assert CLAIMS["ex1-greedy-fails"].rule.at(0.3) == "holds" and share_verdict(0.3).startswith("agrees")
    assert CLAIMS["ex1-greedy-fails"].rule.at(0.2) == "partly" and CLAIMS["ex1-greedy-fails"].rule.at(0.19) == "fails"
