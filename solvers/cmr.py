"""Cascade multi-resolution (CMR) wrapper -- Bemporad & Paggi 2015, section 5.1, Algorithm 6.

CMR solves the contact problem on a cascade of representations s = 1..l of the same
surface (coarsest first, spacing delta(s)) at the same far-field displacement Delta:

* (1.1) I_C(s) = {(i, j): xi_ij >= xi_max(s) - Delta}, the rigid-body trial set;
* (1.2) s = 1: I_C,p(1) = I_C(1); s > 1: keep only the points of I_C(s) within
  r <= h * delta(s-1) of a contact point of the level s-1 solution, I_C*(s-1);
* (2-3) build Q on I_C,p(s), solve it with any registered solver, pass I_C*(s) down.

The mathematics of the levels is in ``problems/coarsen.py``: the representations
(``cascade_surfaces``: exact sub-samples z[::s, ::s] -- the RMD generator's own stages
where it kept them -- or block means of s x s fine elements, as ``coarse`` says), their
element positions in the fine frame (``grid_positions``) and the coarse QP of a level
(``coarse_qp``: the rigid-body trial set and ubar at the fine problem's Delta, measured
from the level's OWN maximum xi_max(s)).  This module holds the cascade itself: the
pruning (step 1.2), the solves, and the records; it only picks the levels.

The last level is the QP the harness gave, restricted to the projected set
(``QP.restrict``); the answer is returned on the FULL trial set, zeros outside the
projected set, so the harness's KKT check judges the whole problem honestly (a wrongly
excluded point shows up as a negative gap w_i < 0).  Every level's solution summary is
returned in ``SolveResult.info["levels"]`` (the paper: coarse predictions come for free);
``info["left_out"]`` counts the points outside the fine projected set whose gap is negative
(contacts step 1.2 pruned that the fine answer needs), and where it is not 0 the message
begins by saying so (``left_out_text``), the table's record of why such an answer fails.

Parameters (``Param``s below): ``h`` (area-of-influence factor, default 2), ``coarse``
(``"subsample"``, default: exact sub-samples; ``"mean"``: block means, the cell averages
the paper's heights xi_ij are), ``coarsest`` (points per side of the first level, default
16; a size the surface cannot give, N // 2^j, is refused), ``levels`` (explicit sizes),
``base_params`` (passed to the base), ``repair`` (default False, not in the paper:
re-admit pruned points that overlap and re-solve until none does, which makes the answer
exact).  Each base solve gets the tolerance and iteration limit asked of CMR (when none
is asked, the base's own defaults) and what is LEFT of CMR's time limit, so a CMR solve
never runs past its limit; coarse levels not reached in time are dropped.

Skip policy: ``capabilities.needs_geometry`` -- a problem without a surface
(``ProblemTraits.has_surface`` False, e.g. the counterexample) is skipped, not failed;
so is a surface without the coarse levels a variant asks (``skip_params``: its
``coarsest``, or its ``levels``).
Warm start: a primal warm start for the fine problem is restricted to the projected set
and handed to the base solver when the base accepts one; coarse levels start cold.
The base solver is looked up by registry name at solve time; ``cmr+<base>`` is
registered for the bases in ``CMR_BASES`` (``make_cmr(name)`` wraps any other).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np
from scipy.spatial import cKDTree

from contactbench.problems.coarsen import (
    COARSE_KINDS,
    cascade_surfaces,
    coarse_qp,
    grid_positions,
    level_sizes,
    level_trial_set,
    missing_level,
    posable,
    power_law_check,
)
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, Geometry, OperatorKind, relative_contact_mask
from contactbench.problems.surfaces import Surface

from .base import (
    DEFAULT_TOL,
    Capabilities,
    Outcome,
    Param,
    ParamError,
    ProblemTraits,
    SolveContext,
    SolveResult,
    Solver,
    SolverSettings,
    Status,
    WarmStart,
)
from .registry import all_solvers, get_solver, register

#: Bases for which ``cmr+<base>`` is registered (others: ``make_cmr(name)``).
CMR_BASES: tuple[str, ...] = ("nnls", "pk", "scipy-nnls", "nnls-gp", "fast-ccg", "fast-dual-pccg")
#: With ``repair``, gaps below -REPAIR_GAP * max|ubar| on pruned points count as missed contacts.
REPAIR_GAP = 1e-9
MAX_REPAIR_ROUNDS = 50
#: h values of the paper's Fig. 9 (the sweep grid of ``h``).
PAPER_H_SWEEP: tuple[float, ...] = (1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0)


@dataclass(frozen=True)
class SizesParam(Param):
    """A parameter holding grid sizes (points per side): a list or tuple of ints >= 2."""

    def _coerce(self, value: Any) -> Any:
        ok = isinstance(value, (list, tuple)) and all(
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 2 for v in value)
        if not ok:
            raise ParamError(f"parameter {self.name!r} takes a list of grid sizes (ints >= 2), got {value!r}")
        return tuple(int(v) for v in value)


@dataclass
class LevelRecord:
    """One level of the cascade: its size, the rigid-body trial set n, the projected set
    n_p, time (build + solve, s), total load (sum p), contact fraction A/A0."""

    level: int
    N: int
    delta: float
    n: int
    n_p: int
    n_p_over_n: float
    time: float
    load: float
    contact_fraction: float
    n_contact: int
    converged: bool
    status: str
    iterations: int


@dataclass
class LevelSolution:
    record: LevelRecord
    contact_positions: np.ndarray  # (m, 2) element-centre coordinates in the fine frame


@dataclass
class FineSolution:
    """The fine level: p and its gap w on the full trial set, the last base solve, its
    record, the repair rounds, the matvecs of the base solves, and ``left_out``: the points
    outside the projected set whose gap is negative (``_missed_contacts``), contacts the
    answer leaves out."""

    p: np.ndarray
    w: np.ndarray
    result: SolveResult
    record: LevelRecord
    rounds: int
    matvecs: int
    left_out: int


def within_radius(points: np.ndarray, centres: np.ndarray, radius: float, period: float | None) -> np.ndarray:
    """Mask of ``points`` lying within ``radius`` of any of ``centres`` (Euclidean,
    minimum-image when ``period`` is given)."""
    if centres.shape[0] == 0 or points.shape[0] == 0:
        return np.zeros(points.shape[0], dtype=bool)
    if period is not None:
        tree = cKDTree(np.mod(centres, period), boxsize=period)
        d, _ = tree.query(np.mod(points, period), k=1, distance_upper_bound=radius * (1 + 1e-9))
    else:
        tree = cKDTree(centres)
        d, _ = tree.query(points, k=1, distance_upper_bound=radius * (1 + 1e-9))
    return np.isfinite(d)


class CMRSolver(Solver):
    """CMR (Algorithm 6) over the registered solver ``base``."""

    family = "wrapper"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), needs_dense=False,
                                warm_start="primal", exact=False, needs_geometry=True)
    params: ClassVar[tuple[Param, ...]] = (
        Param("h", float, 2.0, "area-of-influence factor: level s keeps the points within h*delta(s-1) "
              "of a level s-1 contact", low=1.0),
        Param("coarse", str, "subsample", "how coarse levels are made: 'subsample' (exact sub-samples "
              "z[::s, ::s], the RMD generator's stages) or 'mean' (block means of s x s fine elements)",
              choices=COARSE_KINDS),
        Param("coarsest", int, 16, "points per side of the first (coarsest) level, N // 2^j (the study uses "
              "16|32|64)", low=2),
        SizesParam("levels", tuple, None, "explicit points-per-side of the coarse levels (default: all "
                   "from `coarsest` up)"),
        Param("base_params", dict, None, "parameters passed to the base solver"),
        Param("repair", bool, False, "re-admit pruned points that overlap and re-solve (exact; not in the paper)"),
    )
    grid: ClassVar[dict[str, tuple[Any, ...]]] = {"h": PAPER_H_SWEEP}
    #: None: each base solve uses the base's own tolerance unless one is asked.
    default_tol: ClassVar[float | None] = None
    #: A limit bounds each base solve (a level, a repair round: ``info["stages"]``), as the
    #: paper's Algorithm 6 runs its base at each level; the iterations are their sum.
    limit_per_stage = True

    def default_max_iter(self, n: int) -> int | None:
        """None: each base solve uses the base's own iteration limit unless one is asked."""
        return None

    def __init__(self, base: str = "nnls") -> None:
        self.base_name = base
        self.name = f"cmr+{base}"  # type: ignore[misc]
        self.description = (  # type: ignore[misc]
            f"cascade multi-resolution (paper Alg. 6) over {base}: coarse levels prune "
            "the trial set to h*delta(s-1) around the coarser contact set")

    def base(self) -> Solver:
        return get_solver(self.base_name)

    def availability(self) -> tuple[bool, str]:
        b = all_solvers().get(self.base_name)
        if b is None:
            return False, f"base solver {self.base_name!r} is not registered"
        ok, why = b.availability()
        return ok, ("available" if ok else f"base solver {self.base_name!r} unavailable: {why}")

    def memory_estimate(self, n: int) -> float:
        b = all_solvers().get(self.base_name)
        return b.memory_estimate(n) if b is not None else super().memory_estimate(n)

    @property
    def time_scales_with_grid(self) -> bool:  # type: ignore[override]
        """As the base's model."""
        b = all_solvers().get(self.base_name)
        return b.time_scales_with_grid if b is not None else True

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """The base's model at n: the finest level dominates, on a trial set pruned to at
        most the fine one (the coarse levels add a geometric tail)."""
        b = all_solvers().get(self.base_name)
        return b.time_estimate(n, operator_kind) if b is not None else None

    def skip_params(self, traits: ProblemTraits, params: dict[str, Any]) -> str | None:
        """Skipped (a declared capability, not a failure) where the surface cannot give the
        coarse levels ``params`` ask (``coarsest``, or the explicit ``levels``): CMR would
        refuse the problem."""
        if not traits.surface_side:
            return None
        missing = missing_level(traits.surface_side, int(params["coarsest"]), params["levels"])
        if missing is None:
            return None
        what, size = missing
        return (f"{self.name} needs a {what} of {size} points per side; the {traits.surface_side} x "
                f"{traits.surface_side} surface has {sorted(level_sizes(traits.surface_side))}")

    def iterate(self, ctx: SolveContext) -> Outcome:
        g = require_surface(ctx.qp)
        assert g.surface is not None
        base = self.base()
        if base.capabilities.warm_start == "none":
            ctx.p0 = None  # a warm start the base cannot take is not used, and the result says so
        h = float(ctx.params["h"])
        cascade = cascade_surfaces(g.surface, int(ctx.params["coarsest"]), ctx.params["levels"],
                                   kind=str(ctx.params["coarse"]))
        posed = [posable(surf, g) for surf in cascade]  # not where a layer is thinner than the spacing
        coarse = [surf for surf, ok in zip(cascade, posed) if ok]
        dropped = [surf.shape[0] for surf, ok in zip(cascade, posed) if not ok]
        period = g.surface.length if (g.periodic and g.surface.periodic) else None
        op_kind: OperatorKind = "dense" if ctx.qp.H.kind == "DenseOperator" else "fft"

        records: list[LevelRecord] = []
        prev: LevelSolution | None = None
        prev_delta = 0.0
        for surf in coarse:
            if ctx.expired():
                break  # the fine level still gets solved, pruned by the last level reached
            prev = _coarse_level(ctx, len(records) + 1, surf, g, base, prev, h * prev_delta, period, op_kind)
            records.append(prev.record)
            prev_delta = surf.delta
        it0 = sum(r.iterations for r in records)
        fine = _fine_level(ctx, len(records) + 1, g, base, prev, h * prev_delta, period, it0)
        records.append(fine.record)
        ctx.add_matvecs(fine.matvecs)
        power_law, psd_message = _psd_check(g.surface)
        info: dict[str, Any] = {
            "levels": [asdict(r) for r in records],
            "h": h,
            "coarse": str(ctx.params["coarse"]),
            "base": self.base_name,
            "n_p_over_n": fine.record.n_p_over_n,
            "cascade": [r.N for r in records],
            "psd_power_law": power_law,
            "repair_rounds": fine.rounds,
            "left_out": fine.left_out,
            "stages": " ".join([f"N{r.N}" for r in records[:-1]]
                               + [f"N{fine.record.N}:round{k}" for k in range(fine.rounds + 1)]),
        }
        summary = (f"CMR {'->'.join(str(r.N) for r in records)} h={h:g} coarse={ctx.params['coarse']}: n_p/n={fine.record.n_p_over_n:.4f} "
                   f"coarse-loads=[{', '.join(f'{r.load:.6g}' for r in records[:-1])}]")
        if dropped:
            info["levels_not_posed"] = dropped
            summary = f"{summary}; levels {dropped} not posed (the layer is thinner than their spacing)"
        msg = f"{summary}; base: {fine.result.message}" if fine.result.message else summary
        if fine.left_out:  # first: the worker keeps a message's first 500 characters
            msg = f"{left_out_text(fine.left_out, bool(ctx.params['repair']))}; {msg}"
        if not power_law:
            info["warnings"] = [psd_message]
            msg = f"{msg}; WARNING: {psd_message}"
        converged, status = bool(fine.result.converged), _status_of(fine.result.status)
        full_kkt = ctx.kkt(fine.p, fine.w)
        claim_tol = claim_tolerance(ctx, base)
        if converged and not full_kkt <= claim_tol:
            # The base converged on the pruned trial set only: CMR does not claim the full problem.
            converged, status = False, Status.STALLED
            msg = (f"{msg}; the pruned problem converged, but the full problem's scaled KKT error is "
                   f"{full_kkt:.2e} > tol {claim_tol:.1e}")
        return Outcome(p=fine.p, iterations=sum(r.iterations for r in records), converged=converged,
                       message=msg, w=fine.w, status=status, info=info)


