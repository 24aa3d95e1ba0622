"""Hardness-bounded pressures: the box 0 <= p <= H_A delta^2 (a mixed LCP).

BVLS is checked against brute force on small random boxes; every solver that claims
bounds against BVLS; the limits (infinite hardness: the elastic answer; a tiny one: every
touching element plastic); the figures against answers above the bound, at the bound
with an open gap, or inside it with a negative one."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from contactbench.problems.constraints import Constraints, hardness_bounds, make_constraints, uniform_hardness
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import bvls, constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers.base import ProblemTraits, SolverSettings
from contactbench.solvers.registry import available_solvers, get_solver

E = 1e9


def builder(N: int, seed: int = 3) -> InstanceBuilder:
    return InstanceBuilder(fourier_synthesis(N, 0.8, 0.1, length=1e-4, seed=seed), E, operator="dense")


def brute_force_box(H: np.ndarray, u: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """The solution by trying every assignment of the n elements to {0, free, ub}."""
    n = u.size
    for states in itertools.product((0, 1, 2), repeat=n):
        st = np.array(states)
        p = np.where(st == 2, ub, 0.0)
        F = np.flatnonzero(st == 1)
        if F.size:
            p[F] = np.linalg.solve(H[np.ix_(F, F)], u[F] - H[np.ix_(F, np.flatnonzero(st == 2))] @ ub[st == 2])
        w = H @ p - u
        if (np.all(p >= -1e-12) and np.all(p <= ub + 1e-12) and np.all(w[st == 0] >= -1e-12)
                and np.all(w[st == 2] <= 1e-12)):
            return p
    raise AssertionError("no solution found")


@pytest.mark.parametrize("seed", range(20))
def test_bvls_is_exact_on_small_boxes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 7))
    A = rng.normal(size=(n, n))
    H = A @ A.T + 0.1 * np.eye(n)
    u = rng.normal(size=n)
    ub = rng.random(n) * 0.5 + 0.01
    want = brute_force_box(H, u, ub)
    for p0 in (None, rng.random(n)):
        out = bvls(H, u, ub, p0)
        assert out.converged
        assert np.allclose(out.p, want, rtol=0, atol=1e-10)
    ref = constrained_exact_solution(H, u, make_constraints(n, ub))
    assert np.allclose(ref.p, want, rtol=0, atol=1e-10)


@pytest.fixture(scope="module")
def elastic() -> tuple[InstanceBuilder, float, np.ndarray]:
    """A rough surface at 24 x 24 pressed to twice the paper's top step, and its elastic p."""
    b = builder(24, seed=2)
    d = 2.0 * paper_max_displacement(b.surface)
    inst = b.build(d)
    return b, d, exact_solution(inst.qp.H.H, inst.qp.ubar).p


def test_infinite_hardness_is_the_elastic_problem(elastic) -> None:
    b, d, p_el = elastic
    inst = b.build(d, hardness=math.inf)
    assert inst.qp.constraints.plain
    r = get_solver("bvls").solve(inst.qp)
    assert np.max(np.abs(r.p - p_el)) <= 1e-12 * np.max(p_el)
    high = b.build(d, hardness=10.0 * float(np.max(p_el)) / b.surface.delta ** 2)  # finite, never reached
    assert high.qp.constraints.bounded
    for name in ("bvls", "pk"):
        r = get_solver(name).solve(high.qp, SolverSettings(tol=1e-12 if name == "pk" else None))
        assert np.max(np.abs(r.p - p_el)) <= 1e-8 * np.max(p_el), name
        assert high.plastic_fraction(r.p) == 0.0


def test_a_tiny_hardness_makes_every_touching_element_plastic(elastic) -> None:
    b, d, p_el = elastic
    H_A = 1e-6 * float(np.max(p_el)) / b.surface.delta ** 2
    inst = b.build(d, hardness=H_A)
    ub = inst.qp.constraints.upper
    for name in ("bvls", "pk", "greedy-chol"):
        r = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-12 if name == "pk" else None))
        touching = inst.contact_mask(r.p)
        assert touching.sum() > 0, name
        assert np.all(r.p[touching] == ub[touching]), name  # p = bound on the contact set
        assert inst.plastic_fraction(r.p) == 1.0
        if get_solver(name).capabilities.exact:  # greedy's irreversible removals may miss some
            assert np.all(touching == (inst.qp.ubar > 0.0)), name  # the rigid-body overlap, nearly unloaded
            assert kkt_check(inst, r.p).kkt_error <= 1e-10, name


