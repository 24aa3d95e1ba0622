"""The matrix-free constrained CGs: Polonsky-Keer (fast-ccg, fast-pccg) and Bugnicourt et
al. (fast-dual-ccg, fast-dual-pccg), registrations over the loops of solvers/_ccg.py.

fast-ccg
    Polonsky & Keer, Wear 231 (1999) 206 (Bemporad & Paggi 2015, Algorithm 2),
    displacement control: ``_ccg.polonsky_keer`` -- the loop ``pk`` runs too, here with
    the cheap gap update (one matvec per iteration while the projection is inactive).
fast-dual-ccg
    Bugnicourt, Sainsot, Dureisseix, Gauthier & Lubrecht, Tribol. Lett. 66 (2018) 29,
    algorithm OUT_LIN: ``_ccg.bugnicourt``, projected CG on the pixel forces
    (ContactMechanics calls this the "dual" objective: variable = force, gradient = gap)
    with a Polak-Ribiere beta and *no restart*.
fast-pccg, fast-dual-pccg
    the same two iterations with the CG direction preconditioned on the current free
    set (z = M^-1 r instead of r): by default the exact inverses of H over the contact
    islands (solvers/_preconditioners.py) with the far-field correction between them on grid
    tiles (solvers/_farfield.py: "farfield"), or Vollebregt's Fourier |q| preconditioner.

All four take ``params={"precondition": "farfield" | "islands" | "fourier" | "none"}`` (a QP without
grid positions runs unpreconditioned), ``"precision": "double" | "mixed"`` (mixed: float32
inner CCG rounds under float64 iterative refinement, solvers/_refine.py; same fixed point,
tolerance judged in float64), ``"opening": "fourier" | "none" | "auto"`` (a cold solve's first
iterations preconditioned by the wave numbers, the island blocks after: solvers/_opening.py)
and ``"first_guess": "zero" | "coarse"`` (a cold start begins
from the same solver's answer on the block-averaged 2x-coarser grid, recursively,
``_kit.coarse_first_guess``, a hardness posed there as the same pressure; ignored when
warm-started; "auto" takes it for a cold load-controlled solve only: on the paper's cold top
step, 1024^2, it does not cut the fine matvecs -- 87 -> 85 with fast-pccg, 201 -> 197 with
fast-ccg, plus the coarse solves' -- docs/fast-solvers.md, "Coarse first guess").  They minimise the paper's QP (eq. (5)),
min 1/2 p'Hp - ubar'p, p >= 0, stop on the harness's scaled KKT error
(``SolveContext.kkt``) confirmed on a freshly recomputed gap, and are exact.
Warm start: primal (``ctx.p0``), and its support is the first contact set.

Hardness and load (``problems.constraints``): all four pose a hardness (the box
0 <= p <= u): the Polonsky-Keer ones with Almqvist's saturation, the Bugnicourt ones by
projection onto the box (solvers/_ccg.py, ``bugnicourt``).  All four pose load control
as well (sum(p) = P, the approach Delta reported as the multiplier: solvers/_constrained.py,
``polonsky_keer_box`` and ``bugnicourt_load``).  Under constraints the float32 rounds pose
them too (solvers/_refine.py), a load-controlled QP is screened by the approach
(solvers/_screen.py), and the coarse first guess poses them on the coarse grids (a
hardness as the same pressure, ``_kit.coarse_first_guess``).  Without constraints: the
same iterates as the plain loops.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import numpy as np

from ._ccg import FAST_TYPICAL_MATVECS, CCGRun, FastSolver, bugnicourt, outcome, polonsky_keer
from ._constrained import bugnicourt_load, polonsky_keer_box
from ._device import bring_home, cold_if_worse, resident_space, resident_state
from ._kit import FIRST_GUESSES, coarse_first_guess, resolved_first_guess
from ._opening import StagedPreconditioner, opened, opening_param
from ._preconditioners import KINDS, make_preconditioner, resolved_kind
from ._refine import block_dtype, precision_param, resolved_precision, solve_in_precision
from ._screen import screening_param
from .base import Capabilities, Outcome, Param, SolveContext, Solver
from .registry import register

CCGLoop = Callable[..., CCGRun]


def precondition_param(default: str) -> Param:
    return Param("precondition", str, default, "CG direction preconditioned on the free set", choices=KINDS)


def first_guess_param(default: str = "zero") -> Param:
    return Param("first_guess", str, default, "cold start: zero, or the solver's answer on the 2x-coarser grid; "
                 "auto: coarse under load control (a hardness posed there too), zero elsewhere", choices=FIRST_GUESSES)


def starting_point(solver: Solver, ctx: SolveContext) -> tuple[np.ndarray, dict[str, Any]]:
    """The first p on the host: the warm start, else the first guess of
    ``params["first_guess"]`` (``resolved_first_guess``; the coarse solve's matvecs are
    counted, and reported as "coarse_matvecs"; under a hardness the coarse grids pose the
    same one, ``_kit.coarse_first_guess``)."""
    wanted = resolved_first_guess(ctx.params.get("first_guess", "zero"), ctx)
    if ctx.p0 is not None or wanted == "zero":
        return ctx.first_p(), {}
    guess = coarse_first_guess(solver, ctx)
    ctx.add_matvecs(guess.matvecs)
    info = {"first_guess": guess.note, "coarse_matvecs": guess.matvecs, "coarse_iterations": guess.iterations}
    return (np.zeros(ctx.n) if guess.p is None else guess.p), info


#: The products of a typical cold solve of the loops without a preconditioner
#: (``FastSolver.typical_matvecs``; results/perf/cost-law.md: 85-363 at 256^2-4096^2, about
#: 2.5x the preconditioned loops').
PLAIN_TYPICAL_MATVECS = 150.0


class _FastCCG(FastSolver):
    """A constrained CG loop of solvers/_ccg.py with the preconditioner of
    ``params["precondition"]``, in the precision of ``params["precision"]``, from the
    first guess of ``params["first_guess"]``."""

    params = (precondition_param("none"), precision_param(), first_guess_param(), screening_param(),
              opening_param())

    #: The loop of solvers/_ccg.py (``staticmethod(polonsky_keer)`` or ``(bugnicourt)``).
    loop: ClassVar[CCGLoop]
    #: The loop for a QP with a hardness or a load (None: ``loop`` poses them itself).
    constrained_loop: ClassVar[CCGLoop | None] = None
    #: Grid points from which ``precondition="auto"`` takes the far field on the host
    #: (``_preconditioners.resolved_kind``; None: that module's rule).
    far_field_from: ClassVar[int | None] = None
    #: Whether "auto" takes the island kinds for a non-periodic step under a load alone that
    #: the caller warm-started with little of it in contact (``_preconditioners.
    #: WARM_LOAD_MAX_CONTACT``: the Bugnicourt loop's measurement; a cold solve's screening
    #: rounds keep the wave numbers, as measured).
    warm_load_islands: ClassVar[bool] = False

    def iterate_on(self, ctx: SolveContext) -> Outcome:
        """The loop on ``ctx``'s QP as it is (``FastSolver.iterate`` screens it first)."""
        precision = resolved_precision(ctx.params["precision"], ctx.qp)
        kind = resolved_kind(ctx.params["precondition"], ctx.qp, warm=ctx.p0 is not None, far_from=self.far_field_from,
                             warm_load_contact=ctx.caller_warm_contact() if self.warm_load_islands else None)
        space, where = resident_space(ctx, kind)
        dtype = block_dtype(precision)
        M = opened(make_preconditioner(kind, ctx.qp, dtype, space), ctx, dtype, space,
                   auto_kind=ctx.params["precondition"] == "auto")
        ctx.mark_setup_done()
        p0, info = starting_point(self, ctx)
        state = resident_state(ctx, space, p0)
        info.update(cold_if_worse(ctx, state))
        loop = self.loop if ctx.constraints.plain or self.constrained_loop is None else self.constrained_loop
        run, more = solve_in_precision(ctx, state, loop, M)
        bring_home(ctx, state)
        info.update(more)
        info.update(where)
        info["preconditioner"] = kind
        if M is not None:
            info["preconditioner_builds"] = M.builds
        if isinstance(M, StagedPreconditioner):
            info["opening"] = "fourier"
        return outcome(state, run, info)


