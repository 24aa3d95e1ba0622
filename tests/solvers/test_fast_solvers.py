"""The matrix-free fast solvers (solvers/fast_*.py) and pk (solvers/pk.py), all on the
constrained-CG loops of solvers/_ccg.py, against a dense reference and the paper's
Example 1.

Reference: scipy.optimize.nnls on the Cholesky factor (H = L L', the QP is
min 1/2 ||L'p - L^-1 ubar||^2 over p >= 0).  Small grids only; no timing asserts (the
one wall-clock bound is a time-LIMIT test).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import nnls
from threadpoolctl import threadpool_limits

from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, counterexample, load_ramp, paper_max_displacement
from contactbench.problems.operators import FFTOperator
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import ParamError, SolverSettings, WarmStart
from contactbench.solvers.registry import get_solver

FAST = ["fast-ccg", "fast-dual-ccg", "fast-pdas", "fast-pccg", "fast-dual-pccg"]
HIGH = SolverSettings(tol=1e-9)


def nnls_reference(qp) -> np.ndarray:
    """scipy NNLS on the Cholesky factor.  A periodic QP is posed on the whole grid, where
    H is singular along the constant vector: solve it on the upper half of ubar (a proper
    subset, H positive definite there), extend by zeros and prove the extension exact by
    the full-grid KKT check."""
    idx = np.arange(qp.n)
    if qp.n == int(np.prod(qp.geometry.grid_shape)) if qp.geometry is not None else False:
        idx = np.sort(np.argsort(qp.ubar)[qp.n // 2:])
    H = qp.H.submatrix(idx, idx)
    L = sla.cholesky(H, lower=True)
    b = sla.solve_triangular(L, qp.ubar[idx], lower=True)
    p_sub, _ = nnls(L.T, b, maxiter=50 * idx.size)
    p = np.zeros(qp.n)
    p[idx] = p_sub
    assert kkt_check(qp, p).kkt_error <= 1e-10, "reference subset too small"
    return p


def instance(N: int, kernel: str, periodic: bool, frac: float = 1.0, operator: str = "fft", seed: int = 3):
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=seed)
    b = InstanceBuilder(s, 1e9, kernel, periodic=periodic, operator=operator)
    return b, b.build(frac * paper_max_displacement(s))


@pytest.mark.parametrize("name", FAST)
@pytest.mark.parametrize(
    "N,kernel,periodic,operator",
    [(33, "bcc", False, "fft"), (32, "bcc", True, "fft"), (64, "spectral", True, "fft"), (33, "love", False, "dense")],
)
def test_same_p_as_dense_nnls(name, N, kernel, periodic, operator):
    _, inst = instance(N, kernel, periodic, operator=operator)
    assert inst.n > 20
    p_ref = nnls_reference(inst.qp)
    res = get_solver(name).solve(inst.qp, HIGH)
    assert res.converged
    assert kkt_check(inst, res.p).kkt_error <= 1e-8
    assert relative_error(res.p, p_ref) <= 1e-6
    assert np.all(res.p >= 0)


@pytest.mark.parametrize("name", FAST)
def test_warm_start_from_previous_step(name):
    s = rmd_surface_n(64, 0.7, length=100e-6, seed=5)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    d1, d2 = load_ramp(paper_max_displacement(s), 2)
    i1, i2 = b.build(d1), b.build(d2)
    r1 = get_solver(name).solve(i1.qp, HIGH)
    full = np.zeros(s.heights.size)
    full[i1.geometry.indices] = r1.p
    warm = get_solver(name).solve(i2.qp, HIGH, WarmStart(full[i2.geometry.indices]))
    cold = get_solver(name).solve(i2.qp, HIGH)
    assert warm.warm_started and not cold.warm_started
    assert kkt_check(i2, warm.p).kkt_error <= 1e-8
    assert relative_error(warm.p, cold.p) <= 1e-6
    again = get_solver(name).solve(i2.qp, HIGH, WarmStart(warm.p))
    assert again.iterations <= 2  # started at the solution: (almost) nothing left to do
    assert relative_error(again.p, warm.p) <= 1e-8


def warm_sweep(name: str, N: int, seed: int, steps: int = 10) -> np.ndarray:
    """The paper's non-periodic BCC ramp on an N^2 RMD surface, each step warm-started
    from the last and checked to kkt <= 1e-8: rows (load, A/A0, n) per step."""
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=seed, family="saupe")
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    prev = np.zeros(s.heights.size)
    rows = []
    for k, d in enumerate(load_ramp(paper_max_displacement(s), steps)):
        inst = b.build(d)
        idx = inst.geometry.indices
        res = get_solver(name).solve(inst.qp, HIGH, WarmStart(prev[idx]) if k else None)
        assert kkt_check(inst, res.p).kkt_error <= 1e-8, (name, k)
        prev = np.zeros(s.heights.size)
        prev[idx] = res.p
        rows.append((inst.load(res.p), inst.contact_fraction(res.p), inst.n))
    return np.array(rows)


def test_sweep_loads_agree_between_exact_solvers():
    """A 10-step non-periodic BCC sweep at 128^2 (paper scene, smaller grid):
    every fast solver reaches kkt <= 1e-8 and they agree on every load."""
    ref = warm_sweep("fast-ccg", 128, seed=0)
    for name in FAST[1:]:
        np.testing.assert_allclose(warm_sweep(name, 128, seed=0)[:, 0], ref[:, 0], rtol=1e-6)


def test_pruned_fft_matvec_matches_full_convolution():
    for periodic, kernel in ((False, "bcc"), (True, "bcc"), (True, "spectral")):
        b, inst = instance(32 if periodic else 33, kernel, periodic)
        op = inst.qp.H
        assert isinstance(op, FFTOperator)
        x = np.random.default_rng(1).random(op.n)
        full = b.transform.convolve(op.scatter(x)).ravel()[op.pidx]
        np.testing.assert_allclose(op.matvec(x), full, rtol=1e-12, atol=1e-12 * np.abs(full).max())
        np.testing.assert_allclose(op.matvec(x), op.to_dense() @ x, rtol=1e-10)


@pytest.mark.parametrize("name", FAST)
def test_bad_warm_start_shape_is_a_clear_error(name):
    _, inst = instance(33, "bcc", False)
    with pytest.raises(ProblemInputError, match="warm-start"):
        get_solver(name).solve(inst.qp, HIGH, WarmStart(np.zeros(inst.n + 1)))


@pytest.mark.parametrize("name", FAST)
def test_registered_as_exact_fast_solvers(name):
    s = get_solver(name)
    assert s.family == "fast" and s.capabilities.exact and s.capabilities.warm_start == "primal"
    assert not s.capabilities.needs_dense


@pytest.mark.slow
def test_paper_sweep_at_512_same_loads_from_two_exact_solvers():
    """The paper's headline workload (512^2, H = 0.7, L = 100 um, 10 steps to
    (z_max - z_mean)/2, warm-started): the island-preconditioned dual CCG and the plain
    Polonsky-Keer CCG both pass our KKT check at every step and agree on every load and
    contact area."""
    from contactbench.problems.scenes.core import PAPER_SEED

    a, c = warm_sweep("fast-dual-pccg", 512, PAPER_SEED), warm_sweep("fast-ccg", 512, PAPER_SEED)
    assert a[-1, 2] > 30_000  # the paper's ~35,000-point trial set at the top step
    np.testing.assert_allclose(a[:, 0], c[:, 0], rtol=1e-7)
    np.testing.assert_allclose(a[:, 1], c[:, 1], rtol=0, atol=2.0 / 512**2)


def test_pk_and_fast_ccg_run_one_loop():
    """pk is the paper's configuration of fast-ccg's loop: warm-started from the same p
    (whose support is pk's first domain) they take the same iterates."""
    s = rmd_surface_n(64, 0.7, length=100e-6, seed=5)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    d1, d2 = load_ramp(paper_max_displacement(s), 2)
    i1, i2 = b.build(d1), b.build(d2)
    full = np.zeros(s.heights.size)
    full[i1.geometry.indices] = get_solver("pk").solve(i1.qp, HIGH).p
    warm = WarmStart(full[i2.geometry.indices])
    a, c = get_solver("pk").solve(i2.qp, HIGH, warm), get_solver("fast-ccg").solve(i2.qp, HIGH, warm)
    assert a.converged and a.iterations == c.iterations > 2
    np.testing.assert_array_equal(a.p, c.p)


def test_unknown_parameter_lists_the_allowed_keys():
    _, inst = instance(33, "bcc", False)
    with pytest.raises(ParamError, match="allowed: max_outer, precision, precondition"):
        get_solver("fast-pdas").solve(inst.qp, SolverSettings(params={"precondtion": "fourier"}))
    with pytest.raises(ParamError, match="precondition"):
        get_solver("fast-pccg").solve(inst.qp, SolverSettings(params={"precondition": True}))


@pytest.mark.parametrize("kind", ["fourier", "islands"])
def test_pdas_preconditioned_inner_cg_reaches_the_same_answer(kind):
    _, inst = instance(65, "bcc", False)
    ref = get_solver("fast-pdas").solve(inst.qp, HIGH)
    res = get_solver("fast-pdas").solve(inst.qp, SolverSettings(tol=1e-9, params={"precondition": kind}))
    assert ref.converged and res.converged and "preconditioner_builds" in res.info
    assert res.info["inner_matvecs"] < ref.info["inner_matvecs"]
    assert relative_error(res.p, ref.p) <= 1e-6


def test_pdas_returns_within_its_time_limit():
    """The paper's top step at 1024^2 (n = 140,199) needs several times 2 s of
    fast-pdas at its default tolerance; with time_limit = 2 the solve stops at its limit
    and says so (its inner CG used to ignore the limit, and its safeguard restarted the
    clock: that is checked without a clock in the next test)."""
    from contactbench.problems.scenes.core import PAPER_SEED

    s = rmd_surface_n(1024, 0.7, length=100e-6, seed=PAPER_SEED, family="saupe")
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(paper_max_displacement(s))
    solver = get_solver("fast-pdas")
    res = solver.solve(inst.qp, SolverSettings(time_limit=2))
    assert res.status == "time_limit" and not res.converged


def test_pdas_safeguard_runs_under_the_solve_deadline(monkeypatch):
    """The CCG safeguard gets what is left of the solve's one deadline, not a new one."""
    from contactbench.solvers import fast_pdas

    newton_step, bugnicourt, left = fast_pdas.newton_step, fast_pdas.bugnicourt, []

    def slow_newton_step(*args, **kwargs):
        time.sleep(0.3)
        return newton_step(*args, **kwargs)

    def spy(ctx, *args, **kwargs):
        left.append(ctx.deadline.remaining())
        return bugnicourt(ctx, *args, **kwargs)

    monkeypatch.setattr(fast_pdas, "newton_step", slow_newton_step)
    monkeypatch.setattr(fast_pdas, "bugnicourt", spy)
    _, inst = instance(65, "bcc", False)
    res = get_solver("fast-pdas").solve(inst.qp, SolverSettings(tol=1e-9, time_limit=30, params={"max_outer": 1}))
    assert res.converged and res.info["finished_by_ccg"]
    assert len(left) == 1 and left[0] <= 30 - 0.3


def test_pdas_trace_numbers_the_ccg_safeguard_after_the_newton_steps():
    """Newton steps 1..outer, then the CCG's from outer on: the trace never goes back and
    ends at the answer's iteration count (no point appended out of order)."""
    _, inst = instance(32, "bcc", False)
    res = get_solver("fast-pdas").solve(inst.qp, SolverSettings(params={"max_outer": 1}))
    assert res.info["finished_by_ccg"]
    its = [t[0] for t in res.trace]
    assert its == sorted(its) and its[-1] == res.iterations


CCG_SOLVERS = [*FAST, "pk"]


@pytest.mark.parametrize("name", CCG_SOLVERS)
def test_counterexample_is_unit_invariant(name):
    """Paper Example 1 (E = 0.01, diag H = 64) and the same problem with E = 1: the
    forces scale by E and the iteration is the same.  fast-pccg once gave entering
    points a force in the wrong units and failed at E = 0.01 (solvers/_ccg.py)."""
    for seed in range(5):
        a, b = counterexample(100, seed), counterexample(100, seed, E=1.0)
        ra, rb = (get_solver(name).solve(i.qp, HIGH) for i in (a, b))
        assert ra.converged and rb.converged and kkt_check(a, ra.p).kkt_error <= 1e-8
        assert relative_error(100.0 * ra.p, rb.p) <= 1e-6
        assert abs(ra.iterations - rb.iterations) <= 2


@pytest.mark.slow
def test_fast_pccg_solves_the_counterexample_at_1_and_2_threads(monkeypatch):
    """fast-pccg, declared exact, must solve paper Example 1 (seeds 0-99 at
    n = 25, 100, 400 on 1 thread), and the same on 2 threads (seeds 0-19)."""
    loads = {}
    for threads, seeds in ((1, 100), (2, 20)):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", str(threads))
        with threadpool_limits(threads):
            for n in (25, 100, 400):
                for seed in range(seeds):
                    inst = counterexample(n, seed)
                    res = get_solver("fast-pccg").solve(inst.qp, SolverSettings())
                    assert res.converged and kkt_check(inst, res.p).kkt_error <= 1e-8, (threads, n, seed)
                    loads[threads, n, seed] = inst.load(res.p)
    for (threads, n, seed), load in loads.items():
        assert load == pytest.approx(loads[1, n, seed], rel=1e-7)


@pytest.mark.parametrize("name", ["fast-pccg", "fast-dual-pccg"])
def test_coarse_first_guess_reaches_the_same_answer(name):
    """first_guess="coarse": a cold start from the 2x-coarser grid's answer (its matvecs
    counted and reported); the same fixed point as from zero."""
    s = rmd_surface_n(256, 0.7, length=100e-6, seed=3)
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(paper_max_displacement(s))
    zero = get_solver(name).solve(inst.qp, HIGH)
    coarse = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-9, params={"first_guess": "coarse"}))
    assert zero.converged and coarse.converged
    assert coarse.info["coarse_matvecs"] > 0 and coarse.matvecs > coarse.info["coarse_matvecs"]
    assert abs(coarse.p.sum() - zero.p.sum()) <= 1e-8 * zero.p.sum()
    assert kkt_check(inst.qp, coarse.p).passes(1e-9)


