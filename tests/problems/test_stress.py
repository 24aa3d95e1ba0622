"""The stress battery's recipes build what they promise."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance.cases import exact_reference
from contactbench.problems.instances import counterexample
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.lcp import UncertifiedSolutionError, exact_solution_on_subset
from contactbench.problems.operators import FFTOperator
from contactbench.problems.scenes import SceneConfig, all_scenes, get_scene
from contactbench.problems.scenes.stress import (
    GROUPS,
    UNIT_SYSTEMS,
    battery_specs,
    build_battery_spec,
    condition_number,
    extreme_eigenvalues,
    known_solution_instance,
    packed_instance,
    periodic_instance,
)
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver


def edge(case: str):
    spec = next(s for s in battery_specs("fast", ("edge",)) if s.params["case"] == case)
    return build_battery_spec(spec).at(0)


def test_stress_scenes_are_registered_and_cover_the_battery() -> None:
    scenes = all_scenes()
    assert {"stress", *(f"stress-{g}" for g in GROUPS)} <= set(scenes)
    cfg = SceneConfig(extra={"mode": "fast"})
    whole = get_scene("stress").instances(get_scene("stress").config(cfg))
    assert {s.params["group"] for s in whole} == set(GROUPS)
    for g in GROUPS:
        part = get_scene(f"stress-{g}").instances(get_scene(f"stress-{g}").config(cfg))
        assert part and {s.params["group"] for s in part} == {g}
        assert all(s.scene == f"stress-{g}" for s in part)
    default = get_scene("stress-conditioning").instances(get_scene("stress-conditioning").config(None))
    assert max(s.params["n"] for s in default) == 100_000
    assert {s.params["kernel"] for s in default} == {"bcc", "love"}


def test_every_fast_recipe_builds_through_its_scene() -> None:
    scene = get_scene("stress")
    for spec in scene.instances(scene.config(SceneConfig(extra={"mode": "fast"}))):
        seq = scene.build(spec)
        for k in range(len(seq)):
            inst = seq.at(k)
            assert inst.n >= 1 and inst.qp.ubar.shape == (inst.n,)
            assert np.all(np.isfinite(inst.qp.ubar))


def test_delta_zero_touches_one_point_with_zero_ubar() -> None:
    inst = edge("delta0")
    assert inst.n == 1 and inst.qp.ubar[0] == 0.0


def test_single_point_trial_set() -> None:
    inst = edge("single-point")
    assert inst.n == 1 and inst.qp.ubar[0] > 0
    ref = exact_reference(inst)
    assert ref.p[0] == pytest.approx(inst.qp.ubar[0] / inst.qp.H.diagonal()[0], rel=1e-12)


def test_full_contact_puts_every_point_in_contact() -> None:
    inst = edge("full-contact")
    assert inst.n == inst.total_elements
    assert np.all(exact_reference(inst).p > 0)


def test_two_identical_heights_and_a_plateau() -> None:
    two = edge("two-equal-heights")
    assert two.n == 2 and two.qp.ubar[0] == two.qp.ubar[1]
    p = exact_reference(two).p
    assert p[0] == pytest.approx(p[1], rel=1e-12) and p[0] > 0
    plateau = edge("plateau")
    top = np.flatnonzero(plateau.qp.ubar == plateau.qp.ubar.max())
    assert top.size >= 16


def test_strip_is_two_rows() -> None:
    inst = edge("strip-2xN")
    assert inst.geometry.grid_shape[0] == 2 and inst.geometry.grid_shape[1] > 2
    assert exact_reference(inst).kkt_error < 1e-12


def test_dynamic_range_spans_twelve_decades() -> None:
    u = edge("dynamic-range").qp.ubar
    pos = u[u > 0]
    assert pos.max() / pos.min() > 1e10


def test_near_touching_points_have_w_of_1e_14() -> None:
    inst = edge("near-touching")
    p = inst.meta["p_exact"]
    w = inst.qp.H.matvec(p) - inst.qp.ubar
    assert kkt_check(inst, p).kkt_error < 1e-14
    near = (p == 0) & (w < 1e-12 * np.max(np.abs(w)))
    assert near.sum() >= inst.meta["near_touching"]
    assert np.all(w[near] > 0)


def test_example_1_recipes_are_the_papers_counterexample_at_n400() -> None:
    specs = battery_specs("fast", ("counterexample",))
    assert len(specs) >= 3 and {s.params["n"] for s in specs} == {400}
    for spec in specs:
        inst = build_battery_spec(spec).at(0)
        paper = counterexample(400, spec.params["seed"])
        np.testing.assert_array_equal(inst.qp.ubar, paper.qp.ubar)
        assert inst.n == inst.total_elements == 400
    assert {s.params["n"] for s in battery_specs("full", ("counterexample",))} >= {100, 400}


@pytest.mark.parametrize("kernel", ["bcc", "love"])
def test_full_packing_puts_every_point_in_contact_with_a_known_solution(kernel: str) -> None:
    spec = next(s for s in battery_specs("fast", ("packing",)) if s.params["kernel"] == kernel)
    inst = build_battery_spec(spec).at(0)
    p = inst.meta["p_exact"]
    assert inst.n == inst.total_elements and np.all(p > 0)
    assert kkt_check(inst, p).kkt_error < 1e-14
    inst.meta.pop("p_exact")  # the reference must find it on its own
    np.testing.assert_allclose(exact_reference(inst).p, p, rtol=1e-8)


def periodic_cases():
    specs = battery_specs("fast", ("periodic",))
    assert 1 <= len(specs) <= 3
    return [(spec, build_battery_spec(spec).at(0)) for spec in specs]


@pytest.mark.slow
def test_periodic_recipes_are_whole_grid_problems_with_an_exact_reference() -> None:
    """Each fast periodic case is posed on the whole N x N grid (singular H: H 1 = 0,
    entries of both signs), its reference is exact there, a real fraction of the grid
    touches, and some touching points lie below the rigid-body trial set (ubar < 0)."""
    cases = periodic_cases()
    assert {inst.kernel for _, inst in cases} == {"spectral", "bcc"}
    for spec, inst in cases:
        N = spec.params["size"]
        assert inst.periodic and inst.n == N * N == inst.total_elements
        H = inst.qp.H
        assert np.max(np.abs(H.matvec(np.ones(inst.n)))) <= 1e-10 * H.diagonal()[0]
        assert H.entry_floor() < 0
        ref = exact_reference(inst)
        assert ref.method == "known solution" and ref.kkt_error <= 1e-12
        p, u = ref.p, inst.qp.ubar
        touching = p > 0
        assert np.all(p >= 0) and 0.1 <= touching.mean() < 1
        assert np.count_nonzero(touching & (u < 0)) >= 5
        assert inst.meta["contact_points"] == touching.sum()
        assert inst.meta["below_rigid_body"] == np.count_nonzero(touching & (u < 0))


def test_periodic_reference_is_not_the_rigid_body_trial_set_answer() -> None:
    """Solved only on the rigid-body set {ubar >= 0}, the answer misses the points below
    it: the whole-grid KKT check rejects it."""
    for _, inst in periodic_cases():
        trial = np.flatnonzero(inst.qp.ubar >= 0)
        assert trial.size < inst.n
        naive = exact_solution_on_subset(inst.qp, trial, tol=np.inf).p
        assert kkt_check(inst, naive).kkt_error > 1e-6


@pytest.mark.parametrize("solver", ["fast-dual-pccg", "nnls-gp"])
def test_registered_solvers_find_the_periodic_reference(solver: str) -> None:
    for _, inst in periodic_cases():
        res = get_solver(solver).solve(inst.qp, SolverSettings(tol=1e-10))
        assert res.converged and kkt_check(inst, res.p).kkt_error <= 1e-9
        assert relative_error(res.p, inst.meta["p_exact"]) <= 1e-6


def test_subset_solution_grows_from_a_subset_that_misses_contact() -> None:
    """Started on the top eighth of ubar (fewer points than touch), the subset grows by
    the penetrating points until the whole-grid KKT check certifies it."""
    inst = periodic_instance(32, "bcc", 0)
    exact = inst.meta["p_exact"]
    top = np.argsort(inst.qp.ubar)[-inst.n // 8:]
    assert np.count_nonzero(exact > 0) > top.size
    sol = exact_solution_on_subset(inst.qp, top)
    assert sol.rounds > 1 and sol.kkt_error <= 1e-12 and sol.subset.size < inst.n
    np.testing.assert_allclose(sol.p, exact, rtol=0, atol=1e-10 * exact.max())
    with pytest.raises(UncertifiedSolutionError, match="subset solves"):
        exact_solution_on_subset(inst.qp, top, max_rounds=1)


def test_known_solution_instance_rejects_an_empty_contact_set() -> None:
    from contactbench.problems.errors import ProblemInputError

    with pytest.raises(ProblemInputError, match="active_fraction"):
        known_solution_instance(4, 0, active_fraction=0.0)


def test_float32_recipe_hands_over_float32() -> None:
    spec = battery_specs("fast", ("precision",))[0]
    assert build_battery_spec(spec).at(0).qp.ubar.dtype == np.float32
    assert spec.params["profile"] == "high"


def test_lanczos_condition_number_matches_dense() -> None:
    inst = packed_instance(600, 0.5, "bcc", seed=3)
    assert isinstance(inst.qp.H, FFTOperator)
    dense = condition_number(inst.qp.H)
    lmin, lmax, method = extreme_eigenvalues(inst.qp.H, dense_limit=0)
    assert method == "lanczos"
    assert lmax / lmin == pytest.approx(dense, rel=1e-3)


@pytest.mark.parametrize("kernel", ["bcc", "love"])
def test_condition_number_grows_with_n_and_packing_density(kernel: str) -> None:
    by_n = [condition_number(packed_instance(n, 1.0, kernel, 0).qp.H) for n in (64, 256, 1024)]
    assert by_n[0] < by_n[1] < by_n[2]
    by_density = [condition_number(packed_instance(400, d, kernel, 0).qp.H) for d in (0.05, 0.3, 1.0)]
    assert by_density[0] < by_density[1] < by_density[2]


def test_units_recipe_agrees_across_unit_systems_to_1e_8() -> None:
    """The same physical problem in m/Pa, um/MPa and nm/GPa (and E over 12 decades):
    scaled KKT figures and P/(E A) of the exact solutions agree to 1e-8, and the forces
    scale with the force unit."""
    specs = {s.params["variant"]: s for s in battery_specs("fast", ("units",))}
    seq = build_battery_spec(specs["units"])
    insts = [seq.at(k) for k in range(len(seq))]
    assert [i.meta["unit_system"] for i in insts] == list(UNIT_SYSTEMS)
    refs = [exact_reference(i).p for i in insts]
    loads = [i.dimensionless_load(p) for i, p in zip(insts, refs)]
    assert np.ptp(loads) / max(loads) < 1e-8
    for inst, p in zip(insts, refs):
        lf, sf = inst.meta["length_factor"], inst.meta["stress_factor"]
        np.testing.assert_allclose(p, refs[0] * lf * lf * sf, rtol=1e-8, atol=0)
    # The same SI answer judged in every unit system: identical scaled figures.
    reports = [kkt_check(i, refs[0] * i.meta["length_factor"] ** 2 * i.meta["stress_factor"]) for i in insts]
    for name in ("primal", "dual", "complementarity", "complementarity_sum", "kkt_error"):
        assert np.ptp([getattr(r, name) for r in reports]) < 1e-8
    eseq = build_battery_spec(specs["E-range"])
    e_insts = [eseq.at(k) for k in range(len(eseq))]
    assert max(i.E for i in e_insts) / min(i.E for i in e_insts) >= 1e12
    e_loads = [i.dimensionless_load(exact_reference(i).p) for i in e_insts]
    assert np.ptp(e_loads) / max(e_loads) < 1e-8


def test_perturbation_recipe_moves_ubar_by_eps() -> None:
    spec = battery_specs("fast", ("perturbation",))[0]
    seq = build_battery_spec(spec)
    u0, u1 = seq.at(0).qp.ubar, seq.at(1).qp.ubar
    assert np.linalg.norm(u1 - u0) / np.linalg.norm(u0) == pytest.approx(spec.params["eps"], rel=1e-6)


def test_unknown_mode_or_group_is_a_clear_error() -> None:
    from contactbench.problems.errors import ProblemInputError

    with pytest.raises(ProblemInputError, match="mode"):
        battery_specs("huge")
    with pytest.raises(ProblemInputError, match="group"):
        battery_specs("fast", ("nonsense",))


def test_stress_report_renders_survival_units_and_conditioning(tmp_path) -> None:
    import pandas as pd

    from contactbench.harness.report.sections.stress import render_stress_section, write_stress_report

    rows = pd.DataFrame([
        {"solver": "a", "case": "units/u", "label": "units/u@0", "group": "units", "step": 0, "status": "pass",
         "kkt_error": 1e-12, "p_rel_error": 1e-13, "message": ""},
        {"solver": "a", "case": "units/u", "label": "units/u", "group": "units", "step": -1, "status": "flagged",
         "kkt_error": 1e-6, "p_rel_error": 1e-5, "message": "spread"},
        {"solver": "a", "case": "edge/x", "label": "edge/x@0", "group": "edge", "step": 0, "status": "WRONG",
         "kkt_error": 0.3, "p_rel_error": 0.5, "message": "claimed"},
    ])
    rows.to_csv(tmp_path / "survival-fast.csv", index=False)
    pd.DataFrame([{"kernel": "bcc", "target_density": 1.0, "n": 100, "cond": 104.0}]).to_csv(
        tmp_path / "conditioning.csv", index=False)
    text = render_stress_section(tmp_path)
    assert "| a |" in text and "W1" in text and "FAILS" in text and "flagged" in text
    assert "bcc d=1" in text and "104" in text
    assert write_stress_report(tmp_path).exists() and (tmp_path / "survival_matrix-fast.csv").exists()