def left_out_text(k: int, repair: bool) -> str:
    """The message's first words when the answer leaves out ``k`` contact points
    (``FineSolution.left_out``): where the cascade lost them, and what re-admits them."""
    fix = "repair ran out of rounds or time" if repair else "repair=True re-admits them"
    return (f"left out {k} contact points at a pruned level (negative gap outside the projected set: step 1.2 of "
            f"Algorithm 6 as printed; {fix})")


def claim_tolerance(ctx: SolveContext, base: Solver) -> float:
    """The scaled KKT error of the FULL problem at or under which CMR passes on its base's
    claim of convergence: the tolerance asked, else the base's own ``default_tol``, else
    (a base that leaves its backend's defaults, such as scipy-nnls) the caller's check,
    else ``DEFAULT_TOL``, the tolerance of a solver that declares none.  Never None: a
    claim is always checked."""
    for t in (ctx.tol, base.default_tol, ctx.check_tol):
        if t is not None:
            return float(t)
    return DEFAULT_TOL


def require_surface(qp: QP) -> Geometry:
    """The QP's geometry when it carries what CMR rebuilds the levels from (its surface on
    the QP's grid, Delta, E, kernel), else a clear ``ProblemInputError``."""
    g = qp.geometry
    if g is None or g.surface is None or g.far_field is None or g.E is None or g.kernel is None:
        raise ProblemInputError("CMR needs the QP's geometry with its surface, far-field displacement, E and "
                                "kernel (instances built by problems.instances.InstanceBuilder carry them)")
    if not g.has_surface:
        raise ProblemInputError(f"CMR: QP grid {g.grid_shape} does not match its surface {g.surface.shape}")
    return g


