"""Load control: the QP with the equality sum(p) = P, whose multiplier is the approach Delta.

Every solver that claims load control is checked against the exact reference (``bvls``:
the KKT solve with the multiplier); load control at the loads a displacement sweep
produced must give the sweep's p (to 1e-8) and Delta (to 1e-6); the KKT figures must not
be fooled by a wrong, NaN or missing Delta, a load missed, or a non-finite answer."""

from __future__ import annotations

import math
from dataclasses import astuple
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contactbench.problems.constraints import Constraints, fit_multiplier, make_constraints, project_box_sum
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.export import read_qpbenchmark_constraints, read_qpbenchmark_row
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import constrained_figures, kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.qpfile import FORMAT, FORMAT_CONSTRAINED, read_problem_dir, write_problem_dir
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers.base import ProblemTraits, SolverSettings, WarmStart
from contactbench.solvers.registry import available_solvers, get_solver

E = 1e9


def builder(N: int, seed: int = 3, operator: str = "dense") -> InstanceBuilder:
    return InstanceBuilder(fourier_synthesis(N, 0.8, 0.1, length=1e-4, seed=seed), E, operator=operator)


def full_grid(inst, p: np.ndarray) -> np.ndarray:
    out = np.zeros(int(np.prod(inst.qp.geometry.grid_shape)))
    out[inst.qp.geometry.indices] = p
    return out


@pytest.fixture(scope="module")
def sweep() -> tuple[InstanceBuilder, list[tuple[float, np.ndarray]]]:
    """A displacement sweep at 24 x 24: (Delta, p on the whole grid) at three steps."""
    b = builder(24)
    top = paper_max_displacement(b.surface)
    out = []
    for frac in (0.3, 0.7, 1.0):
        inst = b.build(frac * top)
        sol = exact_solution(inst.qp.H.H, inst.qp.ubar)
        out.append((frac * top, full_grid(inst, sol.p)))
    return b, out


@pytest.mark.parametrize("name", ["bvls", "pk"])
def test_load_control_reproduces_the_displacement_sweep(sweep, name: str) -> None:
    b, steps = sweep
    solver = get_solver(name)
    for delta, p_disp in steps:
        inst = b.build_load(float(np.sum(p_disp)))
        r = solver.solve(inst.qp, SolverSettings(tol=1e-12 if name == "pk" else None))
        assert r.status == "converged", (name, r.message)
        assert np.max(np.abs(r.p - p_disp)) <= 1e-8 * np.max(p_disp), name
        assert abs(r.multiplier - delta) <= 1e-6 * delta, (name, r.multiplier, delta)
        assert kkt_check(inst, r.p, r.multiplier).kkt_error <= 1e-10


def test_a_warm_start_along_a_load_history(sweep) -> None:
    b, steps = sweep
    pk, prev, cold_its, warm_its = get_solver("pk"), None, 0, 0
    for _, p_disp in steps:
        inst = b.build_load(float(np.sum(p_disp)))
        cold = pk.solve(inst.qp)
        warm = pk.solve(inst.qp, warm=None if prev is None else WarmStart(p=prev))
        assert warm.status == "converged" and warm.warm_started == (prev is not None)
        assert np.max(np.abs(warm.p - p_disp)) <= 1e-7 * np.max(p_disp)
        cold_its += cold.iterations
        warm_its += warm.iterations
        prev = warm.p
    assert warm_its < cold_its


#: First-order backends whose own stopping tests, mapped from the tolerance asked, stop
#: short of the judge's figures on the equality-constrained QP (scaled KKT 1e-6 .. 1e-4
#: at 12 x 12): the judge rules on them, this test does not hold them to the tolerance.
LOOSE_BACKENDS = frozenset({"qp-osqp", "qp-scs", "qp-qpalm", "qp-proxqp"})


def claimers(flag: str) -> list[str]:
    return sorted(n for n, s in available_solvers().items() if getattr(s.capabilities, flag))


def solve_to_promise(name: str, qp) -> tuple[object, float]:
    s = get_solver(name)
    tol = s.capabilities.promised_tol(1e-12 if s.capabilities.exact else 1e-8)
    settings = SolverSettings(tol=tol if s.default_tol is not None else None, time_limit=60.0)
    return s.solve(qp, settings), tol