def test_a_tiny_hardness_under_load_control_saturates_the_highest_points() -> None:
    b = builder(16, seed=4)
    H_A = 1e3  # Pa: u = H_A delta^2, far below any elastic force here
    u = H_A * b.surface.delta ** 2
    inst = b.build_load(5.0 * u, hardness=H_A)
    highest = np.argsort(inst.qp.ubar)[-5:]
    for name in ("bvls", "pk", "gp"):
        r = get_solver(name).solve(inst.qp)
        assert set(np.flatnonzero(r.p >= u * (1 - 1e-9))) == set(highest.tolist()), name
        assert kkt_check(inst, r.p, r.multiplier).kkt_error <= 1e-6, name


def test_every_solver_claiming_bounds_meets_bvls(elastic) -> None:
    b, d, p_el = elastic
    inst = b.build(d, hardness=0.4 * float(np.max(p_el)) / b.surface.delta ** 2)
    ref = get_solver("bvls").solve(inst.qp)
    assert kkt_check(inst, ref.p).kkt_error <= 1e-12
    assert 0.1 < inst.plastic_fraction(ref.p) < 0.9
    names = sorted(n for n, s in available_solvers().items() if s.capabilities.bounds)
    assert {"bvls", "pk", "gp", "admm", "greedy-cg", "qp-clarabel", "cvxpy"} <= set(names)
    traits = ProblemTraits(n=inst.n, operator="dense", kernel=inst.kernel, periodic=inst.periodic, bounded=True)
    for name in names:
        s = get_solver(name)
        if s.skip(traits):  # a peer that cannot pose this kernel says so
            continue
        tol = 1e-12 if s.capabilities.exact else s.capabilities.promised_tol(1e-8)
        r = s.solve(inst.qp, SolverSettings(tol=tol if s.default_tol is not None else None, time_limit=60.0))
        ubx = inst.qp.constraints.upper
        assert np.all(r.p <= ubx) or not r.converged or name.startswith("qp-") or name == "cvxpy", name
        rep = kkt_check(inst, r.p)
        assert math.isfinite(rep.kkt_error), name
        if s.capabilities.exact:
            assert np.max(np.abs(r.p - ref.p)) <= 1e-8 * np.max(ref.p), name


def test_greedy_with_saturation_is_judged_not_trusted(elastic) -> None:
    """Greedy's removals are irreversible: a saturated element pushes force to neighbours it
    may already have dropped.  Whatever it claims, the judge's figures decide."""
    b, d, p_el = elastic
    inst = b.build(d, hardness=0.3 * float(np.max(p_el)) / b.surface.delta ** 2)
    ref = get_solver("bvls").solve(inst.qp)
    r = get_solver("greedy-chol").solve(inst.qp)
    rep = kkt_check(inst, r.p)
    agrees = np.max(np.abs(r.p - ref.p)) <= 1e-8 * np.max(ref.p)
    assert agrees == rep.passes(1e-8)
    assert np.all(r.p >= 0.0) and np.all(r.p <= inst.qp.constraints.upper)


GREEDY = ("greedy-cg", "greedy-gs", "greedy-chol")


@pytest.mark.parametrize("name", GREEDY)
@pytest.mark.parametrize("share", [0.3, 0.05, 1e-3])
def test_greedy_claims_a_saturated_end_only_where_the_judge_agrees(elastic, name: str, share: float) -> None:
    """The saturation fixes elements irreversibly (``greedy.saturation_claim``): a loop that
    ends with plastic elements claims convergence only at a scaled KKT error within tol.
    A plastic sweep's step once claimed it at 0.05-0.16; here the hardness is a share of
    the largest elastic force, and whichever way a variant ends, its claim agrees with the
    judge, and a refused claim says why."""
    b, d, p_el = elastic
    inst = b.build(d, hardness=share * float(np.max(p_el)) / b.surface.delta ** 2)
    r = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10))
    rep = kkt_check(inst, r.p)
    assert r.info["plastic"] > 0
    assert r.converged == rep.passes(1e-8), (r.message, rep.kkt_error)
    if not r.converged:
        assert r.status == "stalled" and "saturation" in r.message and "KKT error" in r.message


