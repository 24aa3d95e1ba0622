"""Device-resident solves of the fast CCGs (not a solver module: the registry skips "_"
names): where a solve keeps its vectors, and their one trip there and back.

A fast CCG runs with ubar, p, its gap and its directions in the array space of its
operator (``ContactOperator.space``: an ``ArrayFFTOperator`` on CuPy, or on NumPy -- the
same code, the path the CPU tests run) when its preconditioner runs there too:
``DEVICE_KINDS``, the wave-number one (FFTs) or none, and no hardness (whose bounds are a
host array).  The loops of solvers/_ccg.py and solvers/_constrained.py are written once:
NumPy's functions dispatch to the arrays' own module (NEP 18), arrays are made "like"
the state's, and inside the loop only scalars (inner products, norms, the KKT figures)
are read on the host.  Per solve -- per screening round, solvers/_screen.py -- ubar and
the start go to the space once, and p and its gap come back once.  The exact finish's set
crosses when a loop calls it (at most ``_finish.FINISH_MAX_POINTS`` entries); the partial
products of raised forces gather from the kernel table's quarter on the device
(``ArrayFFTOperator.partial_product``), uploaded once per operator.

On an operator with a space a solve whose preconditioner cannot run there (the island
kinds: dense block factorisations on the host) runs its loop on the host, each product
crossing the bus, and says so in ``info["array_space"]``.

Where the state starts: ``resident_state`` at the start the solver chose, and
``cold_if_worse`` back at p = 0 when a warm start is farther from the answer than that.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from contactbench.problems.operators_gpu import HOST, ArraySpace

from ._ccg import GapState
from .base import SolveContext

#: The preconditioners whose work runs in the operator's array space.
DEVICE_KINDS = ("fourier", "none")


def resident_space(ctx: SolveContext, kind: str) -> tuple[ArraySpace, dict[str, Any]]:
    """The space the solve's vectors live in, for the resolved preconditioner ``kind``, and
    what ``info`` records of it ("array_space": the space's name, or "host" and why;
    nothing for an operator without a space)."""
    space = ctx.qp.H.space
    if space is None:
        return HOST, {}
    if kind not in DEVICE_KINDS:
        return HOST, {"array_space": f"host (the {kind!r} preconditioner runs on the host)"}
    if ctx.constraints.bounded:
        return HOST, {"array_space": "host (a hardness bound runs on the host)"}
    return space, {"array_space": space.name}


def resident_state(ctx: SolveContext, space: ArraySpace, p0: np.ndarray) -> GapState:
    """The state at the host start ``p0`` with ubar and p moved to ``space`` (the host: as
    they are)."""
    return GapState(ctx.qp.H, space.put(ctx.qp.ubar), space.put(p0), space=space)


def cold_if_worse(ctx: SolveContext, state: GapState) -> dict[str, str]:
    """Move ``state`` (at the warm start, its gap exact) to p = 0 when the warm start's
    scaled KKT error is not below the cold start's -- a start farther from the answer than
    no force at all (or not finite): on a periodic grid a uniform p0 of 1e30 left every fast
    CCG stalled at an error of 1e50, where a cold start converges.  Only without constraints
    (under a load or a hardness the loops first move p0 into the feasible set, which undoes
    its size).  The gap at p = 0 is -ubar: no matvec.  What ``info`` records of it (nothing
    when the warm start stands)."""
    if ctx.p0 is None or not ctx.constraints.plain:
        return {}
    zero = state.space.xp.zeros_like(state.p)
    if ctx.kkt(state.p, state.g) <= ctx.kkt(zero, -state.ubar):
        return {}
    state.p = zero
    state.refresh()
    return {"warm_start": "dropped: its KKT error was not below a cold start's"}


def bring_home(ctx: SolveContext, state: GapState) -> None:
    """p and the gap back on the host (once, at the end of the solve); the host's state is
    left as it is."""
    if state.space.host:
        return
    get = state.space.get
    state.p, state.g, state.ubar, state.space = get(state.p), get(state.g), ctx.qp.ubar, HOST
