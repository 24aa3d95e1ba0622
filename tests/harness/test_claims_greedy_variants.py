"""The claims ledger's reading of section 3.1's words around Example 1 (harness/report/claims.py
``example1_variant_rows``): "in many cases the LCP is not solved exactly" on a random SPD Q with
positive entries (``greedy-random-h-fails``), and "always a solution satisfying w* >= 0" with the
trial elements 2 delta apart (``greedy-spacing-2delta``) -- both able to fail -- and the study
that runs them (harness/run/studies.py ``claims_parts``)."""

from __future__ import annotations

import math

import pandas as pd
import pytest
from contactbench.harness.report import claim_rules as cr
from contactbench.harness.report import claims as cl
from contactbench.harness.run.studies import claims_parts

RANDOM, SPACED = "random-positive-h", "counterexample-2delta"


def _seeds(scene: str, n: int, rejected: int, seeds: int = 10, status: str = "inaccurate",
           verdict: str = "wrong", operator: str = "dense") -> list[dict]:
    """greedy-cg rows of ``scene`` at n, seeds 0..seeds-1, the first ``rejected`` of them not solved."""
    variant = {RANDOM: "random-positive", SPACED: "spacing-2"}.get(scene, "")
    side = math.isqrt(n)
    N = {RANDOM: math.nan, SPACED: 2 * side - 1}.get(scene, side)  # the mesh's side (none for a random Q)
    out = []
    for s in range(seeds):
        bad = s < rejected
        out.append({"scene": scene, "instance": f"n{n}-s{s}-{variant}", "seed": s, "step": 0, "solver": "greedy-cg",
                    "base_solver": "greedy-cg", "params": "{}", "profile": cl.CONDITION_PROFILES[operator],
                    "history": "warm", "repeat": 0, "status": status if bad else "solved",
                    "verdict": (verdict if bad else "pass"), "solver_converged": verdict == "wrong" or not bad,
                    "n": n, "N": N, "operator": operator, "variant": variant, "solve_time_s": 0.01,
                    "p_rel_error": 0.5 if bad else 0.0, "check_tol": 1e-6})
    return out


def _ledger(*parts: list[dict]) -> pd.DataFrame:
    return cl.ledger(pd.DataFrame([r for p in parts for r in p]))


def _row(led: pd.DataFrame, claim: str, n: int, condition: str = "dense") -> pd.Series:
    hit = led[(led["claim"] == claim) & (led["condition"] == condition) & (led["n_or_size"] == f"n = {n}")]
    assert len(hit) == 1, led[led["claim"] == claim]
    return hit.iloc[0]


def test_random_positive_h_reads_many_failures_as_holds_and_none_as_fails() -> None:
    led = _ledger(_seeds(RANDOM, 25, 3), _seeds(RANDOM, 100, 1), _seeds(RANDOM, 400, 0))
    many, few, none = (_row(led, "greedy-random-h-fails", n) for n in (25, 100, 400))
    assert many["measured"] == pytest.approx(0.3) and many["verdict"] == "holds" and many["seeds"] == "0-9"
    assert "rejected by the judge on 3 of 10 seeds (n = 25, seeds 0-9)" in many["evidence"]
    assert RANDOM in many["evidence"] and "3 wrong" in many["evidence"]
    assert few["measured"] == pytest.approx(0.1) and few["verdict"] == "partly"
    assert none["measured"] == 0.0 and none["verdict"] == "fails"  # greedy never fails: "many cases" is false


def test_spacing_2delta_holds_only_where_greedy_never_fails() -> None:
    led = _ledger(_seeds(SPACED, 25, 0), _seeds(SPACED, 100, 1, status="inaccurate", verdict="unconverged"))
    never, once = _row(led, "greedy-spacing-2delta", 25), _row(led, "greedy-spacing-2delta", 100)
    assert never["measured"] == 0.0 and never["verdict"] == "holds"
    assert "0 of 10 seeds" in never["evidence"]
    # one unconverged seed of ten: not "always a solution satisfying w* >= 0"
    assert once["measured"] == pytest.approx(0.1) and once["verdict"] == "fails"
    assert "1 unconverged" in once["evidence"]
    # a crash is no solution either: rejected, not left out
    led = _ledger(_seeds(SPACED, 25, 2, status="failed", verdict=""))
    r = _row(led, "greedy-spacing-2delta", 25)
    assert r["measured"] == pytest.approx(0.2) and r["verdict"] == "fails" and "2 no answer" in r["evidence"]


def test_no_rows_or_no_answer_is_unmeasured() -> None:
    led = cl.ledger(pd.DataFrame(_seeds("counterexample", 25, 4)))
    for claim in ("greedy-random-h-fails", "greedy-spacing-2delta"):
        r = led[led["claim"] == claim]
        assert len(r) == 1 and r.iloc[0]["verdict"] == "unmeasured" and "not in this table" in r.iloc[0]["evidence"]
        assert cr.CLAIMS[claim].rule.kind != "untestable"
    led = _ledger(_seeds(SPACED, 25, 10, status="failed", verdict=""))
    r = _row(led, "greedy-spacing-2delta", 25)
    assert math.isnan(r["measured"]) and r["verdict"] == "unmeasured"


def test_the_variants_never_pool_with_example_1() -> None:
    led = _ledger(_seeds("counterexample", 25, 4), _seeds(SPACED, 25, 0), _seeds(RANDOM, 25, 10))
    assert _row(led, "ex1-greedy-fails", 25)["measured"] == pytest.approx(0.4)
    assert _row(led, "greedy-spacing-2delta", 25)["measured"] == 0.0
    assert _row(led, "greedy-random-h-fails", 25)["measured"] == 1.0
    # the fft condition has none of these rows: no row there
    assert led[(led["claim"] == "greedy-spacing-2delta") & (led["condition"] == "fft")].empty


def test_many_is_a_lower_bound_on_a_share() -> None:
    rule = cr.CLAIMS["greedy-random-h-fails"].rule
    assert [rule.at(m) for m in (0.0, 0.09, 0.1, 0.19, 0.2, 0.75, 1.0)] == [
        "fails", "fails", "partly", "partly", "holds", "holds", "holds"]
    assert rule.text() == "share at least 0.2: holds if measured >= 0.2, partly if >= 0.1, else fails"
    assert cr.CLAIMS["greedy-spacing-2delta"].rule.at(0.01) == "fails"


def test_the_claims_study_runs_both_variants_with_greedy_cg_at_the_papers_profile() -> None:
    parts = {p.study.scene: p for p in claims_parts() if p.study.scene in (RANDOM, SPACED)}
    assert set(parts) == {RANDOM, SPACED}
    for p in parts.values():
        assert p.study.solvers == ("greedy-cg",) and p.study.profiles == (cl.CONDITION_PROFILES["dense"],)
        assert tuple(p.cfg.seeds) == tuple(range(100)) and tuple(p.cfg.extra["sizes"]) == (25, 100)
