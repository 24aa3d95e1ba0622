"""The solver registry and the shared solver records."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import QP
from contactbench.problems.operators import DenseOperator
from contactbench.harness.profiles import PROFILES, get_profile
from contactbench.solvers.base import Capabilities, Outcome, SolveContext, SolveResult, Solver, SolverSettings
from contactbench.solvers.registry import all_solvers, get_solver, load_solver, register, unregister


class _Dummy(Solver):
    name = "test-dummy"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), exact=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(p=np.maximum(ctx.qp.ubar, 0.0), iterations=1, converged=True)


def test_register_and_lookup_roundtrip() -> None:
    register(_Dummy)
    try:
        assert "test-dummy" in all_solvers()
        s = get_solver("test-dummy")
        qp = QP(DenseOperator(np.eye(3)), np.array([1.0, -1.0, 2.0]))
        r = s.solve(qp, SolverSettings())
        np.testing.assert_array_equal(r.p, [1.0, 0.0, 2.0])
    finally:
        unregister("test-dummy")
    assert "test-dummy" not in all_solvers()


def test_unknown_solver_message_lists_known() -> None:
    with pytest.raises(KeyError) as e:
        get_solver("no-such-solver")
    assert "no-such-solver" in str(e.value)


def test_load_solver_by_import_path() -> None:
    s = load_solver("tests.test_registry:_Dummy")
    assert isinstance(s, _Dummy)


def test_duplicate_name_of_other_class_is_refused() -> None:
    class Other(_Dummy):
        pass

    register(_Dummy)
    try:
        with pytest.raises(ValueError, match="already registered"):
            register(Other)
    finally:
        unregister("test-dummy")


def test_profiles_and_settings_tolerance() -> None:
    assert get_profile("high").tol == 1e-9 and get_profile("high").check_tol == 1e-8
    with pytest.raises(ValueError, match="unknown profile"):
        get_profile("ultra")
    assert set(PROFILES) == {"default", "low", "mid", "high"}


def test_every_registered_solver_is_well_formed() -> None:
    for name, s in all_solvers().items():
        assert s.name == name
        assert isinstance(s.capabilities, Capabilities)
        ok, why = s.availability()
        assert isinstance(ok, bool) and why