def test_greedy_refuses_the_claim_on_a_box_it_saturates_wrongly() -> None:
    """An 8 x 8 surface pressed to 0.3 of its relief under a bound of 0.2 of its largest
    elastic force: the greedy variants end their passes with no negative p and a wrong
    plastic set (scaled KKT error 0.46), which they once claimed; now "stalled".  bvls
    solves it exactly."""
    b = builder(8, seed=0)
    d = 0.3 * float(np.ptp(b.surface.heights))
    p_el = get_solver("bvls").solve(b.build(d).qp).p
    inst = b.build(d, hardness=0.2 * float(np.max(p_el)) / b.surface.delta ** 2)
    assert kkt_check(inst, get_solver("bvls").solve(inst.qp).p).kkt_error <= 1e-12
    for name in GREEDY:
        r = get_solver(name).solve(inst.qp)
        assert not kkt_check(inst, r.p).passes(1e-2), name
        assert r.status == "stalled" and not r.converged, (name, r.message)


def test_bounded_solvers_skip_and_refuse_correctly() -> None:
    b = builder(8)
    inst = b.build(1e-7, hardness=1e6)
    traits = ProblemTraits(n=inst.n, operator="dense", bounded=True)
    unbounded = sorted(n for n, s in available_solvers().items()  # the shipped ones (tests register others)
                       if not s.capabilities.bounds and type(s).__module__.startswith("contactbench.solvers."))
    assert {"nnls", "scipy-nnls"} <= set(unbounded)
    for name in unbounded:
        assert "cannot pose bounded pressures" in get_solver(name).skip(traits)
        with pytest.raises(ProblemInputError, match="bounded"):
            get_solver(name).solve(inst.qp)
    for name in ("greedy-cg", "fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg"):
        assert get_solver(name).skip(traits) is None
    assert "load control" in get_solver("greedy-cg").skip(ProblemTraits(n=4, operator="dense", load_control=True))


# ---------------------------------------------------------------------------
# The figures cannot be fooled
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def box_solution(elastic) -> tuple[object, np.ndarray]:
    b, d, p_el = elastic
    inst = b.build(d, hardness=0.4 * float(np.max(p_el)) / b.surface.delta ** 2)
    ref = constrained_exact_solution(inst.qp.H.H, inst.qp.ubar, inst.qp.constraints)
    return inst, ref.p


def test_above_the_bound_is_primal_infeasible(box_solution) -> None:
    inst, p = box_solution
    ub = inst.qp.constraints.upper
    q = np.minimum(p * 1.5, 2.0 * ub)  # every plastic element at twice its bound, "solved"
    rep = kkt_check(inst, q)
    assert rep.primal >= 0.49 * float(ub[0]) / rep.p_scale and not rep.passes(1e-6)
    unbounded = QP(inst.qp.H, inst.qp.ubar, inst.qp.geometry)  # the same p judged without the bound
    assert kkt_check(unbounded, q).primal == 0.0


def test_an_open_gap_at_the_bound_fails(box_solution) -> None:
    inst, p = box_solution
    ub = inst.qp.constraints.upper
    q = p.copy()
    q[(p > 0) & (p < ub)] = 0.0  # the elastic contact dropped, the plastic kept: gaps open at the bound
    assert not kkt_check(inst, q).passes(1e-6)
    interior = p.copy()
    interior[p >= ub] *= 0.5  # pulled off the bound where the gap is closed: a negative gap inside
    rep = kkt_check(inst, interior)
    assert rep.dual > 1e-3 and not rep.passes(1e-6)


@pytest.mark.parametrize("entry", [math.nan, math.inf, 1e308, -1e308])
def test_non_finite_or_huge_entries_fail(box_solution, entry: float) -> None:
    inst, p = box_solution
    q = p.copy()
    q[0] = entry
    assert not kkt_check(inst, q).passes(1e-6)


def test_hardness_bounds_refuse_nonsense() -> None:
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ProblemInputError):
            hardness_bounds(bad, 1e-6, 4)
    with pytest.raises(ProblemInputError):
        hardness_bounds(1e9, 0.0, 4)
    assert np.all(hardness_bounds(2e9, 1e-6, 3) == 2e9 * 1e-12)
    assert make_constraints(3, math.inf).plain
    with pytest.raises(ProblemInputError):
        Constraints(upper=np.ones(2)).check(3)


