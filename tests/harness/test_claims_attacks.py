"""Tables made to fool the claims ledger (harness/report/claims.py and its readers): an
inexact method's answer that is not the paper's, Fig. 8's error read below the top step, a
repeat short of a step, the paper's methods missing from the whole table, a cold solve
counting no iteration, "always" on a handful of seeds, and Algorithm 2's reading named."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from contactbench.harness.report import claim_rules as cr
from contactbench.harness.report import claim_tables as ct
from contactbench.harness.report import claims as cl

from tests.harness.test_claims import _one, _repeated, _rows, _table
from tests.harness.test_claims_greedy_variants import SPACED, _ledger, _row, _seeds
from tests.harness.test_claims_readings import _cmr_table


def _admm_as_printed(t: pd.DataFrame, **values: object) -> pd.DataFrame:
    """``t`` with ADMM's dense answers rejected by the KKT check (read as printed) and ``values`` set."""
    at = (t["solver"] == "admm") & (t["operator"] == "dense")
    t.loc[at, ["status", "verdict"]] = ["inaccurate", "unconverged"]
    for col, v in {"load": 1.0, **values}.items():
        t.loc[at, col] = v
    return t


def test_an_inexact_method_is_read_only_at_its_own_stop_with_the_same_load() -> None:
    """ADMM as printed at Kmax (solver_converged False) or with half the load held "two
    orders" (tex 1039-1044: every method reaches the same normal force)."""
    ok = _one(cl.ledger(_admm_as_printed(_table(), load=1.01)), "fig4-admm-over-nnlsgp", "dense")
    assert ok["measured"] == pytest.approx(80.0) and "inexact by design" in ok["evidence"], ok["evidence"]
    for values, why in (({"solver_converged": False}, "did not reach its own stop"),
                        ({"load": 0.5}, "INEXACT_LOAD_TOL"), ({"load": 1.0 + 2 * ct.INEXACT_LOAD_TOL}, "load is off")):
        r = _one(cl.ledger(_admm_as_printed(_table(), **values)), "fig4-admm-over-nnlsgp", "dense")
        assert r["verdict"] == "unmeasured" and math.isnan(r["measured"]), (values, r["evidence"])
        assert why in r["evidence"] and "read as printed is no measurement" in r["evidence"], r["evidence"]


def test_fig8_error_is_read_at_the_top_step_only() -> None:
    """CMR's top step gone on the worst instance with H > 0.5: its error at a lower step
    stood for the error at the maximum normal force (tex 1226-1228)."""
    t = _cmr_table()
    worst = _one(cl.ledger(t), "fig8-cmr-error", "dense", "256^2")
    tot = cl.papers_cmr(cl.cmr_totals(t, "cmr", "dense"))
    inst = str(tot.loc[tot[tot["H"] > 0.5]["err"].abs().idxmax(), "instance"])
    top = t["step"].max()
    cut = t[~((t["instance"] == inst) & (t["step"] == top) & (t["base_solver"] == "cmr+nnls"))]
    led = cl.ledger(cut)
    for claim in ("fig8-cmr-error", "fig8-error-falls-with-h-exponent"):
        r = _one(led, claim, "dense", "256^2")
        assert r["verdict"] == "unmeasured" and inst in r["evidence"].split("top step")[-1], (claim, r["evidence"])
    assert worst["verdict"] != "unmeasured"


def test_a_repeat_short_of_a_step_gives_no_total() -> None:
    """pk's repeats 0 and 1 lost step 1: their sums (one step) made the median."""
    t = _repeated({"nnls-gp": [[0.1, 0.1]] * 3, "pk": [[0.3, 0.3]] * 3})
    short = t[~((t["solver"] == "pk") & (t["step"] == 1) & t["repeat"].isin([0, 1]))]
    rt = ct.repeat_totals(short)
    assert math.isnan(rt[("pk", 0)]) and math.isnan(rt[("pk", 1)]) and rt[("pk", 2)] == pytest.approx(0.6)
    tot = ct.totals(short)
    assert tot.loc["pk", "total_s"] == pytest.approx(0.6) and tot.loc["pk", "repeats"] == 1
    none = t[~((t["solver"] == "pk") & (t["step"] == t["repeat"] % 2))]  # every repeat lacks a step
    tot = ct.totals(none)
    assert math.isnan(tot.loc["pk", "total_s"]) and not tot.loc["pk", "comparable"]
    assert math.isnan(ct.ratio(tot, "pk", "nnls-gp")[0])


def test_the_fastest_needs_every_one_of_the_papers_methods() -> None:
    """Every paper method but P&K removed from the whole table: "the fastest" held."""
    r = _one(cl.ledger(pd.DataFrame(_rows("paper-sweep", "dense", {"nnls-gp": [0.1, 0.1], "pk": [0.3, 0.3]}))),
             "fig4-nnlsgp-fastest", "dense")
    assert r["verdict"] == "unmeasured", r["evidence"]
    assert "no row at this size of: admm, gp, greedy-cg" in r["evidence"]
    assert set(ct.PAPER_METHODS) >= {"admm", "pk-printed", "greedy-cg", "nnls"}


def test_a_cold_solve_counting_no_iteration_is_no_iteration_count() -> None:
    t = _table()
    t["iterations"] = t["solver"].map({"pk": 0.0, "greedy-cg": 50.0}).fillna(10.0)
    r = _one(cl.ledger(t), "pk-fewer-iterations-than-greedy", "dense")
    assert r["verdict"] == "unmeasured" and "no iteration" in r["evidence"], r["evidence"]
    t["iterations"] = t["iterations"].replace(0.0, 5.0)
    assert _one(cl.ledger(t), "pk-fewer-iterations-than-greedy", "dense")["verdict"] == "holds"


def test_always_is_not_read_on_a_handful_of_seeds() -> None:
    """One seed answered right held "always" (and "many cases" on one rejected seed)."""
    few = cr.MIN_SEEDS - 1
    r = _row(_ledger(_seeds(SPACED, 25, 0, seeds=few)), "greedy-spacing-2delta", 25)
    assert r["measured"] == 0.0 and r["verdict"] == "unmeasured" and "MIN_SEEDS" in r["evidence"]
    r = _row(_ledger(_seeds("random-positive-h", 25, few, seeds=few)), "greedy-random-h-fails", 25)
    assert r["measured"] == 1.0 and r["verdict"] == "unmeasured"
    # one rejected seed refutes "always", however few were run
    assert _row(_ledger(_seeds(SPACED, 25, 1, seeds=few)), "greedy-spacing-2delta", 25)["verdict"] == "fails"
    assert _row(_ledger(_seeds(SPACED, 25, 0, seeds=cr.MIN_SEEDS)), "greedy-spacing-2delta", 25)["verdict"] == "holds"


def test_the_printed_algorithm_2_names_its_reading() -> None:
    rows = _rows("greedy-linear-solvers", "dense", {"pk-printed": [52.0], "nnls-gp": [4.0]}, N=512)
    for row in rows:
        row["n"], row["skip_reason"] = 35218, ""
    led = cl.ledger(pd.concat([_table(), pd.DataFrame(rows)], ignore_index=True))
    r = _one(led, "fig4-pkprinted-over-nnlsgp", "dense", "512^2")
    assert "step 3.4 on every point" in r["evidence"] and "line 743" in r["evidence"], r["evidence"]
    for claim in ("fig4-pkprinted-over-nnlsgp", "pkprinted-fewer-iterations-than-greedy"):
        assert cr.PK_PRINTED_READING in cr.CLAIMS[claim].measures
