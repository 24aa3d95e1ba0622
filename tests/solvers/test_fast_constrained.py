"""The fast CCGs under a hardness (0 <= p <= u) and load control (sum p = P): each solver
that claims a family meets the exact reference (``problems.mixed_lcp``: BVLS with the
multiplier) on a plastic case, a load-controlled case, both together and a rectangular
grid with unequal spacings; the limits (infinite and tiny hardness) hold; a warm start
along a history pays; the inputs that cannot be posed are refused, a load the box
barely carries ends with an answer, never NaN, and a box that carries 99 % to 100 % of
the load is solved to the judge's tolerance."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.constraints import Constraints, make_constraints
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.surfaces import Surface, fourier_synthesis
from contactbench.solvers._preconditioners import MIXED_GRID_POINTS
from contactbench.solvers._refine import resolved_precision
from contactbench.solvers._constrained import winkler_start
from contactbench.solvers.base import SolveContext, SolverSettings, WarmStart
from tests.helpers import loop_context
from contactbench.solvers.registry import available_solvers, get_solver

E = 1e9
FAST = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg")
LOAD = FAST  # every fast CCG poses the load equality too
TIGHT = SolverSettings(tol=1e-12)


def test_the_claims() -> None:
    """What each fast CCG claims (a silently dropped claim would skip the tests below)."""
    solvers = available_solvers()
    assert {n for n in FAST if solvers[n].capabilities.bounds} == set(FAST)
    assert {n for n in FAST if solvers[n].capabilities.load_control} == set(LOAD)


def reference(inst) -> tuple[np.ndarray, float | None]:
    qp = inst.qp
    ref = constrained_exact_solution(qp.H.to_dense(), qp.ubar, qp.constraints)
    assert ref.kkt_error <= 1e-12
    return ref.p, ref.multiplier if qp.constraints.load_control else None


def assert_meets(name: str, inst, p_ref: np.ndarray, delta_ref: float | None, **params) -> object:
    r = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-12, params=params or None))
    assert r.status == "converged", (name, r.message)
    assert np.max(np.abs(r.p - p_ref)) <= 1e-8 * np.max(p_ref), name
    if delta_ref is not None:
        assert abs(r.multiplier - delta_ref) <= 1e-6 * abs(delta_ref), (name, r.multiplier, delta_ref)
    assert kkt_check(inst, r.p, r.multiplier).kkt_error <= 1e-10, name
    assert kkt_check(inst, r.p).kkt_error <= 1e-10, name  # the judge's own Delta, fitted from p
    return r


@pytest.fixture(scope="module")
def square() -> tuple[InstanceBuilder, float, np.ndarray]:
    """A 32 x 32 rough surface (FFT operator) at the paper's top step, and its elastic p."""
    b = InstanceBuilder(fourier_synthesis(32, 0.8, 0.1, length=1e-4, seed=3), E, operator="fft")
    d = paper_max_displacement(b.surface)
    inst = b.build(d)
    return b, d, exact_solution(inst.qp.H.to_dense(), inst.qp.ubar).p


def on_grid(inst, p: np.ndarray) -> np.ndarray:
    """p of ``inst`` on the whole grid (0 off its trial set)."""
    out = np.zeros(int(np.prod(inst.qp.geometry.grid_shape)))
    out[inst.qp.geometry.indices] = p
    return out


def carried(p: np.ndarray, source, target) -> np.ndarray:
    """p of instance ``source`` as a warm start of instance ``target`` (through the grid)."""
    return on_grid(source, p)[target.qp.geometry.indices]


def hardness_of(b: InstanceBuilder, p_el: np.ndarray, share: float) -> float:
    return share * float(np.max(p_el)) / float(np.prod(b.surface.spacing))


Case = tuple[object, np.ndarray, "float | None"]  # (instance, exact p, exact Delta)


@pytest.fixture(scope="module")
def plastic(square) -> Case:
    b, d, p_el = square
    inst = b.build(d, hardness=hardness_of(b, p_el, 0.4))
    return (inst, *reference(inst))


@pytest.fixture(scope="module")
def loaded(square) -> Case:
    b, d, p_el = square
    inst = b.build_load(float(np.sum(p_el)))
    return (inst, *reference(inst))


