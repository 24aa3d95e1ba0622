"""Why fast-pccg with the far-field correction stalls on the paper's 4096^2 cold top step
(a diagnosis, not a benchmark; docs/fast-solvers.md "The far-field correction").

Runs ``fast-pccg`` (Polonsky-Keer, preconditioned) on the paper-sweep scene's top step at
grid size N with ``precondition=<kind>`` under a time limit, and logs per iteration: the
scaled KKT figures (primal / dual / complementarity, ``problems.kkt.kkt_figures``) of the
running gap and the size of the contact set, then the projections that followed (how many
points entered or were clipped, the force raised) and the far-field (re)builds.  It wraps
private functions of solvers/_ccg.py and solvers/_preconditioners.py to observe them;
nothing is changed.

Usage: python benchmarks/diagnose_pk_farfield.py N farfield|islands TIME_LIMIT_S
The run of 2026-11-23 (N = 4096, farfield, 200 s; committed in 92225c1, 2-core Intel Xeon VM) is
results/perf/pk-farfield-4096.log.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from contactbench.problems.kkt import kkt_figures
from contactbench.problems.scenes import get_scene
from contactbench.problems.scenes.base import SceneConfig
from contactbench.solvers import _ccg
from contactbench.solvers import _preconditioners as precond
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

Event = tuple[str, Any, Any, int]


def top_step(N: int):
    """The paper-sweep scene's top load step at grid size N (as bench_cost_law solves it)."""
    scene = get_scene("paper-sweep")
    (spec,) = scene.instances(scene.config(SceneConfig(size=N, steps=10)))
    seq = scene.build(spec)
    return seq.at(len(seq) - 1)


def observe(log: list[Event]) -> None:
    """Wrap the projection, the far-field build and the KKT checkpoint to append events."""
    raise_forces = _ccg.GapState.raise_forces
    update_far_field = precond.IslandPreconditioner._update_far_field
    checkpoint = _ccg.checkpoint

    def raising(state, cols, amounts):
        log.append(("raise", int(cols.size), float(amounts.sum()), int((state.p > 0).sum())))
        return raise_forces(state, cols, amounts)

    def building(M, S):
        before = M._far_set
        update_far_field(M, S)
        if M._far_set is not before:
            log.append(("farbuild", int(S.sum()), M._far is not None, 0))

    def checking(ctx, state, done, first):
        run = checkpoint(ctx, state, done, first)
        f = kkt_figures(state.p, state.g, ctx.qp.ubar, ctx.diag_max, ctx.ubar_scale())
        log.append(("kkt", done, f"{f.primal:.1e}/{f.dual:.1e}/{f.complementarity:.1e}", int((state.p > 0).sum())))
        return run

    _ccg.GapState.raise_forces = raising
    precond.IslandPreconditioner._update_far_field = building
    _ccg.checkpoint = checking


def main() -> None:
    N, kind, limit = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
    inst = top_step(N)
    log: list[Event] = []
    observe(log)
    t0 = time.perf_counter()
    res = get_solver("fast-pccg").solve(inst.qp, SolverSettings(tol=1e-9, time_limit=limit,
                                                                 params={"precondition": kind}))
    print(f"N={N} n={inst.n} precondition={kind}: {time.perf_counter() - t0:.1f} s, {res.status}, "
          f"{res.iterations} iterations, {res.matvecs} matvecs, {res.info}")
    print("every 8th checkpoint: (kkt, iteration, primal/dual/complementarity, |S|) and the events after it")
    checks = [i for i, e in enumerate(log) if e[0] == "kkt"]
    for i in checks[::8]:
        print(log[i], log[i + 1:i + 4])
    builds = [e for e in log if e[0] == "farbuild"]
    print(f"far-field builds: {len(builds)}; the last five {builds[-5:]}")


if __name__ == "__main__":
    main()