@pytest.mark.parametrize("hardness", [None, "half"])
def test_every_solver_claiming_load_control_meets_the_reference(hardness) -> None:
    b = builder(12, seed=5)
    top = paper_max_displacement(b.surface)
    elastic = b.build(top)
    p_el = exact_solution(elastic.qp.H.H, elastic.qp.ubar).p
    H_A = None if hardness is None else 0.5 * float(np.max(p_el)) / b.surface.delta ** 2
    inst = b.build_load(float(np.sum(p_el)), hardness=H_A)
    ref = constrained_exact_solution(inst.qp.H.H, inst.qp.ubar, inst.qp.constraints)
    assert ref.kkt_error <= 1e-12
    names = claimers("load_control")
    assert {"bvls", "pk", "gp", "admm", "qp-clarabel", "cvxpy"} <= set(names)
    traits = ProblemTraits(n=inst.n, operator="dense", kernel=inst.kernel, periodic=inst.periodic,
                           load_control=True, bounded=inst.qp.constraints.bounded)
    for name in names:
        if get_solver(name).skip(traits):  # a peer that cannot pose this kernel says so
            continue
        r, tol = solve_to_promise(name, inst.qp)
        rep = kkt_check(inst, r.p, r.multiplier)
        if get_solver(name).capabilities.exact:
            assert np.max(np.abs(r.p - ref.p)) <= 1e-8 * np.max(ref.p), name
            assert abs(r.multiplier - ref.multiplier) <= 1e-6 * abs(ref.multiplier), name
        assert math.isfinite(rep.kkt_error), name
        if r.converged and name not in LOOSE_BACKENDS:
            assert rep.kkt_error <= 100 * tol, (name, rep.kkt_error)
            assert rep.equality <= 100 * tol, name


def test_solvers_that_cannot_pose_load_control_say_so() -> None:
    b = builder(8)
    inst = b.build_load(1e-3)
    traits = ProblemTraits(n=inst.n, operator="dense", load_control=True)
    for name in ("fast-pdas", "nnls", "scipy-nnls", "greedy-cg"):
        s = get_solver(name)
        assert "cannot pose load control" in s.skip(traits)
        with pytest.raises(ProblemInputError, match="cannot pose load control"):
            s.solve(inst.qp)
    for name in ("pk", "fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg"):
        assert get_solver(name).skip(traits) is None


def test_the_result_gap_includes_the_multiplier(sweep) -> None:
    b, steps = sweep
    inst = b.build_load(float(np.sum(steps[1][1])))
    r = get_solver("pk").solve(inst.qp)
    w = inst.qp.H.matvec(r.p) - inst.qp.ubar - r.multiplier
    assert np.allclose(r.w, w, rtol=0, atol=1e-9 * np.max(np.abs(inst.qp.ubar)))
    assert np.min(r.w) >= -1e-8 * np.max(np.abs(inst.qp.ubar))


# ---------------------------------------------------------------------------
# The figures cannot be fooled
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def solved() -> tuple[object, np.ndarray, float]:
    b = builder(12, seed=7)
    elastic = b.build(paper_max_displacement(b.surface))
    P = float(np.sum(exact_solution(elastic.qp.H.H, elastic.qp.ubar).p))
    inst = b.build_load(P)
    ref = constrained_exact_solution(inst.qp.H.H, inst.qp.ubar, inst.qp.constraints)
    return inst, ref.p, ref.multiplier


def test_the_exact_answer_passes_with_its_own_or_a_fitted_delta(solved) -> None:
    inst, p, delta = solved
    assert kkt_check(inst, p, delta).kkt_error <= 1e-12
    fitted = kkt_check(inst, p)
    assert fitted.kkt_error <= 1e-12 and abs(fitted.multiplier - delta) <= 1e-9 * delta


@pytest.mark.parametrize("factor", [0.9, 1.1, 0.0, -1.0])
def test_a_wrong_delta_fails(solved, factor: float) -> None:
    inst, p, delta = solved
    rep = kkt_check(inst, p, factor * delta)
    assert rep.kkt_error > 1e-3 and not rep.passes(1e-6)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 1e308])
