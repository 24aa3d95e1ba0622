"""Coarse representations of a surface for the cascade multi-resolution method (CMR,
Bemporad & Paggi 2015, section 5), the coarse QP of a level, and the PSD power-law test.

* The coarsening filter (section 5.2: "a filter to downsample the acquired surfaces") is
  :func:`block_average`: area-weighted 2 x 2 block averaging.  Each coarse element is the
  mean of the four fine elements it covers, which is exactly the average height over the
  coarse element's area -- the same meaning the BEM gives a fine element's height.
  :func:`coarse_levels` applies it repeatedly; :func:`with_coarse_levels` fills
  ``Surface.levels`` with it unless the generator already did (RMD keeps its own levels,
  exact sub-samples).
* :func:`cascade_surfaces` picks the levels a cascade runs on; :func:`grid_positions`
  puts every level's element centres in the finest surface's frame, so distances between
  levels are measured correctly.
* :func:`coarse_qp` is THE builder of a coarse level's QP (section 5.1, Algorithm 6, steps
  (1.1)-(2)): the rigid-body trial set of the level at the fine problem's far-field
  displacement Delta, restricted to the points CMR kept.
* :func:`power_law_check` tests whether the radially averaged PSD is a single power law
  over the scales a cascade spans -- the condition under which the paper found CMR
  reliable (its 10x solar-cell scan with a PSD roll-off made CMR fail).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .errors import ProblemInputError
from .instances import QP, Geometry, InstanceBuilder, OperatorKind, rigid_body_ubar, trial_set
from .surfaces import RadialPSD, Surface, check_not_flat, radial_psd

# ---------------------------------------------------------------------------
# Coarsening filter and levels
# ---------------------------------------------------------------------------


def block_average(surface: Surface) -> Surface:
    """Area-weighted 2 x 2 block-average coarsening: coarse element (i, j) is the mean of
    fine elements (2i..2i+1, 2j..2j+1); spacing doubles.  An odd last row/column is
    dropped.  ``meta["origin"]`` is the coarse element (0, 0) centre in the fine
    surface's frame (element centres at origin + index * delta)."""
    n = surface.N // 2
    if n < 2:
        raise ProblemInputError(f"cannot coarsen a {surface.N} x {surface.N} surface below 2 x 2")
    h = surface.heights[: 2 * n, : 2 * n]
    coarse = h.reshape(n, 2, n, 2).mean(axis=(1, 3))
    ox, oy = surface.meta.get("origin", (0.0, 0.0))
    origin = (ox + 0.5 * surface.delta, oy + 0.5 * surface.delta)
    return Surface(coarse, 2.0 * surface.delta, unit=surface.unit, name=f"{surface.name}-avg{n}",
                   periodic=surface.periodic and surface.N % 2 == 0,
                   meta={"filter": "block-average-2x2", "origin": origin})


def coarse_levels(surface: Surface, n_levels: int) -> tuple[Surface, ...]:
    """``n_levels`` successive block-average coarsenings, coarsest first (the surface
    itself not included) -- the same layout as ``Surface.levels`` of RMD surfaces."""
    if int(n_levels) != n_levels or n_levels < 0:
        raise ProblemInputError(f"number of coarse levels must be an integer >= 0, got {n_levels}")
    out: list[Surface] = []
    s = surface
    for _ in range(int(n_levels)):
        s = block_average(s)
        out.append(s)
    return tuple(reversed(out))


def with_coarse_levels(surface: Surface, coarsest: int) -> Surface:
    """The surface with ``levels`` filled by block averaging down to the first level with
    at most ``coarsest`` points per side (kept as is when it already has levels)."""
    if surface.levels:
        return surface
    n_levels, n = 0, surface.N
    while n // 2 >= max(2, coarsest) and n > coarsest:
        n //= 2
        n_levels += 1
    return replace(surface, levels=coarse_levels(surface, n_levels))


def cascade_surfaces(surface: Surface, coarsest: int,
                     sizes: list[int] | tuple[int, ...] | None = None) -> list[Surface]:
    """The coarse representations a cascade runs on, coarsest first (the fine surface
    excluded): the levels with at least ``coarsest`` points per side, or exactly the
    sizes listed in ``sizes``."""
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


def element_origin(surface: Surface) -> tuple[float, float]:
    """Centre of element (0, 0) in the finest surface's frame (0 for RMD sub-samples)."""
    o = surface.meta.get("origin", (0.0, 0.0))
    return float(o[0]), float(o[1])


def grid_positions(surface: Surface, flat_idx: np.ndarray) -> np.ndarray:
    """(n, 2) element-centre coordinates of flat indices, in the finest surface's frame."""
    i, j = np.divmod(np.asarray(flat_idx, dtype=np.int64), surface.shape[1])
    ox, oy = element_origin(surface)
    return np.column_stack([ox + i * surface.delta, oy + j * surface.delta])


# ---------------------------------------------------------------------------
# The QP of a coarse level
# ---------------------------------------------------------------------------