def base_settings(ctx: SolveContext) -> SolverSettings:
    """Settings of one base solve: CMR's tolerance, check and iteration limit (None: the
    base's own), ``base_params``, and the time LEFT of CMR's deadline."""
    return SolverSettings(tol=ctx.tol, max_iter=ctx.max_iter, time_limit=ctx.deadline.remaining(),
                          params=dict(ctx.params["base_params"] or {}), check_tol=ctx.check_tol)


def _coarse_level(ctx: SolveContext, s: int, surf: Surface, g: Geometry, base: Solver,
                  prev: LevelSolution | None, radius: float, period: float | None,
                  op_kind: OperatorKind) -> LevelSolution:
    """Steps (1.1)-(3) on a coarse representation (its QP from ``problems.coarsen``)."""
    t = time.perf_counter()
    idx_all = level_trial_set(surf, g)
    idx = idx_all[_projection(grid_positions(surf, idx_all), prev, radius, period)]
    p = np.zeros(idx.size)
    res = SolveResult(p=p, converged=True, status="empty")
    if idx.size:
        res = base.solve(coarse_qp(surf, g, idx, op_kind), base_settings(ctx), None)
        p = np.asarray(res.p, dtype=np.float64)
    c = relative_contact_mask(p)
    rec = _record(s, surf, idx_all.size, idx.size, time.perf_counter() - t, p, c, res)
    return LevelSolution(rec, grid_positions(surf, idx[c]))


