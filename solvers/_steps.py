"""Step lengths of the constrained CG loops (not a solver module: the registry skips "_"
names): the exact line search along a direction, the curvature below which a direction is
flat to round-off, and Polak-Ribiere's beta.

Flat directions
---------------
A periodic grid's operator removes the mean (H 1 = 0), so on a free set that is the whole
grid the constant vector is a null direction, and a preconditioned direction can come
arbitrarily close to it (a warm start near full contact: an 8 x 8 checkerboard warm-started
from half the top displacement to 0.9999 of it).  The computed curvature d'Hd is then
round-off, possibly positive, and the "exact" step -res'd / d'Hd is 1e14 times too long:
the projection clipped every force to 0, the loop fell back to a KKT error of 1 every few
iterations and ran to ``max_iter``.  A curvature of at most ``FLAT_ULPS`` units in the last
place of the product's precision times max diag H d'd (``flat_curvature``) is flat: along
it the objective is linear to round-off, and its minimum on p >= 0 is where the first force
reaches 0 -- the step taken (``flat_step``), no longer than the exact step of the least
curvature the round-off could hide.  A flat direction that does not descend restarts the
loop as a lost definiteness does.

A direction's Rayleigh quotient is at least the smallest eigenvalue of H on the free set:
about max diag H / N on an N x N grid (1e-4 of it at N = 16384), above the float32 floor
(64 ulps: 7.6e-6); but on a periodic free set within k points of the whole grid, about
k max diag H / N^2 along the near-constant direction (3.8e-6 at 512^2, k = 1), below it.
There the step is the flat one, no longer than the exact step of a curvature at the floor
and ending at the first force at 0: shorter than the exact step, never longer.
"""

from __future__ import annotations

import math

import numpy as np
from contactbench.problems.fft_threads import dots_in_bands
from contactbench.problems.kkt import read_scalars

#: Polak-Ribiere's |beta| above this restarts the Bugnicourt loops (``polak_ribiere``): on the
#: surface population's solves |beta| stays below 12, at a negative curvature 0.07-0.7.
MAX_BETA = 1e6

#: A curvature within this many units in the last place of the product's precision (times
#: max diag H d'd) is round-off: the direction is flat (module doc).
FLAT_ULPS = 64.0


def flat_curvature(diag_max: float, dtype: object) -> float:
    """The curvature per unit d'd at or below which a direction is flat (module doc), for
    products in ``dtype`` on an operator whose largest diagonal entry is ``diag_max``."""
    return FLAT_ULPS * float(np.finfo(np.dtype(dtype)).eps) * float(diag_max)


def exact_step(res: np.ndarray, d: np.ndarray, Hd: np.ndarray, flat: float = 0.0,
               p: np.ndarray | None = None) -> tuple[float, float]:
    """(alpha, d'Hd): the exact line-search step -res'd / d'Hd along d, the products read in
    one transfer.  Where the curvature is at most ``flat`` d'd and d descends, the step
    along a flat direction (``flat_step``, from the forces ``p``); else NaN where the
    curvature is not positive or is flat."""
    dHd, rd, dd = read_scalars(*dots_in_bands([(d, Hd), (res, d), (d, d)]))
    if dHd > flat * dd:
        return -rd / dHd, dHd
    return flat_step(p, d, rd, flat * dd), dHd


def curved_step(slope: float, curvature: float, t: np.ndarray, flat: float, p: np.ndarray) -> float:
    """The Polonsky-Keer step tau = slope / curvature of p - tau t (slope = r't, curvature
    = t'Ht); where the curvature is at most ``flat`` t't and the step descends, the step
    along a flat direction (``flat_step`` along -t); else NaN where it is not positive."""
    (tt,) = read_scalars(*dots_in_bands([(t, t)]))
    if curvature > flat * tt:
        return slope / curvature
    return flat_step(p, -t, -slope, flat * tt)


def flat_step(p: np.ndarray | None, d: np.ndarray, slope: float, floor: float) -> float:
    """The step along a flat direction d (module doc) on which the objective falls at
    ``slope`` = res'd < 0: to the first force d takes to 0, and no longer than the exact
    step of the least curvature round-off hides, -slope / ``floor``, so that the objective
    falls either way; NaN where d does not descend, nothing is flat (``floor`` 0) or no
    forces are given."""
    if p is None or not (floor > 0.0 and slope < 0.0):
        return math.nan
    down = d < 0.0
    (bound,) = read_scalars(np.where(down, p / np.where(down, -d, 1.0), np.inf).min())
    return min(float(bound), -slope / floor)


def polak_ribiere(z: np.ndarray, res: np.ndarray, res_old: np.ndarray, step_curvature: float) -> float:
    """Polak-Ribiere's beta of the Bugnicourt loops (preconditioned: z = M^-1 res),
    (z'res - z'res_old) / (alpha d'Hd) with alpha d'Hd = -res_old'd; 0 (a restart along
    -z) where the step's curvature ``step_curvature`` is 0 or not finite, or |beta| is
    above ``MAX_BETA`` (a curvature lost to round-off).  A negative curvature is kept: after
    ``inward`` or a projection d need not descend, the step then goes back along it (alpha
    < 0; one or two steps a solve), and restarting there cost the plain loop 13 % more
    products at 1024^2 on the surface population (median 68.5 against 60.5 matvecs on 32
    members; results/perf/device-choice/README.md)."""
    if step_curvature == 0.0 or not math.isfinite(step_curvature):
        return 0.0
    z_res, z_res_old = read_scalars(*dots_in_bands([(z, res), (z, res_old)]))
    beta = (z_res - z_res_old) / step_curvature
    return beta if abs(beta) <= MAX_BETA else 0.0


__all__ = ["FLAT_ULPS", "MAX_BETA", "curved_step", "exact_step", "flat_curvature", "flat_step", "polak_ribiere"]
