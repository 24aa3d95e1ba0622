"""Mixed precision (float32 inner CCG, float64 iterative refinement; solvers/_refine.py):
the same answer as float64, judged in float64, on every fast solver."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.profiles import PROFILES
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import scaled_kkt_error
from contactbench.problems.operators import ContactOperator
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _refine
from contactbench.solvers.base import Solver, SolverSettings
from contactbench.solvers.registry import get_solver

pytestmark = pytest.mark.skipif(not hasattr(ContactOperator, "with_precision"),
                                reason="ContactOperator.with_precision (the float32 operator) is not in this checkout")

FAST = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "fast-pdas")
#: |p_mixed - p_double|_inf / max p <= SPREAD * tol: two exact float64 solvers at the same
#: tolerance differ by up to ~25 tol on these instances (the KKT error bounds p only up to
#: the conditioning of H on the contact set), and mixed vs double is measured within that.
SPREAD = 100.0


def instance(N: int, periodic: bool, seed: int = 1):
    surf = rmd_surface_n(N, 0.7, length=100e-6, seed=seed)
    return InstanceBuilder(surf, 1e9, "bcc", periodic=periodic).build(paper_max_displacement(surf))


def float64_kkt(qp, p: np.ndarray) -> float:
    """The judge's figure, recomputed here from a float64 matvec."""
    return scaled_kkt_error(p, qp.H.matvec(p) - qp.ubar, qp.ubar, float(np.max(qp.H.diagonal())))


def solve(name: str, qp, tol: float, precision: str):
    return get_solver(name).solve(qp, SolverSettings(tol=tol, params={"precision": precision}))


@pytest.mark.parametrize("N,periodic", [(32, False), (64, True), (128, False), (256, True)])
@pytest.mark.parametrize("profile", ["low", "mid", "high"])
@pytest.mark.parametrize("name", ["fast-ccg", "fast-dual-pccg"])
def test_mixed_gives_the_float64_answer(name: str, profile: str, N: int, periodic: bool) -> None:
    if N >= 256 and profile != "high":
        pytest.skip("medium instances: the tightest profile only (time)")
    inst = instance(N, periodic)
    tol = PROFILES[profile].tol
    double = solve(name, inst.qp, tol, "double")
    mixed = solve(name, inst.qp, tol, "mixed")
    assert double.converged and mixed.converged, (double.message, mixed.message)
    assert mixed.info["precision"] == "mixed" and mixed.info["matvecs_float32"] > 0, mixed.info
    assert float64_kkt(inst.qp, mixed.p) <= tol
    scale = float(np.max(double.p))
    assert np.max(np.abs(mixed.p - double.p)) <= SPREAD * tol * scale
    assert abs(mixed.p.sum() - double.p.sum()) <= 10 * tol * double.p.sum()


def test_mixed_counts_both_precisions_and_spends_few_float64_matvecs() -> None:
    inst = instance(64, False)
    res = solve("fast-dual-pccg", inst.qp, 1e-9, "mixed")
    info = res.info
    assert info["matvecs_float64"] <= 2 * info["refinement_rounds"] + 2
    assert info["matvecs_float32"] > info["matvecs_float64"]
    assert res.matvecs >= info["matvecs_float32"] + info["matvecs_float64"]


@pytest.mark.parametrize("kkt", [1.0, 1e-3, 1.01e-4, 1e-4, 1e-5, 1e-8, 1e-12, float("inf")])
def test_a_round_is_asked_for_tol_when_its_loose_target_is_within_reach(kkt: float) -> None:
    tol = 1e-9
    asked = _refine.round_tolerance(tol, kkt)
    loose = _refine.INNER_REDUCTION * kkt
    assert asked >= tol
    assert asked == (tol if loose <= _refine.LAST_ROUND_REACH * tol else loose)


def test_a_round_near_tol_saves_the_third_round(monkeypatch: pytest.MonkeyPatch) -> None:
    """On this instance the second round starts near 8e-5: asked 8e-9, it stops short of
    1e-9 and a third round follows; asked 1e-9, two rounds do."""
    inst = instance(128, False)
    asked: list[tuple[float, float]] = []
    plain = _refine.inner_context

    def spy(ctx, kkt, used):
        out = plain(ctx, kkt, used)
        asked.append((kkt, out.tol))
        return out

    monkeypatch.setattr(_refine, "inner_context", spy)
    near = solve("fast-dual-pccg", inst.qp, 1e-9, "mixed")
    fired = [(k, t) for k, t in asked if t == 1e-9 and _refine.INNER_REDUCTION * k > 1e-9]
    assert fired, asked
    monkeypatch.setattr(_refine, "LAST_ROUND_REACH", 0.0)
    short = solve("fast-dual-pccg", inst.qp, 1e-9, "mixed")
    assert near.converged and short.converged
    assert float64_kkt(inst.qp, near.p) <= 1e-9
    assert near.info["refinement_rounds"] < short.info["refinement_rounds"]
    assert near.matvecs < short.matvecs


def test_mixed_warm_start_is_primal_and_cheaper() -> None:
    from contactbench.solvers.base import WarmStart

    inst = instance(64, True)
    cold = solve("fast-ccg", inst.qp, 1e-9, "mixed")
    warm = get_solver("fast-ccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"precision": "mixed"}),
                                        WarmStart(p=cold.p))
    assert warm.converged and warm.warm_started
    assert warm.matvecs < cold.matvecs


def test_fast_pdas_mixed_runs_its_inner_cg_in_float32() -> None:
    inst = instance(64, False)
    res = solve("fast-pdas", inst.qp, 1e-9, "mixed")
    assert res.converged and res.info["inner_matvecs_float32"] > 0
    assert float64_kkt(inst.qp, res.p) <= 1e-9


def mixed_variant(name: str) -> Solver:
    """The registered solver with ``precision="mixed"`` as its default (unregistered)."""
    cls = type(get_solver(name))
    params = tuple(replace(p, default="mixed") if p.name == "precision" else p for p in cls.params)
    return type(f"{cls.__name__}Mixed", (cls,), {"name": f"{name}+mixed", "params": params})()


@pytest.mark.parametrize("name", FAST)
def test_every_fast_solver_in_mixed_precision_conforms(name: str) -> None:
    table = cf.validate(mixed_variant(name))
    assert table.outcome() == "conforms", table.format()
    assert table.count("pass") > 0 and not table.unsolved, table.format()
