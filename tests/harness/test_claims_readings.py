"""What the claims ledger (harness/report/claims.py) reads for each claim: the paper's own
methods found by their parameters (ADMM as printed, the CMR cascade of tex 1208-1211),
each condition at its profile, Algorithm 2 as printed beside P&K 1999, no time from an
unconverged answer or a cell counted twice, and evidence that carries its figures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd
import pytest
from contactbench.harness.report import claims as cl
from contactbench.solvers.admm import PAPER_PARAMS

from tests.harness.test_claims import _every_paper_method, _one, _rows, _table

#: The committed paper-claims table (its CMR scenes are read below).
RESULTS = Path(__file__).resolve().parents[2] / "results" / "claims" / "results.csv"


def _with(t: pd.DataFrame, rows: list[dict]) -> pd.DataFrame:
    return pd.concat([t, pd.DataFrame(rows)], ignore_index=True)


def _cmr_table(scenes: tuple[str, ...] = ("cmr",)) -> pd.DataFrame:
    t = pd.read_csv(RESULTS, low_memory=False)
    return t[t["scene"].isin(scenes) & (t["operator"] == "dense")].reset_index(drop=True)


# ---------------------------------------------------------------------------
# ADMM as the paper prints it (tex 1028-1029)
# ---------------------------------------------------------------------------


def test_the_registrys_admm_plays_no_part_in_the_fastest() -> None:
    """The registry's ADMM (rho relative, the KKT stop) 100x faster than NNLS+GP made "NNLS+GP
    is the fastest" fail: it played the paper's ADMM, the first admm label by name."""
    rows = _rows("paper-sweep", "dense", _every_paper_method({"nnls-gp": [0.1, 0.1], "pk": [0.3, 0.3],
                                                              "admm": [0.001, 0.001], "admm[paper]": [10.0, 10.0]}))
    for r in rows:
        if r["solver"] == "admm[paper]":
            r["base_solver"], r["params"] = "admm", json.dumps(PAPER_PARAMS)
    led = cl.ledger(pd.DataFrame(rows))
    r = _one(led, "fig4-nnlsgp-fastest", "dense")
    assert r["verdict"] == "holds" and "fastest other paper method: pk" in r["evidence"], r["evidence"]
    assert _one(led, "fig4-admm-over-nnlsgp", "dense")["measured"] == pytest.approx(100.0)


def test_the_registrys_admm_at_the_papers_n_is_not_the_papers_admm_there() -> None:
    big = pd.DataFrame(_rows("greedy-linear-solvers", "dense", {"admm": [1.0]})).assign(n=35_000)
    led = cl.ledger(_with(_table(), big.to_dict("records")))
    assert ((led["claim"] == "fig4-admm-over-nnlsgp") & led["n_or_size"].str.startswith("n = ")).any()


def test_the_papers_admm_is_one_fact_for_the_role_and_the_claim() -> None:
    from contactbench.harness.report import claim_measures as cm
    from contactbench.harness.report import claim_tables as ct
    for params in ({}, PAPER_PARAMS, {"rho_relative": False, "stop": "printed"}, {**PAPER_PARAMS, "rho": 2.0},
                   {**PAPER_PARAMS, "linear": "cg"}):
        assert ct.plays("admm", json.dumps(params)) == cm.is_papers_admm(json.dumps(params)), params
    assert not ct.plays("admm", "{}") and ct.plays("admm", json.dumps(PAPER_PARAMS))


# ---------------------------------------------------------------------------
# Each condition at its profile
# ---------------------------------------------------------------------------


def test_a_row_of_another_profile_never_stands_for_the_condition() -> None:
    """NNLS+GP's dense rows run at profile "low" (100x faster): they are not the paper's
    condition (profile "paper"), replaced or mixed in."""
    t = _table()
    at = (t["scene"] == "paper-sweep") & (t["solver"] == "nnls-gp") & (t["operator"] == "dense")
    low = t[at].assign(profile="low", solve_time_s=t.loc[at, "solve_time_s"] / 100)
    replaced = cl.ledger(pd.concat([t[~at], low], ignore_index=True))
    dense = replaced[(replaced["claim"] == "fig4-pk-cold-over-nnlsgp") & (replaced["condition"] == "dense")]
    assert (dense["verdict"] == "unmeasured").all(), dense
    mixed = cl.ledger(pd.concat([t, low], ignore_index=True))
    r = _one(mixed, "fig4-pk-cold-over-nnlsgp", "dense")
    assert r["measured"] == pytest.approx(26.0) and "profile paper" in r["evidence"], r
    big = pd.DataFrame(_rows("greedy-linear-solvers", "dense", {"admm": [1.0]})).assign(
        n=35_000, profile="low", params=json.dumps(PAPER_PARAMS))  # the paper's n, but not the paper's profile
    led = cl.ledger(_with(t, big.to_dict("records")))
    assert ((led["claim"] == "fig4-admm-over-nnlsgp") & led["n_or_size"].str.startswith("n = ")).any()