@register
class FastPolonskyKeer(_FastCCG):
    """Polonsky-Keer CCG (1999; paper Algorithm 2), ``_ccg.polonsky_keer``; warm start:
    primal (see module doc)."""

    name = "fast-ccg"
    description = "Polonsky-Keer constrained CG on the FFT operator, warm-started (Wear 1999)"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), needs_dense=False, warm_start="primal",
                                exact=True, load_control=True, bounds=True)

    loop = staticmethod(polonsky_keer)
    constrained_loop = staticmethod(polonsky_keer_box)
    typical_matvecs = PLAIN_TYPICAL_MATVECS


@register
class FastBugnicourtCCG(_FastCCG):
    """Bugnicourt et al. (2018) constrained CG without restart, ``_ccg.bugnicourt``; warm
    start: primal (see module doc)."""

    name = "fast-dual-ccg"
    description = "Bugnicourt et al. 2018 constrained CG without restart on the forces (ContactMechanics' 'dual'), FFT operator"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), needs_dense=False, warm_start="primal",
                                exact=True, load_control=True, bounds=True)

    loop = staticmethod(bugnicourt)
    constrained_loop = staticmethod(bugnicourt_load)
    typical_matvecs = PLAIN_TYPICAL_MATVECS


@register
class FastPolonskyKeerIslands(FastPolonskyKeer):
    """Polonsky-Keer CCG with the island block-Jacobi preconditioner (solvers/_preconditioners.py):
    the CG direction on the contact set S is z = B_S^-1 r with B_S the blocks of H over the
    8-connected islands of S (cut into compact grid patches of at most 128 points, fewer while the set
    is large; islands of up to 512 points whole where the build affords it: solvers/_partition.py),
    refactored when S drifts by 20 %; an entering point gets the force
    -tau g_j / H_jj (solvers/_ccg.py, "Preconditioned entry"), plus by default the far-field
    coupling between the blocks (solvers/_farfield.py, ``precondition="farfield"``), which
    the loop drops if it stops making progress (solvers/_ccg.py, "Cycling");
    ``precondition="islands"`` keeps the blocks alone.  Its default, ``"auto"``, is the far
    field, and under load control and on a device the wave-number preconditioner.
    Same fixed point and KKT test as fast-ccg; warm start: primal.  Without grid
    positions (QP.geometry) it runs unpreconditioned."""

    name = "fast-pccg"
    description = "Polonsky-Keer CCG preconditioned by exact inverses of the contact islands' blocks, FFT operator"
    #: auto by default: the far field on the host at every grid size (0.81-0.88x the islands'
    #: time on the paper's cold top step, 1024^2-4096^2; at 512^2 the islands took 1.035x,
    #: median of 16 members); the wave numbers under load control, where this loop with the
    #: island blocks cycled (the 256^2 load sweep: seven of ten steps ran out of iterations at
    #: a KKT error of 0.05-0.14; with the wave numbers 41-53 products a step) and on a device
    params = (precondition_param("auto"), precision_param(), first_guess_param(), screening_param(),
              opening_param())
    far_field_from = 0
    typical_matvecs = FAST_TYPICAL_MATVECS

    def uses_islands(self) -> bool:
        """The memory model's blocks: "auto" is the far field on the host under displacement
        control, at every grid size."""
        return True


