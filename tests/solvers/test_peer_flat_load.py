"""Peers under load control on a flat surface (every height equal, ubar = 0) end with an
answer our judge accepts: cm-pk-ccg's tolerances are read on the judge's load-aware
displacement scale (a tolerance of 0 kept ContactMechanics' PK iterating to its limit), and
tamaas-kato-saturated answers a flat periodic field itself (Tamaas' KatoSaturated does not
return on one, whatever its ``max_iter``).  Skipped where the peer package is not installed."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.solvers import SolverSettings, get_solver
from contactbench.solvers.base import SolveContext
from contactbench.solvers.peer_tamaas import TamaasKatoSaturated

CM_OK, CM_WHY = get_solver("cm-pk-ccg").availability()
TM_OK, TM_WHY = get_solver("tamaas-kato-saturated").availability()
needs_cm = pytest.mark.skipif(not CM_OK, reason=CM_WHY)
needs_tamaas = pytest.mark.skipif(not TM_OK, reason=TM_WHY)
CHECK_TOL = 1e-8


def flat_load_instance(kernel: str, periodic: bool, hardness: float | None = None,
                       N: int = 8) -> ContactInstance:
    """A flat N x N surface pressed by a dimensionless load of 1e-3 (a mean pressure of 1 MPa)."""
    b = InstanceBuilder(Surface(np.zeros((N, N)), 1e-6, periodic=periodic), 1e9, kernel, periodic=periodic)
    return b.build_load(b.load_force(1e-3), hardness=hardness)


@needs_cm
def test_cm_pk_tolerance_is_above_zero_on_a_flat_surface() -> None:
    inst = flat_load_instance("love", periodic=False)
    solver = get_solver("cm-pk-ccg")
    seen: dict[str, float] = {}
    tolerance = type(solver).tolerance

    def record(self: Any, ctx: SolveContext, gp: Any) -> float:
        seen["pentol"] = tolerance(self, ctx, gp)
        raise StopIteration  # the tolerance is all this test reads

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(type(solver), "tolerance", record, raising=True)
        with pytest.raises(StopIteration):
            solver.solve(inst.qp)
    assert np.max(np.abs(inst.qp.ubar)) == 0.0
    assert seen["pentol"] > 0.0


@needs_cm
@pytest.mark.parametrize("kernel", ["love", "bcc"])
def test_cm_pk_converges_on_a_flat_surface_under_load(kernel: str) -> None:
    inst = flat_load_instance(kernel, periodic=False)
    res = get_solver("cm-pk-ccg").solve(inst.qp, SolverSettings(max_iter=200))
    assert res.converged and res.iterations < 200
    assert judge(inst, res.p, res.converged, CHECK_TOL, multiplier=res.multiplier).status == "solved"


def never_called(*args: object, **kwargs: object) -> Any:
    raise AssertionError("Tamaas' KatoSaturated was called")


@needs_tamaas
@pytest.mark.parametrize("hardness", [None, 2e6])
def test_tamaas_kato_saturated_answers_a_flat_field_without_tamaas(monkeypatch: pytest.MonkeyPatch,
                                                                   hardness: float | None) -> None:
    monkeypatch.setattr(TamaasKatoSaturated, "make", never_called)
    inst = flat_load_instance("spectral", periodic=True, hardness=hardness)
    res = get_solver("tamaas-kato-saturated").solve(inst.qp)
    assert res.converged and res.iterations == 0 and res.info["answered_by_adapter"]
    assert judge(inst, res.p, res.converged, CHECK_TOL, multiplier=res.multiplier).status == "solved"


@needs_tamaas
def test_tamaas_kato_saturated_still_runs_tamaas_on_a_rough_field(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(TamaasKatoSaturated, "make", never_called)
    s = rmd_surface_n(8, 0.7, length=100e-6, rms_height=1e-6, seed=2)
    b = InstanceBuilder(s, 1e9, "spectral", periodic=True)
    with pytest.raises(AssertionError, match="KatoSaturated was called"):
        get_solver("tamaas-kato-saturated").solve(b.build_load(b.load_force(1e-3)).qp)
