"""The exact LCP solution (problems/lcp.py): Lawson-Hanson NNLS on the Cholesky factor plus
block principal pivoting, checked against a brute-force enumeration of contact sets, the
judge's KKT figures, a change of units, and the repair of perturbed guesses."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from contactbench.problems.instances import ContactInstance, InstanceBuilder, counterexample, paper_max_displacement
from contactbench.problems.kkt import kkt_check, scaled_kkt_error
from contactbench.problems.lcp import bpp_polish, cholesky_factor, exact_solution
from contactbench.problems.surfaces import rmd_surface_n


def random_lcp(n: int, seed: int, cond: float = 1e3) -> tuple[np.ndarray, np.ndarray]:
    """A random SPD H with condition number ``cond`` and a mixed-sign ubar."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    H = (Q * np.geomspace(1.0, 1.0 / cond, n)) @ Q.T
    return 0.5 * (H + H.T), rng.standard_normal(n)


def brute_force(H: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The LCP solution by trying every contact set A: p_A = H_AA^{-1} u_A >= 0, p = 0
    off A, and w = Hp - u >= 0 off A (unique for SPD H)."""
    n = u.size
    found = []
    for mask in itertools.product((False, True), repeat=n):
        A = np.flatnonzero(mask)
        p = np.zeros(n)
        if A.size:
            p[A] = np.linalg.solve(H[np.ix_(A, A)], u[A])
        w = H @ p - u
        off = np.setdiff1d(np.arange(n), A)
        if np.all(p[A] >= -1e-12) and np.all(w[off] >= -1e-12):
            found.append(np.maximum(p, 0.0))
    assert found, "no contact set satisfies the LCP"
    for p in found[1:]:  # degenerate sets may repeat the same point, never another one
        np.testing.assert_allclose(p, found[0], atol=1e-9)
    return found[0]


@pytest.mark.parametrize("seed", range(12))
def test_exact_solution_agrees_with_enumeration(seed: int) -> None:
    n = 3 + seed % 6  # n = 3 ... 8
    H, u = random_lcp(n, seed, cond=10.0 ** (1 + seed % 3))
    sol = exact_solution(H, u)
    p_bf = brute_force(H, u)
    np.testing.assert_allclose(sol.p, p_bf, rtol=1e-9, atol=1e-11 * np.max(np.abs(p_bf), initial=1.0))
    assert sol.converged and sol.kkt_error <= 1e-12
    assert np.all(sol.p >= 0.0)
    np.testing.assert_allclose(sol.w, H @ sol.p - u, atol=1e-14)


def test_random_spd_lcp_is_solved_to_round_off() -> None:
    # round-off in w grows like cond(H) eps: at cond 1e3 the KKT error is ~1e-14
    H, u = random_lcp(120, 7, cond=1e3)
    sol = exact_solution(H, u)
    assert sol.converged
    assert sol.kkt_error <= 1e-12
    assert sol.kkt_error == scaled_kkt_error(sol.p, H @ sol.p - u, u, float(np.max(np.diag(H))))
    assert 0 < np.count_nonzero(sol.p) < 120  # a genuine mix of contact and gap


def _bcc_instances() -> dict[str, ContactInstance]:
    surf = rmd_surface_n(16, 0.7, seed=3)
    return {"rmd16": InstanceBuilder(surf, 1e9, operator="dense").build(paper_max_displacement(surf)),
            "counterexample": counterexample(100, 4)}


@pytest.mark.parametrize("key", ["rmd16", "counterexample"])
def test_bcc_contact_instance_is_exact_by_the_judge(key: str) -> None:
    inst = _bcc_instances()[key]
    sol = exact_solution(inst.qp.H.to_dense(), inst.qp.ubar)
    assert sol.converged and sol.kkt_error <= 1e-12
    assert kkt_check(inst, sol.p).kkt_error <= 1e-12  # the judge's own figures agree
    assert np.count_nonzero(sol.p) > 0


@pytest.mark.parametrize("h_unit, u_unit", [(4e-6, 1e-6), (1e-9, 1e-14), (1e3, 1e2)])
def test_solution_follows_a_change_of_units(h_unit: float, u_unit: float) -> None:
    # p scales as ubar / H; violations are measured in the problem's own units, so a
    # tiny-unit problem is neither polished too loosely nor too strictly
    H, u = random_lcp(40, 11, cond=1e3)
    base = exact_solution(H, u)
    expected = base.p * (u_unit / h_unit)
    si = exact_solution(h_unit * H, u_unit * u)
    np.testing.assert_allclose(si.p, expected, rtol=1e-9, atol=1e-12 * np.max(expected))
    assert si.kkt_error <= 1e-12 and si.converged
    blind = bpp_polish(h_unit * H, u_unit * u, np.zeros(40), max_rounds=200)
    assert blind.converged
    np.testing.assert_allclose(blind.p, expected, rtol=1e-9, atol=1e-12 * np.max(expected))


def test_bpp_polish_repairs_a_perturbed_guess() -> None:
    inst = counterexample(100, 1)
    H, u = inst.qp.H.to_dense(), inst.qp.ubar  # original units: the polish is unit-free
    exact = exact_solution(H, u).p
    on, off = np.flatnonzero(exact > 0), np.flatnonzero(exact == 0)
    assert on.size >= 5 and off.size >= 5
    guess = exact.copy()
    guess[on[:5]] = 0.0  # five contact elements wrongly released
    guess[off[:5]] = np.max(exact)  # five free elements wrongly pressed
    out = bpp_polish(H, u, guess)
    assert out.converged and out.improved and out.rounds > 1
    assert out.history[0] > 0 and out.history[-1] == 0
    np.testing.assert_allclose(out.p, exact, rtol=0, atol=1e-10 * np.max(exact))


@pytest.mark.parametrize("start", ["zeros", "everything-pressed"])
def test_bpp_polish_from_a_blind_guess_terminates(start: str) -> None:
    H, u = random_lcp(60, 5, cond=1e5)
    p0 = np.zeros(60) if start == "zeros" else np.ones(60)
    out = bpp_polish(H, u, p0, max_rounds=200)
    assert out.converged
    np.testing.assert_allclose(out.p, exact_solution(H, u).p, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed, n", [(4, 10), (7, 10), (27, 6)])
def test_murty_fallback_ends_a_cycle_of_block_pivots(seed: int, n: int) -> None:
    # on these ill-conditioned cases block pivots alone cycle (found by search): the
    # violation count stalls, Murty's single pivots take over and finish
    H, u = random_lcp(n, seed, cond=1e6)
    p0 = (np.random.default_rng(seed).random(n) < 0.5).astype(float)
    out = bpp_polish(H, u, p0, max_rounds=200)
    assert out.converged and out.rounds > 4
    best = np.minimum.accumulate(out.history)
    assert np.any(np.asarray(out.history[1:]) >= best[:-1])  # at least one round without progress
    np.testing.assert_allclose(out.p, brute_force(H, u), rtol=1e-8, atol=1e-10 * np.max(out.p))


@pytest.mark.parametrize("seed", range(5))
def test_bpp_polish_never_returns_a_worse_point(seed: int) -> None:
    H, u = random_lcp(50, 20 + seed, cond=1e6)
    rng = np.random.default_rng(seed)
    p0 = np.maximum(exact_solution(H, u).p + 0.05 * rng.standard_normal(50), 0.0)
    out = bpp_polish(H, u, p0, max_rounds=1)
    diag_max = float(np.max(np.diag(H)))
    before = scaled_kkt_error(p0, H @ p0 - u, u, diag_max)
    after = scaled_kkt_error(out.p, H @ out.p - u, u, diag_max)
    assert after <= before
    if not out.improved:
        assert out.p is p0 or np.array_equal(out.p, p0)


def test_bad_input_is_named() -> None:
    H, u = random_lcp(5, 0)
    with pytest.raises(ValueError, match="square"):
        exact_solution(H[:, :4], u)
    with pytest.raises(ValueError, match="ubar has shape"):
        exact_solution(H, u[:4])
    with pytest.raises(ValueError, match="p0 has shape"):
        bpp_polish(H, u, np.zeros(4))
    indefinite = H - 2.0 * np.eye(5)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        cholesky_factor(indefinite)
    big_H, big_u = random_lcp(30, 1)
    with pytest.raises(RuntimeError, match="[Ii]teration"):
        exact_solution(big_H, np.abs(big_u), max_iter=1)
