"""Coarse representations of a surface for the cascade multi-resolution method (CMR,
Bemporad & Paggi 2015, section 5), the coarse QP of a level, and the PSD power-law test.

* A coarse level of stride s (s = 2, 4, ...; ``level_sizes``) is made in one of two ways
  (``COARSE_KINDS``, :func:`coarse_level`, the one place levels are built):
  ``"subsample"`` -- the exact sub-sample z[::s, ::s] (the RMD generator's own stage, which
  is exactly that, when the surface has one); ``"mean"`` -- the block mean of the s x s fine
  elements a coarse element covers (:func:`mean_level`), the average height over its area,
  the same meaning the BEM gives a fine element's height (the paper's xi_ij, and its
  section 5.2 "filter to downsample the acquired surfaces").  :func:`block_average` is the
  2 x 2 case.
* :func:`cascade_surfaces` picks the levels a cascade runs on (from ``coarsest`` up, or
  the sizes listed; a size the surface cannot give is refused); :func:`grid_positions`
  puts every level's element centres in the finest surface's frame (block means sit at
  their blocks' centres), so distances between levels are measured correctly.
* :func:`coarse_qp` is THE builder of a coarse level's QP (section 5.1, Algorithm 6, steps
  (1.1)-(2)): the rigid-body trial set of the level at the fine problem's far-field
  displacement Delta, restricted to the points CMR kept.
* :func:`power_law_check` tests whether the radially averaged PSD is a single power law
  over the scales a cascade spans -- the condition under which the paper found CMR
  reliable (its 10x solar-cell scan with a PSD roll-off made CMR fail).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ProblemInputError
from .instances import QP, Geometry, InstanceBuilder, OperatorKind, rigid_body_ubar, trial_set
from .surfaces import RadialPSD, Surface, check_not_flat, radial_psd

# ---------------------------------------------------------------------------
# Coarse levels: exact sub-samples or block means
# ---------------------------------------------------------------------------

#: How a cascade's coarse level of stride s is made from the fine surface z:
#: "subsample" -- the generator's exact stage (RMD), else z[::s, ::s], element centres on
#: fine grid points; "mean" -- the block mean of each s x s block of fine elements (a cell
#: average, the paper's meaning of a height xi_ij), centred in its block.
COARSE_KINDS: tuple[str, ...] = ("subsample", "mean")


def check_coarse_kind(kind: object) -> str:
    """``kind`` when it is one of ``COARSE_KINDS``, else a one-line ``ProblemInputError``."""
    if kind not in COARSE_KINDS:
        raise ProblemInputError(f"unknown coarse-level kind {kind!r}: choose 'subsample' (exact sub-samples of the "
                                "fine grid) or 'mean' (block means of s x s fine elements)")
    return str(kind)


def level_sizes(N: int) -> dict[int, int]:
    """{size: stride} of the coarse levels a surface of N points per side can give:
    stride s = 2, 4, 8, ... with size N // s >= 2 (a level's size counts the s x s blocks
    it spans; a sub-sample of a 2^k + 1 grid has one point more, its closing row)."""
    out: dict[int, int] = {}
    s = 2
    while N // s >= 2:
        out[N // s] = s
        s *= 2
    return out


def missing_level(N: int, coarsest: int, sizes: list[int] | tuple[int, ...] | None = None) -> tuple[str, int] | None:
    """The first coarse level a cascade asks of an N-point side that the side cannot give
    (``level_sizes``), as ("coarse level" | "coarsest level", its size); None when it gives all."""
    avail = level_sizes(N)
    wanted = [("coarse level", int(v)) for v in sorted({int(v) for v in sizes})] if sizes is not None \
        else [("coarsest level", int(coarsest))]
    return next(((what, n) for what, n in wanted if n not in avail), None)


def level_strides(surface: Surface, coarsest: int, sizes: list[int] | tuple[int, ...] | None = None) -> list[int]:
    """Strides of the cascade's coarse levels, coarsest first: every level from ``coarsest``
    points per side up to the fine surface (excluded), or exactly the sizes listed in
    ``sizes``.  A size the surface cannot give (``missing_level``) is a
    ``ProblemInputError`` listing those it can."""
    avail = level_sizes(surface.N)
    missing = missing_level(surface.N, coarsest, sizes)
    if missing is not None:
        raise ProblemInputError(
            f"CMR {missing[0]} {missing[1]} is not available on the {surface.N} x {surface.N} surface "
            f"{surface.name!r}: its coarse levels have {sorted(avail)} points per side (N // s for strides "
            "s = 2, 4, 8, ...)")
    if sizes is not None:
        return sorted((avail[int(n)] for n in {int(v) for v in sizes}), reverse=True)
    return [s for s in sorted(avail.values(), reverse=True) if s <= avail[int(coarsest)]]


def subsample_level(surface: Surface, stride: int) -> Surface:
    """The coarse level of ``stride`` as an exact sub-sample: the generator's own stage of
    that stride when the surface has one (RMD), else z[::s, ::s] (element centres on fine
    grid points, origin 0 in the fine frame)."""
    for lev in surface.levels:
        if int(lev.meta.get("stride", 0)) == stride:
            return lev
    h = surface.heights[::stride, ::stride]
    d0, d1 = surface.spacing
    return Surface(h, stride * d0, unit=surface.unit, name=f"{surface.name}-sub{stride}",
                   periodic=surface.periodic and all(n % stride == 0 for n in surface.shape),
                   meta={"filter": "subsample", "stride": stride, "origin": element_origin(surface)},
                   delta1=None if surface.delta1 is None else stride * d1)


def mean_level(surface: Surface, stride: int) -> Surface:
    """The coarse level of ``stride`` as block means: element (I, J) is the mean of fine
    elements (sI..sI+s-1, sJ..sJ+s-1) -- the average height over its area; a last partial
    block is dropped.  ``meta["origin"]``: its element (0, 0) centre in the fine frame,
    (s - 1)/2 fine spacings in from the fine element (0, 0)."""
    N0, N1 = surface.shape
    n0, n1 = N0 // stride, N1 // stride
    if min(n0, n1) < 2 or stride < 2:
        raise ProblemInputError(f"cannot coarsen the {N0} x {N1} surface {surface.name!r} by blocks "
                                f"of {stride} x {stride}: a level needs stride >= 2 and at least 2 x 2 blocks")
    h = surface.heights[: n0 * stride, : n1 * stride]
    coarse = h.reshape(n0, stride, n1, stride).mean(axis=(1, 3))
    ox, oy = element_origin(surface)
    d0, d1 = surface.spacing
    off0, off1 = 0.5 * (stride - 1) * d0, 0.5 * (stride - 1) * d1
    return Surface(coarse, stride * d0, unit=surface.unit, name=f"{surface.name}-mean{stride}",
                   periodic=surface.periodic and N0 % stride == 0 and N1 % stride == 0,
                   meta={"filter": f"block-mean-{stride}x{stride}", "stride": stride, "origin": (ox + off0, oy + off1)},
                   delta1=None if surface.delta1 is None else stride * d1)


def coarse_level(surface: Surface, stride: int, kind: str = "subsample") -> Surface:
    """THE coarse level of ``stride`` of ``surface``, made as ``kind`` (``COARSE_KINDS``)."""
    return mean_level(surface, stride) if check_coarse_kind(kind) == "mean" else subsample_level(surface, stride)


def cascade_surfaces(surface: Surface, coarsest: int, sizes: list[int] | tuple[int, ...] | None = None,
                     kind: str = "subsample") -> list[Surface]:
    """The coarse representations a cascade runs on, coarsest first (the fine surface
    excluded): every level from ``coarsest`` points per side up (``level_strides``), or
    exactly the sizes listed in ``sizes``, each made as ``kind`` (``coarse_level``)."""
    check_coarse_kind(kind)
    return [coarse_level(surface, s, kind) for s in level_strides(surface, coarsest, sizes)]


def block_average(surface: Surface) -> Surface:
    """Area-weighted 2 x 2 block-average coarsening (``mean_level`` with stride 2): spacing
    doubles, an odd last row/column is dropped, ``meta["origin"]`` is the coarse element
    (0, 0) centre in the fine surface's frame."""
    return mean_level(surface, 2)