def test_plastic_fraction_counts_touching_elements_at_the_bound(box_solution) -> None:
    inst, p = box_solution
    ub = inst.qp.constraints.upper
    want = np.count_nonzero(p >= ub) / np.count_nonzero(inst.contact_mask(p))
    assert inst.plastic_fraction(p) == pytest.approx(want)
    assert inst.plastic_fraction(np.zeros_like(p)) == 0.0
    plain = QP(DenseOperator(inst.qp.H.H), inst.qp.ubar)
    assert not plain.constraints.bounded


def test_nnls_gp_poses_bounds_within_the_dense_budget_and_skips_beyond() -> None:
    s = get_solver("nnls-gp")
    assert s.skip(ProblemTraits(n=1000, operator="fft", bounded=True)) is None
    assert s.skip(ProblemTraits(n=1000, operator="fft", load_control=True)) is None
    why = s.skip(ProblemTraits(n=10**6, operator="fft", bounded=True))  # 7.3 TiB of dense H
    assert why is not None and "memory budget" in why and "n = 1000000" in why
    assert s.skip(ProblemTraits(n=10**6, operator="fft")) is None  # the plain problem never needs the dense H


@pytest.mark.parametrize("delta", [1e-6, (1e-6, 1.5e-6)])
def test_uniform_hardness_reads_back_the_hardness_of_its_bounds(delta) -> None:
    """``uniform_hardness`` inverts ``hardness_bounds`` (square and rectangular elements), and
    says None where no single hardness poses the box: none, an infinite, a NaN, a zero or
    a varying bound, or no points."""
    for h in (3e7, 2e9, 1e12):
        assert uniform_hardness(hardness_bounds(h, delta, 5), delta) == pytest.approx(h, rel=1e-14)
    u = hardness_bounds(2e9, delta, 5)
    assert uniform_hardness(None, delta) is None and uniform_hardness(u[:0], delta) is None
    for bad in (np.inf, np.nan, 0.0, 1.5 * u[0]):
        v = u.copy()
        v[2] = bad
        assert uniform_hardness(v, delta) is None, bad
    v = u.copy()
    v[1] *= 1.0 + 1e-15  # round-off between equal bounds is still one hardness
    assert uniform_hardness(v, delta) == pytest.approx(2e9, rel=1e-14)


@pytest.mark.parametrize("upper", [-1.0, 0.0, math.nan])
def test_the_judge_refuses_bounds_that_cannot_be_posed(elastic, upper: float) -> None:
    """A QP whose upper bounds are <= 0 (or NaN) is refused by kkt_check in one line (with a
    bound of -1 the force scale would turn negative, and every answer -- the exact one, p =
    0 -- would score 0)."""
    b, d, p_exact = elastic
    qp = b.build(d).qp
    bounds = np.ones(qp.n)
    bad = QP(qp.H, qp.ubar, qp.geometry, Constraints(bounds, None))
    bounds[:] = upper  # (an array changed after the constraints were posed)
    for p in (p_exact, np.zeros(qp.n)):
        with pytest.raises(ProblemInputError, match="upper bounds"):
            kkt_check(bad, p)


def test_a_complex_answer_is_no_answer(elastic) -> None:
    """A candidate with an imaginary part scores inf (not its real part's figures); a complex
    dtype with zero imaginary parts is read as the real answer it is."""
    b, d, p = elastic
    qp = b.build(d).qp
    assert kkt_check(qp, p + 1j).kkt_error == math.inf
    assert kkt_check(qp, p + 0j).kkt_error == pytest.approx(kkt_check(qp, p).kkt_error, abs=1e-15)


def test_a_bound_that_float64_holds_only_as_a_subnormal_is_refused() -> None:
    """1e-300 Pa on a 1e-11 m^2 element is a force of 1e-311 N: a subnormal, whose products
    and sums lose digits -- refused as underflow, as 0 is."""
    with pytest.raises(ProblemInputError, match="float64 cannot hold"):
        hardness_bounds(1e-300, (1e-5, 1e-6), 4)
    assert hardness_bounds(1e-290, (1e-5, 1e-6), 4)[0] == pytest.approx(1e-301)