def test_a_non_finite_or_absurd_delta_fails(solved, bad: float) -> None:
    inst, p, _ = solved
    rep = kkt_check(inst, p, bad)
    assert not rep.passes(1e-6)
    if not math.isfinite(bad):
        assert rep.kkt_error == math.inf


def test_a_missed_load_fails_on_the_equality(solved) -> None:
    inst, p, delta = solved
    rep = kkt_check(inst, 1.01 * p, delta)
    assert rep.equality == pytest.approx(0.01, rel=1e-6) and not rep.passes(1e-6)
    zero = kkt_check(inst, np.zeros_like(p))  # p = 0 is primal-feasible for p >= 0, not for the load
    assert zero.equality == pytest.approx(1.0) and not zero.passes(1e-6)


@pytest.mark.parametrize("entry", [math.nan, math.inf, 1e308, -1e308])
def test_non_finite_or_huge_entries_fail(solved, entry: float) -> None:
    inst, p, delta = solved
    q = p.copy()
    q[int(np.argmax(q))] = entry
    rep = kkt_check(inst, q, delta)
    assert not rep.passes(1e-6)


def test_wrong_shape_is_refused(solved) -> None:
    inst, p, delta = solved
    with pytest.raises(ValueError, match="shape"):
        kkt_check(inst, p[:-1], delta)
    f = constrained_figures(p[:-1], np.zeros(p.size), inst.qp.ubar, 1.0, inst.qp.constraints, delta)
    assert f.kkt_error == math.inf


def test_fit_multiplier_refuses_non_finite_input() -> None:
    assert math.isnan(fit_multiplier(np.array([1.0, math.nan]), np.array([1.0, 1.0]), None))
    assert math.isnan(fit_multiplier(np.array([1.0, 2.0]), np.array([math.inf, 1.0]), None))
    assert fit_multiplier(np.array([1.0, 3.0]), np.array([1.0, 1.0]), None) == 2.0
    assert fit_multiplier(np.array([1.0, 3.0]), np.array([0.0, 0.0]), None) == 1.0  # no contact: where it begins


# ---------------------------------------------------------------------------
# Constraints, projection, files
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [dict(load=-1.0), dict(load=math.nan), dict(load=math.inf),
                                 dict(upper=np.array([1.0, math.nan])), dict(upper=np.array([1.0, 0.0])),
                                 dict(upper=np.array([1.0, 1.0]), load=3.0)])
def test_constraints_refuse_what_cannot_be_posed(bad) -> None:
    with pytest.raises(ProblemInputError):
        make_constraints(2, bad.get("upper"), bad.get("load"))


def test_projection_onto_box_and_load() -> None:
    rng = np.random.default_rng(0)
    for trial in range(300):
        n = int(rng.integers(1, 25))
        x = rng.normal(size=n) * float(rng.choice([1e-6, 1.0, 1e6]))
        u = np.where(rng.random(n) < 0.5, rng.random(n) * 2.0, np.inf) if trial % 3 else None
        cap = math.inf if u is None else float(np.sum(u))
        load = float(min(rng.random() * 3.0, cap))
        p = project_box_sum(x, u, load)
        ub = np.full(n, math.inf) if u is None else u
        assert np.all(p >= 0.0) and np.all(p <= ub)
        assert abs(float(np.sum(p)) - load) <= 1e-12 * max(1.0, load, float(np.sum(np.abs(x))))
        free = (p > 0.0) & (p < ub)  # optimality: x - p is one shift on the free points
        if np.count_nonzero(free) > 1:
            assert np.ptp((x - p)[free]) <= 1e-9 * max(1.0, float(np.max(np.abs(x))))
        tau = float(np.mean((x - p)[free])) if np.any(free) else None
        if tau is not None:  # and the bounded points sit on the right side of it
            assert np.all(x[p <= 0.0] - tau <= 1e-9 * max(1.0, float(np.max(np.abs(x)))))


def test_plain_instances_are_unchanged() -> None:
    b = builder(12)
    d = paper_max_displacement(b.surface)
    a, c = b.build(d), b.build(d, hardness=math.inf)
    assert c.qp.constraints.plain and a.qp.constraints.plain
    assert np.array_equal(a.qp.ubar, c.qp.ubar)
    p = exact_solution(a.qp.H.H, a.qp.ubar).p
    assert kkt_check(a, p) == kkt_check(c, p)


