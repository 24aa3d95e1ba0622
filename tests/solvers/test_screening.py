"""Safe screening (problems ``QP.can_touch``, solvers/_screen.py): the rule keeps every
point of the exact solution's contact set, the screened solves give the unscreened
answer, a screened set that misses contact points grows until the answer holds on the
whole problem, and the trace and matvec count span every round."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from contactbench.problems.instances import QP, Geometry, InstanceBuilder, paper_max_displacement, rigid_body_ubar
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import Deadline, SolveContext, SolverSettings, Trace, WarmStart
from contactbench.solvers.registry import get_solver
from contactbench.solvers._screen import approach_floor

CCGS = ["fast-ccg", "fast-dual-ccg", "fast-pccg", "fast-dual-pccg", "fast-pdas"]
HIGH = 1e-9


def periodic_instance(N: int = 64, frac: float = 1.0, seed: int = 5):
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=seed)
    return InstanceBuilder(s, 1e9, "spectral", periodic=True).build(frac * paper_max_displacement(s))


def solve(name: str, qp, screening: str, p0: np.ndarray | None = None):
    warm = None if p0 is None else WarmStart(p=p0)
    return get_solver(name).solve(qp, SolverSettings(tol=HIGH, params={"screening": screening}), warm)


@pytest.fixture(scope="module")
def periodic():
    inst = periodic_instance()
    exact = solve("fast-dual-pccg", inst.qp, "none")
    assert kkt_check(inst.qp, exact.p).kkt_error <= HIGH
    return inst, exact.p


def test_can_touch_keeps_the_contact_set(periodic):
    inst, p = periodic
    load = float(p.sum())
    T = inst.qp.can_touch(load)
    contact = np.flatnonzero(p > 0.0)
    assert np.all(np.isin(contact, T))
    assert T.size < 0.5 * inst.n  # a real reduction on a periodic problem
    # the margin below the rigid-body set is needed: points with ubar < 0 carry force
    assert np.any(inst.qp.ubar[contact] < 0.0)
    assert not np.all(np.isin(contact, inst.qp.can_touch(0.0)))


def test_aperiodic_rule_is_the_trial_set():
    s = rmd_surface_n(33, 0.7, length=100e-6, seed=3)
    qp = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(paper_max_displacement(s)).qp
    assert np.array_equal(qp.can_touch(1e9), np.arange(qp.n))


@pytest.mark.parametrize("name", CCGS)
def test_screened_cold_solve_matches_unscreened(name, periodic):
    inst, exact = periodic
    res = solve(name, inst.qp, "safe")
    assert res.converged
    assert kkt_check(inst.qp, res.p).kkt_error <= HIGH
    assert relative_error(res.p, exact) <= 1e-6
    assert res.info["screened_size"] < inst.n
    assert "screened_rounds" not in solve(name, inst.qp, "none").info


@pytest.mark.parametrize("name", ["fast-ccg", "fast-dual-pccg", "fast-pdas"])
def test_too_small_a_set_grows_until_the_answer_holds(name, periodic):
    """A warm start carrying 1 % of the load on the rigid-body set screens to about that
    set, which misses contact points (ubar < 0): the solve must grow the set and still end
    at the answer."""
    inst, exact = periodic
    res = solve(name, inst.qp, "safe", p0=np.where(inst.qp.ubar >= 0.0, 0.01 * exact, 0.0))
    assert res.info["screened_rounds"] >= 2
    assert res.converged
    assert kkt_check(inst.qp, res.p).kkt_error <= HIGH
    assert relative_error(res.p, exact) <= 1e-6
    its = [it for it, _, _ in res.trace]
    assert its == sorted(its) and its[-1] == res.iterations
    # every round's products are counted: at least the rounds' whole-problem checks
    assert res.matvecs >= res.iterations + res.info["screened_rounds"]


def test_screening_none_or_aperiodic_runs_on_every_point():
    s = rmd_surface_n(33, 0.7, length=100e-6, seed=3)
    qp = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(paper_max_displacement(s)).qp
    res = solve("fast-dual-pccg", qp, "safe")
    assert res.converged and "screened_size" not in res.info


@pytest.mark.parametrize("name", ["fast-ccg", "fast-dual-pccg", "fast-pdas"])
def test_a_cold_first_round_is_only_a_guess_and_the_solve_still_converges(name):
    """Cold, the first round runs on the rigid-body set to a loose tolerance (it only has
    to find the load).  With an aperiodic kernel on the whole grid (f = 0, ubar < 0 below
    the rigid body) that set is exactly can_touch(L) for every L: the set cannot grow, and
    the solve must go on on it to the asked tolerance, not stop at the loose one."""
    N = 33
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=3)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    grid = np.arange(N * N)
    qp = QP(b.operator_on(grid), rigid_body_ubar(s.heights, 0.5 * paper_max_displacement(s), grid),
            Geometry((N, N), s.delta, grid))
    assert qp.H.entry_floor() == 0.0 and np.count_nonzero(qp.ubar >= 0.0) < 0.5 * qp.n
    res = solve(name, qp, "safe")
    assert res.converged and res.info["screened_rounds"] == 2
    assert res.info["screened_size"] == np.count_nonzero(qp.ubar >= 0.0)
    exact = solve(name, qp, "none").p
    assert kkt_check(qp, res.p).kkt_error <= HIGH
    assert relative_error(res.p, exact) <= 1e-6


# ---------------------------------------------------------------------------
# Load control: the approach bounds the set (QP.can_touch(P, Delta_b))
# ---------------------------------------------------------------------------

LOAD_CCGS = ["fast-ccg", "fast-dual-ccg", "fast-pccg", "fast-dual-pccg"]


@pytest.fixture(scope="module", params=["aperiodic", "periodic"])
def loaded(request):
    """A 64^2 rough surface under load control on the whole grid (n = N^2), at the load
    of the paper's top step, with its unscreened answer and approach."""
    periodic = request.param == "periodic"
    s = rmd_surface_n(64, 0.7, "periodic" if periodic else "saupe", length=100e-6, seed=5)
    b = InstanceBuilder(s, 1e9, "spectral" if periodic else "bcc", periodic=periodic)
    disp = solve("fast-dual-pccg", b.build(0.5 * paper_max_displacement(s)).qp, "none")
    inst = b.build_load(float(disp.p.sum()))
    exact = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=HIGH, params={"screening": "none"}))
    assert exact.converged and "screened_size" not in exact.info
    return inst, exact