def coarse_levels(surface: Surface, n_levels: int) -> tuple[Surface, ...]:
    """``n_levels`` block-mean levels of strides 2, 4, ..., 2^n_levels, coarsest first (the
    surface itself not included) -- the layout of ``Surface.levels`` of RMD surfaces."""
    if int(n_levels) != n_levels or n_levels < 0:
        raise ProblemInputError(f"number of coarse levels must be an integer >= 0, got {n_levels}")
    return tuple(mean_level(surface, 2**j) for j in range(int(n_levels), 0, -1))


def element_origin(surface: Surface) -> tuple[float, float]:
    """Centre of element (0, 0) in the finest surface's frame (0 for sub-samples)."""
    o = surface.meta.get("origin", (0.0, 0.0))
    return float(o[0]), float(o[1])


def grid_positions(surface: Surface, flat_idx: np.ndarray) -> np.ndarray:
    """(n, 2) element-centre coordinates of flat indices, in the finest surface's frame."""
    i, j = np.divmod(np.asarray(flat_idx, dtype=np.int64), surface.shape[1])
    ox, oy = element_origin(surface)
    d0, d1 = surface.spacing
    return np.column_stack([ox + i * d0, oy + j * d1])


# ---------------------------------------------------------------------------
# The QP of a coarse level
# ---------------------------------------------------------------------------