# ---------------------------------------------------------------------------
# Sec. 3.2: Algorithm 2 as printed and P&K 1999, each its own verdict
# ---------------------------------------------------------------------------


def test_fewer_iterations_than_greedy_is_read_for_algorithm_2_as_printed_and_for_pk_1999() -> None:
    """tex 716-719 speaks of the constrained CG of Algorithm 2 (726-760): pk-printed read as
    printed (its own stop) gets a verdict of its own beside P&K 1999 (pk)."""
    t = _with(_table(), _rows("greedy-linear-solvers", "dense", {"pk-printed": [5.0, 5.0]},
                              status={("pk-printed", 0): "inaccurate", ("pk-printed", 1): "inaccurate"}))
    t["iterations"] = t["solver"].map({"pk-printed": 500.0, "pk": 5.0, "greedy-cg": 50.0}).fillna(10.0)
    t["load"] = t["load"].fillna(1.0)  # an inexact answer has its load
    led = cl.ledger(t)
    printed = _one(led, "pkprinted-fewer-iterations-than-greedy", "dense")
    assert printed["measured"] == pytest.approx(10.0) and printed["verdict"] == "fails", printed
    assert "inexact by design" in printed["evidence"]
    pk = _one(led, "pk-fewer-iterations-than-greedy", "dense")
    assert pk["measured"] == pytest.approx(0.1) and pk["verdict"] == "holds"
    assert cl.CLAIMS["pkprinted-fewer-iterations-than-greedy"].tex_lines.endswith("726-760")


# ---------------------------------------------------------------------------
# No time from an unconverged answer, from the warm run, or from a cell twice
# ---------------------------------------------------------------------------


def test_a_time_to_an_unconverged_answer_is_no_measurement() -> None:
    """Greedy CG answered a step the KKT check rejects: its time is not a time to
    convergence (tex 1040-1044).  P&K as printed, which the claim reads with its own stop,
    is still read, and the evidence says so."""
    t = _table()
    bad = (t["solver"] == "greedy-cg") & (t["operator"] == "dense") & (t["step"] == 1)
    t.loc[bad, ["status", "verdict"]] = ["inaccurate", "wrong"]  # (an answer: its load kept)
    t.loc[bad, "load"] = 1.0
    r = _one(cl.ledger(t), "fig4-greedy-over-nnlsgp", "dense")
    assert r["verdict"] == "unmeasured" and "not every answer converged" in r["evidence"], r
    rows = _rows("greedy-linear-solvers", "dense", {"pk-printed": [52.0], "nnls-gp": [4.0]}, N=512,
                 status={("pk-printed", 0): "inaccurate"})
    for row in rows:
        row["n"], row["skip_reason"], row["load"] = 35218, "", 1.0
    printed = _one(cl.ledger(_with(_table(), rows)), "fig4-pkprinted-over-nnlsgp", "dense", "512^2")
    assert printed["measured"] == pytest.approx(13.0) and "inexact by design" in printed["evidence"]


def test_pure_gp_is_read_against_nnls_gp_from_p_zero_never_the_warm_run() -> None:
    t = _with(_table(), _rows("greedy-linear-solvers", "dense", {"gp": [1.0, 1.0]}))
    r = _one(cl.ledger(t), "gp-pure-slow", "dense")
    assert r["verdict"] == "unmeasured" and "never the warm run" in r["evidence"], r
    cold = pd.DataFrame(_rows("greedy-linear-solvers", "dense", {"nnls-gp[K=100]": [0.25, 0.25]})).assign(
        base_solver="nnls-gp", params=json.dumps({"K": 100}))
    r = _one(cl.ledger(_with(t, cold.to_dict("records"))), "gp-pure-slow", "dense")
    assert r["measured"] == pytest.approx(4.0) and "nnls-gp cold" in r["evidence"], r


def test_a_cell_written_twice_under_a_fresh_id_counts_once() -> None:
    t = _table()
    t["cell_id"] = [f"c{i}" for i in range(len(t))]
    again = t[(t["scene"] == "paper-sweep") & (t["solver"] == "nnls-gp") & (t["operator"] == "dense")]
    r = _one(cl.ledger(pd.concat([t, again.assign(cell_id=again["cell_id"] + "x")], ignore_index=True)),
             "fig4-pk-cold-over-nnlsgp", "dense")
    assert r["measured"] == pytest.approx(26.0), r


@pytest.mark.parametrize("time, limit", [(0.0, math.nan), (1e308, 60.0), (61.0, 60.0)])
def test_a_time_that_is_zero_or_over_its_limit_is_no_answer(time: float, limit: float) -> None:
    t = _table().assign(time_limit_s=limit)
    at = (t["scene"] == "paper-sweep") & (t["solver"] == "nnls-gp") & (t["operator"] == "dense") & (t["step"] == 0)
    t.loc[at, "solve_time_s"] = time
    r = _one(cl.ledger(t), "fig4-pk-cold-over-nnlsgp", "dense")
    assert r["verdict"] == "unmeasured" and "not every step answered" in r["evidence"], r