def test_the_approach_floor_is_below_the_approach(loaded):
    """approach_floor (each point pressed alone) never exceeds the exact approach on a
    kernel with no negative entry; the rule at the exact approach keeps the contact set."""
    inst, exact = loaded
    if inst.qp.H.entry_floor() == 0.0:
        assert 0.0 < approach_floor(inst.qp) <= exact.multiplier
    T = inst.qp.can_touch(float(inst.qp.constraints.load), exact.multiplier)
    assert np.all(np.isin(np.flatnonzero(exact.p > 0.0), T)) and T.size < inst.n


@pytest.mark.parametrize("name", LOAD_CCGS)
def test_a_load_controlled_solve_is_screened_and_gives_the_whole_answer(loaded, name):
    inst, exact = loaded
    res = solve(name, inst.qp, "safe")
    assert res.converged, res.message
    assert res.info["screened_size"] < 0.5 * inst.n
    assert kkt_check(inst, res.p, res.multiplier).kkt_error <= HIGH
    assert relative_error(res.p, exact.p) <= 1e-6
    assert res.multiplier == pytest.approx(exact.multiplier, rel=1e-6)
    assert float(res.p.sum()) == pytest.approx(float(inst.qp.constraints.load), rel=1e-12)


@pytest.mark.parametrize("factor", [1e-3, 0.3])
def test_a_load_controlled_first_set_too_small_grows(loaded, factor, monkeypatch):
    """A first guess of the approach far below the answer: the first round's set misses
    contact points, its own approach bounds the next set, and the answer holds."""
    import contactbench.solvers._screen as screen  # noqa: PLC0415 -- the guess's factor, patched
    monkeypatch.setattr(screen, "COLD_APPROACH_FACTOR", factor)
    inst, exact = loaded
    res = solve("fast-dual-pccg", inst.qp, "safe")
    assert res.converged and res.info["screened_rounds"] >= 2, res.message
    assert relative_error(res.p, exact.p) <= 1e-6
    assert res.multiplier == pytest.approx(exact.multiplier, rel=1e-6)


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-ccg"])
def test_a_load_on_a_displacement_instance_is_screened_from_its_own_first_touch(name):
    """A displacement instance posed under a load: its ubar is positive at the points the
    rigid body already presses (the first touch is at Delta = -max ubar < 0), so the
    approach floor is negative.  The cold guess reaches in from that first touch
    (``cold_approach``), never outward to an empty set, and the answer is the
    unscreened one."""
    from contactbench.problems.constraints import make_constraints
    from contactbench.solvers._screen import cold_approach

    s = rmd_surface_n(64, 0.7, length=100e-6, seed=3)
    inst = InstanceBuilder(s, 1e9).build(paper_max_displacement(s))
    free = solve("fast-dual-pccg", inst.qp, "none")
    qp = QP(inst.qp.H, inst.qp.ubar, inst.qp.geometry,
            make_constraints(inst.qp.n, None, 0.5 * float(np.sum(free.p))))
    assert approach_floor(qp) < 0.0 and cold_approach(qp) > approach_floor(qp)
    whole = solve(name, qp, "none")
    res = solve(name, qp, "safe")
    assert whole.converged and res.converged, res.message
    assert relative_error(res.p, whole.p) <= 1e-6
    assert kkt_check(qp, res.p, res.multiplier).kkt_error <= 10 * HIGH


