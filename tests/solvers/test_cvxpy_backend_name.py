"""The ``cvxpy`` adapter's ``solver`` parameter names a CVXPY backend: one that CVXPY has
not installed is refused when the parameters are read (``resolve_params``), naming the
installed ones, so that ``contactbench run`` refuses it before anything runs (exit 2, one
line, no folder); and a backend that returns no point has its status in the message."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contactbench.problems.instances import counterexample
from contactbench.solvers import cvxpy_adapter
from contactbench.solvers._scaling import BackendOutcome
from contactbench.solvers.base import ParamError, SolverSettings
from contactbench.solvers.registry import get_solver

from tests.helpers import run_cli

cp = pytest.importorskip("cvxpy")


def test_a_backend_cvxpy_has_not_installed_is_refused_naming_the_installed_ones() -> None:
    solver = get_solver("cvxpy")
    with pytest.raises(ParamError, match="'NOPE', which is not installed here; installed: ") as caught:
        solver.resolve_params({"solver": "NOPE"})
    assert "\n" not in str(caught.value)
    assert all(name.upper() in str(caught.value) for name in cp.installed_solvers())
    installed = cp.installed_solvers()[0]
    assert solver.resolve_params({"solver": installed.lower()})["solver"] == installed.lower()  # (case-insensitive)
    assert solver.resolve_params({})["solver"] == cvxpy_adapter.DEFAULT_CVXPY_SOLVER


def test_run_refuses_an_unknown_backend_before_anything_runs(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "o"
    rc, _, err = run_cli(["run", "paper-sweep", "--size", "16", "--steps", "2", "--seeds", "0", "--solvers",
                          "cvxpy[solver=NOPE]", "--no-progress", "--out", str(out)], capsys)
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("contactbench: error:") and "not installed" in err, err
    assert "NOPE" in err and not out.exists()


def test_a_backend_that_returns_no_point_has_its_status_in_the_message(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_point(self: Any, sqp: Any, prepared: Any, ctx: Any) -> BackendOutcome:
        return BackendOutcome(None, "error: SolverError: the backend broke", False)

    monkeypatch.setattr(cvxpy_adapter.CVXPYAdapter, "run_backend", no_point)
    res = get_solver("cvxpy").solve(counterexample(16, 0).qp, SolverSettings())
    assert "backend returned no finite solution" in res.message
    assert "error: SolverError: the backend broke" in res.message, res.message
    assert not np.all(np.isfinite(res.p))
