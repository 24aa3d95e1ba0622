"""The constrained loops' stagnations (solvers/_constrained.py, ``_loop_head``): where the
Polonsky-Keer loop under a load cycled, on the island blocks or on the wave numbers, and
what ends it (``SetPreconditioner.simplify(blocks=True)``, the wave numbers' ``solo``)."""

from __future__ import annotations

import pytest

from contactbench.harness.judging import judge
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

E = 1e9


@pytest.mark.parametrize("kind", ["islands", "farfield"])
def test_a_warm_load_step_on_island_blocks_does_not_cycle(kind: str) -> None:
    """``fast-pccg`` with its island kinds asked for, on the second step of the shipped
    ``load-sweep`` (256^2, the whole grid under load control, warm from the first step): the
    P&K loop's set swung for 900 iterations at a KKT error of 0.02-0.06, rebuilding the
    blocks at each, and took 1,700-1,870 products; once its stagnation has dropped what M
    can drop (``IslandPreconditioner.simplify``: the far field, then the blocks) it
    converges in about a tenth of that."""
    from contactbench.harness import solve_sequence
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("load-sweep")
    (spec,) = scene.instances(scene.config(SceneConfig()))
    seq = scene.build(spec)
    steps = solve_sequence("fast-pccg", [seq.at(0), seq.at(1)], SolverSettings(tol=1e-9, params={"precondition": kind}),
                           check_tol=1e-8)
    assert [s.verdict.status for s in steps] == ["solved", "solved"]
    assert steps[1].result.matvecs <= 400, steps[1].result.matvecs


def test_the_pk_loop_on_the_wave_numbers_converges_at_a_high_load() -> None:
    """``fast-pccg``'s defaults (the wave numbers under a load) on a cold step of a 128^2
    non-periodic BCC grid at P/(E* A) = 0.072 (26 % in contact): entering points took
    M^-1's diagonal as their force scale, 1.34x the force that closes a point's own gap,
    and the P&K loop cycled at a KKT error of 0.4-0.7 from its fifth iteration to its
    limit (4,560 iterations); it also had nothing to drop when it stagnated.  Now
    (``FourierPreconditioner.solo`` and ``simplify``) it converges in a few hundred."""
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("paper-sweep")
    cfg = SceneConfig(size=128, seeds=(748,), E=E, extra={"surface_family": "periodic", "control": "load",
                                                          "loads": (0.0722,)})
    (spec,) = scene.instances(scene.config(cfg))
    inst = spec.build().at(0)
    r = get_solver("fast-pccg").solve(inst.qp, SolverSettings(tol=1e-8, max_iter=2000))
    assert r.info["preconditioner"] == "fourier"
    assert r.status == "converged", r.message
    assert judge(inst, r.p, True, 2e-8).status == "solved"