def level_trial_set(level: Surface, fine: Geometry) -> np.ndarray:
    """Step (1.1) on a coarse level: flat indices of I_C(s) = {xi >= xi_max(s) - Delta}
    at the fine problem's far-field displacement Delta."""
    return trial_set(level.heights, float(_far_field(fine)))


def posable(level: Surface, fine: Geometry) -> bool:
    """Whether the fine problem ``fine`` can be posed on the coarse representation
    ``level``: an elastic layer's real-space kernel needs T >= the level's spacing
    (``Layer.check_kernel``), which a coarse level can break where the fine grid keeps it."""
    if fine.layer is None or fine.kernel is None:
        return True
    spacing = (float(level.delta), float(level.delta if level.delta1 is None else level.delta1))
    try:
        fine.layer.check_kernel(str(fine.kernel), bool(fine.periodic), spacing)
    except ProblemInputError:
        return False
    return True


def coarse_qp(level: Surface, fine: Geometry, indices: np.ndarray, operator: OperatorKind = "fft",
              hardness: float | None = None) -> QP:
    """The QP of a coarse representation ``level`` on ``indices`` (flat indices into its
    grid, a subset of ``level_trial_set``): the same material, kernel and boundary
    condition as the fine problem ``fine``, at its far-field displacement Delta, and the
    same ``hardness`` (a pressure; None: none), whose bounds are the level's elements'.

    ubar = max(Delta - xi_max(s) + xi, 0) -- on every level, periodic kernels included,
    since a coarse level is posed on its rigid-body trial set (paper Alg. 6, step 1.1);
    the fine level is the QP the caller was given."""
    if fine.E is None or fine.kernel is None:
        raise ProblemInputError("a coarse level needs the fine geometry's E and kernel")
    Delta = float(_far_field(fine))
    idx = np.asarray(indices, dtype=np.int64)
    builder = InstanceBuilder(level, float(fine.E), kernel=str(fine.kernel), periodic=bool(fine.periodic),
                              operator=operator, layer=fine.layer)
    ubar = np.maximum(rigid_body_ubar(level.heights, Delta, idx), 0.0)
    geom = Geometry(level.shape, level.delta, idx, surface=level, far_field=Delta, E=fine.E,
                    kernel=fine.kernel, periodic=fine.periodic, delta1=level.delta1, layer=fine.layer)
    return QP(builder.operator_on(idx), ubar, geom, builder.constraints(idx.size, hardness))


