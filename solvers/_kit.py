"""The one helper kit of the solvers (not a solver module: the registry skips "_" names).

* ``conjugate_gradient`` -- CG on an SPD operator (optionally ``a H + c I``), warm
  started from x0, optionally preconditioned, stopping on ||b - Ax||_inf <= atol, a
  deadline and an iteration cap (paper Algorithm 1 steps 2.1-2.4; PCG as in
  Golub & Van Loan, Algorithm 11.5.1).
* ``lipschitz_constant`` -- ||H||_F (paper Algorithm 4) or a power-iteration estimate.
* ``cholesky_of_h`` -- the lower Cholesky factor of a dense (sub)matrix of H, scaled and
  shifted, within the memory budget.
* ``absolute_tol`` -- a relative tolerance in the problem's units (displacement, force),
  for a solver's internal thresholds (which element is "negative", a CG's atol).
* ``is_dense``.
* ``coarse_first_guess`` -- a cold start's first guess from the same solver on the
  block-averaged 2x-coarser grid (``problems.coarsen``), prolonged by injection.
* ``serial_blas`` -- BLAS on one thread for the span of a matrix-free loop (its doc).
* ``product_seconds`` / ``matvec_seconds`` / ``cholesky_seconds`` -- the rough cost model
  of ``time_estimate`` (``WHOLE_GRID_FFT_POINTS``, ``TYPICAL_PK_LOAD_ITERATIONS``: its
  load-control terms).

The solve lifecycle itself (deadline, trace, matvec count, warm start, tolerance) is in
``contactbench.solvers.base``; the stopping residual is ``SolveContext.kkt``, the
harness's own formula (``contactbench.problems.kkt``).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
import scipy.linalg as sla
from threadpoolctl import ThreadpoolController

from contactbench.problems import operators
from contactbench.problems.coarsen import block_average, coarse_load_qp, coarse_qp, level_trial_set, posable
from contactbench.problems.constraints import uniform_hardness
from contactbench.problems.errors import MemoryBudgetError
from contactbench.problems.kkt import constrained_scales, kkt_figures
from contactbench.problems.operators import (
    ContactOperator,
    DenseOperator,
    check_dense_budget,
    dense_block_pays,
    dense_nbytes,
    dense_switch_enabled,
    spectral_norm_estimate,
)

from .base import Deadline, SolveContext, Solver, SolverSettings

Vector = np.ndarray
LinearMap = Callable[[Vector], Vector]


@dataclass
class CGResult:
    x: np.ndarray
    iterations: int
    residual: float  # ||b - A x||_inf, absolute
    converged: bool
    matvecs: int


def conjugate_gradient(
    matvec: LinearMap | ContactOperator,
    b: np.ndarray,
    x0: np.ndarray | None,
    atol: float,
    max_iter: int,
    deadline: Deadline | None = None,
    precond: LinearMap | None = None,
    scale: float = 1.0,
    shift: float = 0.0,
) -> CGResult:
    """Solve (scale A + shift I) x = b by (preconditioned) CG from x0 until
    ||b - (scale A + shift I) x||_inf <= atol.  ``matvec`` is a function or an operator
    (its ``matvec``); ``precond`` applies M^-1 (SPD).  On reaching atol the residual is
    recomputed from x once to confirm it (recurrence drift).  A run whose residual has not
    halved in ``stagnation_window(n)`` iterations stops there, unconverged (a singular,
    inconsistent system: a periodic whole grid's H 1 = 0 took greedy-cg 100,000 iterations)."""
    n = b.size
    if n == 0:
        return CGResult(np.zeros(0), 0, 0.0, True, 0)
    op = matvec.matvec if isinstance(matvec, ContactOperator) else matvec
    mv = 0

    def amul(v: np.ndarray) -> np.ndarray:
        nonlocal mv
        mv += 1
        out = op(v)
        if scale != 1.0:
            out = out * scale
        if shift:
            out = out + shift * v
        return out

    x = np.zeros(n) if x0 is None else np.array(x0, dtype=np.float64, copy=True)
    r = b - amul(x) if np.any(x) else b.copy()
    res = float(np.max(np.abs(r)))
    z = precond(r) if precond is not None else r
    d = z.copy()
    rz = float(r @ z)
    it = 0
    window, halved, last = stagnation_window(n), res, 0
    while res > atol and it < max_iter and not (deadline is not None and deadline.expired()):
        if it - last > window:
            break
        q = amul(d)
        dq = float(d @ q)
        if not dq > 0.0:  # d = 0, loss of positive definiteness by round-off, or NaN: stop here
            break
        alpha = rz / dq
        x += alpha * d
        r -= alpha * q
        res = float(np.max(np.abs(r)))
        it += 1
        if res <= 0.5 * halved:
            halved, last = res, it
        if res <= atol:  # confirm on the true residual
            r = b - amul(x)
            res = float(np.max(np.abs(r)))
            if res <= atol:
                break
            z = precond(r) if precond is not None else r
            d = z.copy()
            rz = float(r @ z)
            continue
        z = precond(r) if precond is not None else r
        rz_new = float(r @ z)
        d *= rz_new / rz if rz > 0.0 else 0.0  # rz = 0 (r'M^-1 r lost to round-off): restart along z
        d += z
        rz = rz_new
    return CGResult(x, it, res, res <= atol, mv)


def stagnation_window(n: int) -> int:
    """CG steps ``conjugate_gradient`` runs on n unknowns without halving its residual
    before it stops: 2n + 100, twice what exact arithmetic needs for CG to finish, with a
    margin for round-off's loss of conjugacy.  (Not for Gauss-Seidel, whose sweeps to halve
    a residual grow with the condition number: a random SPD H of condition 2e4 on 30
    unknowns took 81,668 sweeps to converge.)"""
    return 2 * int(n) + 100


def lipschitz_constant(op: ContactOperator, method: str) -> float:
    """"frobenius": ||H||_F (paper Algorithm 4; a safe upper bound of lambda_max);
    "power": lambda_max by power iteration (spectral_norm_estimate, inflated 1 %)."""
    if method == "frobenius":
        return op.frobenius_norm()
    if method == "power":
        return spectral_norm_estimate(op, iters=50, rtol=1e-4)
    raise ValueError(f"lipschitz must be 'frobenius' or 'power', got {method!r}")


def cholesky_of_h(op: ContactOperator, idx: np.ndarray | None = None, scale: float = 1.0, shift: float = 0.0,
                  what: str = "Cholesky factor of H") -> np.ndarray:
    """Lower L with L L' = scale H[idx, idx] + shift I (idx None: all of ``op``), the
    block gathered by ``op.submatrix``; ``MemoryBudgetError`` (naming ``what``) when the
    block would exceed the memory budget."""
    idx = np.arange(op.n) if idx is None else np.asarray(idx)
    check_dense_budget(idx.size, what=what)
    try:
        A = np.array(op.submatrix(idx, idx), dtype=np.float64, copy=True)
    except MemoryError as exc:  # the gather itself ran out of memory
        raise MemoryBudgetError(what, dense_nbytes(idx.size), operators.DEFAULT_MEMORY_BUDGET) from exc
    if scale != 1.0:
        A *= scale
    if shift:
        A[np.diag_indices_from(A)] += shift
    return sla.cholesky(A, lower=True, overwrite_a=True, check_finite=False)


def cholesky_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with L L' x = b (L from ``cholesky_of_h``)."""
    return sla.cho_solve((L, True), b, check_finite=False)


@dataclass(frozen=True)
class AbsoluteTol:
    """A relative tolerance tol in the problem's units: ``disp`` = tol u_s [length] and
    ``force`` = tol p_s [force], with the scales of the scaled KKT error
    (``contactbench.problems.kkt``) at p = 0: u_s = ||ubar||_inf, p_s = u_s / max diag H
    (capped by the least upper bound under a hardness, ``constrained_scales``)."""

    disp: float
    force: float


def absolute_tol(ctx: SolveContext, tol: float) -> AbsoluteTol:
    """``AbsoluteTol`` of ``tol`` for the problem of ``ctx``."""
    ubar = ctx.qp.ubar
    if not ctx.qp.constraints.plain:
        u_s, p_s = constrained_scales(ubar, ctx.diag_max, ctx.qp.constraints)
        return AbsoluteTol(disp=tol * u_s, force=tol * p_s)
    f = kkt_figures(np.zeros(ubar.size), -ubar, ubar, ctx.diag_max)
    return AbsoluteTol(disp=tol * f.u_scale, force=tol * f.p_scale)


def is_dense(op: ContactOperator) -> bool:
    return isinstance(op, DenseOperator)


#: The choices of the fast solvers' ``first_guess`` for a cold start ("auto":
#: ``resolved_first_guess``).
FIRST_GUESSES = ("zero", "coarse", "auto")
#: No coarse level is made of a grid with fewer points per side than this.
COARSE_MIN_SIDE = 128
#: The coarse solve's tolerance (at most): the coarse grid's own discretisation error is
#: far larger, so solving it tighter buys nothing.
COARSE_TOL = 1e-4
#: ... under load control: the first guess only has to place the load on the right patches
#: for the fine grid's cold round (solvers/_screen.py), which stops at 1e-3 itself.  On the
#: ASPHER race's Fourier problem at 1024^2 the fine solve took the same products after a
#: coarse chain to 1e-2 as to 1e-3 or 1e-4 (58 / 57 / 57), the chain 47 against 58 products.
COARSE_LOAD_TOL = 1e-2


@dataclass
class FirstGuess:
    """A cold start's first guess (None: start from zero) and what it cost: the coarse
    solve's matvecs (each on a grid 4x smaller than the fine one) and iterations."""

    p: np.ndarray | None
    matvecs: int = 0
    iterations: int = 0
    note: str = ""


def prolong(fine_idx: np.ndarray, fine_shape: tuple[int, int], coarse_idx: np.ndarray,
            coarse_shape: tuple[int, int], p_coarse: np.ndarray) -> np.ndarray:
    """Forces on the fine points ``fine_idx`` from those on the 2x-coarser grid by
    injection: each fine point gets a quarter of its parent's force (p is a force; a
    parent covers four fine elements), zero where the parent is off the coarse set."""
    grid = np.zeros(coarse_shape)
    grid.ravel()[coarse_idx] = p_coarse
    i, j = np.divmod(np.asarray(fine_idx), fine_shape[1])
    ci, cj = i // 2, j // 2
    inside = (ci < coarse_shape[0]) & (cj < coarse_shape[1])
    out = np.zeros(fine_idx.size)
    out[inside] = 0.25 * grid[ci[inside], cj[inside]]
    return out


def resolved_first_guess(wanted: str, ctx: SolveContext) -> str:
    """"zero" or "coarse": ``wanted`` with "auto" decided -- "coarse" for a cold solve under
    load control, with or without a hardness, whose own cold round otherwise sheds the load
    from most of the grid (docs/fast-solvers.md, "Coarse first guess"), "zero" elsewhere."""
    if wanted != "auto":
        return wanted
    return "coarse" if ctx.p0 is None and ctx.constraints.load_control else "zero"


def coarse_first_guess(solver: Solver, ctx: SolveContext) -> FirstGuess:
    """``solver`` (with the same parameters, so recursively down to ``COARSE_MIN_SIDE``)
    on the block-averaged 2x-coarser grid -- at the same far-field displacement to
    ``COARSE_TOL``, or under load control at the same total force on the whole level to
    ``COARSE_LOAD_TOL`` -- prolonged (``prolong``); no guess when the QP carries no surface
    or its grid is too small.  A hardness is posed on the coarse level as the same pressure
    (``uniform_hardness``), so the prolonged forces, a quarter of a coarse element's, keep
    under the fine bounds; a box that no single hardness poses gives no guess, nor does a
    layer thinner than the coarse spacing (``coarsen.posable``)."""
    g = ctx.qp.geometry
    c = ctx.constraints
    posed = g is not None and (g.has_surface_under_load if c.load_control else g.has_surface)
    if not posed or min(g.grid_shape) < 2 * COARSE_MIN_SIDE:
        return FirstGuess(None, note="no coarse level (no surface, or grid below 2 x COARSE_MIN_SIDE)")
    hardness = uniform_hardness(c.upper, g.surface.spacing)
    if c.bounded and hardness is None:
        return FirstGuess(None, note="no coarse level (the box is not one hardness)")
    level = block_average(g.surface)
    if not posable(level, g):
        return FirstGuess(None, note="no coarse level (the layer is thinner than its spacing)")
    kind = "dense" if is_dense(ctx.qp.H) else "fft"
    if c.load_control:
        if hardness is not None and hardness * level.area < float(c.load):
            return FirstGuess(None, note="no coarse level (its box cannot carry the load: an odd row or column "
                                         "dropped)")
        qp = coarse_load_qp(level, g, float(c.load), kind, hardness)
        idx = np.asarray(qp.geometry.indices)
    else:
        idx = level_trial_set(level, g)
        if idx.size == 0:
            return FirstGuess(None, note="empty coarse trial set")
        qp = coarse_qp(level, g, idx, kind, hardness)
    least = COARSE_LOAD_TOL if c.load_control else COARSE_TOL
    tol = least if ctx.tol is None else max(ctx.tol, least)
    res = solver.solve(qp, SolverSettings(tol=tol, max_iter=ctx.max_iter, time_limit=ctx.deadline.remaining(),
                                          params=dict(ctx.params)), None)
    p = prolong(g.indices, g.grid_shape, idx, level.shape, np.asarray(res.p, dtype=np.float64))
    return FirstGuess(p, res.matvecs, res.iterations, f"coarse {level.shape[0]}^2 solve: {res.status}")


#: The product model (``product_seconds``; its doc says where and how it was fitted, the
#: measurements are in results/perf/time-model/README.md): the FFT operator's float64
#: product costs ``FFT_PRODUCT_SECONDS`` plus ``FFT_SECONDS_PER_POINT_LOG`` per P log2 P
#: (P: padded grid points); the dense product ``DENSE_PRODUCT_SECONDS`` plus 2 n^2 flops
#: at ``DENSE_FLOPS``.
FFT_PRODUCT_SECONDS = 1.0e-4
FFT_SECONDS_PER_POINT_LOG = 4.0e-10
DENSE_PRODUCT_SECONDS = 2.0e-6
DENSE_FLOPS = 1.0e10
#: A solver's loop around each product (``matvec_seconds``): Python's cost of one step,
#: and its vector work per unknown (projections, dot products, the KKT check); fitted on
#: recorded ``pk`` and fast-solver solves, less the product model (README above).
LOOP_SECONDS = 3.0e-5
LOOP_SECONDS_PER_UNKNOWN = 7.0e-8
#: A dense Cholesky factorisation's throughput (``cholesky_seconds``; LAPACK on the BLAS's threads).
CHOLESKY_FLOPS = 1.0e10
#: Padded FFT grid points per trial-set unknown at the paper's top load step
#: (trial set ~ 14 % of N^2, aperiodic padding x 4).
FFT_POINTS_PER_UNKNOWN = 28.0
#: Padded FFT grid points per unknown when the trial set is the whole grid (load control,
#: ``InstanceBuilder.build_load``): the 2N x 2N padding (aperiodic), none (periodic).
WHOLE_GRID_FFT_POINTS: dict[bool, float] = {False: 4.0, True: 1.0}
#: ``pk``'s typical iterations under load control (``solvers.pk.TYPICAL_PK_ITERATIONS``
#: counts displacement control): load-sweep at 256^2 (whole grid, n = 65536) took 51-74
#: iterations (103-149 matvecs) per step; with a margin.  Read by ``harness.run.skips``.
TYPICAL_PK_LOAD_ITERATIONS = 100


def product_seconds(n: int, kind: str, points_per_unknown: float = FFT_POINTS_PER_UNKNOWN) -> float:
    """Rough wall time of one float64 product with H at size n, no more: the FFT operator's
    on a padded grid of ``points_per_unknown`` points per unknown (default: a trial set,
    ``FFT_POINTS_PER_UNKNOWN``; the whole grid: ``WHOLE_GRID_FFT_POINTS``), or a dense
    one.  A set small enough for the FFT operator's dense block (``operators.dense_block_pays``:
    a sweep's first steps on a large grid) costs that block's product.

    Fitted on a 2-core AMD EPYC VM that other work shared (results/perf/time-model/README.md:
    host, date, commit and the table): the fastest of several short bursts of products of
    the FFT operator (float64, two FFT threads, the FFT path forced) on the paper's trial
    sets of 64^2-1024^2 grids, and of a dense H of n = 64-4,096 (BLAS on one and two
    threads).  The FFT figure is at or above every grid's fastest product and within 2x of
    it; the dense one within about 2x either way (the BLAS runs several times faster on a
    matrix that fits the cache than on one that does not).  A rough, deliberately
    conservative figure for the skip policy, not a prediction for another machine."""
    pts = points_per_unknown * n
    if kind == "dense" or (dense_switch_enabled() and dense_block_pays(n, pts)):
        return DENSE_PRODUCT_SECONDS + 2.0 * n * n / DENSE_FLOPS
    return FFT_PRODUCT_SECONDS + FFT_SECONDS_PER_POINT_LOG * pts * max(1.0, float(np.log2(pts)))


def matvec_seconds(n: int, kind: str, points_per_unknown: float = FFT_POINTS_PER_UNKNOWN) -> float:
    """Rough wall time of one product with H as a solver's loop spends it, the unit of
    every ``time_estimate``: the product (``product_seconds``, same arguments) and the
    loop's own work around it (``LOOP_SECONDS``, ``LOOP_SECONDS_PER_UNKNOWN``)."""
    return product_seconds(n, kind, points_per_unknown) + LOOP_SECONDS + LOOP_SECONDS_PER_UNKNOWN * n


def cholesky_seconds(n: int) -> float:
    """Rough wall time of a dense Cholesky factorisation of n x n (n^3 / 3 flops at
    ``CHOLESKY_FLOPS``)."""
    return (n**3 / 3.0) / CHOLESKY_FLOPS


_BLAS: ThreadpoolController | None = None


@contextmanager
def serial_blas() -> Iterator[None]:
    """BLAS (and only BLAS) on one thread inside the block, the solve's other threads as
    they were.  For the matrix-free loops, whose BLAS calls are level-1 (dot products over
    n, memory bound): a threaded OpenBLAS keeps its threads spinning after each call, and on
    the cores the FFT pool then needs they slow the next product (measured on 2 cores: a
    1024^2 float32 product in a load-controlled solve 27-34 ms with BLAS on 2 threads,
    23-25 ms on 1; results/perf/serial-blas).  The controller is made once (the BLAS
    libraries are loaded by then: numpy's and scipy's)."""
    global _BLAS
    if _BLAS is None:
        _BLAS = ThreadpoolController()
    with _BLAS.limit(limits=1, user_api="blas"):
        yield
