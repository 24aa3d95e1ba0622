"""The variants one command names are one each (solvers/registry.py
``refuse_same_variants``): a label named twice, or two labels of one solver whose
parameters are equal once every default is filled in, is refused in one line naming
both labels; variants that differ in a parameter, or solvers that differ, are kept."""

from __future__ import annotations

import pytest

from contactbench.solvers.registry import NamedVariant, SolverSpecError, get_solver, refuse_same_variants


def variants(*named: tuple[str, str, dict[str, object] | None]) -> list[NamedVariant]:
    """``NamedVariant``s of (label, registered solver's name, parameters given)."""
    return [NamedVariant(label, get_solver(name), params) for label, name, params in named]


@pytest.mark.parametrize(("named", "labels"), [
    ((("nnls-gp[K=100]", "nnls-gp", {"K": 100}), ("nnls-gp", "nnls-gp", None)), ("nnls-gp[K=100]", "nnls-gp")),
    ((("nnls-gp", "nnls-gp", {}), ("nnls-gp[K=100,lipschitz=frobenius]", "nnls-gp",
                                    {"K": 100, "lipschitz": "frobenius"})),
     ("nnls-gp", "nnls-gp[K=100,lipschitz=frobenius]")),
    ((("nnls-gp[K=50]", "nnls-gp", {"K": 50}), ("nnls-gp[K=50,restart=False]", "nnls-gp", {"K": 50, "restart": False})),
     ("nnls-gp[K=50]", "nnls-gp[K=50,restart=False]")),
    ((("cmr+nnls", "cmr+nnls", None), ("cmr+nnls[h=2.0]", "cmr+nnls", {"h": 2.0})), ("cmr+nnls", "cmr+nnls[h=2.0]")),
], ids=["default-given", "defaults-given", "one-default-given", "float-default"])
def test_two_labels_of_one_solver_with_the_same_full_parameters_are_refused_naming_both(
        named: tuple[tuple[str, str, dict[str, object] | None], ...], labels: tuple[str, str]) -> None:
    with pytest.raises(SolverSpecError) as err:
        refuse_same_variants(variants(*named), "--solvers")
    line = str(err.value)
    assert "\n" not in line and line.startswith("--solvers names one variant twice"), line
    assert f"as {labels[0]!r} and {labels[1]!r}" in line and "defaults are filled in" in line, line


def test_variants_that_differ_in_a_parameter_or_in_their_solver_are_kept_beside_a_refused_pair() -> None:
    kept = variants(("nnls-gp", "nnls-gp", None), ("nnls-gp[K=50]", "nnls-gp", {"K": 50}),
                    ("nnls-gp[restart=True]", "nnls-gp", {"restart": True}), ("nnls", "nnls", None),
                    ("gp", "gp", None), ("pk", "pk", None))
    refuse_same_variants(kept, "--solvers")
    with pytest.raises(SolverSpecError, match=r"as 'nnls-gp\[restart=True\]' and 'nnls-gp\[K=100,restart=yes\]'"):
        refuse_same_variants([*kept, *variants(("nnls-gp[K=100,restart=yes]", "nnls-gp", {"K": 100, "restart": True}))],
                             "--solvers")


def test_a_label_named_twice_is_refused_as_named_twice() -> None:
    with pytest.raises(SolverSpecError, match=r"^the command line names the variant 'nnls-gp\[K=50\]' twice; "):
        refuse_same_variants(variants(("nnls-gp[K=50]", "nnls-gp", {"K": 50}), ("pk", "pk", None),
                                      ("nnls-gp[K=50]", "nnls-gp", {"K": 50})), "the command line")