def test_the_qp_file_carries_bounds_and_load(tmp_path: Path) -> None:
    b = builder(8)
    inst = b.build_load(2e-3, hardness=5e7)
    d = write_problem_dir(inst, tmp_path / "qp", tol=1e-8, time_limit=None)
    back = read_problem_dir(d)
    assert '"format": "' + FORMAT_CONSTRAINED in (d / "problem.json").read_text()
    c = back.qp().constraints
    assert c.load == inst.qp.constraints.load
    assert np.array_equal(c.upper, inst.qp.constraints.upper)
    assert np.array_equal(back.ubar, inst.qp.ubar)
    plain = write_problem_dir(b.build(1e-7), tmp_path / "plain", tol=1e-8, time_limit=None)
    assert '"format": "' + FORMAT in (plain / "problem.json").read_text()
    assert read_problem_dir(plain).qp().constraints.plain


def test_the_qpbenchmark_row_carries_bounds_and_load(tmp_path: Path) -> None:
    from contactbench.problems.export import QPBENCHMARK_KEYS, append_qpbenchmark_row, write_parquet

    b = builder(8)
    inst = b.build_load(2e-3, hardness=5e7)
    rows: dict = {k: [] for k in QPBENCHMARK_KEYS}
    append_qpbenchmark_row(rows, "lc", inst)
    path = write_parquet(rows, tmp_path / "set.parquet")
    P, q, lb = read_qpbenchmark_row(path, "lc")
    ub, A, bb = read_qpbenchmark_constraints(path, "lc")
    assert np.array_equal(q, -inst.qp.ubar) and np.array_equal(lb, np.zeros(inst.n))
    assert np.array_equal(ub, inst.qp.constraints.upper)
    assert A.shape == (1, inst.n) and np.all(A == 1.0) and bb.tolist() == [inst.qp.constraints.load]
    assert Constraints().plain


@pytest.mark.parametrize("name", ["cm-pk-ccg", "tamaas-pkr"])
def test_peers_in_their_native_load_control(name: str) -> None:
    """The field's codes under their own load control (ContactMechanics' external_force,
    Tamaas' pressure-controlled PolonskyKeerRey) on the non-periodic Love kernel both share."""
    solver = get_solver(name)
    ok, why = solver.availability()
    if not ok:
        pytest.skip(why)
    b = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=4), E, kernel="love", operator="dense")
    d = 0.6 * paper_max_displacement(b.surface)
    el = b.build(d)
    inst = b.build_load(float(np.sum(exact_solution(el.qp.H.H, el.qp.ubar).p)))
    ref = constrained_exact_solution(inst.qp.H.H, inst.qp.ubar, inst.qp.constraints)
    r = solver.solve(inst.qp, SolverSettings(tol=1e-8, max_iter=5000, time_limit=60.0))
    rep = kkt_check(inst, r.p, r.multiplier)
    assert r.converged and rep.kkt_error <= 1e-7, (name, rep.kkt_error)
    assert np.max(np.abs(r.p - ref.p)) <= 1e-6 * np.max(ref.p)
    assert abs(r.multiplier - d) <= 1e-6 * d


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=12), st.floats(-1e3, 1e3), st.floats(0.0, 1e4),
       st.sampled_from([1e-9, 1.0, 1e6]))
