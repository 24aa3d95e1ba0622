"""Readings that agree with the judge: the counterexample section counts the judge's
verdicts (never a threshold of its own), the contact fraction of an accepted iterative
answer matches the exact one within its flag ``contact_uncertain``, and the peers on the
paper's counterexample give solved or skipped rows, never failed ones."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
import pytest
from contactbench.harness.report import core as rp
from contactbench.harness.report.view import read_table
from contactbench.harness.report.sections import counterexample as rce
from contactbench.harness.judging import judge
from contactbench.harness.table.schema import ALL_COLUMNS
from contactbench.problems.instances import (
    CONTACT_BAND,
    InstanceBuilder,
    counterexample,
    load_ramp,
    paper_max_displacement,
)
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import SolverSettings, get_solver

CHECK_TOL = 1e-6


def _judged_row(inst_name: str, n: int, solver: str, verdict: Any, repeat: int = 0,
                check_tol: float = CHECK_TOL) -> dict[str, Any]:
    """The row of ``verdict``, judged at ``check_tol``, as the harness writes it."""
    row: dict[str, Any] = {c: np.nan for c in ALL_COLUMNS}
    row.update(scene="counterexample", instance=inst_name, step=0, n=n, solver=solver, base_solver=solver,
               params="{}", profile="default", repeat=repeat, check_tol=check_tol, status=verdict.status,
               verdict=verdict.reading, solver_converged=verdict.claimed, kkt_error=verdict.kkt_error,
               solve_time_s=1e-3, p_rel_error=verdict.figures.get("p_rel_error", np.nan))
    return row


def _counterexample_table() -> tuple[pd.DataFrame, dict[tuple[str, int], int]]:
    """Greedy CG and NNLS judged on Example 1 at n = 100, seeds 0-5, plus rows built to
    fool a section that applies its own threshold: an accepted answer far from p_exact, a
    rejected answer close to it, a failed row (no verdict) and a cell whose second repeat
    is rejected."""
    rows: list[dict[str, Any]] = []
    for seed in range(6):
        inst = counterexample(100, seed)
        ref = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-12))
        for name in ("greedy-cg", "nnls"):
            res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10))
            v = judge(inst, res.p, res.converged, CHECK_TOL, p_ref=ref.p)
            rows.append(_judged_row(f"n100-s{seed}", 100, name, v))
    inst = counterexample(25, 0)
    ref = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-12)).p
    far = judge(inst, ref * (1 + 1e-3 * np.random.default_rng(0).random(25)), True, 1.0, p_ref=ref)
    assert far.status == "solved" and far.figures["p_rel_error"] > 1e-4  # accepted at a loose tolerance
    near = judge(inst, ref - 1e-9 * ref.max(), True, 1e-15, p_ref=ref)
    assert near.status == "inaccurate" and near.figures["p_rel_error"] < 1e-6  # rejected, yet close
    rows.append(_judged_row("n25-s0", 25, "loose", far, check_tol=1.0))
    rows.append(_judged_row("n25-s0", 25, "strict", near, check_tol=1e-15))
    rows.append({**_judged_row("n25-s0", 25, "broken", near), "status": "failed", "verdict": "",
                 "p_rel_error": np.nan, "kkt_error": np.nan, "solve_time_s": np.nan})
    rows.append(_judged_row("n25-s0", 25, "flaky", far, check_tol=1.0))
    rows.append(_judged_row("n25-s0", 25, "flaky", near, repeat=1, check_tol=1e-15))
    table = pd.DataFrame(rows, columns=list(ALL_COLUMNS))
    expected: dict[tuple[str, int], int] = {}
    for (s, n), g in table.groupby(["solver", "n"]):
        rejected = g.groupby("instance")["status"].agg(lambda x: bool((x != "solved").any()))
        expected[(str(s), int(n))] = int(rejected.sum())
    return table, expected


def test_counterexample_counts_are_the_judges() -> None:
    table, expected = _counterexample_table()
    frac = rce.violation_counts(rce.seed_readings(table))
    got = {(str(s), int(n)): int(v) for s, n, v in zip(frac["solver"], frac["n"], frac["violations"])}
    assert got == expected
    assert expected[("loose", 25)] == 0 and expected[("strict", 25)] == 1  # p_rel_error plays no part
    assert expected[("broken", 25)] == 1 and expected[("flaky", 25)] == 1
    assert expected[("nnls", 100)] == 0
    readings = frac.set_index(["solver", "n"])
    assert readings.loc[("broken", 25), "no answer"] == 1 and readings.loc[("strict", 25), "wrong"] == 1
    g = readings.loc[("greedy-cg", 100)]
    assert g["wrong"] + g["unconverged"] + g["no answer"] == g["violations"]


def test_counterexample_section_prints_the_judges_counts(tmp_path: Any) -> None:
    table, expected = _counterexample_table()
    table.to_parquet(tmp_path / "results.parquet", index=False)
    table = read_table(tmp_path)
    section = rce.counterexample_section(rp.ReportContext(tmp_path, table, {}), table).body
    g = expected[("greedy-cg", 100)]
    assert "| greedy-cg | - | " in section and f"({g}/6" in section
    assert "| loose | 0 % (0/1) |" in section and "| strict | 100 % (1/1: 1 wrong) |" in section
    assert "Distance from the exact LCP answer (not a verdict)" in section
    assert "p differs from the exact p" not in section


def _sweep_instance(N: int, step: int):
    surf = rmd_surface_n(N, 0.7, length=100e-6, seed=5)
    return InstanceBuilder(surf, 1e9, "bcc").build(float(load_ramp(paper_max_displacement(surf), 10)[step]))


@pytest.mark.parametrize("name", ["qp-osqp", "gp", "admm"])
def test_contact_fraction_of_an_accepted_iterative_answer_matches_the_exact_one(name: str) -> None:
    inst = _sweep_instance(32, 9)
    exact = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-13)).p
    res = get_solver(name).solve(inst.qp, SolverSettings())
    v = judge(inst, res.p, res.converged, CHECK_TOL)
    if v.status != "solved":
        pytest.skip(f"{name} was not accepted here (kkt {v.kkt_error:.1e}); nothing to read")
    a, a_exact = v.figures["contact_fraction"], inst.contact_fraction(exact, CHECK_TOL)
    assert a_exact > 0
    assert abs(a - a_exact) <= v.figures["contact_uncertain"] + 1e-15, (a, a_exact, v.figures["contact_uncertain"])


def test_contact_rule_ignores_tiny_forces_and_flags_the_ones_near_its_floor() -> None:
    inst = _sweep_instance(32, 9)
    exact = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-13)).p
    floor = inst.contact_floor(CHECK_TOL)
    a0 = inst.contact_fraction(exact, CHECK_TOL)
    # an answer the judge accepts, carrying 1e-3 x floor of force on every separated element:
    # the old relative rule (1e-9 max p) counted them all as contact
    dusty = np.where(exact > 0, exact, 1e-3 * floor)
    assert judge(inst, dusty, True, CHECK_TOL).status == "solved"
    assert inst.contact_fraction(dusty, CHECK_TOL) == a0
    assert inst.contact_uncertain(dusty, CHECK_TOL) == inst.contact_uncertain(exact, CHECK_TOL)
    # forces just above the floor on separated elements are counted, and flagged
    near = np.where(exact > 0, exact, 2.0 * floor)
    off = int(np.count_nonzero(exact <= floor))
    assert inst.contact_fraction(near, CHECK_TOL) * inst.total_elements == pytest.approx(
        a0 * inst.total_elements + off)
    assert inst.contact_uncertain(near, CHECK_TOL) * inst.total_elements >= off
    # the band is a decade either side of the floor (open at its foot, closed at its head)
    probe = np.zeros(inst.n)
    top = np.argsort(inst.qp.ubar)[-4:]  # deep interpenetration: the gap stays closed (w < 0)
    probe[top] = [floor / CONTACT_BAND, floor / CONTACT_BAND * 1.01, floor * CONTACT_BAND, floor * CONTACT_BAND * 1.01]
    assert inst.contact_uncertain(probe, CHECK_TOL) * inst.total_elements == pytest.approx(2)
    assert inst.contact_fraction(probe, CHECK_TOL) * inst.total_elements == pytest.approx(2)
    # NaN is neither in contact nor in the band
    assert inst.contact_fraction(np.full(inst.n, np.nan), CHECK_TOL) == 0.0


@pytest.mark.parametrize("tol, force, gaps", [
    (CHECK_TOL, 1.1 * CONTACT_BAND * CHECK_TOL, (1e-2, 1 / 12)),  # a wide open gap (beyond sqrt(tol) u_s)
    (1e-4, 2.0 * CONTACT_BAND * 1e-4, (3e-3, 8e-3)),  # gap > force, both within sqrt(tol): interior-point-like
])
def test_contact_flag_catches_forces_on_open_gaps_that_the_judge_accepts(tol: float, force: float,
                                                                         gaps: tuple[float, float]) -> None:
    """An accepted answer (at ``tol``) that puts a force (in p_s) just above the band on
    separated elements whose gap (in u_s) lies in ``gaps`` (so |w_i p_i| <= tol u_s p_s
    still holds): the count is fooled, the flag is not."""
    inst = _sweep_instance(32, 9)
    exact = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-13)).p
    u_s, p_s = inst.problem_scales()
    w = inst.qp.H.matvec(exact) - inst.qp.ubar
    lie = force * p_s
    victims = np.flatnonzero((exact == 0) & (w > gaps[0] * u_s) & (w < gaps[1] * u_s))
    assert victims.size >= 2
    p = exact.copy()
    p[victims] = lie
    # keep every exact contact's gap closed: re-solve its forces against the planted ones
    H = inst.qp.H.to_dense()
    c = np.flatnonzero(exact > 0)
    p[c] = np.linalg.solve(H[np.ix_(c, c)], inst.qp.ubar[c] - H[np.ix_(c, victims)] @ p[victims])
    assert np.all(p[c] > 0)
    v = judge(inst, p, True, tol)
    assert v.status == "solved"
    extra = v.figures["contact_fraction"] - inst.contact_fraction(exact, tol)
    assert extra * inst.total_elements == pytest.approx(victims.size)  # the count is fooled
    assert v.figures["contact_uncertain"] >= extra  # the flag covers it


def test_contact_floor_is_the_problems_not_the_answers() -> None:
    inst = _sweep_instance(32, 5)
    p = get_solver("nnls").solve(inst.qp, SolverSettings(tol=1e-13)).p
    f0 = inst.contact_floor(CHECK_TOL)
    assert inst.contact_floor(CHECK_TOL) == f0 and f0 > 0
    huge = p.copy()
    huge[0] = 1e300  # a wild answer does not move the floor (a max(p)-relative rule would drop every contact)
    assert inst.contact_mask(huge, CHECK_TOL)[1:].sum() == inst.contact_mask(p, CHECK_TOL)[1:].sum()
    # unit invariance: E -> 10 E scales forces and the floor alike
    surf = rmd_surface_n(32, 0.7, length=100e-6, seed=5)
    inst10 = InstanceBuilder(surf, 1e10, "bcc").build(inst.delta)
    assert inst10.contact_fraction(10 * p, CHECK_TOL) == inst.contact_fraction(p, CHECK_TOL)


CM_OK, CM_WHY = get_solver("cm-dual-ccg").availability()


def test_counterexample_carries_its_grid_for_the_peers() -> None:
    inst = counterexample(25, 3)
    g = inst.geometry
    assert g is not None and g.grid_shape == (5, 5) and g.delta == 1.0
    assert g.E == 0.01 and g.kernel == "bcc" and g.periodic is False
    assert not g.has_surface  # ubar is drawn, not derived from heights: no cascade on it


def test_peers_on_the_counterexample_solve_or_skip_never_fail(run_harness: Any) -> None:
    solvers = ["cm-dual-ccg", "cm-pk-ccg", "tamaas-pkr"]
    table = run_harness(["counterexample"], solvers=solvers, seeds=(0, 1), size=10)
    assert set(table["solver"]) == set(solvers)
    assert not table["status"].isin(["failed", "crashed", "timeout"]).any(), table[["solver", "status", "error"]]
    for s in ("cm-dual-ccg", "cm-pk-ccg"):
        st = set(table.loc[table["solver"] == s, "status"])
        assert st == ({"solved"} if CM_OK else {"skipped"}), (s, st)
    tm = table[table["solver"] == "tamaas-pkr"]
    assert (tm["status"] == "skipped").all() and tm["skip_reason"].str.len().gt(0).all()


def test_the_counterexample_distance_table_marks_the_reference_own_answers(tmp_path: Any) -> None:
    """The reference's own answers are at distance 0 by construction: the table says
    ``ref``, as the scene tables do, not "0 / 0"."""
    table, _ = _counterexample_table()
    nnls = table["solver"] == "nnls"
    table["reference_solver"] = ""
    table.loc[nnls, "reference_solver"] = "nnls@" + table.loc[nnls, "profile"].astype(str)
    table.loc[nnls, "p_rel_error"] = 0.0
    table.to_parquet(tmp_path / "results.parquet", index=False)
    table = read_table(tmp_path)
    section = rce.counterexample_section(rp.ReportContext(tmp_path, table, {}), table).body
    assert "| nnls | - | ref |" in section and "the reference's own answers" in section
