"""A solve at unit scale (not a solver module: the registry skips "_" names).

The contact QP is homogeneous in (ubar, bounds, load): multiplying them by f multiplies the
answer p, its gap w and its approach Delta by f, and leaves the scaled KKT figures as they
are.  A loop that forms inner products of gaps and forces (r'z ~ ubar^2 / H) overflows past
a relief of about 1e154 and underflows below 1e-154, and the CCGs then stalled on problems
whose answers float64 holds (nnls and the QP backends solved them).  ``at_unit_scale``
solves such a problem with f a power of two that brings its largest |ubar| (or its load) to
about 1 -- exact in float64 but for subnormals -- and maps the answer back.  Problems
within ``UNIT_SCALE_RANGE`` are solved as they are, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np

from contactbench.problems.instances import QP

from .base import Outcome, SolveContext, WarmStart

#: A problem whose largest |ubar| (or load) lies in [1 / UNIT_SCALE_RANGE, UNIT_SCALE_RANGE]
#: is solved as it is; outside, at unit scale.
UNIT_SCALE_RANGE = 1e100
#: The largest power of two a factor may be (float64's own is 1023).
MAX_EXPONENT = 1000


def unit_scale_factor(qp: QP) -> float:
    """The power of two f that brings the problem's magnitude -- its largest |ubar|, or its
    load where that is larger -- to [0.5, 1) (a subnormal one only by 2^``MAX_EXPONENT``);
    1.0 within ``UNIT_SCALE_RANGE``, or for a magnitude of 0 or one that is not finite."""
    magnitude = float(np.max(np.abs(qp.ubar), initial=0.0))
    if qp.constraints.load is not None:
        magnitude = max(magnitude, float(qp.constraints.load))
    if not (math.isfinite(magnitude) and magnitude > 0.0):
        return 1.0
    if 1.0 / UNIT_SCALE_RANGE <= magnitude <= UNIT_SCALE_RANGE:
        return 1.0
    exponent = -math.frexp(magnitude)[1]  # (a subnormal's is past float64's: clipped, still far inside the range)
    return math.ldexp(1.0, max(-MAX_EXPONENT, min(MAX_EXPONENT, exponent)))


def scaled_context(ctx: SolveContext, factor: float) -> SolveContext:
    """``ctx`` on its QP times ``factor`` (``QP.scaled``), its warm start with it; the same
    tolerance, deadline, trace, info and product count (its parent's)."""
    warm = None if ctx.warm is None else WarmStart(None if ctx.warm.p is None else ctx.warm.p * factor,
                                                   None if ctx.warm.w is None else ctx.warm.w * factor)
    return replace(ctx, qp=ctx.qp.scaled(factor), p0=None if ctx.p0 is None else ctx.p0 * factor, warm=warm,
                   _extra_matvecs=0, _ubar_max=None, _parent=ctx)


def at_unit_scale(ctx: SolveContext, solve: Callable[[SolveContext], Outcome]) -> Outcome:
    """``solve`` on ``ctx``'s problem at unit scale (module doc), its outcome mapped back:
    p, w and the approach divided by the factor; ``solve(ctx)`` itself where the factor is 1."""
    factor = unit_scale_factor(ctx.qp)
    if factor == 1.0:
        return solve(ctx)
    sub = scaled_context(ctx, factor)
    out = solve(sub)
    if ctx.setup_time is None:
        ctx.setup_time = sub.setup_time
    out.info["unit_scale_factor"] = factor
    return replace(out, p=out.p / factor, w=None if out.w is None else out.w / factor,
                   multiplier=None if out.multiplier is None else out.multiplier / factor)
