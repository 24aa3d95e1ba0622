"""The solver registry and the shared solver records."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import QP
from contactbench.problems.operators import DenseOperator
from contactbench.harness.profiles import PROFILES, get_profile
from contactbench.solvers.base import Capabilities, Outcome, SolveContext, Solver, SolverSettings
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
    assert set(PROFILES) == {"default", "low", "mid", "high", "paper"}


def test_every_registered_solver_is_well_formed() -> None:
    for name, s in all_solvers().items():
        assert s.name == name
        assert isinstance(s.capabilities, Capabilities)
        ok, why = s.availability()
        assert isinstance(ok, bool) and why


# ---------------------------------------------------------------------------
# Specs on the command line: lists, name[k=v], modules in the current folder
# ---------------------------------------------------------------------------


def test_split_solver_list_keeps_commas_inside_brackets() -> None:
    from contactbench.solvers.registry import SolverSpecError, split_solver_list

    assert split_solver_list("a, b[k=1,j=2] ,c,,") == ["a", "b[k=1,j=2]", "c"]
    assert split_solver_list("") == [] and split_solver_list(" , ") == []
    for bad in ("a[k=1", "a]k", "a[k=[1]]x]"):
        with pytest.raises(SolverSpecError):
            split_solver_list(bad)


def test_param_from_text_reads_the_declared_type_and_checks_it() -> None:
    from contactbench.solvers.base import Param, ParamError
    from contactbench.solvers.registry import param_from_text

    flag = Param("flag", bool, False)
    assert [param_from_text(flag, t) for t in ("true", "Yes", "on", "1", "false", "NO", "0")] == [
        True, True, True, True, False, False, False]
    k = Param("K", int, 10, low=1, high=100)
    assert param_from_text(k, "50") == 50
    x = Param("x", float, 1.0, low=0.0)
    assert param_from_text(x, "1e-3") == 1e-3
    for p, text in ((flag, "maybe"), (k, "1.5"), (k, "0"), (k, "101"), (x, "inf"), (x, "nan"), (x, "-1"),
                    (Param("m", str, "a", choices=("a", "b")), "c")):
        with pytest.raises(ParamError, match=repr(p.name)):
            param_from_text(p, text)


def test_parse_solver_spec_checks_params_against_the_solver() -> None:
    from contactbench.solvers.base import ParamError
    from contactbench.solvers.registry import SolverSpec, SolverSpecError, parse_solver_spec

    spec, solver = parse_solver_spec("nnls-gp[K=5]")
    assert spec == SolverSpec("nnls-gp", {"K": 5}) and solver.name == "nnls-gp"
    assert spec.label == "nnls-gp[K=5]"
    assert SolverSpec("s", {"b": 1, "a": True}).label == "s[a=True,b=1]"  # keys sorted: one label per variant
    assert SolverSpec("s").label == "s"
    with pytest.raises(ParamError, match="has no parameter 'k'"):
        parse_solver_spec("nnls-gp[k=5]")
    for bad in ("nnls-gp[K]", "nnls-gp[]", "nnls-gp[K=1,K=2]", "[K=1]", "nnls-gp[K=1]x"):
        with pytest.raises(SolverSpecError):
            parse_solver_spec(bad)


def test_a_module_in_the_current_folder_loads(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    (tmp_path / "cwd_only_solver.py").write_text(
        "from tests.test_registry import _Dummy\n\nclass Here(_Dummy):\n    name = 'test-here'\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.delitem(sys.modules, "cwd_only_solver", raising=False)
    assert load_solver("cwd_only_solver:Here").name == "test-here"
    with pytest.raises(ModuleNotFoundError):
        load_solver("no_such_module_anywhere:Here")


def test_did_you_mean_names_only_close_ones() -> None:
    from contactbench.plugins import did_you_mean

    assert did_you_mean("scipy-nnsl", ["scipy-nnls", "pk"]) == " (did you mean 'scipy-nnls'?)"
    assert did_you_mean("zzz", ["scipy-nnls", "pk"]) == ""
    with pytest.raises(KeyError, match=r"unknown solver 'greedy-gc' \(did you mean .*'greedy-cg'"):
        get_solver("greedy-gc")