# ---------------------------------------------------------------------------
# Fig. 5: Cholesky's memory limit, about 20,000
# ---------------------------------------------------------------------------


def _chol(answered: int, refused: int) -> pd.DataFrame:
    rows = _rows("greedy-linear-solvers", "dense", {"greedy-chol": [1.0, 1.0, 1.0]},
                 status={("greedy-chol", 1): "failed", ("greedy-chol", 2): "failed"})
    for row, n in zip(rows, (answered, refused, 25_000)):
        row["step"] += 5  # cells of their own beside the table's
        row["n"], row["error"] = n, "" if row["status"] == "solved" else "MemoryBudgetError: over the budget"
    return _with(_table(), rows)


def test_our_memory_budget_refusing_a_small_cholesky_is_not_the_papers_limit() -> None:
    """A refusal of our own memory budget at n = 1,100 held "out of memory above n ~ 20,000"
    (a rule with no lower edge); the failing row is printed."""
    r = _one(cl.ledger(_chol(1_000, 1_100)), "fig5-chol-memory", "dense", "n <=")
    assert r["measured"] == 1100 and r["verdict"] == "fails", r
    assert "n = 1100" in r["evidence"] and "our memory budget" in r["evidence"]
    assert "[1.41e+04, 2.83e+04]" in cl.CLAIMS["fig5-chol-memory"].rule.text()
    assert _one(cl.ledger(_chol(19_000, 21_000)), "fig5-chol-memory", "dense", "n <=")["verdict"] == "holds"


# ---------------------------------------------------------------------------
# CMR: the paper's cascade by its params; the errors' largest
# ---------------------------------------------------------------------------


def test_the_papers_cmr_is_found_by_its_params_not_its_label() -> None:
    """A cascade from 128 (not the paper's 16-32-...-256), 10x faster, whose label also
    reads "h=2 " and comes first: it stood for CMR in "2x faster" and in Fig. 8's times."""
    t = _cmr_table()
    plain = cl.ledger(t)
    v = t[t["base_solver"] == "cmr+nnls"].assign(solver="cmr+nnls coarse=mean h=2 from 128",
                                                  params=json.dumps({"coarse": "mean", "coarsest": 128, "h": 2.0}))
    v = v.assign(solve_time_s=v["solve_time_s"] / 10, cell_id=v["cell_id"] + "v")
    led = cl.ledger(pd.concat([v, t], ignore_index=True))
    for claim in ("cmr-2x-over-nnlsgp", "fig8-cmr-time", "fig8-cmr-error"):
        a, b = _one(plain, claim, "dense", "256^2"), _one(led, claim, "dense", "256^2")
        assert b["measured"] == pytest.approx(a["measured"]) and b["verdict"] == a["verdict"], claim


def test_every_error_under_two_percent_reads_the_largest() -> None:
    """tex 1349-1350: "relative errors were found less than 2 %" -- every one, not 90 %."""
    t = _cmr_table()
    tot = cl.cmr_totals(t, "cmr", "dense")
    tot = tot[(tot["h"] == 2.0) & (tot["coarsest"] == 16) & (tot["H"] > 0.5)]
    r = _one(cl.ledger(t), "fig8-cmr-error", "dense", "256^2")
    assert r["measured"] == pytest.approx(tot["err"].abs().max()) and "largest" in r["evidence"], r
    assert f"{tot['err'].iloc[0]:.3g}" in r["evidence"]


# ---------------------------------------------------------------------------
# Fig. 6 and Fig. 9: the figures in the evidence; K = 200 saves nothing
# ---------------------------------------------------------------------------


def test_a_least_k_of_200_fails_and_the_evidence_gives_each_ks_time() -> None:
    """tex 1092-1097: K = 200 "does not correspond to further savings": a least at 200 read
    "partly"."""
    rows = []
    for K, t in ((0, 3.0), (50, 2.0), (100, 1.5), (200, 1.0)):
        for row in _rows("gp-k-sweep", "fft", {f"nnls-gp[K={K}]": [t, t]}):
            rows.append({**row, "base_solver": "nnls-gp", "params": json.dumps({"K": K})})
    r = _one(cl.ledger(pd.DataFrame(rows)), "fig6-best-k", "fft")
    assert r["measured"] == 200.0 and r["verdict"] == "fails", r
    assert "K 100: 3 s" in r["evidence"] and "K 200: 2 s" in r["evidence"], r["evidence"]


def test_fig9_evidence_gives_the_value_and_the_seeds() -> None:
    r = _one(cl.ledger(_cmr_table(("cmr-h-sweep",))), "fig9-np-low-h", "dense", "256^2")
    assert "(3 seeds)" in r["evidence"] and f"{r['measured']:.4g}" in r["evidence"], r["evidence"]
