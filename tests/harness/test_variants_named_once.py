"""``contactbench run --solvers`` runs each variant once: two labels of one solver whose
parameters are equal once every default is filled in are refused in one line naming
both, exit 2, before anything runs or is written (harness/run/plan.py
``resolve_solver_names``, solvers/registry.py ``refuse_same_variants``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness.run.plan import resolve_solver_names
from contactbench.solvers.registry import SolverSpec, SolverSpecError
from tests.helpers import run_cli

TINY = ["--size", "16", "--steps", "2", "--seeds", "0", "--no-progress"]


@pytest.mark.parametrize(("solvers", "labels"), [
    ("nnls-gp[K=100],nnls-gp[K=100,lipschitz=frobenius],nnls-gp", ("nnls-gp[K=100]",
                                                                   "nnls-gp[K=100,lipschitz=frobenius]")),
    ("pk,nnls-gp,nnls-gp[restart=no]", ("nnls-gp", "nnls-gp[restart=False]")),
    ("nnls-gp[grid],nnls-gp", ("nnls-gp[K=100]", "nnls-gp")),
    ("cmr+nnls[h=2],cmr+nnls", ("cmr+nnls[h=2.0]", "cmr+nnls")),
], ids=["defaults-written-out", "default-bool", "grid-point-is-the-default", "float-written-as-int"])
def test_run_refuses_one_variant_under_two_labels_before_anything_is_written(
        solvers: str, labels: tuple[str, str], in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = run_cli(["run", "paper-sweep", *TINY, "--solvers", solvers, "--out", "o"], capsys)
    assert rc == 2 and "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"as {labels[0]!r} and {labels[1]!r}" in lines[0], err
    assert list(in_tmp.iterdir()) == []


def test_the_planned_solvers_keep_variants_that_differ_and_refuse_one_named_twice() -> None:
    assert resolve_solver_names("nnls-gp,nnls-gp[K=50],pk", None) == ["nnls-gp", SolverSpec("nnls-gp", {"K": 50}), "pk"]
    with pytest.raises(SolverSpecError, match=r"as 'nnls-gp\[K=50\]' and 'nnls-gp\[K=50,linear=auto\]'"):
        resolve_solver_names(["nnls-gp[K=50]", "nnls-gp[K=50,linear=auto]"], None)
