"""``precision="auto"`` (solvers/_refine.py): mixed from ``AUTO_MIXED_MIN_POINTS`` grid
points up, double below; decided by the grid the unknowns sit on, not by their count."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _refine
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver


def small_qp():
    surf = rmd_surface_n(32, 0.7, length=100e-6, seed=3)
    return InstanceBuilder(surf, 1e9, "bcc", periodic=False).build(paper_max_displacement(surf)).qp


def test_auto_is_double_below_the_threshold_and_mixed_from_it() -> None:
    qp = small_qp()
    assert qp.geometry is not None and _refine.grid_points(qp) == 32 * 32
    assert _refine.resolved_precision("auto", qp) == "double"
    geo = qp.geometry
    big = replace(qp, geometry=replace(geo, grid_shape=(2048, 2048)))
    assert _refine.resolved_precision("auto", big) == "mixed"
    just_below = replace(qp, geometry=replace(geo, grid_shape=(2048, 2047)))
    assert _refine.resolved_precision("auto", just_below) == "double"
    # the explicit choices are never changed by the grid
    for p in ("double", "mixed"):
        assert _refine.resolved_precision(p, qp) == p and _refine.resolved_precision(p, big) == p


def test_auto_without_a_geometry_reads_the_unknowns() -> None:
    qp = replace(small_qp(), geometry=None)
    assert _refine.grid_points(qp) == qp.n
    assert _refine.resolved_precision("auto", qp) == "double"


@pytest.mark.parametrize("threshold,expected", [(1, "mixed"), (10**12, "double")])
def test_a_solve_reports_the_precision_auto_chose(monkeypatch: pytest.MonkeyPatch, threshold: int,
                                                   expected: str) -> None:
    monkeypatch.setattr(_refine, "AUTO_MIXED_MIN_POINTS", threshold)
    qp = small_qp()
    res = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=1e-9, params={"precision": "auto"}))
    assert res.converged and res.info["precision"] == expected, res.info
    assert (res.info["matvecs_float32"] > 0) == (expected == "mixed")
    ref = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=1e-9, params={"precision": "double"}))
    assert np.max(np.abs(res.p - ref.p)) <= 100 * 1e-9 * np.max(ref.p)