@pytest.fixture(scope="module")
def loaded_plastic(square) -> Case:
    b, d, p_el = square
    near = b.build(2.0 * d).qp.geometry.indices  # the points near contact: a small reference
    inst = b.build_load(float(np.sum(p_el)), candidates=near, hardness=hardness_of(b, p_el, 0.5))
    return (inst, *reference(inst))


@pytest.mark.parametrize("name", FAST)
def test_a_hardness_with_a_plastic_share(plastic, name: str) -> None:
    inst, p_ref, _ = plastic
    assert 0.1 <= inst.plastic_fraction(p_ref) <= 0.4
    assert_meets(name, inst, p_ref, None)


@pytest.mark.parametrize("name", LOAD)
def test_load_control_is_the_displacement_answer(square, loaded, name: str) -> None:
    b, d, p_el = square
    inst, p_ref, delta_ref = loaded
    r = assert_meets(name, inst, p_ref, delta_ref)
    p_disp = carried(p_el, b.build(d), inst)
    assert np.max(np.abs(r.p - p_disp)) <= 1e-8 * np.max(p_el)  # the displacement-controlled answer ...
    assert abs(r.multiplier - d) <= 1e-6 * d  # ... at the approach that carried that load


@pytest.mark.parametrize("name", LOAD)
def test_load_control_with_a_hardness(square, loaded_plastic, name: str) -> None:
    _, d, _ = square
    inst, p_ref, delta_ref = loaded_plastic
    assert inst.plastic_fraction(p_ref) > 0.05
    assert delta_ref > d  # softer contact: deeper approach for the same load
    assert_meets(name, inst, p_ref, delta_ref)


@pytest.fixture(scope="module")
def rectangle() -> InstanceBuilder:
    """48 x 32 elements with spacings 1 : 1.5 (Love's rectangular kernel, FFT operator)."""
    sq = fourier_synthesis(48, 0.8, 0.1, length=1e-4, seed=5)
    s = Surface(np.array(sq.heights[:, :32]), sq.delta, delta1=1.5 * sq.delta, name="rect")
    return InstanceBuilder(s, E, "love", operator="fft")


@pytest.fixture(scope="module")
def rectangular_cases(rectangle) -> dict[str, Case]:
    """The rectangle under a hardness, displacement- and load-controlled (the latter on the
    rigid-body set at twice the approach, which holds the contact)."""
    b = rectangle
    d = paper_max_displacement(b.surface)
    plain = b.build(d)
    p_el = exact_solution(plain.qp.H.to_dense(), plain.qp.ubar).p
    H_A = hardness_of(b, p_el, 0.5)
    near = b.build(2.0 * d).qp.geometry.indices  # the load case on the points near contact: a small reference
    cases = {"hardness": b.build(d, hardness=H_A),
             "load+hardness": b.build_load(float(np.sum(p_el)), candidates=near, hardness=H_A)}
    return {k: (inst, *reference(inst)) for k, inst in cases.items()}


@pytest.mark.parametrize("name", FAST)
def test_a_rectangular_grid_with_unequal_spacings(rectangular_cases, name: str) -> None:
    for family, (inst, p_ref, delta_ref) in rectangular_cases.items():
        if family == "load+hardness" and name not in LOAD:
            continue
        assert inst.qp.geometry.grid_shape == (48, 32)
        assert inst.plastic_fraction(p_ref) > 0.0
        assert_meets(name, inst, p_ref, delta_ref)


@pytest.mark.parametrize("name", FAST)
def test_mixed_precision_poses_the_constraints_in_its_float32_rounds(plastic, loaded, loaded_plastic,
                                                                      name: str) -> None:
    """float32 rounds under a hardness, a load and both, refined in float64: the double
    path's answer and multiplier to the same tolerance."""
    for inst, p_ref, delta_ref in (plastic, loaded, loaded_plastic):
        r = assert_meets(name, inst, p_ref, delta_ref, precision="mixed")
        assert r.info["precision"] == "mixed" and r.info["matvecs_float32"] > 0, r.info


