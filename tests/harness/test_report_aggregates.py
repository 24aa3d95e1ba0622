"""harness/table/aggregates.py against hand-computed values on a 3-solver, 4-problem table.

The table (scene "s", profile "default", time limit 10 s; times in seconds):

    problem   A                 B                  C
    P1        1.0 solved        2.0 solved         4.0 solved
    P2        2.0 solved        1.0 solved         skipped
    P3        4.0 solved        10.0 timeout       2.0 solved
    P4        0.7 failed        3.0 solved         1.5 solved

plus a second repeat of A on P1 at 1.6 s (the cell keeps the minimum, 1.0 s).

Counted times (unsolved -> time limit 10 s; every cell has a row, so every cell is planned
and counts, C's skipped P2 at the limit):
    A: 1, 2, 4, 10      B: 2, 1, 10, 3      C: 4, 10, 2, 1.5

Shifted geometric mean with shift s = 1 s:
    A: (2 * 3 * 5 * 11)^(1/4) - 1   = 330^(1/4) - 1   = 3.2621...
    B: (3 * 2 * 11 * 4)^(1/4) - 1   = 264^(1/4) - 1   = 3.0309...
    C: (5 * 11 * 3 * 2.5)^(1/4) - 1 = 412.5^(1/4) - 1 = 3.5067...
    relative to the best (B): A 1.0763..., B 1, C 1.1570...

With C's P2 row dropped (the cell never planned, not counted): C over P1, P3, P4 counts
4, 2, 1.5: (5 * 3 * 2.5)^(1/3) - 1 = 37.5^(1/3) - 1 = 2.3472...; over those cells A counts
(2 * 5 * 11)^(1/3) - 1 = 3.7915... and B (3 * 11 * 4)^(1/3) - 1 = 4.0906..., so C is the
best on its own cells (1); A and B, planned on all four, are compared with the solvers
planned on all four (A, B: C is not), and keep their figures.

Performance-profile ratios r = t / min over solvers of t (inf where unsolved):
    P1: best 1   -> A 1,   B 2,   C 4
    P2: best 1   -> A 2,   B 1,   C inf
    P3: best 2   -> A 2,   B inf, C 1
    P4: best 1.5 -> A inf, B 2,   C 1
    rho_A(1) = 1/4, rho_A(2) = 3/4, rho_A(4) = 3/4
    rho_B(1) = 1/4, rho_B(2) = 3/4, rho_B(4) = 3/4
    rho_C(1) = 2/4, rho_C(2) = 2/4, rho_C(4) = 3/4

Claims (solver_converged): A claims convergence on all four (false on P4); B claims
False on P3 (timeout: agrees); C claims True on P1, P3 and False on P4 (disagrees).
    success: A 3/4, B 3/4, C 3/3 (C attempted 3, solved P1, P3, P4)
    correct rows: A 4/5 (two P1 repeats + P2 + P3 agree, P4 not), B 4/4, C 2/3
    false claims: A 1, B 0, C 0
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.table import aggregates as agg
from contactbench.harness.table.schema import ALL_COLUMNS

SHIFT = 1.0


def _row(problem: str, solver: str, t: float, status: str, claim: bool | None, repeat: int = 0) -> dict:
    r = {c: np.nan for c in ALL_COLUMNS}
    r.update(scene="s", instance=problem, step=0, profile="default", solver=solver, solve_time_s=t, status=status,
             solver_converged=claim, repeat=repeat, time_limit_s=10.0)
    return r


def hand_table() -> pd.DataFrame:
    rows = [
        _row("P1", "A", 1.0, "solved", True), _row("P1", "A", 1.6, "solved", True, repeat=1),
        _row("P1", "B", 2.0, "solved", True), _row("P1", "C", 4.0, "solved", True),
        _row("P2", "A", 2.0, "solved", True), _row("P2", "B", 1.0, "solved", True),
        _row("P2", "C", float("nan"), "skipped", None),
        _row("P3", "A", 4.0, "solved", True), _row("P3", "B", 10.0, "timeout", False),
        _row("P3", "C", 2.0, "solved", True),
        _row("P4", "A", 0.7, "failed", True), _row("P4", "B", 3.0, "solved", True),
        _row("P4", "C", 1.5, "solved", False),
    ]
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def test_shifted_geometric_mean_by_hand() -> None:
    t = agg.time_aggregate(agg.cell_table(hand_table()), SHIFT)
    assert t["A"].sgm_s == pytest.approx(330 ** 0.25 - 1, rel=1e-12)
    assert t["B"].sgm_s == pytest.approx(264 ** 0.25 - 1, rel=1e-12)
    assert t["C"].sgm_s == pytest.approx(412.5 ** 0.25 - 1, rel=1e-12)  # its skipped P2 counts at the limit
    assert t["B"].sgm_rel == 1.0
    assert t["A"].sgm_rel == pytest.approx((330 ** 0.25 - 1) / (264 ** 0.25 - 1), rel=1e-12)
    assert t["C"].sgm_rel == pytest.approx((412.5 ** 0.25 - 1) / (264 ** 0.25 - 1), rel=1e-12)
    assert [t[s].cells for s in "ABC"] == [4, 4, 4]


def test_shifted_geometric_mean_basics() -> None:
    assert agg.shifted_geometric_mean([1.0, 4.0], shift=0.0) == pytest.approx(2.0)
    assert agg.shifted_geometric_mean([0.0, 8.0], shift=1.0) == pytest.approx(2.0)  # sqrt(1 * 9) - 1
    assert math.isnan(agg.shifted_geometric_mean([], shift=1.0))
    with pytest.raises(ValueError, match="zero time"):
        agg.shifted_geometric_mean([0.0, 1.0], shift=0.0)
    with pytest.raises(ValueError, match="time limit"):
        agg.shifted_geometric_mean([1.0, float("inf")])
    with pytest.raises(ValueError, match="shift"):
        agg.shifted_geometric_mean([1.0], shift=-1.0)


def test_performance_profile_by_hand() -> None:
    prof = agg.performance_profile(agg.cell_table(hand_table()))
    assert prof.n_problems == 4
    np.testing.assert_array_equal(prof.ratios["A"], [1, 2, 2, np.inf])
    np.testing.assert_array_equal(prof.ratios["B"], [1, 2, 2, np.inf])
    np.testing.assert_array_equal(prof.ratios["C"], [1, 1, 4, np.inf])
    expected = {"A": (0.25, 0.75, 0.75), "B": (0.25, 0.75, 0.75), "C": (0.5, 0.5, 0.75)}
    for s, (r1, r2, r4) in expected.items():
        assert prof.fraction(s, 1.0) == r1
        assert prof.fraction(s, 2.0) == r2
        assert prof.fraction(s, 4.0) == r4
        assert prof.fraction(s, 1e9) == 0.75  # the right end is the success share
    np.testing.assert_array_equal(prof.curve("C", np.array([1.0, 3.9, 4.0])), [0.5, 0.5, 0.75])
    assert prof.max_finite_ratio() == 4.0


def test_summary_rates_by_hand() -> None:
    summ = {s.solver: s for s in agg.summarize(hand_table(), SHIFT)}
    assert (summ["A"].attempted, summ["A"].solved, summ["A"].success_rate) == (4, 3, 0.75)
    assert (summ["B"].attempted, summ["B"].solved, summ["B"].success_rate) == (4, 3, 0.75)
    assert (summ["C"].attempted, summ["C"].skipped, summ["C"].solved, summ["C"].success_rate) == (3, 1, 3, 1.0)
    assert (summ["A"].claim_rows, summ["A"].correct_rate, summ["A"].false_claims) == (5, 0.8, 1)
    assert (summ["B"].claim_rows, summ["B"].correct_rate, summ["B"].false_claims) == (4, 1.0, 0)
    assert summ["C"].correct_rate == pytest.approx(2 / 3) and summ["C"].false_claims == 0
    assert summ["B"].sgm_rel == 1.0
    assert summ["A"].sgm_s == pytest.approx(330 ** 0.25 - 1)
    assert [summ[s].sgm_cells for s in "ABC"] == [4, 4, 4]


def test_problem_nobody_solves_stays_in_the_denominator() -> None:
    t = hand_table()
    extra = pd.DataFrame([_row("P5", s, 10.0, "timeout", False) for s in "ABC"], columns=list(ALL_COLUMNS))
    prof = agg.performance_profile(agg.cell_table(pd.concat([t, extra], ignore_index=True)))
    assert prof.n_problems == 5
    assert prof.fraction("C", 1.0) == pytest.approx(2 / 5)
    assert prof.fraction("A", 1e9) == pytest.approx(3 / 5)


def test_a_solver_skipped_on_every_problem_is_left_out_of_the_profile() -> None:
    """It would draw a flat zero (a panel of them looked empty); the others' ratios and the
    problem count are unchanged, and ``never_attempted`` names it for the caption."""
    t = hand_table()
    skipped = pd.DataFrame([_row(p, "D", float("nan"), "skipped", None) for p in ("P1", "P2", "P3", "P4")],
                           columns=list(ALL_COLUMNS))
    cells = agg.cell_table(pd.concat([t, skipped], ignore_index=True))
    prof = agg.performance_profile(cells)
    assert agg.never_attempted(cells) == ("D",) and "D" in cells.solvers and prof.solvers == ("A", "B", "C")
    assert prof.left_out == ("D",)
    base = agg.performance_profile(agg.cell_table(t))
    assert prof.n_problems == base.n_problems == 4
    for s in base.solvers:
        np.testing.assert_array_equal(prof.ratios[s], base.ratios[s])
    assert agg.never_attempted(agg.cell_table(t)) == ()  # C, skipped on one problem, is drawn


def test_a_solver_skipped_on_every_problem_has_no_time_aggregate() -> None:
    """Its cells would all count at the time limit: an SGM that reads as a time it never
    took.  It gets none (NaN, "-" in the report), the others' figures and the best are
    unchanged, and one skipped on some problems still counts those at the limit."""
    t = hand_table()
    skipped = pd.DataFrame([_row(p, "D", float("nan"), "skipped", None) for p in ("P1", "P2", "P3", "P4")],
                           columns=list(ALL_COLUMNS))
    with_d = {s.solver: s for s in agg.summarize(pd.concat([t, skipped], ignore_index=True), SHIFT)}
    base = {s.solver: s for s in agg.summarize(t, SHIFT)}
    assert np.isnan(with_d["D"].sgm_s) and np.isnan(with_d["D"].sgm_rel) and with_d["D"].attempted == 0
    assert with_d["D"].sgm_cells == 0
    for s in base:
        assert with_d[s].sgm_s == pytest.approx(base[s].sgm_s, rel=1e-12)
        assert with_d[s].sgm_rel == pytest.approx(base[s].sgm_rel, rel=1e-12)
    assert np.isfinite(base["C"].sgm_s)  # C, skipped on one problem, is timed


def test_a_cell_never_planned_is_not_counted_in_the_time_aggregate() -> None:
    """A problem with no row of the solver is no cell it was planned to run: its SGM leaves
    it out (it counted at the 10 s limit: 412.5^(1/4) - 1 over four cells), and it is
    compared, over its own cells, with the solvers planned on all of them.  The solved share
    and the performance profile still count the absent cell as not solved."""
    t = hand_table()
    t = t[~((t["solver"] == "C") & (t["instance"] == "P2"))]  # drop the skipped row: now simply absent
    summ = {s.solver: s for s in agg.summarize(t, SHIFT)}
    assert summ["C"].sgm_s == pytest.approx(37.5 ** (1 / 3) - 1, rel=1e-12)
    assert summ["C"].sgm_rel == 1.0  # A: 110^(1/3) - 1, B: 132^(1/3) - 1 over P1, P3, P4
    assert (summ["C"].sgm_cells, summ["A"].sgm_cells, summ["B"].sgm_cells) == (3, 4, 4)
    assert summ["A"].sgm_s == pytest.approx(330 ** 0.25 - 1, rel=1e-12)
    assert summ["A"].sgm_rel == pytest.approx((330 ** 0.25 - 1) / (264 ** 0.25 - 1), rel=1e-12)
    assert summ["B"].sgm_rel == 1.0
    assert (summ["C"].problems, summ["C"].solved, summ["C"].attempted) == (4, 3, 3)
    cells = agg.cell_table(t)
    assert agg.planned_matrix(cells).to_numpy().sum() == 11
    assert agg.performance_profile(cells).fraction("C", 4.0) == 0.75


def test_csv_style_claims_are_read() -> None:
    t = hand_table()
    t["solver_converged"] = t["solver_converged"].map({True: "True", False: "False", None: ""})
    summ = {s.solver: s for s in agg.summarize(t, SHIFT)}
    assert summ["A"].false_claims == 1 and summ["A"].correct_rate == 0.8
