"""Contact QP instances: trial set and ubar (paper section 2), load sequences, the
greedy counterexample (Example 1), analytic scenes, KKT unit invariance, bad input."""

from __future__ import annotations

import warnings
from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest

from contactbench.problems.kkt import kkt_check
from contactbench.problems.errors import MemoryBudgetError, ProblemInputError
from contactbench.problems.instances import (
    InstanceBuilder,
    counterexample,
    flat_punch_load,
    flat_punch_surface,
    hertz_solution,
    hertz_surface,
    load_ramp,
    load_unload_cycle,
    paper_max_displacement,
    rigid_body_ubar,
    trial_set,
)
from contactbench.problems.surfaces import Surface, rmd_surface

E = 1.0e9


@pytest.fixture(scope="module")
def surface() -> Surface:
    return rmd_surface(5, 0.7, seed=1, periodic=False)


def test_trial_set_and_ubar_follow_the_paper(surface: Surface) -> None:
    D = paper_max_displacement(surface)
    inst = InstanceBuilder(surface, E).build(D)
    h = surface.heights
    expected = [i * h.shape[1] + j for i in range(h.shape[0]) for j in range(h.shape[1]) if h[i, j] >= h.max() - D]
    assert inst.geometry.indices.tolist() == expected
    assert np.allclose(inst.qp.ubar, D - h.max() + h.ravel()[expected], rtol=0, atol=1e-20)
    assert inst.qp.ubar.max() == pytest.approx(D) and (inst.qp.ubar >= 0).all()  # ubar = Delta at the top
    assert trial_set(h, 0.0).tolist() == [int(np.argmax(h))]
    assert D == pytest.approx(0.5 * (h.max() - h.mean()))


def test_load_area_and_pressure_field(surface: Surface) -> None:
    inst = InstanceBuilder(surface, E).build(paper_max_displacement(surface))
    p = np.zeros(inst.n)
    p[::2] = 1.0
    assert inst.load(p) == pytest.approx(p.sum())
    assert inst.contact_fraction(p) == pytest.approx(np.count_nonzero(p) / surface.heights.size)
    assert inst.dimensionless_load(p) == pytest.approx(p.sum() / (E * surface.N**2 * surface.delta**2))
    field = inst.pressure_field(p)
    assert field.shape == surface.shape
    assert field.ravel()[inst.geometry.indices] == pytest.approx(p / surface.delta**2)
    assert field.sum() * surface.delta**2 == pytest.approx(p.sum())