def test_coarse_first_guess_needs_a_surface_and_a_big_enough_grid():
    s = rmd_surface_n(64, 0.7, length=100e-6, seed=3)
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(paper_max_displacement(s))
    res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"first_guess": "coarse"}))
    assert res.converged and res.info["coarse_matvecs"] == 0 and "no coarse level" in res.info["first_guess"]


def blas_threads() -> dict[str, int]:
    """Threads of each loaded BLAS library, by its file."""
    from threadpoolctl import threadpool_info  # noqa: PLC0415

    return {p["filepath"]: p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"}


def test_a_fast_solve_runs_blas_on_one_thread_and_gives_the_threads_back(monkeypatch):
    """``_kit.serial_blas``: inside a fast solve every BLAS library runs on one thread (read
    from threadpoolctl during the solve), and after it each library has the threads the
    caller set again (two, or one where a library was loaded single-threaded), whether the
    solve returned or raised."""
    import contactbench.solvers._ccg as ccg  # noqa: PLC0415 -- the screened entry point, wrapped

    seen: list[dict[str, int]] = []
    inner = ccg.solve_screened

    def watched(ctx, solve):
        seen.append(blas_threads())
        return inner(ctx, solve)

    def crashing(ctx, solve):
        seen.append(blas_threads())
        raise ZeroDivisionError("a solver's crash")

    inst = counterexample(100, 0)
    with threadpool_limits(2, user_api="blas"):
        before = blas_threads()
        monkeypatch.setattr(ccg, "solve_screened", watched)
        res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings())
        after = blas_threads()
        monkeypatch.setattr(ccg, "solve_screened", crashing)
        with pytest.raises(ZeroDivisionError):
            get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings())
        raised = blas_threads()
    assert res.converged and len(seen) == 2 and any(n > 1 for n in before.values()), before
    assert all(set(threads.values()) == {1} for threads in seen), seen
    for lib, n in before.items():  # a library loaded single-threaded stays at 1
        assert after[lib] == raised[lib] == n, (lib, n, after, raised)
