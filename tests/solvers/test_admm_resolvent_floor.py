"""ADMM's resolvent CG is never asked for a residual below its round-off
(``admm.RESOLVENT_ROUND_OFF`` eps ||v||_inf): at a tolerance of 1e-15 each inner solve ran to
its stagnation window (214 products an outer iteration on 8 unknowns, 28 s a solve)."""

from __future__ import annotations

import numpy as np

from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.surfaces import Surface
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver


def test_an_unreachable_tolerance_leaves_the_inner_solves_short() -> None:
    h = np.array([[0.0, 1e-12, 0.3, 1.0], [0.5, 1e-12, 0.7, 0.2]]) * 1e-6
    b = InstanceBuilder(Surface(h, 1e-6), 1e11, "love", False, operator="fft")
    inst = b.build_load(b.load_force(1e-3))
    res = get_solver("admm").solve(inst.qp, SolverSettings(1e-15, max_iter=50))
    assert res.info["linear_solver"] == "cg"
    # an inner solve of 8 unknowns takes at most about 8 products, not a stagnation window
    assert res.info["inner_cg_iterations"] <= 2 * inst.n * max(res.iterations, 1), res.info["inner_cg_iterations"]
    assert np.all(np.isfinite(res.p))
