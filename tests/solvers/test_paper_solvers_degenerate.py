"""The paper's solvers, the references and the QP adapters on degenerate steps: drawn at
the knife edges (gaps exactly 0 or a few ulps either side of it, a box that carries the
load exactly or a few ulps more, a hardness at the elastic answer's peak, a single
element) and perturbed by a few ulps (``np.nextafter``), every solver returns -- never
raises, never NaN -- with a status from ``Status``, and a claim of convergence by a
solver that is not known to fail there (``Solver.refuted_on``) meets the check.

And pk under load control near saturation: a box that carries 99 % ... 100 % of the
imposed load (nearly every element plastic) is solved to the tolerance."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from contactbench.problems.constraints import Constraints
from contactbench.problems.instances import QP, InstanceBuilder, counterexample, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import fourier_synthesis, rmd_surface_n
from contactbench.solvers._kit import stagnation_window, conjugate_gradient
from contactbench.solvers.base import ProblemTraits, SolverSettings, Status
from contactbench.solvers.registry import available_solvers, get_solver

PAPER = ("pk", "greedy-cg", "greedy-gs", "greedy-chol", "gp", "nnls", "nnls-gp", "admm")
REFERENCES = ("scipy-nnls", "bvls")
QP_ADAPTERS = tuple(sorted(n for n, s in available_solvers().items() if s.family == "qp" or n == "cvxpy"))
SOLVERS = tuple(n for n in PAPER + REFERENCES + QP_ADAPTERS if n in available_solvers())
STATUSES = {s.value for s in Status}
#: The scaled KKT error a claim is held to here: every solver's default tolerance or the
#: ``default`` profile's check, whichever is looser.
CLAIM = 1e-6
#: Each solve's time limit (s): the drawn problems have at most 16 unknowns.
TIME_LIMIT = 2.0


def ulps(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """x moved by k[i] ulps (toward +inf for k > 0, -inf for k < 0), element by element."""
    out = np.array(x, dtype=np.float64, copy=True)
    for i, steps in enumerate(np.asarray(k, dtype=int)):
        for _ in range(abs(int(steps))):
            out[i] = np.nextafter(out[i], math.copysign(math.inf, steps))
    return out


@st.composite
def knife_edge_qp(draw: st.DrawFn) -> QP:
    """A BCC dense H on an N x N grid (N = 1..4: n = 1..16) and a gap vector whose
    entries are exactly 0, a few ulps either side of 0, or U(0, 1); then, by the draw,
    no constraint, a box at the elastic answer's peak (a few ulps off), a load, or a box
    that carries the load exactly (or a few ulps less than its capacity)."""
    N = draw(st.integers(1, 4))
    n = N * N
    H = counterexample(max(n, 4), 0).qp.H.to_dense()[:n, :n] if n < 4 else counterexample(n, 0).qp.H.to_dense()
    kinds = draw(st.lists(st.sampled_from(("zero", "ulp", "uniform")), min_size=n, max_size=n))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    ubar = np.where(np.array(kinds) == "uniform", rng.random(n), 0.0)
    ubar = ulps(ubar, np.where(np.array(kinds) == "ulp", rng.integers(-3, 4, n), 0))
    ubar[draw(st.integers(0, n - 1))] = max(float(ubar.max()), 1e-3) if draw(st.booleans()) else ubar.max()
    ubar = ulps(ubar, rng.integers(-2, 3, n))  # a few ulps of noise everywhere
    kind = draw(st.sampled_from(("plain", "box", "load", "box+load")))
    p_el = exact_solution(H, np.maximum(ubar, 0.0)).p if np.any(ubar > 0) else np.zeros(n)
    peak = float(np.max(p_el)) if np.any(p_el > 0) else 1.0 / float(np.max(np.diag(H)))
    upper = load = None
    if kind in ("box", "box+load"):
        upper = ulps(np.full(n, peak * draw(st.sampled_from((1.0, 0.5, 1e-3)))), rng.integers(-2, 3, n))
    if kind == "load":
        load = float(np.sum(p_el)) * draw(st.sampled_from((1.0, 0.5, 2.0))) or peak
    if kind == "box+load":
        cap = float(np.sum(upper))
        load = draw(st.sampled_from((cap, float(np.nextafter(cap, 0.0)), 0.99 * cap, 0.9999 * cap, 0.5 * cap)))
    return QP(DenseOperator(H), ubar, None, Constraints(upper, load))


def poses(name: str, qp: QP) -> bool:
    caps = get_solver(name).capabilities
    c = qp.constraints
    return (caps.load_control or not c.load_control) and (caps.bounds or not c.bounded)


def assert_ends_honestly(name: str, qp: QP) -> None:
    """The property (module doc) for one solver on one problem."""
    solver = get_solver(name)
    r = solver.solve(qp, SolverSettings(time_limit=TIME_LIMIT, check_tol=CLAIM))  # the check, as the harness hands it
    assert r.status in STATUSES, (name, r.status)
    if r.status == Status.FAILED.value:
        assert r.message, name
        return
    assert np.all(np.isfinite(r.p)), (name, r.status, r.message)
    if name not in QP_ADAPTERS:  # they project (an adapter's backend may leave round-off outside the box)
        assert np.all(r.p >= 0.0), name
        if qp.constraints.bounded:
            assert np.all(r.p <= qp.constraints.upper), name
    if qp.constraints.load_control:
        assert r.multiplier is not None and math.isfinite(r.multiplier), (name, r.message)
    if r.converged and not solver.refuted_on:
        kkt = kkt_check(qp, r.p, r.multiplier).kkt_error
        assert kkt <= CLAIM, (name, kkt, r.message)
    if not r.converged:
        assert r.message, name


@pytest.mark.parametrize("name", [n for n in PAPER + REFERENCES if n in SOLVERS])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(qp=knife_edge_qp())
def test_a_knife_edge_problem_ends_with_an_answer_and_an_honest_status(name: str, qp: QP) -> None:
    if poses(name, qp):
        assert_ends_honestly(name, qp)


@pytest.mark.parametrize("name", QP_ADAPTERS)
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(qp=knife_edge_qp())
def test_a_qp_adapter_on_a_knife_edge_problem_ends_with_an_answer(name: str, qp: QP) -> None:
    """As above for the generic QP adapters (fewer draws: a backend call costs more)."""
    if poses(name, qp):
        assert_ends_honestly(name, qp)


@pytest.mark.parametrize("name", SOLVERS)
def test_a_single_element_and_an_all_zero_gap(name: str) -> None:
    """n = 1 (every set empty or full at once) and ubar = 0 under a load: ends honestly."""
    H = counterexample(4, 0).qp.H.to_dense()[:1, :1]
    for ubar, c in ((np.array([1.0]), Constraints()), (np.array([np.nextafter(0.0, 1.0)]), Constraints()),
                    (np.zeros(1), Constraints(None, 1.0)), (np.ones(1), Constraints(np.ones(1), 1.0))):
        qp = QP(DenseOperator(H), ubar, None, c)
        if poses(name, qp):
            assert_ends_honestly(name, qp)


# ---------------------------------------------------------------------------
# pk near saturation
# ---------------------------------------------------------------------------

SHARES = (0.99, 0.999, 0.9999, 1.0)


@pytest.mark.parametrize("periodic", [False, True])
@pytest.mark.parametrize("share", SHARES)
def test_pk_solves_a_load_the_box_nearly_saturates(share: float, periodic: bool) -> None:
    """32^2 rough surface under load control, the whole grid the trial set, a hardness
    whose box carries the load at ``share`` of its capacity, P = share x sum(u) (at 100 %
    exactly sum(u): every element plastic): pk converges to its tolerance."""
    surf = rmd_surface_n(32, 0.7, seed=1)
    b = InstanceBuilder(surf, 1e9, operator="fft", periodic=periodic)
    area = float(np.prod(surf.spacing)) * surf.heights.size
    hardness = 0.05 * 1e9 * float(np.std(surf.heights)) / surf.delta  # a few % of E x rms slope
    capacity = float(np.sum(b.build_load(0.0, hardness=hardness).qp.constraints.upper))
    assert capacity == pytest.approx(hardness * area)
    inst = b.build_load(share * capacity, hardness=hardness)
    r = get_solver("pk").solve(inst.qp, SolverSettings(tol=1e-10, max_iter=500))
    assert r.status == "converged", r.message
    assert kkt_check(inst, r.p, r.multiplier).kkt_error <= 1e-10
    assert kkt_check(inst, r.p).kkt_error <= 1e-9  # the judge's own Delta, fitted from p


@pytest.mark.parametrize("share", (0.9, 0.99))
def test_pk_does_not_stop_when_one_free_point_is_left(share: float) -> None:
    """A hardness at 0.3 of the elastic peak on a 62-point trial set: the first step
    saturates all but one point, whose gap is Delta itself (a zero direction on the free
    set).  pk widens the set by the plastic points that want to shed force and converges
    (it stopped after 1 iteration, reported as max_iter)."""
    b = InstanceBuilder(fourier_synthesis(32, 0.8, 0.1, length=1e-4, seed=3), 1e9, operator="fft")
    inst = b.build(paper_max_displacement(b.surface))
    p_el = exact_solution(inst.qp.H.to_dense(), inst.qp.ubar).p
    u = np.full(inst.n, 0.3 * float(np.max(p_el)))
    qp = QP(inst.qp.H, inst.qp.ubar, inst.qp.geometry, Constraints(u, share * float(np.sum(u))))
    r = get_solver("pk").solve(qp, SolverSettings(tol=1e-10))
    assert r.status == "converged", r.message
    assert kkt_check(qp, r.p, r.multiplier).kkt_error <= 1e-10


@pytest.mark.parametrize("name", PAPER + REFERENCES)
@pytest.mark.parametrize("off", [1.0, np.nextafter(1.0, 0.0), 2.0], ids=["singular", "singular-less-1ulp", "indefinite"])
def test_no_curvature_or_negative_curvature_ends_with_a_status(name: str, off: float) -> None:
    """H = [[1, off], [off, 1]]: singular (a direction of zero curvature), an ulp from
    it, or indefinite (negative curvature), with each constraint kind.  No solver
    raises; a claim of convergence meets the check; a non-finite answer says "failed"."""
    H = np.array([[1.0, off], [off, 1.0]])
    kinds = (Constraints(), Constraints(np.full(2, 0.3)), Constraints(None, 0.5), Constraints(np.full(2, 0.3), 0.6))
    for c in kinds:
        qp = QP(DenseOperator(H), np.array([1.0, 0.5]), None, c)
        if not poses(name, qp):
            continue
        r = get_solver(name).solve(qp, SolverSettings(time_limit=0.5, check_tol=CLAIM))
        assert r.status in STATUSES and r.message, (name, c)
        assert np.all(np.isfinite(r.p)) or r.status == Status.FAILED.value, (name, c, r.status)
        if r.converged and not get_solver(name).refuted_on:
            assert kkt_check(qp, r.p, r.multiplier).kkt_error <= CLAIM, (name, c, r.message)


def test_cg_stops_where_its_residual_stops_halving_and_still_finishes_a_slow_system() -> None:
    """``_kit.conjugate_gradient`` (greedy-cg's passes, nnls's and fast-pdas's solves): on a
    periodic ring's H (H 1 = 0) lifted by 1e-13 along 1, positive definite but past what
    float64 resolves, it stops unconverged within ``stagnation_window(n)`` iterations of
    its last halving (it ran all 100,000 before, as greedy-cg did on a periodic whole grid);
    a slow, well-posed system (a 1-D Laplacian, condition ~ n^2) still converges."""
    n = 64
    ring = 2.0 * np.eye(n) - np.roll(np.eye(n), 1, axis=1) - np.roll(np.eye(n), -1, axis=1)
    b = np.ones(n) + np.linspace(0.0, 1.0, n)
    lifted = ring + 1e-13 * np.ones((n, n)) / n
    r = conjugate_gradient(DenseOperator(lifted), b, None, 1e-12, 100_000)
    assert not r.converged and r.iterations <= 4 * stagnation_window(n), r.iterations
    laplacian = ring.copy()
    laplacian[0, -1] = laplacian[-1, 0] = 0.0
    slow = conjugate_gradient(DenseOperator(laplacian), b, None, 1e-10, 100_000)
    assert slow.converged and np.max(np.abs(laplacian @ slow.x - b)) <= 1e-10


@pytest.mark.parametrize("name", ["greedy-cg", "greedy-chol"])
def test_greedy_ends_stalled_on_a_periodic_whole_grid(name: str) -> None:
    """The first pass takes a periodic 16 x 16 grid whole, whose H is singular (ubar off its
    range): greedy-cg's CG stops at its stagnation window, and greedy-chol's Cholesky, which
    round-off lets through, leaves a residual it now checks -- it had claimed convergence
    there at a scaled KKT error of 0.63 (forces of 1e14, none negative)."""
    b = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=1), 1e9,
                        "spectral", periodic=True, operator="dense")
    h = b.surface.heights
    inst = b.build(0.5 * float(np.max(h) - np.mean(h)))
    r = get_solver(name).solve(inst.qp)
    assert not r.converged and r.status == "stalled", (r.status, r.message)
    assert r.iterations <= 20 * stagnation_window(inst.n)


@pytest.mark.parametrize("name", ["greedy-cg", "greedy-gs", "greedy-chol"])
def test_greedy_declines_a_periodic_whole_grid_and_nothing_else(name: str) -> None:
    """Its first pass on a periodic whole grid is H p = ubar with H 1 = 0: the harness skips
    it with that reason (greedy-gs ran to its time limit there); a part of a periodic grid,
    or the whole of a non-periodic one, it still poses."""
    s = get_solver(name)
    whole = ProblemTraits(n=32 * 32, operator="dense", has_surface=True, surface_side=32, periodic=True,
                          whole_periodic_grid=True)
    assert "singular" in (s.skip(whole) or "")
    assert s.skip(dataclasses.replace(whole, n=300, whole_periodic_grid=False)) is None
    assert s.skip(dataclasses.replace(whole, periodic=False, whole_periodic_grid=False)) is None


def test_the_traits_tell_a_whole_periodic_grid_of_any_shape() -> None:
    """``problem_traits`` marks a periodic problem whose trial set is its whole grid, square
    or not (a 24 x 16 map has no ``surface_side``; greedy-cg ran on its singular H before),
    and nothing else."""
    from contactbench.harness.run.worker import problem_traits
    from contactbench.problems.surfaces import Surface

    h = rmd_surface_n(32, 0.7, length=100e-6, seed=1).heights
    for shape in ((32, 32), (24, 16)):
        s = Surface(np.array(h[: shape[0], : shape[1]]), 100e-6 / 32)
        d = 0.5 * float(np.max(s.heights) - np.mean(s.heights))
        periodic = InstanceBuilder(s, 1e9, "spectral", periodic=True).build(d)
        assert periodic.n == shape[0] * shape[1] and problem_traits(periodic).whole_periodic_grid
        assert "singular" in (get_solver("greedy-cg").skip(problem_traits(periodic)) or "")
        plain = InstanceBuilder(s, 1e9, "bcc").build(d)
        assert not problem_traits(plain).whole_periodic_grid


def test_bvls_solves_a_periodic_whole_grid_on_a_proper_subset_where_its_cholesky_fails(monkeypatch) -> None:
    """On a periodic whole grid H 1 = 0, and whether the whole problem's Cholesky passes is
    round-off (a 64 x 48 map failed it: "failed", p all NaN).  Made to fail here, bvls
    solves on a growing proper subset instead (``reference.on_a_subset``) and certifies."""
    from contactbench.harness.judging import judge
    from contactbench.solvers import reference

    s = rmd_surface_n(32, 0.7, length=100e-6, seed=3, family="periodic")
    inst = InstanceBuilder(s, 1e9, "spectral", periodic=True).build(
        0.5 * float(np.max(s.heights) - np.mean(s.heights)))
    assert inst.n == 32 * 32

    def not_spd(H: np.ndarray, ubar: np.ndarray) -> None:
        raise np.linalg.LinAlgError("H is not positive definite (Cholesky failed)")

    monkeypatch.setattr(reference, "exact_solution", not_spd)
    r = get_solver("bvls").solve(inst.qp, SolverSettings())
    assert r.status == "converged" and "proper subset" in r.message and r.info["subset_size"] < inst.n
    assert judge(inst, r.p, True, 1e-10).status == "solved"


def test_bvls_solves_a_bounded_periodic_whole_grid_on_a_proper_subset_where_its_cholesky_fails(monkeypatch) -> None:
    """The same under a hardness (the constrained path): a 77 x 48 periodic Love map with a
    hardness failed every step ("failed", p all NaN).  Made to fail here on the whole
    problem, bvls solves the bounded problem on a growing proper subset
    (``mixed_lcp.constrained_solution_on_subset``) and certifies, the hardness binding."""
    from contactbench.harness.judging import judge
    from contactbench.solvers import reference

    s = rmd_surface_n(32, 0.7, length=100e-6, seed=3, family="periodic")
    hardness = 2e7
    inst = InstanceBuilder(s, 1e9, "spectral", periodic=True).build(
        0.5 * float(np.max(s.heights) - np.mean(s.heights)), hardness=hardness)
    whole = inst.n

    def not_spd(H: np.ndarray, ubar: np.ndarray, constraints: object, tol: float = 0.0) -> None:
        assert ubar.size == whole  # only the whole problem's solve is made to fail
        raise np.linalg.LinAlgError("H is not positive definite (Cholesky failed)")

    monkeypatch.setattr(reference, "constrained_exact_solution", not_spd)
    r = get_solver("bvls").solve(inst.qp, SolverSettings())
    assert r.status == "converged" and "proper subset" in r.message and r.info["subset_size"] < inst.n
    assert judge(inst, r.p, True, 1e-10).status == "solved"
    bound = inst.qp.constraints.upper_or_inf(inst.n)
    assert int(np.sum(np.isclose(r.p, bound, rtol=1e-9))) > 0  # the hardness carries some elements