def level_trial_set(level: Surface, fine: Geometry) -> np.ndarray:
    """Step (1.1) on a coarse level: flat indices of I_C(s) = {xi >= xi_max(s) - Delta}
    at the fine problem's far-field displacement Delta."""
    return trial_set(level.heights, float(_far_field(fine)))


def coarse_qp(level: Surface, fine: Geometry, indices: np.ndarray, operator: OperatorKind = "fft") -> QP:
    """The QP of a coarse representation ``level`` on ``indices`` (flat indices into its
    grid, a subset of ``level_trial_set``): the same material, kernel and boundary
    condition as the fine problem ``fine``, at its far-field displacement Delta.

    ubar = max(Delta - xi_max(s) + xi, 0) -- on every level, periodic kernels included,
    since a coarse level is posed on its rigid-body trial set (paper Alg. 6, step 1.1);
    the fine level is the QP the caller was given."""
    if fine.E is None or fine.kernel is None:
        raise ProblemInputError("a coarse level needs the fine geometry's E and kernel")
    Delta = float(_far_field(fine))
    idx = np.asarray(indices, dtype=np.int64)
    builder = InstanceBuilder(level, float(fine.E), kernel=str(fine.kernel), periodic=bool(fine.periodic),
                              operator=operator)
    ubar = np.maximum(rigid_body_ubar(level.heights, Delta, idx), 0.0)
    geom = Geometry(level.shape, level.delta, idx, surface=level, far_field=Delta, E=fine.E,
                    kernel=fine.kernel, periodic=fine.periodic)
    return QP(builder.operator_on(idx), ubar, geom)


def _far_field(g: Geometry) -> float:
    if g.far_field is None:
        raise ProblemInputError("a coarse level needs the fine geometry's far-field displacement Delta")
    return g.far_field


# ---------------------------------------------------------------------------
# Is the PSD a power law over the cascade's scales?
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PowerLawCheck:
    """Log-log PSD slopes over [q_min, q_max] and over its lower and upper halves.

    ``power_law`` is False when the two half-range slopes differ by more than
    ``max_slope_change`` (a roll-off plateau flattens the low half) or the single-line
    fit explains less than ``min_r2`` of the variance.
    """

    power_law: bool
    slope: float
    slope_low: float
    slope_high: float
    r2: float
    q_range: tuple[float, float]
    hurst: float
    message: str


def power_law_check(surface: Surface, q_min: float | None = None, q_max: float | None = None,
                    max_slope_change: float = 1.0, min_r2: float = 0.9,
                    psd: RadialPSD | None = None) -> PowerLawCheck:
    """Fit log C(q) against log q on [q_min, q_max] (default: 2 x the fundamental to half
    the Nyquist wave number) and on each half of that range in log q.  A flat surface
    has no PSD: ``ProblemInputError``."""
    check_not_flat(surface)
    psd = radial_psd(surface) if psd is None else psd
    q0 = 2.0 * np.pi / surface.length
    lo = 2.0 * q0 if q_min is None else q_min
    hi = 0.5 * np.pi / surface.delta if q_max is None else q_max
    mid = np.sqrt(lo * hi)
    x, y = np.log(psd.q), np.log(np.maximum(psd.C, np.finfo(float).tiny))

    def fit(a: float, b: float) -> tuple[float, float]:
        m = (psd.q >= a) & (psd.q <= b)
        if m.sum() < 3:
            raise ProblemInputError(f"too few PSD bins in [{a:.3g}, {b:.3g}] rad/m for a power-law check")
        s, c = np.polyfit(x[m], y[m], 1)
        r = y[m] - (c + s * x[m])
        return float(s), 1.0 - float(np.sum(r**2) / max(np.sum((y[m] - y[m].mean()) ** 2), 1e-300))

    slope, r2 = fit(lo, hi)
    s_lo, _ = fit(lo, mid)
    s_hi, _ = fit(mid, hi)
    ok = abs(s_lo - s_hi) <= max_slope_change and r2 >= min_r2
    hurst = -slope / 2.0 - 1.0
    if ok:
        msg = f"PSD is power-law over q in [{lo:.3g}, {hi:.3g}] rad/m (H = {hurst:.2f}, r2 = {r2:.3f})"
    else:
        msg = (f"PSD is NOT a power law over q in [{lo:.3g}, {hi:.3g}] rad/m: slope {s_lo:.2f} in the lower "
               f"half vs {s_hi:.2f} in the upper half (r2 = {r2:.3f}); a roll-off plateau breaks the "
               "lacunarity CMR relies on (paper section 5.2), expect large load errors")
    return PowerLawCheck(ok, slope, s_lo, s_hi, r2, (lo, hi), hurst, msg)


__all__ = [
    "PowerLawCheck",
    "block_average",
    "cascade_surfaces",
    "coarse_levels",
    "coarse_qp",
    "element_origin",
    "grid_positions",
    "level_trial_set",
    "power_law_check",
    "with_coarse_levels",
]
