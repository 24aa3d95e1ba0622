"""The exact reference under load control answers every load whose answer is representable:
loads far below the relief's force (the approach Delta then within round-off of -max ubar,
where a search over Delta cannot resolve it) and far above it (beyond any fixed number of
bracket steps of the relief's size), each certified by its own check and by the judge's."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.constraints import Constraints
from contactbench.problems.instances import QP, InstanceBuilder
from contactbench.problems.kkt import constrained_figures
from contactbench.problems.mixed_lcp import CERTIFY_KKT, constrained_exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers.registry import get_solver

LOADS = (1e-300, 1e-200, 1e-100, 1e-20, 1e20, 1e100)


def coupled(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A small SPD H (E = 1, unit diagonal, coupling 0.3) and a relief with one highest
    element."""
    H = np.eye(n) + 0.3 * (np.ones((n, n)) - np.eye(n))
    return H, np.linspace(1.0, 0.5, n)


def rough8() -> tuple[np.ndarray, np.ndarray]:
    """A rough 8 x 8 surface's dense H and ubar (E = 1e9) at an approach of 1e-7 m: its
    highest element at ubar = 1e-7, not 0, so a tiny load's Delta is round-off of it."""
    b = InstanceBuilder(fourier_synthesis(8, 0.8, 0.1, length=1e-4, seed=3), 1e9, operator="dense")
    qp = b.build(1e-7).qp
    return np.asarray(qp.H.H), np.asarray(qp.ubar)


def assert_exact(H: np.ndarray, ubar: np.ndarray, load: float) -> np.ndarray:
    """The reference's answer, certified and carrying the load to round-off."""
    c = Constraints(None, load)
    sol = constrained_exact_solution(H, ubar, c)
    f = constrained_figures(sol.p, H @ sol.p - ubar, ubar, float(np.max(np.diag(H))), c, sol.multiplier)
    assert sol.kkt_error <= CERTIFY_KKT and f.kkt_error <= CERTIFY_KKT
    assert np.all(sol.p >= 0.0)
    assert float(np.sum(sol.p)) == pytest.approx(load, rel=1e-12)
    return sol.p


def test_one_element_at_a_tiny_load_carries_exactly_that_load() -> None:
    p = assert_exact(np.eye(1), np.ones(1), 1e-300)
    assert p[0] == pytest.approx(1e-300, rel=1e-15)


@pytest.mark.parametrize("load", LOADS)
@pytest.mark.parametrize("n", [1, 2, 3])
def test_small_problems_at_extreme_loads(n: int, load: float) -> None:
    H, ubar = coupled(n)
    p = assert_exact(H, ubar, load)
    if load < 1e-10:  # the load lands on the highest element alone
        assert p[0] == pytest.approx(load, rel=1e-12) and np.all(p[1:] == 0.0)


@pytest.mark.parametrize("load", LOADS)
def test_a_rough_surface_at_extreme_loads(load: float) -> None:
    H, ubar = rough8()
    assert_exact(H, ubar, load)


@pytest.mark.parametrize("load", [1e-300, 1e100])
def test_the_registered_reference_claims_extreme_loads(load: float) -> None:
    H, ubar = coupled(3)
    res = get_solver("bvls").solve(QP(DenseOperator(H), ubar, constraints=Constraints(None, load)))
    assert res.converged, res.message
