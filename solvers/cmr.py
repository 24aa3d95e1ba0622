"""Cascade multi-resolution (CMR) wrapper -- Bemporad & Paggi 2015, section 5.1, Algorithm 6.

CMR solves the contact problem on a cascade of representations s = 1..l of the same
surface (coarsest first, spacing delta(s)) at the same far-field displacement Delta:

* (1.1) I_C(s) = {(i, j): xi_ij >= xi_max(s) - Delta}, the rigid-body trial set;
* (1.2) s = 1: I_C,p(1) = I_C(1); s > 1: keep only the points of I_C(s) within
  r <= h * delta(s-1) of a contact point of the level s-1 solution, I_C*(s-1);
* (2-3) build Q on I_C,p(s), solve it with any registered solver, pass I_C*(s) down.

The last level is the QP the harness gave: its operator is restricted to the projected
set (``H.restrict``) and the answer is returned on the FULL trial set, zeros outside
the projected set, so the harness's KKT check judges the whole problem honestly (a
wrongly excluded point shows up as a negative gap w_i < 0).

Representations: the surface's own ``levels`` (random midpoint displacement keeps its
coarse levels, exact sub-samples), else the area-weighted 2 x 2 block-average filter of
``problems.io.coarse_levels``.  Levels with fewer than ``coarsest`` (default 16) points
per side are skipped.  Every level's solution summary is returned in
``SolveResult.info["levels"]`` (the paper: coarse predictions come for free).

Parameters (``SolverSettings.params``): ``h`` (area-of-influence factor, default 2),
``coarsest`` (points per side of the first level, default 16), ``levels`` (explicit
list of points-per-side to use, optional), ``base_params`` (dict passed to the base),
``repair`` (default False, not in the paper: re-admit pruned points that overlap and
re-solve until none does, which makes the answer exact).
Warm start: a primal warm start for the fine problem is restricted to the projected
set and handed to the base solver when the base accepts one; coarse levels start cold.
The base solver is looked up by registry name at solve time.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import CONTACT_THRESHOLD, QP, Geometry, InstanceBuilder, trial_set
from contactbench.problems.io import element_origin, power_law_check, with_coarse_levels
from contactbench.problems.surfaces import Surface

from .base import Capabilities, SolveResult, Solver, SolverSettings, WarmStart
from .registry import all_solvers, get_solver, register

#: Bases for which ``cmr+<base>`` is registered (others: ``make_cmr(name)``).
CMR_BASES: tuple[str, ...] = ("nnls", "pk", "scipy-nnls", "nnls-gp", "fast-ccg")
CMR_KEYS = frozenset({"h", "coarsest", "levels", "base_params", "repair"})
#: With ``repair``, gaps below -REPAIR_GAP * max|ubar| on pruned points count as missed contacts.
REPAIR_GAP = 1e-9
MAX_REPAIR_ROUNDS = 50


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


def grid_positions(surface: Surface, flat_idx: np.ndarray) -> np.ndarray:
    """(n, 2) element-centre coordinates of flat indices, in the finest surface's frame."""
    i, j = np.divmod(np.asarray(flat_idx, dtype=np.int64), surface.shape[1])
    ox, oy = element_origin(surface)
    return np.column_stack([ox + i * surface.delta, oy + j * surface.delta])


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


def contact_mask(p: np.ndarray) -> np.ndarray:
    pmax = float(np.max(p)) if p.size else 0.0
    return p > CONTACT_THRESHOLD * pmax if pmax > 0 else np.zeros(p.shape, dtype=bool)


def cascade_surfaces(surface: Surface, coarsest: int, sizes: list[int] | None = None) -> list[Surface]:
    """The coarse representations to use, coarsest first (the fine surface excluded)."""
    levels = with_coarse_levels(surface, coarsest).levels
    if sizes is not None:
        wanted = {int(n) for n in sizes}
        chosen = [s for s in levels if s.N in wanted]
        missing = wanted - {s.N for s in chosen} - {surface.N}
        if missing:
            raise ProblemInputError(f"CMR levels {sorted(missing)} not available; the surface has "
                                    f"{[s.N for s in levels]} below its own {surface.N}")
        return chosen
    return [s for s in levels if s.N >= coarsest]


