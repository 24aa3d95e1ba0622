"""The paper sections' words match what a table holds (harness/report/sections/paper.py,
paper_readings.py): Fig. 5's caption names the solvers it draws and says when none is a
greedy solver; Fig. 6 says in words when no NNLS+GP K-variant ran, and which solvers did;
Fig. 6's reading hedges a small sweep by the same size rule as Fig. 4's (``SMALL_N``, one
constant) and never reads a disagreement from it; the sweep totals' captions say that a
step's time is the minimum over its repeats.

The tables are small fabricated scenes; a section is called directly on a report context
over the written table, its figures not saved.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.report.sections import paper_readings as pr
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.harness.test_paper_readings_fair import section_body
from tests.helpers import report_row


def _body(tmp_path: Path, rows: list[dict[str, Any]], scene: str) -> str:
    """The body of the paper section of ``scene`` over the table of ``rows``."""
    return section_body(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)), scene)


def _caption(body: str) -> str:
    """The text of the first figure caption of a section body."""
    return body.split("*Figure ", 1)[1].split("*\n", 1)[0]


def _narrowed(scene: str, solvers: tuple[str, ...] = ("fast-dual-pccg", "nnls", "pk")) -> list[dict[str, Any]]:
    """Rows of ``scene`` run with a narrowed solver list: none a greedy solver, none a K-variant."""
    return [report_row(scene=scene, instance="i0", step=k, n=50 * (k + 1), N=64, solver=s, solve_time_s=0.01 * (k + 1),
                       dim_load=1e-4 * (k + 1)) for s in solvers for k in range(3)]


def test_fig5_caption_names_the_drawn_solvers_and_says_no_greedy_solver_ran(tmp_path: Path) -> None:
    body = _body(tmp_path, _narrowed("greedy-linear-solvers"), "greedy-linear-solvers")
    cap = _caption(body)
    assert "greedy solve time" not in cap
    assert "`fast-dual-pccg`, `nnls`, `pk`" in cap
    assert "no greedy solver ran in this scene" in cap
    assert "greedy" not in rpp.FIG5_PAGE[0].title  # the page's chart of the same rows


def test_fig5_caption_with_greedy_solvers_cites_the_paper(tmp_path: Path) -> None:
    rows = _narrowed("greedy-linear-solvers", ("greedy-cg", "greedy-chol", "nnls"))
    cap = _caption(_body(tmp_path, rows, "greedy-linear-solvers"))
    assert "`greedy-cg`, `greedy-chol`, `nnls`" in cap
    assert "(paper Fig. 5: greedy with CG" in cap and "no greedy solver" not in cap


def test_fig6_without_k_variants_says_none_ran_and_which_did(tmp_path: Path) -> None:
    body = _body(tmp_path, _narrowed("gp-k-sweep"), "gp-k-sweep")
    assert "No NNLS+GP K-variant was run in this scene" in body
    assert "the solvers that ran: `fast-dual-pccg`, `nnls`, `pk`" in body


def _k_sweep(n_top: int) -> list[dict[str, Any]]:
    """A one-repeat K sweep whose least total is at K = 25, K = 100 at 4.8x it; its largest
    trial set has ``n_top`` points."""
    return [report_row(scene="gp-k-sweep", instance="i0", step=k, n=n_top // (3 - k), N=64, solver=f"nnls-gp-K{K}",
                       base_solver="nnls-gp", params=json.dumps({"K": K}), solve_time_s=t, dim_load=1e-4 * (k + 1))
            for K, t in ((0, 2.0), (25, 1.0), (100, 4.8), (200, 4.6)) for k in range(3)]


def _sweep(n_top: int) -> list[dict[str, Any]]:
    """A one-repeat paper-sweep of NNLS+GP and P&K whose largest trial set has ``n_top`` points."""
    return [report_row(scene="paper-sweep", instance="i0", step=k, n=n_top // (3 - k), N=64, solver=s,
                       profile="high", solve_time_s=t, dim_load=1e-4 * (k + 1))
            for s, t in (("nnls-gp", 1.0), ("pk", 20.0)) for k in range(3)]


def _reading(body: str) -> str:
    return body.split("**Reading.**", 1)[1]


def test_fig6_at_small_sizes_reads_no_disagreement(tmp_path: Path) -> None:
    """K = 100 at 4.8x the least total, from a sweep with n <= 204 and one repeat: the
    reading names the ratio and gives the claims ledger's verdict (its rule reads every
    size alike), with Fig. 4's hedge, and no verdict of its own."""
    reading = _reading(_body(tmp_path, _k_sweep(204), "gp-k-sweep"))
    assert "does not agree" not in reading and "unresolved at this size" not in reading
    assert "the largest trial set has n = 204, where K = 100 takes 4.8x" in reading
    assert "`fig6-best-k`" in reading
    assert pr.SMALL_N_TEXT in reading


def test_fig6_at_the_papers_sizes_still_reads_a_disagreement(tmp_path: Path) -> None:
    reading = _reading(_body(tmp_path, _k_sweep(pr.SMALL_N), "gp-k-sweep"))
    assert "this does not agree with the paper: K = 100 takes 4.8x the minimum" in reading
    assert pr.SMALL_N_TEXT not in reading


@pytest.mark.parametrize("n_top", [150, 300])
def test_figs_4_and_6_hedge_by_one_size_threshold(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  n_top: int) -> None:
    """With the threshold moved to 200, a sweep at n = 150 is hedged in both readings and
    one at n = 300 in neither: both read ``paper_readings.SMALL_N``."""
    monkeypatch.setattr(pr, "SMALL_N", 200)
    small = n_top < 200
    fig4 = _reading(_body(tmp_path / "p", _sweep(n_top), "paper-sweep"))
    fig6 = _reading(_body(tmp_path / "k", _k_sweep(n_top), "gp-k-sweep"))
    assert (pr.SMALL_N_TEXT in fig4) == small
    assert (pr.SMALL_N_TEXT in fig6) == small
    assert ("does not agree" in fig6) == (not small)


def test_sweep_totals_captions_say_the_minimum_over_repeats(tmp_path: Path) -> None:
    """Two repeats, the second slower: Table 2's total is the sum of each step's minimum,
    and its caption says so, as does Fig. 6's totals table."""
    rows = [dict(r, repeat=rep, solve_time_s=r["solve_time_s"] * (1 + rep)) for r in _sweep(400) for rep in (0, 1)]
    body = _body(tmp_path / "p", rows, "paper-sweep")
    table = body.split("*Table ", 1)[1]
    assert table.split("*", 1)[0].count("minimum over its repeats") == 1
    assert "| nnls-gp | paper | 3 of 3 | 3 |" in table  # 1 s per step, the minimum of 1 s and 2 s
    krows = [dict(r, repeat=rep, solve_time_s=r["solve_time_s"] * (1 + rep)) for r in _k_sweep(400) for rep in (0, 1)]
    k_caption = _body(tmp_path / "k", krows, "gp-k-sweep").split("*Table ", 1)[1].split("*", 1)[0]
    assert "minimum over its repeats" in k_caption
