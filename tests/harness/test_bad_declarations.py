"""A solver declared badly is refused in one line before anything runs; one whose methods
answer what their contracts do not allow fails its rows naming the method and the answer.

* ``Capabilities`` checks its fields when made (solvers/_capabilities.py): a module that
  declares an unknown operator kind, a warm start outside "none"/"primal"/"primal-dual",
  a ``max_n`` below 1 (or NaN, or text) or a flag that is not a bool does not import;
* ``check_declaration`` (solvers/registry.py) refuses a name ``--solvers`` cannot read
  back, a ``family`` or ``description`` that is not a str on one line, a ``default_tol``
  that is not None or a finite number > 0, a ``refuted_on`` that is not a frozenset of str
  and a method that is not one;
* a solver named by import path whose ``availability()`` raises or answers what is not
  (bool, str) is refused when it is loaded, ``run`` and ``validate`` alike;
* ``skip``/``skip_params`` answer None or a reason (a str): 1, True or a list is no reason,
  and fails the rows instead of skipping them with the text "1";
* ``default_max_iter`` answers None or an integer >= 0, and ``iterate`` an ``Outcome`` whose
  fields are of their kinds (solvers/base.py ``read_max_iter``, ``read_outcome``): a string
  "no" as ``converged`` is not a claim of convergence, -5 iterations are none."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contactbench.harness.run.skips import capability_decision
from contactbench.problems.instances import QP
from contactbench.problems.operators import DenseOperator
from contactbench.solvers import Capabilities, Outcome, ProblemTraits, SolveContext, Solver, Status
from contactbench.solvers.base import SolverReturnError
from contactbench.solvers.registry import (SolverDeclarationError, SolverLoadError, check_declaration,
                                           load_named_solver)
from tests.helpers import refused_in_one_line, run_cli

TRAITS = ProblemTraits(n=3, operator="dense")
GiB = float(2**30)


class Clipper(Solver):
    """Exact for H = I: p = max(ubar, 0)."""

    name = "test-decl-clipper"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(np.maximum(np.asarray(ctx.qp.ubar, dtype=float), 0.0), 1, True)


def identity_qp() -> QP:
    return QP(DenseOperator(np.eye(3)), np.array([1.0, -1.0, 2.0]))


def with_attrs(**attrs: Any) -> Solver:
    """A ``Clipper`` whose class sets ``attrs``."""
    return type("Declared", (Clipper,), attrs)()


# ---------------------------------------------------------------------------
# Declarations: refused before anything runs
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("fields, words", [
    ({"operators": ["dense", "fft"]}, "operators is a non-empty frozenset"),
    ({"operators": "fft"}, "operators is a non-empty frozenset"),
    ({"operators": frozenset({"sparse"})}, "operators is a non-empty frozenset"),
    ({"operators": frozenset()}, "operators is a non-empty frozenset"),
    ({"warm_start": "dual"}, "warm_start is one of 'none', 'primal', 'primal-dual'"),
    ({"warm_start": True}, "warm_start is one of"),
    ({"max_n": 0}, "max_n is None or an integer >= 1"),
    ({"max_n": -1}, "max_n is None or an integer >= 1"),
    ({"max_n": float("nan")}, "max_n is None or an integer >= 1"),
    ({"max_n": "100"}, "max_n is None or an integer >= 1"),
    ({"needs_dense": "no"}, "needs_dense is True or False"),
    ({"load_control": "no"}, "load_control is True or False"),
    ({"input_format": "csv"}, "input_format is one of"),
    ({"promise": float("nan")}, "a solver's promise is"),
])
def test_capabilities_outside_their_values_are_refused_naming_the_field(fields: dict[str, Any], words: str) -> None:
    with pytest.raises(ValueError, match="Capabilities") as caught:
        Capabilities(**fields)
    assert words in str(caught.value) and len(str(caught.value).splitlines()) == 1


def test_capabilities_within_their_values_are_kept() -> None:
    caps = Capabilities(operators=frozenset({"dense"}), warm_start="primal-dual", max_n=np.int64(10),
                        needs_dense=np.bool_(True), input_format="kernel-table", promise=1e-6)
    assert caps.max_n == 10 and caps.needs_dense is True and caps.accuracy_floor == 1e-6


@pytest.mark.parametrize("attrs, words", [
    ({"name": "probe\nbad"}, "cannot be named in --solvers"),
    ({"name": "probe,bad"}, "cannot be named in --solvers"),
    ({"name": "probe[x]"}, "cannot be named in --solvers"),
    ({"name": "probe:x"}, "cannot be named in --solvers"),
    ({"name": "probe bad"}, "cannot be named in --solvers"),
    ({"name": " probe"}, "cannot be named in --solvers"),
    ({"family": 3}, "`family` is 3"),
    ({"family": None}, "`family` is None"),
    ({"family": ""}, "`family` is ''"),
    ({"family": "a\nb"}, "`family` is 'a\\nb'"),
    ({"description": 3}, "`description` is 3"),
    ({"description": "a\nb"}, "`description` is 'a\\nb'"),
    ({"default_tol": float("nan")}, "`default_tol` is nan"),
    ({"default_tol": -1}, "`default_tol` is -1"),
    ({"default_tol": 0.0}, "`default_tol` is 0.0"),
    ({"default_tol": "1e-8"}, "`default_tol` is '1e-8'"),
    ({"default_tol": True}, "`default_tol` is True"),
    ({"default_tol": float("inf")}, "`default_tol` is inf"),
    ({"refuted_on": "paper"}, "`refuted_on` is 'paper'"),
    ({"refuted_on": ["paper"]}, "`refuted_on` is ['paper']"),
    ({"time_scales_with_grid": "no"}, "`time_scales_with_grid` is 'no'"),
    ({"time_scales_with_grid": None}, "`time_scales_with_grid` is None"),
    ({"availability": (True, "available")}, "`availability` is (True, 'available'), not a method"),
])
def test_a_declaration_the_harness_cannot_use_is_refused_in_one_line(attrs: dict[str, Any], words: str) -> None:
    with pytest.raises(SolverDeclarationError) as caught:
        check_declaration(with_attrs(**attrs))
    line = str(caught.value)
    assert words in line and len(line.splitlines()) == 1, line


def test_a_family_is_any_one_line_of_text_and_a_name_one_word() -> None:
    kept = dict(name="probe-ok.v2+x", family="a, b", description="", default_tol=1, refuted_on=frozenset({"x"}))
    assert check_declaration(with_attrs(**kept)).family == "a, b"
    with pytest.raises(SolverDeclarationError, match=re.escape("`family` is 'a, b\\n'")):
        check_declaration(with_attrs(**{**kept, "family": "a, b\n"}))


# ---------------------------------------------------------------------------
# availability(): asked once when a solver named by import path is loaded
# ---------------------------------------------------------------------------

MODULE = """
from contactbench.solvers import Solver, Outcome
import numpy as np