def coarse_load_qp(level: Surface, fine: Geometry, load: float, operator: OperatorKind = "fft",
                   hardness: float | None = None) -> QP:
    """The QP of a coarse representation ``level`` under load control at the fine problem's
    total force ``load`` (P, the same force on a coarser grid): the whole level's grid, the
    same material, kernel and boundary condition as ``fine`` and the same ``hardness``
    (``InstanceBuilder.build_load``)."""
    if fine.E is None or fine.kernel is None:
        raise ProblemInputError("a coarse level needs the fine geometry's E and kernel")
    builder = InstanceBuilder(level, float(fine.E), kernel=str(fine.kernel), periodic=bool(fine.periodic),
                              operator=operator, layer=fine.layer)
    return builder.build_load(float(load), hardness=hardness).qp


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

    ``power_law`` is False when the low half's slope is flatter than the high half's by
    more than ``max_slope_change`` (a roll-off plateau flattens the low half) or the
    single-line fit explains less than ``min_r2`` of the variance.  A STEEPER low half is
    not flagged: it is extra long-wavelength power, which non-periodic (saupe) RMD
    surfaces show on some seeds (2 of seeds 0-19 at 256^2, slopes about -4.6 vs -3.2 at
    H = 0.7) and which breaks no lacunarity.
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
    """Fit log C(q) against log q on [q_min, q_max] (default: 2 x the fundamental of the
    shorter side to half the Nyquist wave number of the coarser spacing) and on each half of that range in log q.  A flat surface
    has no PSD: ``ProblemInputError``."""
    check_not_flat(surface)
    psd = radial_psd(surface) if psd is None else psd
    q0 = 2.0 * np.pi / min(surface.lengths)
    lo = 2.0 * q0 if q_min is None else q_min
    hi = 0.5 * np.pi / max(surface.spacing) if q_max is None else q_max
    if not lo < hi:
        raise ProblemInputError(f"the grid is too small for a power-law check of its PSD: from twice its fundamental "
                                f"({lo:.3g} rad/m) to half its Nyquist wave number ({hi:.3g} rad/m) there is no range")
    mid = np.sqrt(lo * hi)
    x, y = np.log(psd.q), np.log(np.maximum(psd.C, np.finfo(float).tiny))

    def fit(a: float, b: float) -> tuple[float, float]:
        m = (psd.q >= a) & (psd.q <= b)
        if m.sum() < 3:
            raise ProblemInputError(f"the grid is too small for a power-law check of its PSD: {int(m.sum())} bins "
                                    f"in [{a:.3g}, {b:.3g}] rad/m, 3 needed")
        s, c = np.polyfit(x[m], y[m], 1)
        r = y[m] - (c + s * x[m])
        return float(s), 1.0 - float(np.sum(r**2) / max(np.sum((y[m] - y[m].mean()) ** 2), 1e-300))

    slope, r2 = fit(lo, hi)
    s_lo, _ = fit(lo, mid)
    s_hi, _ = fit(mid, hi)
    ok = s_lo - s_hi <= max_slope_change and r2 >= min_r2  # slopes are negative: s_lo - s_hi > 0 is flatter
    hurst = -slope / 2.0 - 1.0
    if ok:
        msg = f"PSD is power-law over q in [{lo:.3g}, {hi:.3g}] rad/m (H = {hurst:.2f}, r2 = {r2:.3f})"
    else:
        msg = (f"PSD is NOT a power law over q in [{lo:.3g}, {hi:.3g}] rad/m: slope {s_lo:.2f} in the lower "
               f"half vs {s_hi:.2f} in the upper half (r2 = {r2:.3f}); a roll-off plateau breaks the "
               "lacunarity CMR relies on (paper section 5.2), expect large load errors")
    return PowerLawCheck(ok, slope, s_lo, s_hi, r2, (lo, hi), hurst, msg)


__all__ = [
    "COARSE_KINDS",
    "PowerLawCheck",
    "block_average",
    "cascade_surfaces",
    "check_coarse_kind",
    "coarse_level",
    "coarse_levels",
    "coarse_qp",
    "element_origin",
    "grid_positions",
    "level_sizes",
    "level_strides",
    "level_trial_set",
    "mean_level",
    "missing_level",
    "posable",
    "power_law_check",
    "subsample_level",
]
