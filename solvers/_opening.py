"""The opening of a cold solve (not a solver module: the registry skips "_" names): the
wave-number preconditioner for a cold start's first iterations, the island one after --
the fast CCGs' ``opening`` parameter.

Why.  A cold start's free set is the whole trial set, and the first iterations shed most of
it.  Island blocks serve that phase poorly: on a set that large they are small
(``_preconditioners.BUILD_BUDGET``: 16-point patches on 160,000 points at 1024^2), the far
field is not built on it (``_farfield.MAX_SET_FRACTION``), and each 20 % drift of the set
costs a build.  On the held-out Saupe H 0.9 member of the surface population (1024^2, seed
3: 163,577 trial points, 31,399 in contact at the answer) the steps of fast-dual-pccg stayed
at 0.01-0.06 of a preconditioned CG's natural step of 1 for 40 iterations, with 24 builds:
117 matvecs against the population's median of 48.  The wave-number preconditioner
(``FourierPreconditioner``) needs no build and shed that set to a KKT error of 5e-3 in 8
iterations.  Left on for the whole solve it is slower on a settled set, where the islands
and their far field win (134 iterations against 75 on that member).

So a staged preconditioner (``StagedPreconditioner``) runs the wave-number one until the
loop tells it (``progress``) that the scaled KKT error is at most ``OPENING_KKT`` while the
free set has stopped shedding fast (``OPENING_SETTLED``), then the island kind the solver
would have used from the start; the loop restarts its conjugacy at the switch.  "auto"
opens this way where it was measured to pay: a cold start (a warm start begins near its
answer), no constraints beyond p >= 0, the island kinds on the host, and products that
are not a dense block (``operators.runs_dense_blocks``).  Figures: results/perf/opening.
"""

from __future__ import annotations

import numpy as np

from contactbench.problems.operators import runs_dense_blocks
from contactbench.problems.operators_gpu import HOST, ArraySpace

from ._preconditioners import FourierPreconditioner, IslandPreconditioner, SetPreconditioner, drifted, grid_points
from .base import Param, SolveContext

#: The opening's preconditioner runs until the loop's scaled KKT error is at most this.
OPENING_KKT = 0.03

#: ... and the free set has changed in at most this fraction of its points since the last
#: check: the KKT error of a set still shedding can dip below the threshold for an iteration
#: (results/perf/opening).
OPENING_SETTLED = 0.3

#: The island stage of an opened solve, and a warm solve, build their far field on sets of up
#: to this fraction of the unknowns (``IslandPreconditioner.far_fraction``; a cold unopened
#: solve: ``_farfield.MAX_SET_FRACTION``, which keeps it off the shrinking trial sets that the
#: opening now serves).  Without it the opening's island stage went without its far field for
#: most of a large set's last shedding (results/perf/opening); a warm start's sets are contact
#: sets from its first step (solvers/_ccg.py, "A warm start's first iterations"), and on the
#: smooth members of the population's 512^2 sweeps (H 0.9, contact above a fifth of the trial
#: set) the far field came only with this fraction (results/perf/warm-far-field).
OPENED_FAR_FRACTION = 0.5

#: An opened solve whose preconditioner "auto" chose takes the far field from this many grid
#: points (an unopened one: ``_preconditioners.FAR_FIELD_GRID_POINTS``, 1024^2).  Over the
#: surface population at 512^2 (results/perf/opened-farfield-512, quiet 2-core vm, 32 members
#: on seeds 0-1 and 32 held out on seeds 3-4): matvecs median / worst 44 / 77 -> 37 / 47 and
#: 44.5 / 115 -> 39.5 / 58, seconds per member median 0.94x and 0.87x, no member with more
#: products.  A warm step is not opened; its far field is
#: ``_preconditioners.WARM_FAR_FIELD_GRID_POINTS``'s (it paid only once its first steps were
#: held on its contact set).
OPENED_FAR_FIELD_GRID_POINTS = 512 * 512

#: The openings a fast CCG takes: "fourier" (module doc), "none" (the solver's
#: preconditioner from the start), "auto" (``resolved_opening``).
OPENINGS = ("fourier", "none", "auto")