class CMRSolver(Solver):
    """CMR (Algorithm 6) over the registered solver ``base``."""

    family = "wrapper"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), needs_dense=False,
                                warm_start="primal", exact=False)

    def __init__(self, base: str = "nnls") -> None:
        self.base_name = base
        self.name = f"cmr+{base}"  # type: ignore[misc]
        self.description = (f"cascade multi-resolution (paper Alg. 6) over {base}: coarse levels prune "
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

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        t0 = time.perf_counter()
        g = _require_context(qp)
        base = self.base()
        h = float(settings.param("h", 2.0))
        if not h >= 1.0:
            raise ProblemInputError(f"CMR area-of-influence factor h must be >= 1, got {h}")
        sizes = settings.param("levels", None)
        coarse = cascade_surfaces(g.surface, int(settings.param("coarsest", 16)), sizes)
        sub_settings = _base_settings(settings)
        period = g.surface.length if (g.periodic and g.surface.periodic) else None
        op_kind = "dense" if qp.H.kind == "DenseOperator" else "fft"

        records: list[LevelRecord] = []
        prev: LevelSolution | None = None
        prev_delta = 0.0
        for s, surf in enumerate(coarse, start=1):
            prev = self._coarse_level(s, surf, g, base, sub_settings, prev, h * prev_delta, period, op_kind)
            records.append(prev.record)
            prev_delta = surf.delta
        p, fine_result, rec, rounds = self._fine_level(len(coarse) + 1, qp, g, base, sub_settings, prev,
                                                       h * prev_delta, period, warm,
                                                       bool(settings.param("repair", False)))
        records.append(rec)
        check = _psd_check(g.surface)
        info = {
            "levels": [asdict(r) for r in records],
            "h": h,
            "base": self.base_name,
            "n_p_over_n": rec.n_p_over_n,
            "cascade": [r.N for r in records],
            "psd_power_law": check[0],
            "repair_rounds": rounds,
        }
        summary = (f"CMR {'->'.join(str(r.N) for r in records)} h={h:g}: n_p/n={rec.n_p_over_n:.4f} "
                   f"coarse-loads=[{', '.join(f'{r.load:.6g}' for r in records[:-1])}]")
        msg = f"{summary}; base: {fine_result.message}" if fine_result.message else summary
        if not check[0]:
            info["warnings"] = [check[1]]
            msg = f"{msg}; WARNING: {check[1]}" if msg else f"WARNING: {check[1]}"
        return SolveResult(
            p=p,
            w=None,
            iterations=sum(r.iterations for r in records),
            converged=fine_result.converged,
            status=fine_result.status,
            message=msg,
            solve_time=time.perf_counter() - t0,
            setup_time=0.0,
            matvecs=fine_result.matvecs,
            warm_started=fine_result.warm_started,
            trace=fine_result.trace,
            info=info,
        )

    def _coarse_level(self, s: int, surf: Surface, g: Geometry, base: Solver, settings: SolverSettings,
                      prev: LevelSolution | None, radius: float, period: float | None,
                      op_kind: str) -> LevelSolution:
        """Steps (1.1)-(3) on a coarse representation built with InstanceBuilder."""
        t = time.perf_counter()
        Delta = float(g.far_field)  # type: ignore[arg-type]
        idx_all = trial_set(surf.heights, Delta)
        keep = _projection(grid_positions(surf, idx_all), prev, radius, period)
        idx = idx_all[keep]
        p = np.zeros(idx.size)
        res = SolveResult(p=p, converged=True, status="empty")
        if idx.size:
            builder = InstanceBuilder(surf, float(g.E), kernel=str(g.kernel), periodic=bool(g.periodic),
                                      operator=op_kind)  # type: ignore[arg-type]
            ubar = np.maximum(Delta - surf.z_max + surf.heights.ravel()[idx], 0.0)
            geom = Geometry(surf.shape, surf.delta, idx, surface=surf, far_field=Delta, E=g.E,
                            kernel=g.kernel, periodic=g.periodic)
            res = base.solve(QP(builder.operator_on(idx), ubar, geom), settings, None)
            p = np.asarray(res.p, dtype=np.float64)
        c = contact_mask(p)
        rec = _record(s, surf, idx_all.size, idx.size, time.perf_counter() - t, p, c, res)
        return LevelSolution(rec, grid_positions(surf, idx[c]))

    def _fine_level(self, s: int, qp: QP, g: Geometry, base: Solver, settings: SolverSettings,
                    prev: LevelSolution | None, radius: float, period: float | None,
                    warm: WarmStart | None, repair: bool = False) -> tuple[np.ndarray, SolveResult, LevelRecord, int]:
        """The given QP restricted to the projected set; p returned on the full set.

        With ``repair`` (not in the paper): pruned points whose gap comes out negative
        were wrongly excluded; they are added to the set and the restricted problem is
        solved again, warm started, until no pruned point overlaps -- the answer is then
        the exact solution of the full QP, and the cascade only chose the start."""
        t = time.perf_counter()
        surf = g.surface
        assert surf is not None
        keep = _projection(grid_positions(surf, g.indices), prev, radius, period)
        pos = np.flatnonzero(keep)
        p_full = np.zeros(qp.n)
        res = SolveResult(p=np.zeros(0), converged=True, status="empty")
        if pos.size:
            sub_geom = Geometry(g.grid_shape, g.delta, g.indices[pos], surface=surf, far_field=g.far_field,
                                E=g.E, kernel=g.kernel, periodic=g.periodic)
            sub_warm = None
            if warm is not None and warm.p is not None and base.capabilities.warm_start != "none":
                sub_warm = WarmStart(p=np.asarray(warm.p)[pos],
                                     w=None if warm.w is None else np.asarray(warm.w)[pos])
            res = base.solve(QP(qp.H.restrict(pos), qp.ubar[pos], sub_geom), settings, sub_warm)
            p_full[pos] = np.asarray(res.p, dtype=np.float64)
        rounds = 0
        while repair and rounds < MAX_REPAIR_ROUNDS:
            missed = _missed_contacts(qp, p_full, pos)
            if missed.size == 0:
                break
            rounds += 1
            pos = np.union1d(pos, missed)
            sub_geom = Geometry(g.grid_shape, g.delta, g.indices[pos], surface=surf, far_field=g.far_field,
                                E=g.E, kernel=g.kernel, periodic=g.periodic)
            start = WarmStart(p=p_full[pos]) if base.capabilities.warm_start != "none" else None
            res = base.solve(QP(qp.H.restrict(pos), qp.ubar[pos], sub_geom), settings, start)
            p_full[:] = 0.0
            p_full[pos] = np.asarray(res.p, dtype=np.float64)
        c = contact_mask(p_full)
        rec = _record(s, surf, qp.n, int(pos.size), time.perf_counter() - t, p_full, c, res)
        return p_full, res, rec, rounds


def _missed_contacts(qp: QP, p_full: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Positions outside ``pos`` whose gap w = Hp - ubar is negative beyond round-off."""
    w = qp.H.matvec(p_full) - qp.ubar
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


def _require_context(qp: QP) -> Geometry:
    g = qp.geometry
    if g is None or g.surface is None or g.far_field is None or g.E is None or g.kernel is None:
        raise ProblemInputError("CMR needs the QP's geometry with its surface, far-field displacement, E and "
                                "kernel (instances built by problems.instances.InstanceBuilder carry them)")
    if tuple(g.grid_shape) != g.surface.shape:
        raise ProblemInputError(f"CMR: QP grid {g.grid_shape} does not match its surface {g.surface.shape}")
    return g


def _base_settings(settings: SolverSettings) -> SolverSettings:
    params = {k: v for k, v in settings.params.items() if k not in CMR_KEYS}
    params.update(settings.param("base_params", {}) or {})
    return SolverSettings(tol=settings.tol, max_iter=settings.max_iter,
                          time_limit=settings.time_limit, params=params)


_PSD_CACHE: dict[tuple[str, int, float, float], tuple[bool, str]] = {}


def _psd_check(surface: Surface) -> tuple[bool, str]:
    """(power_law, message) of problems.io.power_law_check, cached per surface."""
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

__all__ = ["CMRSolver", "LevelRecord", "cascade_surfaces", "grid_positions", "make_cmr", "within_radius"]