@pytest.mark.parametrize("name", FAST)
def test_the_coarse_first_guess_under_a_hardness_on_a_grid_too_small_starts_from_zero(plastic, name: str) -> None:
    inst, p_ref, _ = plastic
    r = assert_meets(name, inst, p_ref, None, first_guess="coarse")
    assert r.info["first_guess"].startswith("no coarse level (no surface, or grid below")
    assert r.info["coarse_matvecs"] == 0


@pytest.mark.parametrize("name", FAST)
def test_infinite_and_unreached_hardness_give_the_elastic_answer(square, name: str) -> None:
    b, d, p_el = square
    inst = b.build(d, hardness=math.inf)
    assert inst.qp.constraints.plain
    plain = get_solver(name).solve(b.build(d).qp, TIGHT)
    r = get_solver(name).solve(inst.qp, TIGHT)
    assert np.array_equal(r.p, plain.p) and r.iterations == plain.iterations  # the plain path, untouched
    high = b.build(d, hardness=hardness_of(b, p_el, 10.0))
    assert high.qp.constraints.bounded
    r = get_solver(name).solve(high.qp, TIGHT)
    assert r.status == "converged", r.message
    assert np.max(np.abs(r.p - p_el)) <= 1e-8 * np.max(p_el)
    assert high.plastic_fraction(r.p) == 0.0


@pytest.mark.parametrize("name", FAST)
def test_a_tiny_hardness_puts_the_bound_on_the_contact_set(square, name: str) -> None:
    b, d, p_el = square
    inst = b.build(d, hardness=hardness_of(b, p_el, 1e-6))
    u = inst.qp.constraints.upper
    r = get_solver(name).solve(inst.qp, TIGHT)
    assert r.status == "converged", r.message
    touching = inst.contact_mask(r.p)
    assert touching.sum() > 0
    assert np.all(r.p[touching] == u[touching])
    assert np.all(touching == (inst.qp.ubar > 0.0))  # the rigid-body overlap, nearly unloaded


@pytest.mark.parametrize("name", LOAD)
def test_a_warm_start_along_a_load_history(square, name: str) -> None:
    b, d, p_el = square
    H_A = hardness_of(b, p_el, 0.5)
    steps = [b.build_load(f * float(np.sum(p_el)), hardness=H_A) for f in (0.9, 1.0)]
    first = get_solver(name).solve(steps[0].qp, TIGHT)
    cold = get_solver(name).solve(steps[1].qp, TIGHT)
    warm = get_solver(name).solve(steps[1].qp, TIGHT, warm=WarmStart(p=carried(first.p, steps[0], steps[1])))
    assert first.status == cold.status == warm.status == "converged"
    assert warm.warm_started
    assert np.max(np.abs(warm.p - cold.p)) <= 1e-8 * np.max(cold.p)
    assert warm.iterations < cold.iterations and warm.matvecs < cold.matvecs, (warm.iterations, cold.iterations)


@pytest.mark.parametrize("name", FAST)
def test_a_warm_start_along_a_displacement_history_with_a_hardness(square, name: str) -> None:
    b, d, p_el = square
    H_A = hardness_of(b, p_el, 0.4)
    before = b.build(0.9 * d, hardness=H_A)
    first = get_solver(name).solve(before.qp, TIGHT)
    inst = b.build(d, hardness=H_A)
    cold = get_solver(name).solve(inst.qp, TIGHT)
    warm = get_solver(name).solve(inst.qp, TIGHT, warm=WarmStart(p=carried(first.p, before, inst)))
    assert cold.status == warm.status == "converged"
    assert np.max(np.abs(warm.p - cold.p)) <= 1e-8 * np.max(cold.p)
    # 15-26 iterations cold on this grid: the warm start may not save one, but never costs one
    assert warm.iterations <= cold.iterations, (warm.iterations, cold.iterations)


# ---------------------------------------------------------------------------
# What cannot be posed, and the edge of what can
# ---------------------------------------------------------------------------


def qp_with(inst, constraints: Constraints) -> QP:
    qp = inst.qp
    return QP(qp.H, qp.ubar, qp.geometry, constraints)


