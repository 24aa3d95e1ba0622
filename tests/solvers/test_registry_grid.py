"""A solver's declaration is checked where it is registered or loaded (its parameters'
kinds, ranges, choices and its grid), and ``name[grid]`` expands a solver's declared
grid into one spec per point (solvers/registry.py)."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import pytest

from contactbench.solvers import Capabilities, Outcome, Param, SolveContext, Solver
from contactbench.solvers.registry import (MAX_GRID_VARIANTS, PARAM_KINDS, SolverDeclarationError, SolverSpec,
                                           SolverSpecError, all_solvers, check_declaration, expand_solver_spec,
                                           grid_points, parse_solver_spec, register, split_solver_spec, unregister)


class Declared(Solver):
    """A solver whose ``params`` and ``grid`` each test sets (never registered as is)."""

    name = "test-declared"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}))
    params: ClassVar[tuple[Param, ...]] = (
        Param("step", float, 1.0, low=0.1, high=1.0),
        Param("mode", str, "a", choices=("a", "b")),
        Param("count", int, 1, low=1),
        Param("flag", bool, False),
    )

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(np.maximum(np.asarray(ctx.qp.ubar, dtype=np.float64), 0.0), 1, False)


def declared(grid: dict[str, Any] | None = None, params: tuple[Param, ...] | None = None) -> Solver:
    """An instance of a fresh subclass of ``Declared`` with this grid and these params."""
    attrs: dict[str, Any] = {"grid": grid or {}}
    if params is not None:
        attrs["params"] = params
    return type("Made", (Declared,), attrs)()


def refused(solver: Solver, *needles: str) -> str:
    """The one-line ``SolverDeclarationError`` of ``solver``, holding every needle."""
    with pytest.raises(SolverDeclarationError) as err:
        check_declaration(solver)
    line = str(err.value)
    assert "\n" not in line and line.startswith("solver 'test-declared': "), line
    for needle in needles:
        assert needle in line, (needle, line)
    return line


# ---------------------------------------------------------------------------
# The declaration checks
# ---------------------------------------------------------------------------


def test_every_registered_solver_passes_the_declaration_checks() -> None:
    for solver in all_solvers().values():
        assert check_declaration(solver) is solver


def test_a_grid_key_that_names_no_declared_parameter_is_refused() -> None:
    refused(declared({"nonexistent": (1, 2)}), "its grid names 'nonexistent', which is not a declared parameter",
            "'step'")


@pytest.mark.parametrize(("values", "needle"), [
    (("fast", 0.5), "parameter 'step' takes a number, got 'fast'"),
    ((0.5, 7.0), "parameter 'step' must lie in [0.1, 1], got 7.0"),
    ((0.5, float("nan")), "parameter 'step' takes a number, got nan"),
    ((True,), "parameter 'step' takes a number, got True"),
], ids=["type", "range", "nan", "bool"])
def test_a_grid_value_its_parameter_refuses_is_refused(values: tuple[Any, ...], needle: str) -> None:
    refused(declared({"step": values}), "its grid values of 'step'", needle)


def test_a_grid_value_outside_the_choices_is_refused() -> None:
    refused(declared({"mode": ("a", "c")}), "parameter 'mode' must be one of 'a', 'b', got 'c'")


@pytest.mark.parametrize(("values", "needle"), [
    ((), "are (), not a non-empty tuple of values"),
    (0.5, "are 0.5, not a non-empty tuple of values"),
    ("ab", "are 'ab', not a non-empty tuple of values"),
    ((0.5, 0.5), "list 0.5 twice"),
    ((1, 1.0), "list 1.0 twice"),
], ids=["empty", "scalar", "string", "repeat", "repeat-as-checked"])
def test_a_grid_value_list_is_a_non_empty_tuple_without_repeats(values: Any, needle: str) -> None:
    refused(declared({"step": values}), needle)


def test_a_grid_that_is_not_a_dict_is_refused() -> None:
    solver = declared()
    type(solver).grid = [("step", (0.5,))]  # type: ignore[assignment]
    refused(solver, "its `grid` is [('step', (0.5,))], not a dict")


def test_every_fault_of_a_declaration_is_named_in_its_one_line() -> None:
    line = refused(declared({"step": ("fast", 7.0), "nonexistent": (1, 2)}))
    assert "'fast'" in line and "7.0" in line and "'nonexistent'" in line


@pytest.mark.parametrize("kind", [list, set, np.ndarray, object, complex])
def test_a_parameter_kind_outside_the_supported_ones_is_refused(kind: type) -> None:
    refused(declared(params=(Param("opts", kind, None),)), f"parameter 'opts' is of kind {kind.__name__}, not one of",
            "bool, int, float, str, tuple, dict")


def test_the_supported_kinds_are_the_scalars_and_tuple_and_dict() -> None:
    assert PARAM_KINDS == (bool, int, float, str, tuple, dict)
    for kind, default in ((bool, True), (int, 1), (float, 0.5), (str, "x"), (tuple, (1, 2)), (dict, {})):
        check_declaration(declared(params=(Param("p", kind, default),)))


@pytest.mark.parametrize(("param", "needle"), [
    (Param("choice", str, "a", choices=("a", 3)), "its choices: parameter 'choice' takes text, got 3"),
    (Param("choice", str, "a", choices=()), "its choices are (), not a non-empty tuple"),
    (Param("choice", str, "a", choices=("a", "a")), "its choices list 'a' twice"),
    (Param("k", int, 1, low=0, high=3, choices=(1, 5)), "parameter 'k' must lie in [0, 3], got 5"),
    (Param("name", str, "a", low=0.0), "declares a range, but is a str"),
    (Param("x", float, 1.0, low=2.0, high=1.0), "its range is empty (low=2.0 > high=1.0)"),
    (Param("x", float, 1.0, low="0"), "are not numbers"),  # type: ignore[arg-type]
    (Param("x", float, 1.0, low=0.0, open="left"), "its open ends are 'left'"),
    (Param("", float, 1.0), "a declared parameter has no name"),
], ids=["choice-kind", "no-choices", "choice-twice", "choice-range", "str-range", "empty-range", "range-text",
        "open", "no-name"])
def test_a_parameter_declaration_outside_the_rules_is_refused(param: Param, needle: str) -> None:
    refused(declared(params=(param,)), needle)


def test_a_parameter_declared_twice_is_refused() -> None:
    refused(declared(params=(Param("k", int, 1), Param("k", int, 2))), "parameter 'k' is declared twice")


def test_register_refuses_a_bad_grid_and_registers_nothing() -> None:
    class BadGrid(Declared):
        name = "test-bad-grid"
        grid = {"step": (0.5, 7.0)}

    with pytest.raises(SolverDeclarationError, match=r"'test-bad-grid'.*7\.0"):
        register(BadGrid)
    assert "test-bad-grid" not in all_solvers()


# ---------------------------------------------------------------------------
# name[grid]
# ---------------------------------------------------------------------------


class Gridded(Declared):
    name = "test-gridded-spec"
    grid = {"mode": ("b", "a"), "step": (0.5, 1)}


@pytest.fixture
def gridded() -> Any:
    register(Gridded, replace=True)
    yield Gridded
    unregister(Gridded.name)


def test_the_grid_word_is_read_beside_fixed_parameters() -> None:
    parts = split_solver_spec("x[ grid ,k=1]")
    assert (parts.name, parts.raw, parts.grid) == ("x", {"k": "1"}, True)
    assert not split_solver_spec("x[k=1]").grid and split_solver_spec("x[grid]").raw == {}
    with pytest.raises(SolverSpecError, match="'grid' given twice"):
        split_solver_spec("x[grid,grid]")


def test_name_grid_is_the_cross_product_of_the_grid_in_its_order(gridded: type) -> None:
    specs, solver = expand_solver_spec("test-gridded-spec[grid]")
    assert isinstance(solver, Gridded)
    assert [s.params for s in specs] == [{"mode": "b", "step": 0.5}, {"mode": "b", "step": 1.0},
                                         {"mode": "a", "step": 0.5}, {"mode": "a", "step": 1.0}]
    assert all(type(s.params["step"]) is float for s in specs)  # each value as its Param reads it
    assert [s.label for s in specs][:2] == ["test-gridded-spec[mode=b,step=0.5]", "test-gridded-spec[mode=b,step=1.0]"]
    assert specs[0].label == SolverSpec("test-gridded-spec", {"step": 0.5, "mode": "b"}).label  # as if written out


def test_a_fixed_parameter_leaves_the_grid_and_joins_every_variant(gridded: type) -> None:
    specs, _ = expand_solver_spec("test-gridded-spec[grid,step=0.25,flag=yes]")
    assert [s.params for s in specs] == [{"step": 0.25, "flag": True, "mode": "b"},
                                         {"step": 0.25, "flag": True, "mode": "a"}]
    assert grid_points(Gridded(), {"mode": "a", "step": 1.0}) == [{}]


def test_a_fixed_parameter_in_a_grid_spec_is_checked(gridded: type) -> None:
    with pytest.raises(ValueError, match="parameter 'step' must lie in"):
        expand_solver_spec("test-gridded-spec[grid,step=5]")


def test_a_spec_without_the_grid_word_is_one_variant(gridded: type) -> None:
    specs, _ = expand_solver_spec("test-gridded-spec[step=0.5]")
    assert specs == [SolverSpec("test-gridded-spec", {"step": 0.5})]
    assert expand_solver_spec("test-gridded-spec")[0] == [SolverSpec("test-gridded-spec")]


def test_one_variant_parsing_refuses_the_grid_word(gridded: type) -> None:
    with pytest.raises(SolverSpecError, match="every point of a grid"):
        parse_solver_spec("test-gridded-spec[grid]")


def test_a_solver_without_a_grid_refuses_the_grid_word() -> None:
    with pytest.raises(SolverSpecError, match=r"'pk\[grid\]': 'pk' declares no grid"):
        expand_solver_spec("pk[grid]")


def test_a_grid_of_more_points_than_the_limit_is_refused_and_fixing_a_key_brings_it_under() -> None:
    class Big(Declared):
        name = "test-big-grid"
        params = (Param("a", int, 0, low=0), Param("b", int, 0, low=0))
        grid = {"a": tuple(range(MAX_GRID_VARIANTS)), "b": (0, 1)}

    register(Big, replace=True)
    try:
        with pytest.raises(SolverSpecError, match=f"its grid has {2 * MAX_GRID_VARIANTS} points, over the limit of "
                                                  f"{MAX_GRID_VARIANTS}"):
            expand_solver_spec("test-big-grid[grid]")
        assert len(expand_solver_spec("test-big-grid[grid,b=1]")[0]) == MAX_GRID_VARIANTS
    finally:
        unregister("test-big-grid")
