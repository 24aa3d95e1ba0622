"""Every option of the fast solvers on rough surfaces of 16^2-72^2 converges.

Hypothesis draws a surface (RMD or Fourier synthesis, Hurst 0.3-0.9, periodic or not), a
control (displacement, load, a hardness, or both: a load on a box), how far in, and for each
fast solver that poses the control one value of each option it declares with a list of choices (the
preconditioners, the precision, the opening, the first guess, screening), cold or from the
answer of a step 10 % shallower mapped by grid index (a sweep's warm start).  Each must
converge within its own iteration limit to an answer the harness's judge accepts.  Grids
this small reach every option's code (an explicit option overrides the grid-size rules of
"auto"); the knife edges of 2 x 2 to 12 x 12 grids are tests/solvers/test_degenerate_steps.py's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from contactbench.harness.judging import judge
from contactbench.harness.run.sequence import map_by_grid_index
from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import QP, ContactInstance, InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import fourier_synthesis, rmd_surface_n
from contactbench.solvers.base import SolverSettings, WarmStart, constraint_skip
from contactbench.solvers.registry import get_solver
from tests.helpers import drawn_options

E = 1e9
TOL = 1e-9
FAST = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "fast-pdas")
CONTROLS = ("displacement", "load", "hardness", "load+hardness")


@dataclass(frozen=True)
class Rough:
    """A drawn case: the surface (``side`` points a side: RMD where the side is 2^k or
    2^k + 1, else Fourier synthesis), the control, the approach as a fraction of the
    paper's top step, and the hardness as a fraction of the largest elastic pressure."""

    side: int
    hurst: float
    periodic: bool
    seed: int
    depth: float
    control: str
    hardness: float


def builder(r: Rough) -> InstanceBuilder:
    rmd = r.side & (r.side - 1) == 0 or (r.side - 1) & (r.side - 2) == 0
    s = (rmd_surface_n(r.side, r.hurst, length=1e-4, seed=r.seed) if rmd
         else fourier_synthesis(r.side, r.hurst, 0.1, length=1e-4, seed=r.seed))
    return InstanceBuilder(s, E, "spectral" if r.periodic else "bcc", periodic=r.periodic)


def posed(r: Rough, b: InstanceBuilder, depth: float) -> ContactInstance:
    """The case at ``depth`` x the paper's top step (its load, under load control)."""
    inst = b.build(depth * paper_max_displacement(b.surface))
    if r.control == "displacement":
        return inst
    elastic = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-10)).p
    load = float(np.sum(elastic))
    bound = r.hardness * float(np.max(elastic))
    if r.control == "hardness":
        return with_box(inst, make_constraints(inst.n, np.full(inst.n, bound), None))
    loaded = b.build_load(load)
    if r.control == "load":
        return loaded
    return with_box(loaded, make_constraints(loaded.n, np.full(loaded.n, max(bound, 1.2 * load / loaded.n)), load))


def with_box(inst: ContactInstance, c) -> ContactInstance:
    qp = inst.qp
    return replace(inst, qp=QP(qp.H, qp.ubar, qp.geometry, c))


roughs = st.builds(
    Rough,
    side=st.sampled_from([16, 17, 24, 33, 48, 64, 72]),
    hurst=st.sampled_from([0.3, 0.5, 0.7, 0.9]),
    periodic=st.booleans(),
    seed=st.integers(0, 99),
    depth=st.sampled_from([0.02, 0.05, 0.3, 1.0]),
    control=st.sampled_from(CONTROLS),
    hardness=st.sampled_from([0.05, 0.3, 0.9]),
)


@settings(max_examples=30, deadline=None, derandomize=True, phases=(Phase.explicit, Phase.generate),
          suppress_health_check=[HealthCheck.too_slow])
@given(roughs, st.booleans(), st.data())
@example(Rough(64, 0.5, False, 78, 0.05, "load+hardness", 0.9), False, None)  # one summit's load on a box
@example(Rough(48, 0.5, True, 31, 0.05, "load+hardness", 0.3), True, None)
def test_every_option_converges_on_rough_surfaces(r: Rough, warm: bool, data: st.DataObject | None) -> None:
    b = builder(r)
    inst = posed(r, b, r.depth)
    shallower = posed(r, b, 0.9 * r.depth) if warm else None
    c = inst.qp.constraints
    for name in FAST:
        solver = get_solver(name)
        if constraint_skip(solver.capabilities, c.load_control, c.bounded) is not None:
            continue
        params = drawn_options(data, name)
        start = None
        if shallower is not None:
            prev = get_solver(name).solve(shallower.qp, SolverSettings(tol=TOL, params=params))
            start = WarmStart(p=map_by_grid_index(prev.p, shallower.qp.geometry.indices, inst.qp.geometry.indices))
        res = solver.solve(inst.qp, SolverSettings(tol=TOL, params=params), start)
        assert res.converged, (name, params, res.status, res.message)
        assert judge(inst, res.p, True, 2 * TOL).status == "solved", (name, params)
