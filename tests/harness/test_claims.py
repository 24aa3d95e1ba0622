"""The paper's claims ledger (harness/report/claims.py, harness/report/sections/claims.py): verdict rules
against inputs that should fool them, the ledger read from a small synthetic table, and
claims.md written from claims.csv alone."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
from contactbench.harness.report import claims as cl
from contactbench.harness.report.sections import claims as rc
from contactbench.harness.cli import main
from contactbench.harness.run.studies import CLAIMS_DENSE_PROFILE, CLAIMS_FFT_PROFILE, expand

# ---------------------------------------------------------------------------
# Verdict rules
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("measured", [math.nan, math.inf, -math.inf, None, "abc", ""])
def test_a_measurement_that_is_not_a_finite_number_is_never_a_verdict(measured: object) -> None:
    for claim in cl.CLAIMS.values():
        assert cl.verdict(measured, claim.rule, "results.csv: x") == "unmeasured"  # type: ignore[arg-type]


def test_no_evidence_or_an_untestable_claim_is_unmeasured_even_on_the_paper_value() -> None:
    rule = cl.CLAIMS["fig4-pk-cold-over-nnlsgp"].rule
    assert cl.verdict(26.0, rule, "results.csv") == "holds"
    assert cl.verdict(26.0, rule, "") == "unmeasured"
    assert cl.verdict(26.0, rule, "   ") == "unmeasured"
    assert cl.verdict(26.0, rule, "results.csv", testable=False) == "unmeasured"


def test_ratio_rules_read_the_direction_and_the_factor() -> None:
    rule = cl.about(26.0)
    assert cl.verdict(26.0 * cl.RATIO_FACTOR, rule, "e") == "holds"
    assert cl.verdict(26.0 * cl.RATIO_FACTOR * 1.01, rule, "e") == "partly"  # same way, too large
    assert cl.verdict(1e308, rule, "e") == "partly"  # huge but finite: never holds
    assert cl.verdict(1.5, rule, "e") == "partly"
    assert cl.verdict(0.308, rule, "e") == "fails"  # the opposite direction
    assert cl.verdict(0.0, rule, "e") == "fails"
    assert cl.verdict(-26.0, rule, "e") == "fails"  # a negative time ratio is no speed-up


def test_error_bounds_read_the_magnitude() -> None:
    rule = cl.CLAIMS["real-power-law-error"].rule
    assert cl.verdict(-0.004, rule, "e") == "holds"
    assert cl.verdict(-0.03, rule, "e") == "partly"
    assert cl.verdict(-0.98, rule, "e") == "fails"
    cutoff = cl.CLAIMS["real-cutoff-error"].rule
    assert cl.verdict(-0.98, cutoff, "e") == "holds"
    assert cl.verdict(0.001, cutoff, "e") == "fails"


def test_every_claim_has_a_rule_whose_holds_band_lies_in_its_partly_band_or_is_disjoint_by_design() -> None:
    for c in cl.CLAIMS.values():
        lo, hi = c.rule.holds
        assert lo <= hi, c.id
        assert c.id == c.id.strip() and c.figure and c.paper_value


def test_ratio_guards_an_infinite_or_incomplete_total() -> None:
    tot = pd.DataFrame({"total_s": [2.6, 0.0, 1.0], "steps": [10, 10, 10], "answered": [10, 10, 9],
                        "solved": [10, 10, 9], "comparable": [True, True, False]},
                       index=["pk cold", "zero", "short"])
    assert math.isnan(cl.ratio(tot, "pk cold", "zero")[0])  # t_b = 0: an inf ratio is not a measurement
    assert math.isnan(cl.ratio(tot, "pk cold", "short")[0])
    assert math.isnan(cl.ratio(tot, "pk cold", "absent")[0])
    assert "no rows of absent" in cl.ratio(tot, "pk cold", "absent")[1]


def test_spread_of_a_nan_load_is_not_zero() -> None:
    assert math.isnan(cl.spread(pd.Series([1.0, math.nan, 1.0])))
    assert math.isnan(cl.spread(pd.Series([1.0])))
    assert cl.spread(pd.Series([1.0, 1.0, 1.1])) == pytest.approx(0.1)


# ---------------------------------------------------------------------------
# The ledger from a synthetic table
# ---------------------------------------------------------------------------


def _rows(scene: str, operator: str, times: dict[str, list[float]], N: int = 64, status: dict | None = None,
          load: float = 1.0) -> list[dict]:
    out = []
    for solver, ts in times.items():
        for k, t in enumerate(ts):
            st = (status or {}).get((solver, k), "solved")
            out.append({"scene": scene, "instance": f"saupe-H0.7-N{N}-bcc-np-s5", "seed": 5, "step": k, "solver": solver,
                        "base_solver": solver, "params": "{}", "profile": "paper" if operator == "dense" else "default",
                        "history": "warm", "repeat": 0, "status": st, "solve_time_s": t, "n": 100 * (k + 1),
                        "N": N, "operator": operator, "load": load if st == "solved" else math.nan,
                        "contact_fraction": 0.1, "matvecs": 10, "verdict": "pass" if st == "solved" else "wrong",
                        "solver_converged": True})
    return out


def _table() -> pd.DataFrame:
    rows = []
    # the paper's condition: P&K cold 26x NNLS+GP, greedy CG 120x, ADMM 80x
    rows += _rows("paper-sweep", "dense", {"nnls-gp": [0.1, 0.1], "admm": [8.0, 8.0]})
    rows += _rows("greedy-linear-solvers", "dense", {"pk": [2.6, 2.6], "greedy-cg": [12.0, 12.0],
                                                     "greedy-chol": [7.8, 7.8], "greedy-gs": [36.0, 36.0]})
    # ours: P&K cold faster than NNLS+GP; one NNLS+GP step failed at the larger size
    rows += _rows("paper-sweep", "fft", {"nnls-gp": [1.0, 1.0], "fast-dual-pccg": [0.1, 0.1]})
    rows += _rows("greedy-linear-solvers", "fft", {"pk": [0.3, 0.3]})
    rows += _rows("paper-sweep", "fft", {"nnls-gp": [1.0, 1.0]}, N=128, status={("nnls-gp", 1): "failed"})
    rows += _rows("greedy-linear-solvers", "fft", {"pk": [0.3, 0.3]}, N=128)
    return pd.DataFrame(rows)


def _one(ledger: pd.DataFrame, claim: str, condition: str, size: str = "64^2") -> pd.Series:
    hit = ledger[(ledger["claim"] == claim) & (ledger["condition"] == condition)
                 & ledger["n_or_size"].str.startswith(size)]
    assert len(hit) == 1, (claim, condition, size, ledger[["claim", "condition", "n_or_size"]])
    return hit.iloc[0]


def test_ledger_reads_each_condition_apart() -> None:
    led = cl.ledger(_table())
    assert list(led.columns) == list(cl.LEDGER_COLUMNS)
    r = _one(led, "fig4-pk-cold-over-nnlsgp", "dense")
    assert r["measured"] == pytest.approx(26.0) and r["verdict"] == "holds"
    assert "pk cold 5.2 s, 20 matvecs" in r["evidence"]  # the time's load-independent witness
    assert _one(led, "fig4-greedy-over-nnlsgp", "dense")["verdict"] == "holds"
    assert _one(led, "fig4-admm-over-nnlsgp", "dense")["measured"] == pytest.approx(80.0)
    assert _one(led, "fig4-nnlsgp-fastest", "dense")["verdict"] == "holds"
    assert _one(led, "fig5-chol-over-cg", "dense")["measured"] == pytest.approx(0.65)
    assert _one(led, "fig5-gs-over-cg", "dense")["verdict"] == "holds"
    fft = _one(led, "fig4-pk-cold-over-nnlsgp", "fft")
    assert fft["measured"] == pytest.approx(0.3) and fft["verdict"] == "fails"
    assert _one(led, "fig4-nnlsgp-fastest", "fft")["verdict"] == "fails"  # fast-dual-pccg is 10x faster
    # a failed NNLS+GP step: no ratio, and the evidence says why
    short = _one(led, "fig4-pk-cold-over-nnlsgp", "fft", "128^2")
    assert short["verdict"] == "unmeasured" and "not every step answered" in short["evidence"]
    assert set(led["verdict"]) <= set(cl.VERDICTS)


def test_a_lying_solver_does_not_make_the_loads_agree() -> None:
    t = _table()
    t.loc[(t["scene"] == "paper-sweep") & (t["solver"] == "admm") & (t["step"] == 1), "load"] = 1.5
    led = cl.ledger(t)
    assert _one(led, "fig4-same-load", "dense")["verdict"] == "fails"
    assert _one(led, "fig4-same-load", "fft")["verdict"] == "holds"


def test_cholesky_memory_claim_is_unmeasured_below_the_paper_limit() -> None:
    r = _one(cl.ledger(_table()), "fig5-chol-memory", "dense", "n <=")
    assert r["verdict"] == "unmeasured" and "our dense limit" in r["n_or_size"]


# ---------------------------------------------------------------------------
# claims.md from claims.csv alone; the study
# ---------------------------------------------------------------------------


def test_report_writes_claims_md_from_the_ledger_alone(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    cl.write_ledger(_table(), tmp_path)
    assert main(["report", str(tmp_path)]) == 0
    md = (tmp_path / rc.CLAIMS_MD).read_text()
    assert "fig4-pk-cold-over-nnlsgp" in md and "## Fails under the paper's own condition" in md
    assert "not every step answered" in md
    before = md
    assert main(["report", str(tmp_path)]) == 0
    assert (tmp_path / rc.CLAIMS_MD).read_text() == before  # deterministic
    assert not (tmp_path / "report.md").exists()  # no results table: the ledger only


@pytest.mark.parametrize("edit, message", [
    (lambda df: df.drop(columns=["verdict"]), "lacks column(s) verdict"),
    (lambda df: df.assign(verdict="agrees"), "not in holds"),
    (lambda df: df.assign(condition="gpu"), "condition(s) 'gpu'"),
])
def test_a_broken_ledger_is_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, edit, message) -> None:
    edit(cl.ledger(_table())).to_csv(tmp_path / cl.LEDGER_NAME, index=False)
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_a_nan_measured_cell_reads_back_as_unmeasured(tmp_path: Path) -> None:
    led = cl.ledger(_table())
    led.to_csv(tmp_path / cl.LEDGER_NAME, index=False)
    back = rc.read_ledger(tmp_path / cl.LEDGER_NAME)
    assert back["measured"].isna().sum() == led["measured"].isna().sum() > 0
    assert "| - |" in rc.claims_markdown(back)


def test_paper_claims_runs_each_condition_at_its_profile() -> None:
    parts = expand("paper-claims", None)
    by_op = {(cfg.operator, p) for study, cfg in parts for p in study.profiles}
    assert by_op == {("dense", CLAIMS_DENSE_PROFILE), ("fft", CLAIMS_FFT_PROFILE), (None, CLAIMS_DENSE_PROFILE)}
    scenes = {study.scene for study, _ in parts}
    assert {"paper-sweep", "greedy-linear-solvers", "gp-k-sweep", "counterexample", "cmr", "cmr-h-sweep",
            "cmr-cutoff"} <= scenes
    dense_fig4 = [cfg.size for study, cfg in parts if study.scene == "paper-sweep" and cfg.operator == "dense"]
    assert len(dense_fig4) >= 3  # the ratios against n


def test_every_claim_of_the_issue_is_in_the_ledger() -> None:
    assert len(cl.CLAIMS) >= 12
    figs = {c.figure for c in cl.CLAIMS.values()}
    assert {"Example 1", "Fig. 4", "Fig. 5", "Fig. 6", "Fig. 8", "Fig. 9", "Fig. 11", "Conclusion"} <= figs


def test_example1_counts_each_condition_apart() -> None:
    rows = []
    for op, rejected in (("dense", 4), ("fft", 0)):
        for s in range(10):
            bad = s < rejected
            rows.append({"scene": "counterexample", "instance": f"n100-s{s}", "seed": s, "step": 0, "solver": "greedy-cg",
                         "base_solver": "greedy-cg", "params": "{}", "profile": "paper", "history": "warm",
                         "repeat": 0, "status": "inaccurate" if bad else "solved",
                         "verdict": "wrong" if bad else "pass",
                         "solver_converged": True, "n": 100, "N": 10, "operator": op, "solve_time_s": 0.01,
                         "p_rel_error": 0.5 if bad else 0.0, "check_tol": 1e-6})
    led = cl.ledger(pd.DataFrame(rows))
    dense, fft = _one(led, "ex1-greedy-fails", "dense", "n = 100"), _one(led, "ex1-greedy-fails", "fft", "n = 100")
    assert dense["measured"] == pytest.approx(0.4) and dense["verdict"] == "holds" and dense["seeds"] == "0-9"
    assert fft["measured"] == 0.0 and fft["verdict"] == "fails"


def _paper_n(status: dict | None = None) -> pd.DataFrame:
    """The table plus the study's top step at the paper's size (512^2, dense, no paper-sweep there)."""
    rows = _rows("greedy-linear-solvers", "dense", {"pk": [2.0], "nnls-gp": [4.0]}, N=512, status=status)
    for r in rows:
        r["n"], r["skip_reason"] = 35218, "over the memory budget" if r["status"] == "skipped" else ""
    return pd.concat([_table(), pd.DataFrame(rows)], ignore_index=True)


def test_the_paper_size_top_step_is_read_without_a_load_history() -> None:
    led = cl.ledger(_paper_n())
    for claim in ("fig4-pk-cold-over-nnlsgp", "conclusion-pk"):
        r = _one(led, claim, "dense", "512^2")
        assert r["measured"] == pytest.approx(0.5) and r["verdict"] == "fails"
        assert "1 step(s) cold, n <= 35218" in r["n_or_size"]
    # the sizes with a load history keep their own rows, once each
    assert _one(led, "fig4-pk-cold-over-nnlsgp", "dense")["measured"] == pytest.approx(26.0)


def test_a_skipped_paper_size_is_unmeasured_and_says_why() -> None:
    led = cl.ledger(_paper_n({("nnls-gp", 0): "skipped"}))
    r = _one(led, "fig4-pk-cold-over-nnlsgp", "dense", "512^2")
    assert r["verdict"] == "unmeasured" and "over the memory budget" in r["evidence"]


def test_a_skipped_cholesky_at_a_large_n_does_not_test_the_memory_claim() -> None:
    rows = _rows("greedy-linear-solvers", "dense", {"greedy-chol": [1.0]}, N=512, status={("greedy-chol", 0): "skipped"})
    rows[0]["n"] = 35218
    r = _one(cl.ledger(pd.concat([_table(), pd.DataFrame(rows)], ignore_index=True)), "fig5-chol-memory", "dense",
             "n <=")
    assert r["verdict"] == "unmeasured"