def test_a_cold_load_round_narrows_to_the_points_near_contact(loaded):
    """After the cold round the set is read from its answer (``near_contact``): smaller
    than the safe rule's set at the exact approach, which the rounds used to carry, and
    the answer is the unscreened one."""
    inst, exact = loaded
    res = solve("fast-dual-pccg", inst.qp, "safe")
    safe = inst.qp.can_touch(float(inst.qp.constraints.load), exact.multiplier)
    assert res.converged and res.info["screened_rounds"] >= 2, res.message
    assert res.info["screened_size"] < safe.size
    assert relative_error(res.p, exact.p) <= 1e-6


@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-ccg"])
def test_a_narrowed_set_with_no_margin_still_gives_the_answer(loaded, name, monkeypatch):
    """No margin at all: the narrowed set is the support of p and the penetrating points
    only; any point of the answer it misses is added by the rounds, and the answer holds."""
    import contactbench.solvers._screen as screen  # noqa: PLC0415 -- the margin, patched

    monkeypatch.setattr(screen, "NEAR_GAP_FACTOR", 0.0)
    inst, exact = loaded
    res = solve(name, inst.qp, "safe")
    assert res.converged, res.message
    assert relative_error(res.p, exact.p) <= 1e-6
    assert res.multiplier == pytest.approx(exact.multiplier, rel=1e-6)


def test_a_cold_load_solve_whose_first_set_would_not_pay_starts_on_the_whole_grid(loaded, monkeypatch):
    """Where the safe rule's first set is too large to pay, the cold round runs on every
    point (to the cold round's tolerance) and the rounds after it on the narrowed set."""
    import contactbench.solvers._screen as screen  # noqa: PLC0415 -- the threshold, patched

    monkeypatch.setattr(screen, "MAX_SCREENED_FRACTION", 1e-9)
    inst, exact = loaded
    res = solve("fast-dual-pccg", inst.qp, "safe")
    assert res.converged and res.info["screened_rounds"] >= 2, res.message
    assert res.info["screened_size"] < 0.5 * inst.n
    assert relative_error(res.p, exact.p) <= 1e-6
    warm = solve("fast-dual-pccg", inst.qp, "safe", exact.p)  # a warm start is not narrowed from the whole grid
    assert warm.converged and "screened_rounds" not in warm.info


def bare_context(qp: QP) -> SolveContext:
    """A solve's context on ``qp`` outside any solver (for the screening helpers)."""
    return SolveContext(qp, HIGH, 100, {}, None, None, Deadline(None, 0.0), Trace(t0=0.0), 1.0)