class S(Solver):
    name = "test-decl-probe"
    family = "test"

    def availability(self):
{body}

    def iterate(self, ctx):
        return Outcome(np.maximum(ctx.qp.ubar, 0.0), 1, True)
"""


@pytest.fixture
def user_module(in_tmp: Path, monkeypatch: pytest.MonkeyPatch):
    """Write a solver module whose ``availability`` body is given; name its solver ``module:S``."""
    def write(body: str, name: str = "cb_bad_decl") -> str:
        (in_tmp / f"{name}.py").write_text(MODULE.format(body=f"        {body}"))
        monkeypatch.delitem(sys.modules, name, raising=False)
        return f"{name}:S"
    return write


@pytest.mark.parametrize("body, words", [
    ("raise RuntimeError('boom')", "its availability() failed: RuntimeError: boom"),
    ("raise SystemExit(3)", "availability() raised SystemExit: 3"),
    ("return None", "availability() returned None, not a pair (available, reason)"),
    ("return (True,)", "availability() returned (True,)"),
    ("return ('yes', 3)", "availability() returned ('yes', 3)"),
    ("return (False, 3)", "availability() returned (False, 3)"),
], ids=["raises", "exits", "none", "one", "yes-3", "false-3"])
def test_an_availability_that_fails_or_answers_no_pair_refuses_the_load(body: str, words: str, user_module) -> None:
    spec = user_module(body)
    with pytest.raises(SolverLoadError) as caught:
        load_named_solver(spec)
    line = str(caught.value)
    assert words in line and f"'{spec}'" in line and len(line.splitlines()) == 1, line


def test_run_refuses_an_availability_that_raises_in_one_line_and_writes_nothing(
        user_module, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = user_module("raise RuntimeError('boom')")
    rc, _, err = run_cli(["run", "paper-sweep", "--size", "8", "--steps", "2", "--reference", "none",
                          "--no-progress", "--solvers", spec, "--out", "o"], capsys)
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, (rc, err)
    assert "its availability() failed: RuntimeError: boom" in err and not (in_tmp / "o").exists()


def test_validate_refuses_an_availability_that_answers_no_pair(user_module, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused_in_one_line([user_module("return ('yes', 3)")], capsys)
    assert "availability() returned ('yes', 3)" in line


# ---------------------------------------------------------------------------
# skip(), skip_params(): a reason is a str
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["skip", "skip_params"])
@pytest.mark.parametrize("answer", [1, True, ["x"], 0.5])
def test_a_skip_answer_that_is_no_reason_fails_the_rows_naming_it(method: str, answer: Any) -> None:
    def own(self: Solver, *args: Any) -> Any:
        return answer

    decision = capability_decision(with_attrs(**{method: own}), TRAITS, GiB)
    assert decision.skip and decision.failed, decision
    assert f"{method}() returned {answer!r}, not a reason" in decision.reason


@pytest.mark.parametrize("answer, reason", [(False, None), ("", None), ("line one\nline two", "line one / line two")])
def test_a_skip_answer_that_is_a_reason_or_none_is_read_as_one(answer: Any, reason: str | None) -> None:
    def skip(self: Solver, traits: ProblemTraits) -> Any:
        return answer

    assert with_attrs(skip=skip).skip(TRAITS) == reason
    decision = capability_decision(with_attrs(skip=skip), TRAITS, GiB)
    assert not decision.failed and decision.reason == (reason or decision.reason)


# ---------------------------------------------------------------------------
# default_max_iter(), iterate(): read by the lifecycle
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("answer", [-1, float("nan"), 1e300, "10", 10.0, True])
def test_a_default_max_iter_that_is_no_limit_fails_the_solve_naming_it(answer: Any) -> None:
    solver = with_attrs(default_max_iter=lambda self, n: answer)
    with pytest.raises(SolverReturnError, match=r"default_max_iter\(3\) returned .*not an integer >= 0 or None"):
        solver.solve(identity_qp())


def test_a_numpy_integer_is_an_iteration_limit_and_a_float_is_none() -> None:
    seen: list[int | None] = []

    def iterate(self: Solver, ctx: SolveContext) -> Outcome:
        seen.append(ctx.max_iter)
        return Clipper.iterate(self, ctx)

    with_attrs(default_max_iter=lambda self, n: np.int64(7), iterate=iterate).solve(identity_qp())
    assert seen == [7]
    with pytest.raises(SolverReturnError, match=r"default_max_iter\(3\) returned 7\.0"):
        with_attrs(default_max_iter=lambda self, n: 7.0, iterate=iterate).solve(identity_qp())


def _changed(**fields: Any) -> Any:
    def iterate(self: Solver, ctx: SolveContext) -> Any:
        out = Clipper.iterate(self, ctx)
        for key, value in fields.items():
            setattr(out, key, value)
        return out
    return iterate


@pytest.mark.parametrize("iterate, words", [
    (lambda self, ctx: None, "iterate() returned None, not an Outcome"),
    (lambda self, ctx: (np.ones(3), 1, True), "iterate() returned (array("),
    (_changed(iterations=-5), "whose iterations is -5, not an integer from 0 to 9223372036854775807"),
    (_changed(iterations=2**63), "whose iterations is 9223372036854775808, not an integer from 0"),
    (_changed(iterations=float("nan")), "whose iterations is nan"),
    (_changed(iterations="5"), "whose iterations is '5'"),
    (_changed(iterations=5.5), "whose iterations is 5.5"),
    (_changed(converged="no"), "whose converged is 'no', not True or False"),
    (_changed(status="converged"), "whose status is 'converged', not a Status or None"),
    (_changed(status=3), "whose status is 3"),
    (_changed(message=5), "whose message is 5, not a str"),
    (_changed(info=[1]), "whose info is [1], not a dict"),
    (_changed(w=np.zeros(2)), "whose w is array("),
    (_changed(multiplier="x"), "whose multiplier is 'x', not None or a real number"),
], ids=["none", "tuple", "iter-neg", "iter-past-int64", "iter-nan", "iter-str", "iter-float", "conv-str", "status-str", "status-int",
        "message-int", "info-list", "w-short", "mult-str"])
def test_an_outcome_of_the_wrong_kind_fails_the_solve_naming_the_field(iterate: Any, words: str) -> None:
    with pytest.raises(SolverReturnError) as caught:
        with_attrs(iterate=iterate).solve(identity_qp())
    line = str(caught.value)
    assert words in line and "'test-decl-clipper'" in line and len(line.splitlines()) == 1, line


def test_a_numpy_bool_is_a_claim_and_the_text_false_is_none() -> None:
    result = with_attrs(iterate=_changed(converged=np.bool_(True), iterations=np.int64(4), status=Status.CONVERGED,
                                         multiplier=np.float64(0.0))).solve(identity_qp())
    assert result.converged is True and result.iterations == 4 and result.status == "converged"
    np.testing.assert_allclose(result.p, [1.0, 0.0, 2.0])
    with pytest.raises(SolverReturnError, match="whose converged is 'False', not True or False"):
        with_attrs(iterate=_changed(converged="False")).solve(identity_qp())


def test_validate_refuses_a_user_solver_named_like_a_registered_one(in_tmp: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A module's solver named "pk" would be judged, and its verdict read, as the project's
    pk: ``validate`` refuses it in one line, as ``run`` does (``plan.refuse_name_clash``)."""
    (in_tmp / "cb_clash.py").write_text(MODULE.format(body="        return (True, 'here')").replace(
        'name = "test-decl-probe"', 'name = "pk"'))
    line = refused_in_one_line(["cb_clash:S", "--quiet"], capsys)
    assert "is named 'pk', the name of the registered solver" in line