@pytest.mark.parametrize("bad", [math.nan, -1.0, 0.0])
@pytest.mark.parametrize("name", FAST)
def test_a_bound_that_is_nan_or_not_positive_is_refused(square, name: str, bad: float) -> None:
    b, d, _ = square
    inst = b.build(d)
    with pytest.raises(ProblemInputError, match="upper bounds"):
        make_constraints(inst.n, upper=bad)
    u = np.full(inst.n, 1.0)
    u[3] = bad
    with pytest.raises(ProblemInputError, match="upper bounds"):
        get_solver(name).solve(qp_with(inst, Constraints(u)))


@pytest.mark.parametrize("name", LOAD)
def test_a_load_beyond_the_box_is_refused_before_solving(square, name: str) -> None:
    b, d, p_el = square
    inst = b.build(d)
    u = np.full(inst.n, 1e-3 * float(np.max(p_el)))
    with pytest.raises(ProblemInputError, match="exceeds what the bounds can carry"):
        get_solver(name).solve(qp_with(inst, Constraints(u, 1.01 * float(np.sum(u)))))


@pytest.mark.parametrize("name", LOAD)
@pytest.mark.parametrize("share", [0.999, 1.0])
def test_a_load_the_box_barely_carries_ends_with_an_answer(square, name: str, share: float) -> None:
    """sum(u) ~ P: nearly every element plastic.  The solve ends converged on a finite
    answer inside the box carrying P, never NaN (a knife edge that once divided by a zero
    step: ``_ccg.polak_ribiere``)."""
    b, d, p_el = square
    inst = b.build(d)
    u = np.full(inst.n, 1e-3 * float(np.max(p_el)))
    qp = qp_with(inst, Constraints(u, share * float(np.sum(u))))
    r = get_solver(name).solve(qp, SolverSettings(tol=1e-10, max_iter=300))
    assert np.all(np.isfinite(r.p)) and math.isfinite(r.multiplier), r.message
    assert np.all(r.p >= 0.0) and np.all(r.p <= u)
    assert abs(float(np.sum(r.p)) - share * float(np.sum(u))) <= 1e-9 * float(np.sum(u))
    assert r.status == "converged", (r.status, r.message)
    assert kkt_check(qp, r.p, r.multiplier).kkt_error <= 1e-9


def box_at_share(n: int, load: float, share: float) -> np.ndarray:
    """Equal bounds whose box carries load / share (never less than the load: nudged up
    by ulps where the division rounded below it)."""
    u = np.full(n, load / (share * n))
    while float(np.sum(u)) < load:
        u = np.nextafter(u, math.inf)
    return u


@pytest.mark.parametrize("name", [n for n in LOAD if n in FAST])
@pytest.mark.parametrize("share", [0.99, 0.999, 0.9999, 1.0])
@pytest.mark.parametrize("ulps", [-1, 0, 1])
def test_near_saturation_the_load_is_solved_up_to_the_box_capacity(square, name: str, share: float,
                                                                   ulps: int) -> None:
    """The 32^2 surface under load control (the elastic top step's load, moved by an ulp
    either way) with a hardness whose box carries 99 % ... 100 % of it: nearly every
    element plastic.  Each fast CCG that poses load and hardness solves it, as the judge
    reads it (the Delta fitted from p) and with its own Delta, and the answer is in the
    box carrying the load."""
    b, _, p_el = square
    load = float(np.sum(p_el))
    if ulps:
        load = float(np.nextafter(load, math.copysign(math.inf, ulps)))
    inst = b.build_load(load)
    u = box_at_share(inst.n, load, share)
    qp = qp_with(inst, Constraints(u, load))
    case = replace(inst, qp=qp)
    r = get_solver(name).solve(qp, SolverSettings(tol=1e-10))
    assert r.status == "converged", (name, share, r.message)
    verdict = judge(case, r.p, r.converged, 1e-10)
    assert verdict.status == "solved", verdict.message()
    assert kkt_check(qp, r.p, r.multiplier).kkt_error <= 1e-10
    assert np.all(r.p >= 0.0) and np.all(r.p <= u)
    assert abs(float(np.sum(r.p)) - load) <= 1e-12 * load
    plastic = float(np.mean(r.p >= u))
    assert plastic >= 0.98, plastic  # nearly every element at its bound, as posed


@pytest.mark.parametrize("name", LOAD)
def test_a_zero_load_is_no_contact(square, name: str) -> None:
    b, _, _ = square
    inst = b.build_load(0.0)
    r = get_solver(name).solve(inst.qp, TIGHT)
    assert r.status == "converged", r.message
    assert not np.any(r.p)