def test_a_near_set_that_cannot_carry_the_load_is_refused(loaded):
    """Under a hardness whose bounds over the near points sum below P, ``near_contact``
    gives None (the caller solves the whole problem); with room for the load, the set."""
    from contactbench.problems.constraints import make_constraints  # noqa: PLC0415
    from contactbench.solvers._screen import near_contact  # noqa: PLC0415

    inst, exact = loaded
    qp = inst.qp
    load = float(qp.constraints.load)
    w = qp.H.matvec(exact.p) - qp.ubar
    near = (exact.p > 0.0) | (w - exact.multiplier < 0.0)
    for share, refused in ((0.999, True), (2.0, False)):
        bounds = make_constraints(qp.n, np.full(qp.n, share * load / np.count_nonzero(near)), load)
        got = near_contact(bare_context(QP(qp.H, qp.ubar, qp.geometry, bounds)), exact.p, w, exact.multiplier, 0.0)
        assert (got is None) if refused else np.array_equal(got, near)


@pytest.mark.parametrize("name", ["fast-ccg", "fast-dual-pccg"])
def test_a_warm_start_worse_than_a_cold_one_is_dropped(name, periodic):
    """A uniform warm start of 1e30 (its scaled KKT error 1e50) left every fast CCG stalled;
    it is dropped for p = 0 and said so, while a warm start near the answer is kept."""
    inst, exact = periodic
    r = solve(name, inst.qp, "safe", np.full(inst.n, 1e30))
    assert r.converged, r.message
    assert r.info["warm_start"].startswith("dropped")
    assert relative_error(r.p, exact) <= 1e-6
    near = solve(name, inst.qp, "safe", 1.01 * exact)
    assert near.converged and "warm_start" not in near.info


def spoiled_rounds(monkeypatch, spoil) -> list[float]:
    """Make fast-dual-pccg's rounds at the high tolerance return ``spoil(p, k)`` for their
    k-th answer p (k from 1); the tolerances those rounds were asked for, as they come."""
    cls = type(get_solver("fast-dual-pccg"))
    real = cls.iterate_on
    asked: list[float] = []

    def spoiled(self, ctx):
        out = real(self, ctx)
        if ctx.tol <= HIGH:
            asked.append(ctx.tol)
            out = dataclasses.replace(out, p=spoil(out.p, len(asked)))
        return out

    monkeypatch.setattr(cls, "iterate_on", spoiled)
    return asked


@pytest.mark.parametrize("misses", [1, 2])
def test_a_round_that_misses_on_the_whole_problem_is_solved_once_more_on_its_set(periodic, monkeypatch, misses):
    """A round on T that meets the tolerance there but not on the whole problem, while T
    cannot grow (round-off and the reading of Delta), runs once more on T at a tighter
    tolerance (``RETRY_FACTOR``); a second miss ends "stalled".  The round's answer is made
    to miss by scaling it by 1 + 50 tol."""
    from contactbench.solvers import _screen

    inst, exact = periodic
    asked = spoiled_rounds(monkeypatch, lambda p, k: p * (1.0 + 50.0 * HIGH) if k <= misses else p)
    r = solve("fast-dual-pccg", inst.qp, "safe", exact)
    assert len(asked) == 2 and asked[0] == HIGH
    assert asked[1] < _screen.RETRY_FACTOR * HIGH
    if misses == 1:
        assert r.converged and kkt_check(inst.qp, r.p).kkt_error <= HIGH
    else:
        assert r.status == "stalled" and not r.converged


def test_a_round_whose_whole_problem_error_is_not_finite_ends_stalled_without_a_retry(periodic, monkeypatch):
    """A round on T whose answer gives a non-finite error on the whole problem (an
    overflowed force) while T cannot grow: no retry (its tighter tolerance, tol^2 / error,
    would not be finite, 0 here): it ends unconverged -- "failed", as an answer that is
    not finite is -- never an exception."""
    inst, exact = periodic
    asked = spoiled_rounds(monkeypatch, lambda p, k: np.where(p > 0.0, np.inf, p))
    with np.errstate(invalid="ignore", over="ignore"):
        r = solve("fast-dual-pccg", inst.qp, "safe", exact)
    assert asked and all(t == HIGH for t in asked), asked
    assert r.status in ("stalled", "failed") and not r.converged, (r.status, r.message)
