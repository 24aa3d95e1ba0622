"""``contactbench validate`` takes a solver's variants as ``run`` does: ``NAME[k=v]``
validates that variant, ``NAME[grid]`` each point of the solver's declared grid, each
labelled as ``run`` labels it; a bad entry is refused in one line, exit 2
(harness/conformance/command.py ``named_candidates``)."""

from __future__ import annotations

import pytest

from contactbench.harness.conformance.command import main as validate_main
from contactbench.solvers.registry import SolverSpec, get_solver, grid_points
from tests.helpers import refused_in_one_line

SMALL = ["--cases", "edge/single-point*", "--quiet"]


def test_a_grid_entry_validates_every_point_under_its_own_label(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["nnls-gp[grid]", *SMALL]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    labels = [SolverSpec("nnls-gp", point).label for point in grid_points(get_solver("nnls-gp"))]
    assert len(labels) > 1 and [line.split(" [fast]")[0] for line in lines] == labels
    assert all("CONFORMS" in line for line in lines)


def test_a_variant_entry_validates_that_variant_beside_a_plain_name(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["nnls-gp[K=5]", "pk", *SMALL]) == 0
    assert [line.split(" [fast]")[0] for line in capsys.readouterr().out.strip().splitlines()] == ["nnls-gp[K=5]", "pk"]


@pytest.mark.parametrize("argv, says", [
    (["pk[grid]"], "declares no grid"),
    (["nnls-gp[K=-5]"], "parameter 'K' must lie in"),
    (["nnls-gp[K=5]", "--params", '{"K": 3}'], "--params goes with plain solver names"),
    (["no-such-solver[K=5]"], "no-such-solver"),
    (["nnls-gp[K=1_0]"], "parameter 'K' takes a whole number, got '1_0'"),
], ids=["no-grid", "bad-value", "params-twice", "unknown", "not-written-plainly"])
def test_a_bad_variant_entry_is_refused_in_one_line(argv: list[str], says: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main([*argv, *SMALL]) == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1


@pytest.mark.parametrize("argv, says", [
    (["nnls-gp[K=100]", "nnls-gp"], "names one variant twice, as 'nnls-gp[K=100]' and 'nnls-gp'"),
    (["nnls-gp", "pk", "nnls-gp[lipschitz=frobenius,restart=off]"],
     "as 'nnls-gp' and 'nnls-gp[lipschitz=frobenius,restart=False]'"),
    (["nnls-gp[grid]", "nnls-gp[K=50]"], "names the variant 'nnls-gp[K=50]' twice"),
    (["nnls-gp", "pk", "nnls-gp"], "names the variant 'nnls-gp' twice"),
], ids=["default-given", "defaults-given", "grid-point-named-again", "name-given-twice"])
def test_one_variant_named_twice_is_refused_naming_its_labels(argv: list[str], says: str,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert says in refused_in_one_line([*argv, *SMALL], capsys)