def _fine_level(ctx: SolveContext, s: int, g: Geometry, base: Solver, prev: LevelSolution | None,
                radius: float, period: float | None, it0: int) -> FineSolution:
    """The given QP restricted to the projected set; p returned on the full set.

    With ``repair`` (not in the paper): pruned points whose gap comes out negative
    were wrongly excluded; they are added to the set and the restricted problem is
    solved again, warm started, until no pruned point overlaps (or the time is up) --
    the answer is then the exact solution of the full QP, and the cascade only chose
    the start."""
    t = time.perf_counter()
    qp, surf = ctx.qp, g.surface
    assert surf is not None
    pos = np.flatnonzero(_projection(grid_positions(surf, g.indices), prev, radius, period))
    p_full = np.zeros(qp.n)
    res = SolveResult(p=np.zeros(0), converged=True, status="empty")
    matvecs = 0
    warm = _restricted_warm(ctx, pos)
    rounds = -1
    while True:
        if pos.size:
            t_start = ctx.trace.elapsed()
            res = base.solve(qp.restrict(pos), base_settings(ctx), warm)
            matvecs += res.matvecs
            p_full[:] = 0.0
            p_full[pos] = np.asarray(res.p, dtype=np.float64)
            _replace_trace(ctx, res, it0, t_start)
        w = qp.H.matvec(p_full) - qp.ubar
        rounds += 1
        if not ctx.params["repair"] or rounds >= MAX_REPAIR_ROUNDS or ctx.expired():
            break
        missed = _missed_contacts(qp, w, pos)
        if missed.size == 0:
            break
        pos = np.union1d(pos, missed)
        warm = WarmStart(p=p_full[pos])  # a base that takes none is handed none by its lifecycle
    rec = _record(s, surf, qp.n, int(pos.size), time.perf_counter() - t, p_full, relative_contact_mask(p_full), res)
    return FineSolution(p_full, w, res, rec, rounds, matvecs, int(_missed_contacts(qp, w, pos).size))


