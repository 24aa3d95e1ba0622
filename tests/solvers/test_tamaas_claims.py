"""Tamaas' load-controlled solvers are claimed on Tamaas' own convergence figure:
KatoSaturated's solve returns 0.0 whether it converged or was stopped at max_iter, so the
adapter reads its ``computeError``; a solve stopped early is not claimed, and the judge
agrees.  Tamaas exposes no iteration count: the outcome says so (``peer_iterations`` None,
the message names it) instead of reading 0 as a count.  Skipped where Tamaas is not
installed."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import SolverSettings, get_solver
from contactbench.solvers.peer_tamaas import ITERATIONS_NOT_REPORTED

TM_OK, TM_WHY = get_solver("tamaas-kato-saturated").availability()
needs_tamaas = pytest.mark.skipif(not TM_OK, reason=TM_WHY)
CHECK_TOL = 1e-8
LOAD_CONTROLLED = ("tamaas-kato-saturated", "tamaas-kato", "tamaas-beck-teboulle", "tamaas-condat", "tamaas-pkr")


def rough_load_instance(hardness: float | None = 1e8) -> ContactInstance:
    """A rough periodic 16 x 16 spectral surface under a dimensionless load of 1e-2."""
    s = rmd_surface_n(16, 0.7, length=100e-6, rms_height=1e-6, seed=2)
    b = InstanceBuilder(s, 1e9, "spectral", periodic=True)
    return b.build_load(b.load_force(1e-2), hardness=hardness)


@needs_tamaas
def test_kato_saturated_stopped_early_is_not_claimed() -> None:
    inst = rough_load_instance()
    r = get_solver("tamaas-kato-saturated").solve(inst.qp, SolverSettings(max_iter=3))
    verdict = judge(inst, r.p, r.converged, CHECK_TOL, multiplier=r.multiplier)
    assert not r.converged and r.status == "max_iter", r.message
    assert r.info["peer_error"] > CHECK_TOL
    assert verdict.status != "solved" and verdict.correct_claim


@needs_tamaas
def test_kato_saturated_run_to_its_end_is_claimed_and_solved() -> None:
    inst = rough_load_instance()
    r = get_solver("tamaas-kato-saturated").solve(inst.qp)
    verdict = judge(inst, r.p, r.converged, CHECK_TOL, multiplier=r.multiplier)
    assert r.converged and 0.0 < r.info["peer_error"] <= CHECK_TOL, r.message
    assert verdict.status == "solved" and verdict.correct_claim


@needs_tamaas
@pytest.mark.parametrize("name", LOAD_CONTROLLED)
def test_the_iteration_count_is_reported_unknown(name: str) -> None:
    inst = rough_load_instance(hardness=1e8 if name == "tamaas-kato-saturated" else None)
    r = get_solver(name).solve(inst.qp, SolverSettings(max_iter=50))
    assert r.info["peer_iterations"] is None
    assert ITERATIONS_NOT_REPORTED in r.message
    assert np.isfinite(r.info["peer_error"])