@pytest.mark.parametrize("name", ["fast-pccg", "fast-dual-pccg"])
@pytest.mark.parametrize("precondition", ["farfield", "islands", "none"])
def test_the_direction_keeps_the_load(square, loaded, name: str, precondition: str) -> None:
    """Under load control the (preconditioned) direction sums to zero on the free set
    (``_constrained.zero_sum``), so a step changes the load only when it clips: a warm
    step along a close load history costs about one matvec per iteration, not the two
    that a rescale after every step would."""
    b, _, p_el = square
    inst, p_ref, _ = loaded
    nxt = b.build_load(1.02 * float(np.sum(p_el)))
    s = get_solver(name)
    r = s.solve(nxt.qp, SolverSettings(tol=1e-12, params={"precondition": precondition}), warm=WarmStart(p=p_ref))
    assert r.status == "converged", r.message
    assert r.matvecs <= 1.5 * r.iterations + 2, (r.iterations, r.matvecs)


def test_auto_precision_is_the_grid_s_under_load_control_too() -> None:
    """The one rule of ``precision="auto"``: mixed from ``MIXED_GRID_POINTS`` grid points
    (512^2), with or without a load; double below."""
    def qp(N: int, load: float | None) -> SimpleNamespace:  # a stand-in: the grid, constraints and no dense block
        return SimpleNamespace(geometry=SimpleNamespace(grid_shape=(N, N)), n=N * N, H=None,
                               constraints=Constraints(None, load))

    assert MIXED_GRID_POINTS == 512 * 512
    for load in (1.0, None):
        assert resolved_precision("auto", qp(512, load)) == "mixed"
        assert resolved_precision("auto", qp(511, load)) == "double"
        assert resolved_precision("auto", qp(2048, load)) == "mixed"
        assert resolved_precision("double", qp(2048, load)) == "double"


def test_the_cold_start_under_load_control_is_the_summits_carrying_the_load(square, loaded, loaded_plastic) -> None:
    """``winkler_start``: p >= 0 on the points above the water level only, sum(p) = P, the
    highest point carrying the most; under a hardness within the box and still carrying P;
    None without a load."""
    inst = loaded[0]
    u = inst.qp.constraints.upper_or_inf(inst.n)
    p = winkler_start(context_of(inst.qp), u)
    assert p is not None and np.all(p >= 0.0)
    assert float(np.sum(p)) == pytest.approx(float(inst.qp.constraints.load), rel=1e-12)
    assert 0 < np.count_nonzero(p) < inst.n
    assert int(np.argmax(p)) == int(np.argmax(inst.qp.ubar))
    hard = loaded_plastic[0]
    cap = hard.qp.constraints.upper_or_inf(hard.n)
    capped = winkler_start(context_of(hard.qp), cap)
    assert capped is not None and np.all(capped <= cap * (1 + 1e-12)) and np.any(capped >= cap)
    assert float(np.sum(capped)) == pytest.approx(float(hard.qp.constraints.load), rel=1e-9)
    b, d, _ = square
    assert winkler_start(context_of(b.build(d).qp), u) is None


def context_of(qp: QP) -> SolveContext:
    return loop_context(qp, 100)


def greedy_in_order(amount: float, caps: np.ndarray) -> np.ndarray:
    """The greedy pass ``taken_in_order`` replaces, one point at a time."""
    out = np.zeros(caps.size)
    for i, cap in enumerate(caps):
        if amount <= 0.0:
            break
        out[i] = min(amount, cap)
        amount -= out[i]
    return out


@pytest.mark.parametrize("seed", range(40))
def test_dealing_out_in_order_is_the_greedy_pass(seed: int) -> None:
    """``taken_in_order`` (the fill and the shed of ``scale_to_load``) against the loop:
    caps with infinities and zeros, amounts of nothing, part and more than all."""
    from contactbench.solvers._constrained import taken_in_order

    rng = np.random.default_rng(seed)
    caps = rng.exponential(1.0, rng.integers(0, 30))
    caps[rng.random(caps.size) < 0.1] = 0.0
    if seed % 3 == 0 and caps.size:
        caps[rng.integers(caps.size)] = math.inf
    total = float(np.sum(caps[np.isfinite(caps)]))
    for amount in (0.0, 0.3 * total, total, 2.0 * total + 1.0):
        got, want = taken_in_order(amount, caps), greedy_in_order(amount, caps)
        assert got.shape == caps.shape and np.all(got >= 0.0) and np.all(got <= caps)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * max(total, 1.0)), (amount, got, want)