def test_candidates_restrict_the_trial_set(surface: Surface) -> None:
    builder = InstanceBuilder(surface, E)
    D = paper_max_displacement(surface)
    full = builder.build(D).geometry.indices
    keep = full[: full.size // 2]
    part = builder.build(D, candidates=np.concatenate([keep, [0, 1, 2]]))
    assert set(part.geometry.indices) == set(keep) | (set([0, 1, 2]) & set(full))
    mask = np.zeros(surface.shape, dtype=bool)
    mask.ravel()[keep] = True
    assert np.array_equal(builder.build(D, candidates=mask).geometry.indices, np.sort(keep))


def test_load_ramp_and_cycle() -> None:
    assert np.allclose(load_ramp(2.0, 4), [0.5, 1.0, 1.5, 2.0])
    assert np.allclose(load_unload_cycle(3.0, 3), [1, 2, 3, 2, 1])
    assert np.allclose(load_unload_cycle(3.0, 3, cycles=2), [1, 2, 3, 2, 1, 2, 3, 2, 1])
    with pytest.raises(ProblemInputError, match="number of load steps must be a positive integer, got 0"):
        load_ramp(1.0, 0)
    with pytest.raises(ProblemInputError, match="maximum displacement"):
        load_ramp(-1.0, 3)


@pytest.mark.parametrize("n", [25, 100, 400])
def test_counterexample_is_paper_example_1(n: int) -> None:
    inst = counterexample(n, seed=42)
    assert np.array_equal(inst.qp.ubar, np.random.default_rng(42).random(n))
    assert inst.n == n and inst.kernel == "bcc" and inst.E == 0.01
    assert np.allclose(inst.qp.H.diagonal(), 2.0 / (np.pi * 0.01 * 1.0))
    H = inst.qp.H.to_dense()
    assert H[0, 1] == pytest.approx(2.0 / (np.pi * 0.01) * np.arcsin(0.5))
    assert np.array_equal(counterexample(n, seed=42).qp.ubar, inst.qp.ubar)
    with pytest.raises(ProblemInputError, match="n = N\\^2 .* got n = 24"):
        counterexample(24, seed=0)


def test_hertz_closed_forms() -> None:
    R, Es, D = 2.0, 3.0, 0.02
    s = hertz_solution(R, Es, D)
    assert s.contact_radius == pytest.approx(np.sqrt(R * D))
    assert s.load == pytest.approx(4.0 / 3.0 * Es * np.sqrt(R) * D**1.5)
    # the Hertz pressure p0 sqrt(1 - r^2/a^2) integrates to the load
    assert s.load == pytest.approx(2.0 / 3.0 * np.pi * s.contact_radius**2 * s.peak_pressure)
    surf = hertz_surface(16, radius=R, length=1.0)
    x = (np.arange(16) - 7.5) / 16
    assert surf.heights == pytest.approx(-(x[:, None] ** 2 + x[None, :] ** 2) / (2 * R))


@pytest.mark.parametrize("kernel,tol", [("love", 0.03), ("bcc", 0.06)])
def test_flat_punch_load_matches_2_a_E_Delta(kernel: str, tol: float) -> None:
    """Every punch element is in contact, so Hp = Delta; compare with the closed form at
    the area-equivalent radius of the staircase punch."""
    a, D, Es = 0.3, 1e-3, 2.0
    surf = flat_punch_surface(32, a, 1.0)
    inst = InstanceBuilder(surf, Es, kernel, operator="dense").build(D)
    assert np.allclose(inst.qp.ubar, D)
    p = np.linalg.solve(inst.qp.H.to_dense(), inst.qp.ubar)
    a_eff = np.sqrt(inst.n * surf.delta**2 / np.pi)
    assert abs(inst.load(p) / flat_punch_load(a_eff, Es, D) - 1.0) < tol
    assert flat_punch_load(a, Es, D) == pytest.approx(2 * a * Es * D)


def test_scaled_kkt_figures_are_unit_invariant(surface: Surface) -> None:
    """E -> 1e6 E (p -> 1e6 p) and every length -> 1e-6 length (p -> 1e-12 p, forces
    scale with area): every scaled KKT figure is unchanged to 1e-10."""
    D = paper_max_displacement(surface)
    base = InstanceBuilder(surface, E).build(D)
    rng = np.random.default_rng(0)
    p_s = base.qp.ubar.max() / base.qp.H.diagonal().max()
    p = p_s * rng.normal(0.0, 1.0, base.n)  # not optimal: negative entries, w of both signs
    stiff = InstanceBuilder(surface, E * 1e6).build(D)
    small = InstanceBuilder(surface.scaled(1e-6), E).build(D * 1e-6)
    assert np.array_equal(small.geometry.indices, base.geometry.indices)
    reports = [kkt_check(base, p), kkt_check(stiff, p * 1e6), kkt_check(small, p * 1e-12)]
    names = ("primal", "dual", "complementarity", "complementarity_sum", "kkt_error")
    for name in names:
        ref = getattr(reports[0], name)
        assert ref > 0, name
        for other in reports[1:]:
            assert getattr(other, name) == pytest.approx(ref, rel=1e-10, abs=0), name


# ---------------------------------------------------------------------------
# bad input: each error names the problem
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [0.0, -5.0, np.nan])
def test_non_positive_modulus_is_refused(surface: Surface, bad: float) -> None:
    with pytest.raises(ProblemInputError, match="E \\(composite modulus\\) must be a finite positive number"):
        InstanceBuilder(surface, bad)


@pytest.mark.parametrize("bad", [-1e-9, np.nan, np.inf])
def test_negative_or_non_finite_displacement_is_refused(surface: Surface, bad: float) -> None:
    with pytest.raises(ProblemInputError, match="far-field displacement Delta must be a finite number >= 0"):
        InstanceBuilder(surface, E).build(bad)


def test_empty_trial_set_is_refused(surface: Surface) -> None:
    builder = InstanceBuilder(surface, E)
    lowest = int(np.argmin(surface.heights))  # never in I_C at a small Delta
    with pytest.raises(ProblemInputError, match="empty trial set at Delta = 0.0 within the given candidate"):
        builder.build(0.0, candidates=np.array([lowest]))
    with pytest.raises(ProblemInputError, match="empty trial set"):
        builder.build(1e-9, candidates=np.zeros(surface.shape, dtype=bool))


def test_bad_candidates_are_refused(surface: Surface) -> None:
    builder = InstanceBuilder(surface, E)
    with pytest.raises(ProblemInputError, match="candidate mask has shape \\(3, 3\\)"):
        builder.build(0.0, candidates=np.ones((3, 3), dtype=bool))
    with pytest.raises(ProblemInputError, match="candidate indices must lie in 0..1088"):
        builder.build(0.0, candidates=np.array([5000]))


def test_periodic_problem_is_posed_on_the_whole_grid_and_refused_when_unbounded() -> None:
    s = rmd_surface(4, 0.7, seed=0, periodic=True)
    builder = InstanceBuilder(s, E, "bcc", periodic=True)
    inst = builder.build(paper_max_displacement(s))
    assert inst.n == s.heights.size  # points below xi_max - Delta may touch: whole grid
    assert inst.qp.ubar.min() < 0.0 and inst.qp.ubar.sum() < 0.0
    np.testing.assert_allclose(inst.qp.ubar.max(), paper_max_displacement(s))
    with pytest.raises(ProblemInputError, match="xi_max - xi_mean: H is singular .* unbounded"):
        builder.build(10 * (s.z_max - s.heights.min()))


