"""The two honest throw-away solvers of tests/helpers.py are right: the harness tests
rely on them (test-exact as the reference, test-warm-pg as a warm-started iterative solver)."""

from __future__ import annotations

import numpy as np

from contactbench.problems.instances import counterexample
from contactbench.problems.kkt import kkt_check
from contactbench.solvers import SolverSettings
from tests.helpers import ExactStub, WarmPGStub, dense_exact_solution


def test_exact_solver_is_exact_on_the_counterexample() -> None:
    inst = counterexample(25, seed=1)
    p = ExactStub().solve(inst.qp, SolverSettings()).p
    assert kkt_check(inst, p).kkt_error < 1e-10


def test_warm_pg_reaches_the_exact_answer() -> None:
    inst = counterexample(16, seed=2)
    res = WarmPGStub().solve(inst.qp, SolverSettings(tol=1e-9))
    p_ref = dense_exact_solution(inst.qp)
    assert np.max(np.abs(res.p - p_ref)) <= 1e-6 * np.max(p_ref)