@register
class FastBugnicourtIslands(FastBugnicourtCCG):
    """Bugnicourt et al. (2018) CCG without restart, with the island block-Jacobi
    preconditioner on the free set {res != 0} (Polak-Ribiere beta on z = M^-1 res).
    Both choices are ``auto`` by default, decided by the grid: the islands' far-field
    correction ("farfield", solvers/_farfield.py) from 1024^2 grid points
    (``_preconditioners.FAR_FIELD_GRID_POINTS``; from 512^2 for a warm step of a non-periodic
    problem, ``WARM_FAR_FIELD_GRID_POINTS``), the islands alone below; under load control the
    wave numbers, but for a warm non-periodic step without a hardness and with little contact
    (``WARM_LOAD_MAX_CONTACT``); mixed precision
    (float32 inner sweeps, float64 iterative refinement judged by the float64 KKT error,
    solvers/_refine.py) from 512^2 (``_preconditioners.MIXED_GRID_POINTS``), float64 below.
    ``precondition`` and ``precision`` fix either.  Warm start: primal."""

    name = "fast-dual-pccg"
    description = "Bugnicourt et al. 2018 CCG preconditioned by exact inverses of the contact islands' blocks, FFT operator"
    #: auto by default: the far field and float32 where they pay for their set-up (1024^2 and 512^2 grid points up)
    #: and a cold, unconstrained solve opened by the wave numbers (solvers/_opening.py); a cold
    #: load-controlled one started from the coarser grids (``_kit.resolved_first_guess``)
    params = (precondition_param("auto"), precision_param("auto"), first_guess_param("auto"), screening_param(),
              opening_param("auto"))
    warm_load_islands = True
    typical_matvecs = FAST_TYPICAL_MATVECS