def test_a_load_equality_alone_gives_the_general_figures(values: list[float], delta: float, load: float,
                                                         scale: float) -> None:
    """A load equality with no upper bound takes a shorter path through the figures
    (``kkt._load_figures``); it must give the general path's figures (upper = inf given
    explicitly) to the last digits, negative forces, NaN-free extremes and all."""
    p = np.asarray(values) * scale
    g = np.roll(p, 1) - 0.5 * scale
    ubar = np.linspace(0.0, 1.0, p.size)  # (u_s: the approach, max ubar = 1) * scale
    short = constrained_figures(p, g, ubar, 2.0, Constraints(None, load), delta)
    general = constrained_figures(p, g, ubar, 2.0, Constraints(np.full(p.size, np.inf), load), delta)
    for a, b in zip(astuple(short), astuple(general)):
        assert a == pytest.approx(b, rel=1e-14, abs=0.0) or (math.isnan(a) and math.isnan(b)), (short, general)


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.lists(st.floats(0.0, 3.0), min_size=2, max_size=10), st.floats(-1e-14, 1e-14), st.sampled_from([1e2, 1e6, 1e12]))
def test_a_bound_far_above_every_force_is_judged_as_no_bound(forces: list[float], noise: float, far: float) -> None:
    """Round-off in w on the free set, times a bound a million times the forces, read as a
    complementarity violation of 1e-8 and more (a load of 1e-6 of what the box carries: bvls
    could not certify its exact answer).  The upper product's slack is capped at the force
    scale, so a far bound gives the unbounded figures' reading of the same w, never more."""
    p = np.asarray(forces)
    ubar = np.linspace(0.0, 1.0, p.size)  # (u_s: the approach, max ubar = 1)
    g = np.where(np.arange(p.size) % 2 == 0, noise, -noise)  # w = g: round-off on every element
    free = constrained_figures(p, g, ubar, 1.0, Constraints(np.full(p.size, np.inf), None))
    boxed = constrained_figures(p, g, ubar, 1.0, Constraints(np.full(p.size, far * (1.0 + float(np.max(p)))), None))
    assert boxed.kkt_error <= free.kkt_error + 1e-300 and boxed.kkt_error <= 1e-13


@pytest.mark.parametrize("far", [1e2, 1e6])
def test_a_negative_gap_far_below_its_bound_is_still_read_in_full(far: float) -> None:
    """The cap cannot hide a violation: w = -1e-3 u_s on an element far below its bound is
    the dual figure's 1e-3, as without the bound."""
    p = np.array([1.0, 0.5, 0.0])
    ubar = np.array([-1.0, -0.5, 0.0])
    g = np.array([-1e-3, 0.0, 0.5])  # u_s = max |ubar| = 1
    free = constrained_figures(p, g, ubar, 1.0, Constraints(np.full(3, np.inf), None))
    boxed = constrained_figures(p, g, ubar, 1.0, Constraints(np.full(3, far), None))
    assert boxed.kkt_error == pytest.approx(1e-3 / boxed.u_scale, rel=1e-9)
    assert free.kkt_error >= boxed.kkt_error


@pytest.mark.parametrize("eps", [1e-4, 1e-6])
def test_a_gap_of_the_allowed_sign_near_either_bound_reads_as_its_product(eps: float) -> None:
    """Mirror images read alike: an element eps p_s above 0 with w = +eps u_s (an interior-
    point answer near p = 0), and one eps p_s below its bound with w = -eps u_s, both read
    eps^2, the product; the natural residual min(-w / u_s, (u - p) / p_s) had read the
    second eps (interior-point solvers' plastic answers at kkt 3e-4 for products of 6e-7)."""
    ubar = np.array([1.0, 0.5, 0.0])  # u_s = max ubar = 1 and, with diag 1 and u = 5, p_s = 1
    c = Constraints(np.full(3, 5.0), None)
    lower = constrained_figures(np.array([eps, 2.0, 3.0]), np.array([eps, 0.0, 0.0]), ubar, 1.0, c)
    upper = constrained_figures(np.array([5.0 - eps, 2.0, 3.0]), np.array([-eps, 0.0, 0.0]), ubar, 1.0, c)
    assert (lower.u_scale, lower.p_scale) == (1.0, 1.0)
    assert lower.kkt_error == pytest.approx(eps * eps, rel=1e-6)
    assert upper.kkt_error == pytest.approx(lower.kkt_error, rel=1e-6)
    # the wrong sign near either bound is read in full: w < 0 near 0, w > 0 near u
    assert constrained_figures(np.array([eps, 2.0, 3.0]), np.array([-1e-3, 0.0, 0.0]), ubar, 1.0, c).kkt_error >= 1e-3
    assert constrained_figures(np.array([5.0 - eps, 2.0, 3.0]), np.array([1e-3, 0.0, 0.0]), ubar, 1.0,
                               c).kkt_error >= 1e-3