def opening_param(default: str = "none") -> Param:
    """The one declaration of the fast CCGs' ``opening`` parameter."""
    return Param("opening", str, default,
                 "a cold solve's first iterations: fourier (the wave-number preconditioner until the "
                 f"KKT error is {OPENING_KKT}, the island blocks after), none (the preconditioner throughout); "
                 "auto: fourier for a cold, unconstrained solve with the island blocks on the host, its "
                 "products not a dense block",
                 choices=OPENINGS)


def resolved_opening(opening: str, M: SetPreconditioner | None, ctx: SolveContext) -> str:
    """"fourier" or "none": ``opening`` with "auto" decided (module doc; not where the
    products are dense blocks, ``operators.runs_dense_blocks``: a wave-number application,
    an FFT pair on the whole grid, costs more than the product; on the periodic 512^2
    sweep's first step, 47 points, 10 ms of its 28); "none" wherever M is not an
    island preconditioner (nothing to open for)."""
    if not isinstance(M, IslandPreconditioner):
        return "none"
    if opening == "auto":
        cold_plain = ctx.p0 is None and ctx.constraints.plain
        return "fourier" if cold_plain and not runs_dense_blocks(ctx.qp.H) else "none"
    return opening


def opened(M: SetPreconditioner | None, ctx: SolveContext, dtype: type = np.float64,
           space: ArraySpace = HOST, auto_kind: bool = False) -> SetPreconditioner | None:
    """M, or M opened by the wave-number preconditioner (in ``dtype``, on ``space``) when
    ``ctx.params["opening"]`` resolves to "fourier"; then, where M's kind was "auto"'s
    (``auto_kind``), with the far field from ``OPENED_FAR_FIELD_GRID_POINTS``.  Opened or
    warm-started, island blocks take their far field on sets of up to ``OPENED_FAR_FRACTION``."""
    if isinstance(M, IslandPreconditioner) and ctx.p0 is not None:
        M.far_fraction = OPENED_FAR_FRACTION
    if resolved_opening(ctx.params.get("opening", "none"), M, ctx) != "fourier":
        return M
    first = FourierPreconditioner.build(ctx.qp, space, dtype)
    if first is None or not isinstance(M, IslandPreconditioner):  # (the second: as resolved_opening)
        return M
    M.far_fraction = OPENED_FAR_FRACTION
    if auto_kind and grid_points(ctx.qp) >= OPENED_FAR_FIELD_GRID_POINTS:
        M.far_field = True
    return StagedPreconditioner(first, M)


class StagedPreconditioner:
    """``first`` until ``progress`` is told a scaled KKT error of at most ``OPENING_KKT`` with
    the free set changed in at most ``OPENING_SETTLED`` of its points since the last call,
    then ``then`` for the rest of the solve (module doc).  Each stage is symmetric positive
    definite on the set, so the loop's CG stays valid between the switch and its restart."""

    def __init__(self, first: SetPreconditioner, then: SetPreconditioner) -> None:
        self.first, self.then = first, then
        self.now = first
        self._seen: np.ndarray | None = None  # the free set at the last check

    @property
    def builds(self) -> int:
        return self.first.builds + self.then.builds

    @property
    def version(self) -> int:
        return self.first.version + self.then.version

    @property
    def opening(self) -> bool:
        """Whether the first stage is still on."""
        return self.now is self.first

    @property
    def on(self) -> np.ndarray:
        return self.now.on

    def update(self, S: np.ndarray) -> None:
        self.now.update(S)

    def apply(self, r: np.ndarray) -> np.ndarray:
        return self.now.apply(r)

    def solo(self, r: np.ndarray) -> np.ndarray:
        return self.now.solo(r)

    def ones(self) -> np.ndarray:
        return self.now.ones()

    def simplify(self, blocks: bool = False) -> bool:
        """The second stage's coarse part (or blocks), once it is on (the first has none)."""
        return not self.opening and self.then.simplify(blocks)

    def progress(self, kkt: float) -> bool:
        """Switch to the second stage at a KKT error of at most ``OPENING_KKT`` on a set that
        has settled (class doc); True when this call switched (the loop restarts its
        conjugacy)."""
        if not self.opening:
            return False
        settled = not drifted(self.on, self._seen, OPENING_SETTLED)
        self._seen = self.on.copy()
        if kkt <= OPENING_KKT and settled:
            self.now = self.then
            return True
        return False
