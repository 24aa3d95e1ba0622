"""The constraints of a contact QP beyond p >= 0: the one home of load control and of
hardness-bounded pressures.

A QP (``problems.instances.QP``) carries one ``Constraints`` record.  Its two optional
parts generalise the displacement-controlled problem  min 1/2 p'Hp - ubar'p, p >= 0:

* ``upper`` -- per-element upper bounds u (a force per element; ``inf`` = none): the box
  0 <= p <= u.  A hardness H_A (a pressure) bounds every element's mean pressure p_i /
  delta^2, so u_i = H_A delta^2 (``hardness_bounds``; ``uniform_hardness`` reads H_A back,
  e.g. to pose the same hardness on a coarser grid); an element at its bound is
  *plastic* (Almqvist et al. 2007).
* ``load`` -- the total force P: the equality sum(p) = P (load control, Polonsky & Keer
  1999).  Its Lagrange multiplier is the rigid-body approach Delta: stationarity reads
  w = Hp - ubar - Delta with w >= 0 where p = 0, w <= 0 where p = u and w = 0 in between.
  A load-control instance poses ubar at Delta = 0 (``ubar = xi - xi_max``), so the
  multiplier *is* the far-field displacement of the displacement-controlled problem.

With neither part (``Constraints()``, ``plain``) the QP is exactly the
displacement-controlled problem.  Also here: the projections onto the feasible set
(``project_box``, ``project_box_sum``), used by the projection solvers, and
``fit_multiplier``, the Delta a candidate implies when it reports none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import ProblemInputError, check_nonnegative, real_number

#: How a contact problem is driven: the far-field displacement Delta given (the
#: default), or the total force P given (``Constraints.load``).
CONTROLS: tuple[str, ...] = ("displacement", "load")


@dataclass(frozen=True, eq=False)
class Constraints:
    """The optional bounds and load equality of a contact QP (module doc).

    upper : None (no upper bounds) or a float64 array of length n, entries in (0, inf];
    load  : None (displacement control) or the total force P >= 0 (load control).
    Construction refuses, in one line, an ``upper`` that is not a 1-D array of entries > 0
    (NaN refused) and a ``load`` that is not a finite real number >= 0 (a bool or a string
    refused); ``check(n)`` adds the length and the capacity."""

    upper: np.ndarray | None = None
    load: float | None = None

    def __post_init__(self) -> None:
        if self.upper is not None:
            u = self.upper
            if getattr(u, "ndim", None) != 1 or not bool((u > 0.0).all()):
                raise ProblemInputError(f"upper bounds must be a 1-D array of entries > 0 (inf for none), got "
                                        f"shape {getattr(u, 'shape', None)} with min {np.nanmin(np.asarray(u), initial=np.inf)!r}")
        if self.load is not None:
            check_nonnegative("the load", self.load)

    @property
    def bounded(self) -> bool:
        """Some element has a finite upper bound."""
        return self.upper is not None and bool(np.any(np.isfinite(self.upper)))

    @property
    def load_control(self) -> bool:
        return self.load is not None

    @property
    def capacity_share(self) -> float:
        """P / sum(upper): the share of what every element at its bound carries that the load
        takes (1: every element plastic); 0 without a load equality or a finite bound."""
        if self.load is None or not self.bounded:
            return 0.0
        return float(self.load) / 2.0 / half_total(self.upper)  # (halved: no overflow)

    @property
    def plain(self) -> bool:
        """Neither bounds nor a load equality: the displacement-controlled problem."""
        return not self.bounded and not self.load_control

    def upper_or_inf(self, n: int, like: Any = None) -> np.ndarray:
        """The upper bounds as an array of length n (inf where there is none); without a
        bound, in the array space of ``like`` when given (a device-resident solve's p)."""
        if self.upper is not None:
            return self.upper
        return np.full(n, math.inf) if like is None else np.full_like(like, math.inf, dtype=np.float64)

    def restrict(self, pos: np.ndarray) -> "Constraints":
        """The constraints on the unknowns at positions ``pos`` (the others held at p = 0:
        the load equality is unchanged)."""
        return Constraints(None if self.upper is None else self.upper[np.asarray(pos)], self.load)

    def scaled(self, factor: float) -> "Constraints":
        """The constraints of the problem whose ubar is multiplied by ``factor`` (its answer
        p is then factor p): the bounds and the load multiplied by it."""
        return Constraints(None if self.upper is None else self.upper * factor,
                           None if self.load is None else float(self.load) * factor)

    def check(self, n: int) -> None:
        """``ProblemInputError`` unless these constraints can be posed on n unknowns: upper
        of length n with entries > 0 (inf allowed, NaN not), load finite and >= 0, and the
        box able to carry the load (``load_exceeds``: sum(upper) >= load to round-off)."""
        if self.upper is not None:
            u = np.asarray(self.upper)
            if u.shape != (n,) or u.dtype != np.float64:
                raise ProblemInputError(f"upper bounds must be a float64 array of length {n}, got {u.dtype} {u.shape}")
            if np.any(np.isnan(u)) or np.any(u <= 0.0):
                raise ProblemInputError("upper bounds must be > 0 (inf for none), got NaN or a value <= 0")
        if self.load is not None:
            if not (isinstance(self.load, float) and math.isfinite(self.load) and self.load >= 0.0):
                raise ProblemInputError(f"the load must be a finite float >= 0, got {self.load!r}")
            cap = bounds_total(self.upper_or_inf(n))
            if load_exceeds(self.load, cap, n):
                raise ProblemInputError(overload_message(self.load, cap, "the load", "the bounds", "sum(upper)"))


def half_total(upper: np.ndarray) -> float:
    """sum(upper) / 2, exactly rounded, with no overflow in the sum for finite bounds (each
    halved first: bounds near the largest float); inf where a bound is inf."""
    u = np.asarray(upper, dtype=np.float64)
    return math.fsum(u / 2.0) if np.all(np.isfinite(u)) else math.inf


def bounds_total(upper: np.ndarray) -> float:
    """sum(upper), exactly rounded (``half_total`` doubled: inf only where the total itself
    is past the largest float, or a bound is inf)."""
    return 2.0 * half_total(upper)


def make_constraints(n: int, upper: np.ndarray | float | None = None, load: float | None = None) -> Constraints:
    """Checked ``Constraints`` on n unknowns: ``upper`` a scalar (every element) or an
    array; an all-infinite ``upper`` is stored as None (no bounds), so an infinite
    hardness poses exactly the unbounded problem."""
    u = None
    if upper is not None:
        u = np.broadcast_to(np.asarray(upper, dtype=np.float64), (n,)).copy()
        if np.all(np.isposinf(u)):
            u = None
    c = Constraints(u, None if load is None else check_nonnegative("the load", load))
    c.check(n)
    return c


def hardness_bounds(hardness: float, delta: float | tuple[float, float], n: int) -> np.ndarray:
    """u_i = H_A d0 d1 for n elements of sides ``delta`` = (d0, d1) (one number: square
    elements): the force at which an element's mean pressure reaches the hardness
    ``hardness`` (inf: no bound); a ``ProblemInputError`` where a finite hardness gives a
    force float64 holds only as a subnormal or not at all (0 by underflow, inf by overflow)."""
    h = real_number("hardness", hardness, "> 0 (inf for none)")
    if math.isnan(h) or h <= 0.0:
        raise ProblemInputError(f"hardness must be > 0 (inf for none), got {hardness!r}")
    sides = (delta, delta) if np.ndim(delta) == 0 else tuple(delta)  # type: ignore[arg-type]
    if len(sides) != 2 or not all(math.isfinite(float(d)) and float(d) > 0.0 for d in sides):
        raise ProblemInputError(f"grid spacing must be finite and > 0, got {delta!r}")
    u = h * float(sides[0]) * float(sides[1])
    if not u >= np.finfo(np.float64).tiny or (math.isinf(u) and math.isfinite(h)):
        raise ProblemInputError(f"hardness {h:g} Pa times the element area {float(sides[0]) * float(sides[1]):g} m^2 "
                                f"is a force float64 cannot hold ({u!r})")
    return np.full(n, u)


#: The round-off allowed per term of ``load_exceeds``: a load within LOAD_SLACK_ULPS (terms + 1)
#: units of round-off (relative, eps = 2^-52) of a capacity is taken as at the capacity.
LOAD_SLACK_ULPS = 8


def load_exceeds(load: float, capacity: float, terms: int) -> bool:
    """Whether the total force ``load`` exceeds what the bounds carry, ``capacity``, by more
    than round-off: load > capacity (1 + s), s = LOAD_SLACK_ULPS (terms + 1) eps, ``terms``
    the number of bounds summed into ``capacity`` (0 for a capacity not summed, e.g. the
    planner's H_A against the load's E* P/(E* A)).  A load within s of the capacity is
    feasible: every element at its bound (p = u) carries it to round-off.  The one test of a
    load against the bounds, made by the planner (``check_load_under_hardness``, terms 0)
    and the build (``Constraints.check``, terms n): a ratio the planner accepts gives a force
    P = (load E*) A within (n + 4) eps of the summed bounds n (H_A d0 d1), inside the
    build's slack (8 n eps more than the planner's), so the build accepts every load the
    planner accepts.  An infinite capacity carries any load."""
    if not math.isfinite(capacity):
        return False
    slack = LOAD_SLACK_ULPS * (max(int(terms), 0) + 1) * float(np.finfo(np.float64).eps)
    return float(load) > float(capacity) * (1.0 + slack)


def overload_message(load: float, capacity: float, what: str, carrier: str, capacity_name: str) -> str:
    """The one-line refusal of a load beyond what every element plastic carries
    (``load_exceeds``): both numbers in the shortest digits that tell them apart (``repr``)
    and the relative excess."""
    excess = float(load) / float(capacity) - 1.0 if capacity > 0.0 else math.inf
    return (f"{what} {float(load)!r} exceeds what {carrier} can carry ({capacity_name} = {float(capacity)!r}; "
            f"{excess:.3g} relative above it): every element plastic cannot balance it")


def check_load_under_hardness(loads: list[float], hardness: float | None, E: float) -> None:
    """``ProblemInputError`` when a dimensionless load P / (E* A) of a load-controlled recipe
    on the whole grid exceeds H_A / E*, the load of every element plastic: sum(u) of
    ``hardness_bounds`` over the nominal area A, which ``Constraints.check`` would refuse
    when the step is built.  Both decide by ``load_exceeds`` (here the product top E*
    against H_A, no sum), so every load accepted here is accepted by the build.  Checked
    from the options, before anything runs."""
    if hardness is None or not loads:
        return
    top = max(float(x) for x in loads)
    if load_exceeds(top * float(E), float(hardness), 0):
        raise ProblemInputError(overload_message(top, float(hardness) / float(E), "--loads: the load P/(E* A) =",
                                                 f"--hardness {float(hardness):g} Pa", "H_A/E*")
                                + "; lower the loads or raise the hardness")


#: Bounds within this relative spread of each other are one hardness (``uniform_hardness``).
UNIFORM_BOUND_RTOL = 1e-12


def uniform_hardness(upper: np.ndarray | None, delta: float | tuple[float, float]) -> float | None:
    """The hardness H_A of a box posed by ``hardness_bounds`` on elements of sides ``delta``:
    u_i / (d0 d1) when every bound is finite and equal (to ``UNIFORM_BOUND_RTOL``); None for
    no box, or one that no single hardness poses."""
    if upper is None:
        return None
    u = np.asarray(upper, dtype=np.float64)
    if u.size == 0 or not np.all(np.isfinite(u)):
        return None
    lo, hi = float(np.min(u)), float(np.max(u))
    if not (lo > 0.0 and hi - lo <= UNIFORM_BOUND_RTOL * hi):
        return None
    sides = (delta, delta) if np.ndim(delta) == 0 else tuple(delta)  # type: ignore[arg-type]
    return hi / (float(sides[0]) * float(sides[1]))


def project_box(x: np.ndarray, upper: np.ndarray | None) -> np.ndarray:
    """The projection of x onto {0 <= p <= upper} (upper None: p >= 0)."""
    p = np.maximum(x, 0.0)
    return p if upper is None else np.minimum(p, upper, out=p)


def project_box_sum(x: np.ndarray, upper: np.ndarray | None, load: float) -> np.ndarray:
    """The Euclidean projection of x onto {0 <= p <= upper, sum(p) = load}: p =
    clip(x - tau, 0, upper), where S(tau) = sum(p) is piecewise linear and non-increasing
    with breakpoints x_i and x_i - upper_i.  A binary search over the sorted breakpoints
    finds the piece holding S(tau) = load (O(n log n)); on it tau solves the linear
    equation exactly.  ``load`` must be feasible (``Constraints.check``)."""
    x = np.asarray(x, dtype=np.float64)
    u = np.full(x.shape, math.inf) if upper is None else upper
    fin = np.isfinite(u)
    bps = np.unique(np.concatenate([x, (x - u)[fin]]))

    def total(t: float) -> float:
        return float(np.sum(np.clip(x - t, 0.0, u)))

    if total(float(bps[0])) < load:  # below every breakpoint: the unbounded points carry the rest
        t_mid = float(bps[0]) - 1.0
        lo_t = t_mid
    else:
        lo, hi = 0, bps.size - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if total(float(bps[mid])) >= load:
                lo = mid
            else:
                hi = mid
        lo_t = float(bps[lo])
        t_mid = 0.5 * (lo_t + float(bps[hi])) if hi > lo else lo_t
    free = (x - t_mid > 0.0) & (x - t_mid < u)
    sat = x - t_mid >= u
    k = int(np.count_nonzero(free))
    tau = (float(np.sum(x[free])) + float(np.sum(u[sat])) - float(load)) / k if k else lo_t
    return np.clip(x - tau, 0.0, u)


def project_feasible(x: np.ndarray, constraints: Constraints) -> np.ndarray:
    """The projection of x onto the feasible set of ``constraints``: p >= 0 (plain,
    ``np.maximum(x, 0)``), the box (``project_box``) or the box with the load
    (``project_box_sum``)."""
    if constraints.load is not None:
        return project_box_sum(x, constraints.upper, float(constraints.load))
    return project_box(x, constraints.upper)


def as_float64(x: Any) -> np.ndarray:
    """x as a float64 array, in the array space it lives in (a device array stays there)."""
    return x.astype(np.float64, copy=False) if hasattr(x, "astype") else np.asarray(x, dtype=np.float64)


#: How many units in the last place of its bound an element may sit below it and still
#: be read as at the bound (``fit_multiplier``).
AT_BOUND_ULPS = 16


def fit_multiplier(g: np.ndarray, p: np.ndarray, upper: np.ndarray | None) -> float:
    """The approach Delta a candidate p implies, from g = Hp - ubar (w = g - Delta):
    the mean of g over the elements strictly inside their bounds, each weighted by its
    distance from the nearer bound (the exact answer has g = Delta on every one of them).
    An element within round-off of its upper bound (``AT_BOUND_ULPS`` units of its last
    place) is at the bound: one a rounding below it does not set Delta alone.  With none
    inside: the largest g over the elements at their upper bound (the least Delta that keeps
    them plastic), else the least g (the approach at which contact begins).  The weights are
    taken relative to the largest, so that neither tiny nor huge forces under- or overflow
    their sum.  NaN when g or p is not finite or empty."""
    g, p = as_float64(g), as_float64(p)
    if g.size == 0 or not (np.all(np.isfinite(g)) and np.all(np.isfinite(p))):
        return math.nan
    u = np.full_like(p, math.inf) if upper is None else upper
    with np.errstate(invalid="ignore", over="ignore"):
        near = AT_BOUND_ULPS * np.spacing(np.where(np.isfinite(u), np.abs(u), 0.0))  # (0 where unbounded)
        slack = u - p
        v = np.minimum(p, np.where(slack > near, slack, 0.0))
    v = np.where(v > 0.0, v, 0.0)
    top = float(np.max(v))
    if top > 0.0:
        v = v / top
        return float(np.sum(v * g) / np.sum(v))
    saturated = slack <= near
    if np.any(saturated):
        return float(np.max(g[saturated]))
    return float(np.min(g))


__all__ = ["Constraints", "fit_multiplier", "hardness_bounds", "load_exceeds", "make_constraints",
           "project_box", "project_box_sum", "project_feasible"]