@pytest.mark.parametrize("case", ["elastic", "plastic", "loaded", "loaded_plastic"])
@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-pccg"])
def test_the_loops_vector_work_in_bands_on_the_threads_takes_the_same_steps(
        name: str, case: str, square, request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """The loops' vector work runs in bands on the pool (``fft_threads.each_band``), bands of
    7 here.  Its elementwise work, positions and extremes (the inner products left whole)
    give the iterates of the whole vectors: the same products, iterations and answer, under
    displacement, a hardness, load control and both.  With the inner products in bands too
    (summed in band order, so rounded otherwise), 1 and 3 threads take the same steps, and
    reach the whole vectors' answer within the tolerance, in as many products +-5 %."""
    from contactbench.problems import fft_threads
    from contactbench.solvers import _steps

    inst = square[0].build(square[1]) if case == "elastic" else request.getfixturevalue(case)[0]
    whole = get_solver(name).solve(inst.qp, TIGHT)
    assert whole.status == "converged", whole.message
    monkeypatch.setattr(fft_threads, "BANDED_VECTOR_MIN", 1)
    monkeypatch.setattr(fft_threads, "VECTOR_BAND", 7)
    runs = {}
    for dots in ("whole", "banded"):
        with monkeypatch.context() as mp:
            if dots == "whole":
                mp.setattr(_steps, "dots_in_bands", lambda pairs: [x @ y for x, y in pairs])
            for workers in ("1", "3"):
                mp.setenv("CONTACTBENCH_FFT_WORKERS", workers)
                runs[dots, workers] = get_solver(name).solve(inst.qp, TIGHT)
    for workers in ("1", "3"):
        banded = runs["whole", workers]
        assert (banded.status, banded.matvecs, banded.iterations) == (whole.status, whole.matvecs, whole.iterations)
        np.testing.assert_allclose(banded.p, whole.p, rtol=0, atol=1e-12 * np.max(whole.p))
    one, three = runs["banded", "1"], runs["banded", "3"]
    assert (one.status, one.matvecs, one.iterations) == (three.status, three.matvecs, three.iterations)
    assert np.array_equal(one.p, three.p)
    assert one.status == "converged" and abs(one.matvecs - whole.matvecs) <= max(1, 0.05 * whole.matvecs)
    assert np.max(np.abs(one.p - whole.p)) <= 1e-8 * np.max(whole.p)


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-dual-ccg", "fast-pccg", "fast-ccg"])
@pytest.mark.parametrize("periodic", [False, True])
def test_load_controlled_projections_cost_no_product_where_partial_products_pay(name: str, periodic: bool,
                                                                                 monkeypatch) -> None:
    """Under load control without a box the projection raises the clipped forces and
    scales p to the load without recomputing the gap (``_constrained._project_raised``):
    with partial products always paying, the same answer as with none, in fewer
    products."""
    from contactbench.problems import operators

    s = fourier_synthesis(64, 0.7, rms_slope=0.3, length=1e-4, seed=5)
    builder = InstanceBuilder(s, E, periodic=periodic)
    inst = builder.build_load(builder.load_force(0.005))
    runs = {}
    for factor in (0.0, 1e9):
        monkeypatch.setattr(operators, "PARTIAL_PRODUCT_FACTOR", factor)
        runs[factor] = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-10, params={"precision": "double"}))
    off, on = runs[0.0], runs[1e9]
    assert off.converged and on.converged
    assert np.max(np.abs(on.p - off.p)) <= 1e-7 * np.max(off.p)
    assert abs(float(np.sum(on.p)) - float(inst.qp.constraints.load)) <= 1e-12 * float(inst.qp.constraints.load)
    assert kkt_check(inst, on.p, on.multiplier).kkt_error <= 1e-9
    assert on.matvecs < off.matvecs, (on.matvecs, off.matvecs)
