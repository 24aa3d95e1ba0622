"""A variant's label ``NAME[k=v,...]`` reads back as that variant: every grid point and
choice a solver declares is written in a label that ``parse_solver_spec`` reads back to
the same solver and parameters, and a declaration holding a value or name that no label
can carry is refused; a value of the wrong kind is named in one line that says, in words,
what the parameter takes (solvers/registry.py, solvers/_params.py)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from contactbench.solvers import Capabilities, Outcome, Param, ParamError, SolveContext, Solver
from contactbench.solvers.registry import (SolverDeclarationError, SolverSpec, all_solvers, check_declaration,
                                           expand_solver_spec, grid_points, param_from_text, parse_solver_spec,
                                           register, unregister)

NAME = "test-label-reads-back"


class Labelled(Solver):
    """A solver whose ``params`` and ``grid`` each test sets (``labelled``)."""

    name = NAME
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}))
    params: ClassVar[tuple[Param, ...]] = ()

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(np.maximum(np.asarray(ctx.qp.ubar, dtype=np.float64), 0.0), 1, False)


def labelled(params: tuple[Param, ...], grid: dict[str, Any] | None = None) -> Solver:
    """An instance of a fresh subclass of ``Labelled`` with these params and this grid."""
    return type("Made", (Labelled,), {"params": params, "grid": grid or {}})()


def reads_back(spec: SolverSpec, solver: Solver) -> None:
    """Assert that ``spec``'s label parses back to ``spec`` and to ``solver``'s class."""
    back, loaded = parse_solver_spec(spec.label)
    assert back == spec and type(back.params) is dict, (spec.label, back)
    assert type(loaded) is type(solver) and loaded.name == solver.name
    for key, value in spec.params.items():
        assert type(back.params[key]) is type(value), (spec.label, key)


def test_every_grid_point_and_choice_of_every_registered_solver_reads_back_from_its_label() -> None:
    for name, solver in all_solvers().items():
        for point in grid_points(solver):
            reads_back(SolverSpec(name, point), solver)
        for param in solver.params:
            for choice in param.choices if param.kind in (bool, int, float, str) and param.choices else ():
                reads_back(SolverSpec(name, {param.name: param.check(choice)}), solver)


#: A grid value of each kind a spec's text is read as; text is drawn among the marks of a
#: spec (``,``, ``=``, ``[``, ``]``, spaces) as well as from all of unicode.
GRID_VALUES = st.one_of(
    st.tuples(st.just(str), st.text(alphabet=st.sampled_from("ab ,=[]\t"), max_size=4) | st.text(max_size=4)),
    st.tuples(st.just(int), st.integers(-10**12, 10**12)),
    st.tuples(st.just(float), st.floats(allow_nan=False, allow_infinity=False)),
    st.tuples(st.just(bool), st.booleans()),
)
DEFAULTS: dict[type, Any] = {str: "a", int: 0, float: 0.5, bool: False}


@settings(max_examples=150, deadline=None, derandomize=True)
@given(GRID_VALUES)
@example((str, "a,b"))
@example((str, "a[b"))
@example((str, "b]"))
@example((str, " a"))
@example((str, ""))
def test_a_declared_grid_value_is_refused_unless_its_label_reads_back(kind_value: tuple[type, Any]) -> None:
    kind, value = kind_value
    solver = labelled((Param("v", kind, DEFAULTS[kind]),), {"v": (value,)})
    try:
        check_declaration(solver)
    except SolverDeclarationError as exc:
        assert "does not read back from a label" in str(exc) and "\n" not in str(exc), str(exc)
        return
    register(solver, replace=True)
    try:
        specs, _ = expand_solver_spec(f"{NAME}[grid]")
        assert len(specs) == 1
        reads_back(specs[0], solver)
    finally:
        unregister(NAME)


@pytest.mark.parametrize(("param", "grid", "needle"), [
    (Param("v", str, "a", choices=("a", "b,c")), {}, "parameter 'v': its choices: 'b,c' does not read back"),
    (Param("v", str, "a", choices=("a", "b]")), {}, "its choices: 'b]' does not read back from a label, written 'v=b]'"),
    (Param("v", str, "a"), {"v": ("a", "[b")}, "its grid values of 'v': '[b' does not read back"),
    (Param("v", str, "a"), {"v": ("a", "b ")}, "its grid values of 'v': 'b ' does not read back"),
    (Param("v", tuple, (1,)), {"v": ((1,), (2,))}, "its grid values of 'v': (1,) does not read back"),
    (Param("a,b", int, 1), {}, "parameter 'a,b': its name cannot be written as the key of name[key=value]"),
    (Param("a]", int, 1), {}, "parameter 'a]': its name cannot be written"),
], ids=["choice-comma", "choice-bracket", "grid-bracket", "grid-space", "grid-tuple", "name-comma", "name-bracket"])
def test_a_value_or_name_no_label_can_carry_is_refused_in_one_line(param: Param, grid: dict[str, Any],
                                                                   needle: str) -> None:
    with pytest.raises(SolverDeclarationError) as err:
        check_declaration(labelled((param,), grid))
    line = str(err.value)
    assert "\n" not in line and line.startswith(f"solver {NAME!r}: ") and needle in line, line
    assert "holds no ',', '[' or ']'" in line


# ---------------------------------------------------------------------------
# The wrong-kind line
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(("kind", "default", "words"), [
    (bool, False, "true or false"), (int, 1, "a whole number"), (float, 1.0, "a number"), (str, "a", "text"),
], ids=["bool", "int", "float", "str"])
def test_a_value_of_the_wrong_kind_is_named_with_what_the_parameter_takes_in_words(kind: type, default: Any,
                                                                                   words: str) -> None:
    param = Param("p", kind, default)
    with pytest.raises(ParamError) as given_err:
        param.check(object)
    assert str(given_err.value) == f"parameter 'p' takes {words}, got {object!r}"
    if kind is not str:  # text is every str parameter's value
        with pytest.raises(ParamError) as written_err:
            param_from_text(param, "1_5x")
        assert str(written_err.value) == f"parameter 'p' takes {words}, got '1_5x'"

