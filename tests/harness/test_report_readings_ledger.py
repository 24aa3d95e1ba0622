"""The readings of the paper sections state a verdict word on a paper claim only where they
read the claims ledger's own measurement of it, and then the ledger's verdict; elsewhere
they give their number and name the ledger row that judges the claim
(harness/report/sections/paper_readings.py, paper_conditions.py, cmr.py).

The tables are small fabricated sweeps; the ledger is ``claims.ledger`` on the same rows.
"""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

from contactbench.harness.report.sections import cmr as rc
from tests.harness.test_report_paper_conditions import ledger_row, rows_of, section, table

#: A verdict word of the claims ledger, or one of the readings' words for one.
VERDICT = re.compile(r"\b(agrees|holds|close|partly|fails|unresolved|opposite way)\b")


def _k_sweep(n_top: int) -> pd.DataFrame:
    """A one-repeat K sweep on the dense H whose least total is at K = 25 (K = 100 at 4.8x,
    K = 0 at 2x), its largest trial set ``n_top`` points."""
    rows = []
    for K, t in ((0, 2.0), (25, 1.0), (100, 4.8), (200, 4.6)):
        rows += rows_of("gp-k-sweep", "dense", {f"nnls-gp-K{K}": [t] * 3}, base_solver="nnls-gp",
                        params=f'{{"K": {K}}}')
    df = table(rows)
    df["n"] = [n_top // (3 - k) for k in df["step"]]
    return df


def _reading(tmp_path: Path, df: pd.DataFrame, scene: str) -> str:
    return section(tmp_path, df, scene).body.split("**Reading.**", 1)[1]


def test_fig6_at_a_small_size_gives_only_the_ledgers_verdict(tmp_path: Path) -> None:
    """n <= 204, K = 25 least: the ledger's row fig6-best-k reads fails; the reading gives
    that verdict and no "unresolved" of its own beside it."""
    df = _k_sweep(204)
    assert ledger_row(df, "fig6-best-k", "dense")["verdict"] == "fails"
    head = _reading(tmp_path, df, "gp-k-sweep").split("Going from", 1)[0]
    assert "unresolved" not in head
    assert "`fig6-best-k`" in head and "reads K = 25 as fails" in head


def test_fig6_savings_carry_no_verdict_word_and_name_their_ledger_rows(tmp_path: Path) -> None:
    """One repeat, K = 0 at 1.03x the least (a tie): the saving is a number with the ledger
    rows named (gp-warm-start-benefit, fig6-k200-over-k100), no "unresolved"."""
    df = _k_sweep(204)
    df.loc[df["solver"] == "nnls-gp-K0", "solve_time_s"] = 1.03
    reading = _reading(tmp_path, df, "gp-k-sweep")
    saving = reading.split("Going from K = 0", 1)[1].split(". ", 1)[0]
    assert not VERDICT.search(saving) and "`gp-warm-start-benefit`" in saving
    top = reading.split("At K = 200", 1)[1]
    assert not VERDICT.search(top) and "`fig6-k200-over-k100`" in top


def test_fig4_reads_pk_without_a_verdict_where_the_ledger_has_no_cold_solves(tmp_path: Path) -> None:
    """P&K and NNLS+GP on the sweep only: the ledger's fig4-pk-cold-over-nnlsgp is defined on
    P&K's cold solves, which the table lacks; the reading gives its ratio, no verdict word,
    and names the row and the cold solves."""
    df = table(rows_of("paper-sweep", "dense", {"nnls-gp": [1.0, 1.0], "pk": [0.5, 0.5]}))
    assert ledger_rows(df, "fig4-pk-cold-over-nnlsgp") <= {"unmeasured"}
    pk = _reading(tmp_path, df, "paper-sweep").split("P&K 1999 / NNLS+GP: ", 1)[1].split(". ", 1)[0]
    assert pk.startswith("measured 0.5x") and "no verdict here" in pk
    assert "cold solves" in pk and "`fig4-pk-cold-over-nnlsgp`" in pk
    assert not VERDICT.search(pk.replace("no verdict here", ""))


def ledger_rows(df: pd.DataFrame, claim: str) -> set[str]:
    """The ledger's verdicts of ``claim`` on ``df``."""
    from contactbench.harness.report import claims as cl

    led = cl.ledger(df)
    return set(led.loc[led["claim"] == claim, "verdict"])


def test_cmr_claim_checks_give_no_verdict_word_and_name_the_ledger_rows() -> None:
    """A variant with median error -1.1 % (the ledger's fig8-cmr-error reads the 90th
    percentile too): its line and the summary give numbers, no verdict word, and the
    summary names the ledger rows."""
    errs = [-0.011, -0.011, -0.05, 0.001, -0.03]
    high = pd.DataFrame({"ratio": [0.6] * 5, "err": errs, "n_p_over_n": [0.5] * 5})
    check = rc.ClaimCheck(("scipy-nnls", "smooth", 256), rc.Summary.of(high), rc.band([0.6] * 5))
    line = check.line()
    assert "-1.1 %" in line and not VERDICT.search(line) and "robust" not in line
    short = rc.verdict_line([check])
    assert not VERDICT.search(short) and "`fig8-cmr-error`" in short and "`fig8-cmr-time`" in short