def test_unknown_kernel_and_operator_are_refused(surface: Surface) -> None:
    with pytest.raises(ProblemInputError, match="unknown kernel 'boussinesq'"):
        InstanceBuilder(surface, E, "boussinesq")
    with pytest.raises(ProblemInputError, match="operator must be 'fft' or 'dense', got 'sparse'"):
        InstanceBuilder(surface, E, operator="sparse")


def test_dense_matrix_over_budget_is_refused_with_the_estimate(surface: Surface) -> None:
    D = paper_max_displacement(surface)
    n = InstanceBuilder(surface, E).build(D).n
    with pytest.raises(MemoryBudgetError, match="dense H \\(\\d+ x \\d+ float64\\) needs about .* GiB, over the memory budget") as err:
        InstanceBuilder(surface, E, operator="dense", memory_budget=1000.0).build(D)
    assert err.value.needed_bytes == 8 * n * n
    assert err.value.budget_bytes == 1000.0
    fft = InstanceBuilder(surface, E, operator="fft", memory_budget=1000.0).build(D)
    with pytest.raises(MemoryBudgetError, match=f"\\({n} x {n} float64\\)"):
        fft.qp.H.to_dense(budget=1000.0)


def test_a_flat_surface_has_no_paper_load_ramp() -> None:
    flat = Surface(np.zeros((16, 16)), 1e-6, name="flat-file")
    with pytest.raises(ProblemInputError, match="'flat-file' is flat \\(all heights equal"):
        paper_max_displacement(flat)
    # an instance at a given Delta stays well defined (the stress scene's full-contact case)
    assert InstanceBuilder(flat, E).build(1e-7).n == flat.heights.size


def test_restricted_qp_keeps_operator_ubar_and_geometry_consistent(surface: Surface) -> None:
    inst = InstanceBuilder(surface, E, operator="dense").build(paper_max_displacement(surface))
    pos = np.array([0, 2, 3])
    sub = inst.qp.restrict(pos)
    np.testing.assert_array_equal(sub.H.to_dense(), inst.qp.H.to_dense()[np.ix_(pos, pos)])
    np.testing.assert_array_equal(sub.ubar, inst.qp.ubar[pos])
    np.testing.assert_array_equal(sub.geometry.indices, inst.geometry.indices[pos])
    assert sub.geometry.surface is surface and sub.geometry.far_field == inst.delta
    np.testing.assert_array_equal(rigid_body_ubar(surface.heights, inst.delta, inst.geometry.indices), inst.qp.ubar)


def test_a_qp_is_frozen_so_no_solver_can_swap_its_arrays(surface: Surface) -> None:
    """A solver handed ``inst.qp`` cannot rebind its fields (a test judging by hand against
    ``inst.qp`` would read the swapped ones); a changed problem is a new QP."""
    qp = InstanceBuilder(surface, E, operator="dense").build(paper_max_displacement(surface)).qp
    ubar, H, geometry, constraints = qp.ubar, qp.H, qp.geometry, qp.constraints
    for name, value in [("ubar", np.zeros_like(ubar)), ("H", None), ("geometry", None), ("constraints", None)]:
        with pytest.raises(FrozenInstanceError):
            setattr(qp, name, value)
    assert qp.ubar is ubar and qp.H is H and qp.geometry is geometry and qp.constraints is constraints
    moved = replace(qp, ubar=ubar + 1.0)
    np.testing.assert_array_equal(moved.ubar, ubar + 1.0)
    assert qp.ubar is ubar and moved.H is H


def test_has_surface_tells_which_problems_can_be_rebuilt_from_their_surface(surface: Surface) -> None:
    inst = InstanceBuilder(surface, E).build(paper_max_displacement(surface))
    assert inst.geometry.has_surface
    assert not counterexample(25, 0).geometry.has_surface  # a grid, but no surface (paper Example 1)


@pytest.mark.parametrize("bad", ["1e-6", True, None])
def test_a_number_given_as_text_a_bool_or_none_is_refused_naming_it(bad: object) -> None:
    """load_ramp("1e-6", 3) failed inside NumPy ("string multiply"); a length of True was 1 m."""
    from contactbench.problems.errors import ProblemInputError, check_positive
    from contactbench.problems.instances import load_ramp

    with pytest.raises(ProblemInputError, match="maximum displacement must be a finite positive number"):
        load_ramp(bad, 3)  # type: ignore[arg-type]
    with pytest.raises(ProblemInputError, match="surface length"):
        check_positive("surface length", bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("n", [-5, 0, 3, 2.5, 4.0, float("nan"), True])
def test_the_counterexample_refuses_a_size_that_is_no_square_count_in_one_line(n: object) -> None:
    """n must be an integer N^2 with N >= 2: anything else is named, with no NumPy warning on
    the way (a negative n once took a square root of it and raised an unrelated ValueError)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ProblemInputError, match=r"counterexample needs n = N\^2 with N >= 2, got n = "):
            counterexample(n, 0)  # type: ignore[arg-type]