def _restricted_warm(ctx: SolveContext, pos: np.ndarray) -> WarmStart | None:
    """CMR's warm start restricted to the projected set (``iterate`` dropped it already
    when the base takes none)."""
    if ctx.p0 is None:
        return None
    w = None if ctx.warm is None or ctx.warm.w is None else np.asarray(ctx.warm.w)[pos]
    return WarmStart(p=ctx.p0[pos], w=w)


def _replace_trace(ctx: SolveContext, res: SolveResult, it0: int, t_start: float) -> None:
    """CMR's trace = the last fine-level base solve's trace, after the cascade's coarse
    iterations and time.  Its final point (a residual of the restricted problem) is left
    out: the lifecycle appends the full problem's final iterate."""
    pts = [(it0 + int(it), t_start + float(t), float(r)) for it, t, r in res.trace]
    if pts and pts[-1][0] == it0 + int(res.iterations):
        pts.pop()
    ctx.trace.points[:] = pts


def _missed_contacts(qp: QP, w: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Positions outside ``pos`` whose gap w = Hp - ubar is negative beyond round-off."""
    out = np.ones(qp.n, dtype=bool)
    out[pos] = False
    return np.flatnonzero(out & (w < -REPAIR_GAP * float(np.max(np.abs(qp.ubar), initial=0.0))))


def _projection(points: np.ndarray, prev: LevelSolution | None, radius: float,
                period: float | None) -> np.ndarray:
    """Step (1.2): all points on the first level, else those near the coarser contacts."""
    if prev is None:
        return np.ones(points.shape[0], dtype=bool)
    return within_radius(points, prev.contact_positions, radius, period)


def _record(s: int, surf: Surface, n: int, n_p: int, elapsed: float, p: np.ndarray, c: np.ndarray,
            res: SolveResult) -> LevelRecord:
    return LevelRecord(level=s, N=surf.N, delta=surf.delta, n=int(n), n_p=int(n_p),
                       n_p_over_n=float(n_p) / max(int(n), 1), time=elapsed, load=float(np.sum(p)),
                       contact_fraction=float(np.count_nonzero(c)) / surf.heights.size,
                       n_contact=int(np.count_nonzero(c)), converged=bool(res.converged),
                       status=str(res.status), iterations=int(res.iterations))


def _status_of(status: str) -> Status | None:
    """The base's status when it is one of ``Status`` (else None: the lifecycle derives it)."""
    try:
        return Status(status)
    except ValueError:
        return None


_PSD_CACHE: dict[tuple[str, int, float, float], tuple[bool, str]] = {}


def _psd_check(surface: Surface) -> tuple[bool, str]:
    """(power_law, message) of problems.coarsen.power_law_check, cached per surface."""
    key = (surface.name, surface.N, surface.delta, float(surface.heights.sum()))
    if key not in _PSD_CACHE:
        try:
            c = power_law_check(surface)
            _PSD_CACHE[key] = (c.power_law, c.message)
        except ProblemInputError as e:
            _PSD_CACHE[key] = (True, f"PSD check skipped: {e}")
    return _PSD_CACHE[key]


def make_cmr(base: str) -> CMRSolver:
    """A CMR wrapper over any registry name (registered or not)."""
    return CMRSolver(base)


for _b in CMR_BASES:
    register(CMRSolver(_b))

__all__ = ["CMR_BASES", "CMRSolver", "LevelRecord", "PAPER_H_SWEEP", "make_cmr", "within_radius"]
