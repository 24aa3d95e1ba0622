"""The KKT figures of the contact QP: the one definition of an answer's quality.

The harness judges every answer with ``kkt_check``; a solver may stop on
``scaled_kkt_error``, the same formula computed from its own gap w = Hp - ubar (no extra
matvec), so a solver stops exactly when the harness will accept its answer.

For the QP  min 1/2 p'Hp - ubar'p, p >= 0  the KKT conditions are the LCP

    w = Hp - ubar >= 0,   p >= 0,   w_i p_i = 0,

(stationarity holds by construction once w is defined as Hp - ubar).  ``kkt_check``
recomputes w itself from H and p -- a solver's own w or status is never used.

Scaled figures
--------------
All scaled figures are dimensionless and invariant under a change of units (E -> c E,
every length -> c length).  Their two scales come from the *problem*, never from the
candidate (a huge answer must not shrink its own residuals):

* a displacement scale  u_s = max(max ubar, ``RELIEF_SHARE`` ||ubar||_inf): the approach,
  the deepest overlap of the rigid body (||ubar||_inf itself where every ubar_i >= 0, as on
  a non-periodic trial set; on a periodic grid ubar holds the whole relief below zero, and
  an approach light for it is not judged against gaps it never closes) (length;
  ``U_SCALE_FALLBACK`` = 1 when ubar = 0, whose only answer is p = 0, so the figures are
  then absolute; under load control, where ubar holds no approach, ||ubar||_inf or the
  load's lengths, ``constrained_scales``), and
* a force scale         p_s = u_s / max(diag H)  (the force that alone indents one
  element by u_s).

Then  primal = max(0, -min p) / p_s,   dual = max(0, -min w) / u_s,
complementarity = max_i |(w_i / u_s)(p_i / p_s)|,  complementarity_sum = |w'p| / (u_s ||p||_1),
and  kkt_error = max(primal, dual, complementarity).

Every figure is computed so that overflow, NaN or inf can only make it worse: a product
that overflows is inf, and any NaN (inf - inf, 0 x inf, a NaN entry) reads as inf --
never as 0, as Python's ``max`` would read it.

Bounds and load control (``problems.constraints``)
--------------------------------------------------
A QP may carry upper bounds u (hardness: 0 <= p <= u) and a load equality sum(p) = P whose
multiplier is the approach Delta; then w = Hp - ubar - Delta (Delta = 0 without a load
equality) and the KKT conditions are  0 <= p <= u,  sum p = P,  w >= 0 where p = 0,
w <= 0 where p = u, w = 0 in between.  ``constrained_figures`` scales them with the same
u_s and p_s:

* primal = max(0, -min p, max(p - u)) / p_s;
* equality = |sum p - P| / P  (the relative load error; scaled by p_s when P = 0, and 0
  without a load equality);
* dual = max_i max(0, -w_i) / u_s x min(max(0, u_i - p_i) / p_s, 1): a negative gap is
  allowed only as far as the element sits at its upper bound, weighted by its distance
  below the bound in the force scale, capped at 1 (for u_i = inf, or a bound far above every
  force, the plain figure max(0, -w_i) / u_s).  Near its bound an element is judged as
  the plain figures judge one near p = 0: a gap of the sign its bound allows (w < 0 below
  u, w > 0 above 0) counts as the product of that gap and the distance, so an answer is
  read the same at either bound;
* complementarity = max_i of (|w_i| p_i) on an unbounded element (the plain figure) and
  of max(max(0, w_i) |p_i|, max(0, -w_i) min(|u_i - p_i|, p_s)) on a bounded one, scaled
  by u_s p_s: the lower and the upper bound's products, the slack capped at the force
  scale.  Beyond it the dual figure reads the same negative gap in full, so a bound far
  above every force is judged as no bound (not as round-off in w times the bound);
* kkt_error = max(primal, equality, dual, complementarity).

The force scale is capped by the bounds, element by element: element i is read on
p_s,i = min(p_s, u_i) with p_s = u_s / max diag H (a uniform hardness: one scale,
min(p_s, u), which ``constrained_scales`` reports), so a small hardness is not judged on a
scale above it, and one element's small bound does not shrink the scale of the others.  Under load
control u_s is at least (P / n) max diag H, the indentation of one element by the mean force
(a heavy load on a low relief, or a flat surface, is judged on the load's length), and at
most P max diag H, the most the load can displace any element (a light load on a high
relief is judged on the load's length, not on gaps it never reaches; not below 1e-6 of the
relief the load can reach, ``RELIEF_SHARE``), p_s = u_s / max diag H with either; and the
complementarity figure also reads the products as a share of the load:
complementarity = max(max_i of the products above, p_s sum_i of them / P) -- the load carried
across open gaps (or pressed past a bound), weighted by the gap in u_s.  A max alone cannot
see a light load spread thin: P / n per element is then far below p_s, and every product
tiny, although the answer puts the load where the surface does not touch.

Delta is the candidate's own (a solver reports it) or, when it gives none,
``constraints.fit_multiplier`` of the candidate; a non-finite Delta makes every figure inf.
With no bounds and no load equality the plain figures above are computed, unchanged.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from .constraints import Constraints, fit_multiplier
from .fft_threads import each_band


class _HasQP(Protocol):
    @property
    def H(self) -> Any: ...

    @property
    def ubar(self) -> np.ndarray: ...


@dataclass(frozen=True)
class KKTReport:
    primal_abs: float  # max(0, -min p)           [force]
    dual_abs: float  # max(0, -min w)             [length]
    complementarity_abs: float  # max_i |w_i p_i| [force x length]
    complementarity_sum_abs: float  # |w'p|       [force x length]
    primal: float  # scaled
    dual: float  # scaled
    complementarity: float  # scaled (max)
    complementarity_sum: float  # scaled (sum)
    kkt_error: float  # max of the three scaled figures
    objective: float
    u_scale: float
    p_scale: float

    equality_abs: float = 0.0  # |sum p - P|        [force]; 0 without a load equality
    equality: float = 0.0  # scaled
    multiplier: float = math.nan  # the Delta w was computed with (NaN without a load equality)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def passes(self, tol: float) -> bool:
        """kkt_error <= tol (False for a NaN or inf error)."""
        return bool(math.isfinite(self.kkt_error) and self.kkt_error <= tol)


#: The scaled figures of a `KKTReport`, by field name.
SCALED_PARTS = ("primal", "dual", "complementarity", "complementarity_sum")

#: u_s when ubar = 0 (the only answer is p = 0; the figures are then absolute).
U_SCALE_FALLBACK = 1.0


@dataclass(frozen=True)
class KKTFigures:
    """The three scaled figures, their max, and the two scales they were scaled by."""

    primal: float
    dual: float
    complementarity: float
    kkt_error: float
    u_scale: float
    p_scale: float
    equality: float = 0.0
    multiplier: float = math.nan


def worse(x: float) -> float:
    """``x`` as a residual: NaN reads as inf (a figure that cannot be computed is the worst)."""
    return math.inf if math.isnan(x) else float(x)


def worst(*xs: float) -> float:
    """max of residuals in which a NaN is inf (Python's ``max`` would drop it)."""
    return max(worse(x) for x in xs)


def read_scalars(*values: Any) -> list[float]:
    """Zero-dimensional results of one array module (NumPy's, or a device's) as floats,
    read together: on a device, one transfer and one wait instead of one per value
    (a bool reads as 0.0 or 1.0)."""
    if all(isinstance(v, (np.generic, numbers.Number)) for v in values):  # the host's: read already
        return [float(v) for v in values]
    return [float(v) for v in np.stack([v.astype(np.float64) for v in values]).tolist()]


def below_zero(m: float) -> float:
    """min(m, 0), NaN for NaN."""
    return m if not m >= 0.0 else 0.0


def above_zero(m: float) -> float:
    """max(m, 0), NaN for NaN."""
    return m if not m <= 0.0 else 0.0


def min_below_zero(x: Any) -> float:
    """min(min x, 0) as a float, NaN when x holds a NaN, 0 for an empty x: ``np.min(x,
    initial=0.0)`` in any array module (CuPy's reductions take no ``initial``)."""
    return below_zero(_exact_reduction(np.min, x)) if x.size else 0.0


def max_above_zero(x: Any) -> float:
    """max(max x, 0) as a float, NaN when x holds a NaN, 0 for an empty x (``min_below_zero``)."""
    return above_zero(_exact_reduction(np.max, x)) if x.size else 0.0


def _exact_reduction(reduce: Any, x: Any) -> float:
    """``reduce`` (np.min or np.max: exact, NaN propagating) of a non-empty x, in bands on
    the threads (``each_band``): the whole's value on any thread count."""
    parts = each_band(lambda s: reduce(x[s]), x)
    return float(parts[0] if len(parts) == 1 else reduce(parts))


def _negative_part(x: float) -> float:
    """max(0, -x), NaN for NaN."""
    return math.nan if math.isnan(x) else max(0.0, -x)


def problem_scales(ubar: np.ndarray, diag_max: float, ubar_max: float | None = None,
                   displacement: bool = True) -> tuple[float, float]:
    """(u_s, p_s) of the problem (module doc): u_s = max(max ubar, ``RELIEF_SHARE`` x
    ||ubar||_inf) under displacement control -- the approach, the deepest overlap the rigid
    body makes, so that a light approach on a high relief (a periodic grid's whole relief in
    ubar) is not judged against gaps it never closes -- and ||ubar||_inf where ``displacement``
    is False (under load control ubar holds no approach: it is the multiplier's);
    p_s = u_s / max diag H.  ``ubar_max``: ||ubar||_inf when the caller already has it."""
    top = float(np.max(np.abs(ubar), initial=0.0)) if ubar_max is None else float(ubar_max)
    u_s = max(max_above_zero(ubar), RELIEF_SHARE * top) if displacement else top
    if not (u_s > 0.0 and u_s / float(diag_max) > 0.0):  # 0, or so small (subnormal) that p_s underflows
        u_s = U_SCALE_FALLBACK
    return u_s, u_s / float(diag_max)


def constrained_scales(ubar: np.ndarray, diag_max: float, constraints: Constraints,
                       ubar_max: float | None = None) -> tuple[float, float]:
    """(u_s, p_s) of a QP with constraints: ``problem_scales``, with p_s capped by the
    least finite upper bound -- the scale a uniform bound reads every element on; with
    bounds that differ, ``constrained_figures`` reads each element on its own (module doc)
    -- (a force no element can exceed, so a violation of the bound is
    read against the bound itself).  The plain scales without bounds.  Under load control
    the load's own lengths count too (``load_length``): u_s is at least (P / n) max diag H,
    the indentation of one element by the mean force, so that a load heavy for the
    surface's relief -- or any load on a flat surface, ubar = 0, where ``problem_scales``
    has no length to go by -- is not judged against a relief round-off in w dwarfs
    (``U_SCALE_FALLBACK`` would judge a flat surface in absolute units); and at most
    P max diag H, the most any element can be displaced by the load, so that a load light
    for the relief is not judged against a relief its gaps never reach."""
    top = float(np.max(np.abs(ubar), initial=0.0)) if ubar_max is None else float(ubar_max)
    length = load_length(ubar, top, diag_max, constraints)
    if length is not None:
        u_s, p_s = length, length / float(diag_max)
    else:
        u_s, p_s = problem_scales(ubar, diag_max, top, not constraints.load_control)  # (||ubar||_inf read once)
    if constraints.bounded:
        p_s = min(p_s, float(np.min(constraints.upper)))
    return u_s, p_s


#: The least share of the reachable relief (``reachable_relief``) a load-controlled QP's
#: displacement scale goes down to (``load_length``): the round-off of w = Hp - ubar - Delta
#: where the load can make contact, a few ulps of that relief, then stays under 1e-9 of the
#: scale (a ubar offset by a constant, which Delta absorbs, moves no answer).
RELIEF_SHARE = 1e-6


def load_length(ubar: np.ndarray, top: float, diag_max: float, constraints: Constraints) -> float | None:
    """The displacement scale of a load-controlled QP with relief ``top`` = ||ubar||_inf,
    where the load sets it; None where the relief does (no load control, no finite
    positive load, or a load whose lengths bracket the relief).

    The load P displaces no element by more than P max diag H (|H_ij| <= max diag H for
    a positive definite H, and p >= 0 sums to P), so its gaps are read on that length
    when the relief exceeds it -- not below ``RELIEF_SHARE`` of the relief the load can
    reach (``reachable_relief``: a deep pit, which no answer touches, loosens nothing);
    and on the mean force's indentation (P / n) max diag H when that exceeds the relief."""
    if not (constraints.load_control and ubar.size):
        return None
    load = float(constraints.load)  # type: ignore[arg-type]
    whole = load * float(diag_max)
    if not (load > 0.0 and 0.0 < whole < math.inf):
        return None
    mean = whole / ubar.size
    if mean > top and mean > 0.0:
        return mean
    if whole < top:
        return max(whole, RELIEF_SHARE * reachable_relief(ubar, whole))
    return None


def reachable_relief(ubar: np.ndarray, whole: float) -> float:
    """max |ubar_i| over the elements a load displacing no element by more than ``whole``
    can bring into contact: ubar_i >= max ubar - 2 whole (two elements in contact differ
    in ubar by their displacements' difference, at most 2 whole, and the highest element
    is in contact or clear of it)."""
    near = ubar[ubar >= float(np.max(ubar)) - 2.0 * whole]  # (any array module: the highest is one of them)
    return float(np.max(np.abs(near))) if near.size else 0.0


def kkt_figures(p: np.ndarray, w: np.ndarray, ubar: np.ndarray, diag_max: float,
                ubar_max: float | None = None) -> KKTFigures:
    """The scaled KKT figures of ``p`` with gap ``w = Hp - ubar`` (module doc), scaled by
    the problem's u_s (``problem_scales``) and p_s = u_s / max diag H.  ``ubar_max``:
    ||ubar||_inf when the caller already has it (a solver testing every iteration).
    A non-finite entry of p or w, or a product that overflows, gives inf."""
    u_s, p_s = problem_scales(ubar, diag_max, ubar_max)
    p_min, w_min, t_max, t_min, finite = _extremes(p, w, p_s)
    with np.errstate(all="ignore"):
        primal = worse(_negative_part(below_zero(p_min)) / p_s)
        dual = worse(_negative_part(below_zero(w_min)) / u_s)
        comp = worse(worst(above_zero(t_max), -below_zero(t_min)) / u_s)
    if not finite:
        primal = dual = comp = math.inf  # an answer or gap with inf or NaN entries is no answer
    return KKTFigures(primal, dual, comp, worst(primal, dual, comp), u_s, p_s)


def _extremes(p: Any, w: Any, p_s: float) -> tuple[float, float, float, float, bool]:
    """min p, min w, max t, min t for t = (p / p_s) w, the scaled complementarity (0 for an
    empty array; NaN propagates), and whether p and w are finite, read in one transfer
    (``read_scalars``), in bands on the threads (``each_band``: min and max are exact, so the
    same figures on any thread count).  An array is finite when its least and greatest
    entries are (a NaN makes both NaN): two reductions where a finiteness mask took two
    passes and a temporary."""
    if p.size == 0 or w.size == 0:
        return min_below_zero(p), min_below_zero(w), 0.0, 0.0, _finite(p, w)

    def part(s: slice) -> tuple[Any, ...]:
        ps, ws = p[s], w[s]
        with np.errstate(all="ignore"):
            t = np.divide(ps, p_s)  # (w / u_s)(p / p_s) in scaled form: no spurious underflow, nor an
            # overflow of 1 / p_s where p_s is subnormal
            np.multiply(t, ws, out=t)
        return np.min(ps), np.min(ws), np.max(t), np.min(t), np.max(ps), np.max(ws)

    bands = each_band(part, p)
    if len(bands) == 1:
        p_min, w_min, t_max, t_min, p_max, w_max = read_scalars(*bands[0])
    else:  # host bands: NumPy's min and max propagate a NaN
        lowest, highest = np.min(bands, axis=0), np.max(bands, axis=0)
        p_min, w_min, t_min, t_max, p_max, w_max = (float(v) for v in (lowest[0], lowest[1], lowest[3],
                                                                      highest[2], highest[4], highest[5]))
    return p_min, w_min, t_max, t_min, all(math.isfinite(v) for v in (p_min, p_max, w_min, w_max))


def scaled_kkt_error(p: np.ndarray, w: np.ndarray, ubar: np.ndarray, diag_max: float,
                     ubar_max: float | None = None) -> float:
    """max(primal, dual, complementarity) of ``kkt_figures``: the residual a solver stops on."""
    if p.size == 0:
        return 0.0
    return kkt_figures(p, w, ubar, diag_max, ubar_max).kkt_error


def _all_infinite(u_s: float, p_s: float, multiplier: float = math.nan) -> KKTFigures:
    inf = math.inf
    return KKTFigures(inf, inf, inf, inf, u_s, p_s, inf, multiplier)


def candidate_multiplier(g: np.ndarray, p: np.ndarray, constraints: Constraints,
                         multiplier: float | None = None) -> float:
    """The Delta the figures use (module doc): 0 without a load equality, else the
    candidate's ``multiplier`` or, when it gives none, ``fit_multiplier`` of (g, p)."""
    if not constraints.load_control:
        return 0.0
    if multiplier is None:
        return fit_multiplier(g, p, constraints.upper)
    return float(multiplier)


def equality_scale(load: float, p_s: float) -> float:
    """The force the load residual is scaled by: the load P itself (a relative load error),
    p_s when P = 0."""
    return load if load > 0.0 else p_s


def _equality(p: np.ndarray, constraints: Constraints, p_s: float, total: float | None = None) -> float:
    """The scaled load residual |sum p - P| (``total``: sum p when the caller has read it)."""
    if not constraints.load_control:
        return 0.0
    load = float(constraints.load)  # type: ignore[arg-type]
    total = float(np.sum(p)) if total is None else total
    with np.errstate(all="ignore"):
        return worse(abs(total - load) / equality_scale(load, p_s))


def _finite(p: Any, g: Any) -> bool:
    """Whether p and g hold only finite entries (one read)."""
    return read_scalars(np.all(np.isfinite(p)) & np.all(np.isfinite(g)))[0] == 1.0


def constrained_figures(p: np.ndarray, g: np.ndarray, ubar: np.ndarray, diag_max: float, constraints: Constraints,
                        multiplier: float | None = None, ubar_max: float | None = None) -> KKTFigures:
    """The scaled KKT figures of ``p`` under bounds and a load equality (module doc), from
    g = Hp - ubar (without Delta).  ``multiplier``: the candidate's Delta (None: fitted).
    Plain constraints give exactly ``kkt_figures``.  A non-finite entry, bound violation
    product or Delta gives inf, never a smaller figure."""
    if constraints.plain:
        return kkt_figures(p, g, ubar, diag_max, ubar_max)
    u_s, p_s = constrained_scales(ubar, diag_max, constraints, ubar_max)
    if p.shape != g.shape or not _finite(p, g):
        return _all_infinite(u_s, p_s)
    delta = candidate_multiplier(g, p, constraints, multiplier)
    if not math.isfinite(delta):
        return _all_infinite(u_s, p_s, delta)
    if constraints.upper is None:  # a load equality alone: the same figures in fewer passes
        return _load_figures(p, g - delta, constraints, u_s, p_s, delta)
    u = constraints.upper_or_inf(p.size)
    bounded = np.isfinite(u)
    with np.errstate(all="ignore"):
        w = g - delta
        slack = u - p
        ps = np.minimum(u_s / float(diag_max), u)  # each element's force scale (module doc): its bound if below
        primal = worse(max_above_zero(np.maximum(-p, -slack) / ps))
        # a negative gap times the distance from the bound, capped at the force scale: the
        # dual figure below the bound, the upper product on a bounded element
        weighted = np.maximum(-w, 0.0) / u_s * np.minimum(np.abs(slack) / ps, 1.0)
        dual = worse(max_above_zero(np.where(slack > 0.0, weighted, 0.0)))
        pos = np.maximum(w, 0.0) / u_s
        lower = np.abs(p) / ps * np.where(bounded, pos, np.abs(w) / u_s)
        upper = np.where(bounded, weighted, 0.0)
        comp = worst(max_above_zero(lower), max_above_zero(upper))
        if constraints.load_control:  # (the products in force x length, over u_s P)
            comp = worst(comp, load_share(float(np.sum((lower + upper) * ps)), constraints))
    equality = _equality(p, constraints, p_s)
    primal, dual, comp = worse(primal), worse(dual), worse(comp)
    return KKTFigures(primal, dual, comp, worst(primal, dual, comp, equality), u_s, p_s, equality, delta)


def load_share(force_sum: float, constraints: Constraints) -> float:
    """The complementarity products as a share of the load (module doc): ``force_sum`` =
    sum_i t_i p_s,i (each product t_i scaled by u_s p_s,i, times its force scale: a force,
    weighted by its gap in u_s) over P, under a load P > 0; 0 without one (P = 0 leaves only
    p = 0, which the primal and equality figures judge).  NaN reads as inf."""
    load = float(constraints.load) if constraints.load_control else 0.0
    if not load > 0.0:
        return 0.0
    return worse(float(np.float64(force_sum) / np.float64(load)))


def _load_figures(p: np.ndarray, w: np.ndarray, constraints: Constraints, u_s: float, p_s: float,
                  delta: float) -> KKTFigures:
    """``constrained_figures`` with no upper bound (u = inf everywhere), w = g - Delta:
    primal from min(p), dual from max(-w), complementarity from max(|p| |w|), each scaled
    as there."""
    with np.errstate(all="ignore"):
        t = np.abs(p) / p_s * (np.abs(w) / u_s)
        if p.size and w.size:  # the five reductions in one read
            p_min, w_min, t_max, t_sum, total = read_scalars(np.min(p), np.min(w), np.max(t), np.sum(t), np.sum(p))
        else:
            p_min, w_min, t_max, t_sum, total = min_below_zero(p), min_below_zero(w), max_above_zero(t), 0.0, 0.0
        primal = worse(float(np.float64(_negative_part(below_zero(p_min))) / p_s))
        dual = worse(float(np.float64(_negative_part(below_zero(w_min))) / np.float64(u_s)))
        comp = worst(worse(above_zero(t_max)), load_share(t_sum * p_s, constraints))
    equality = _equality(p, constraints, p_s, total)
    return KKTFigures(primal, dual, comp, worst(primal, dual, comp, equality), u_s, p_s, equality, delta)


def constrained_kkt_error(p: np.ndarray, g: np.ndarray, ubar: np.ndarray, diag_max: float,
                          constraints: Constraints, multiplier: float | None = None,
                          ubar_max: float | None = None) -> float:
    """kkt_error of ``constrained_figures``: the residual a solver stops on (0 for n = 0)."""
    if p.size == 0:
        return 0.0
    return constrained_figures(p, g, ubar, diag_max, constraints, multiplier, ubar_max).kkt_error


def _as_qp(obj: Any) -> Any:
    return obj.qp if hasattr(obj, "qp") else obj


def infinite_report(u_s: float = math.nan, p_s: float = math.nan) -> KKTReport:
    """The report of an answer that is no answer (non-finite entries): every figure inf."""
    inf, nan = math.inf, math.nan
    return KKTReport(inf, inf, inf, inf, inf, inf, inf, inf, inf, nan, u_s, p_s, inf, inf, nan)


def kkt_check(problem: Any, p: np.ndarray, multiplier: float | None = None,
              also_at: float | None = None) -> KKTReport:
    """KKT figures of candidate ``p`` for ``problem`` (a QP or a ContactInstance),
    recomputing w = Hp - ubar (- Delta) from the problem; ``ValueError`` when p has the
    wrong shape, and ``ProblemInputError`` when the problem's constraints cannot be posed on
    it (``Constraints.check``: a bound <= 0 would turn the scales' signs).  Non-finite
    entries in p (or in Hp), and a p that is not real (a complex entry), give an all-inf
    report.  Under load control ``multiplier`` is the candidate's Delta (None:
    ``fit_multiplier``); without a load equality it is not used.  ``also_at``: a second
    candidate Delta, read from the same product H p; the report at whichever of the two gives
    the smaller KKT error (the first on a tie).  A QP without bounds and load equality is
    judged by the plain figures."""
    qp = _as_qp(problem)
    real = True
    if np.iscomplexobj(p):  # (a real answer in a complex dtype is read as the real answer)
        real, p = not np.any(np.imag(p)), np.real(p)
    p = np.asarray(p, dtype=np.float64)
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    if p.shape != ubar.shape:
        raise ValueError(f"candidate p has shape {p.shape}, the problem has n = {ubar.size}")
    constraints = _constraints_of(qp)
    constraints.check(ubar.size)
    if ubar.size == 0:  # no unknown: every figure 0, as the solvers' own (``constrained_kkt_error``)
        return KKTReport(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, U_SCALE_FALLBACK, math.nan)
    diag_max = float(np.max(qp.H.diagonal()))
    u_s, p_s = constrained_scales(ubar, diag_max, constraints)
    if not (real and np.all(np.isfinite(p))):
        return infinite_report(u_s, p_s)
    with np.errstate(all="ignore"):
        Hp = np.asarray(qp.H.matvec(p), dtype=np.float64)
        g = Hp - ubar
        f = constrained_figures(p, g, ubar, diag_max, constraints, multiplier)
        if also_at is not None and constraints.load_control:
            f_also = constrained_figures(p, g, ubar, diag_max, constraints, also_at)
            f = f_also if f_also.kkt_error < f.kkt_error else f
        if not math.isfinite(f.kkt_error):
            return infinite_report(u_s, p_s)
        objective = float(0.5 * p @ Hp - ubar @ p)
        comp_sum = worse(abs(_complementarity_sum(p, g - f.multiplier if constraints.load_control else g,
                                                  constraints)))
        p1 = float(np.sum(np.abs(p)))
    load = constraints.load
    return KKTReport(
        primal_abs=f.primal * p_s,
        dual_abs=f.dual * u_s,
        complementarity_abs=f.complementarity * u_s * p_s,
        complementarity_sum_abs=comp_sum,
        primal=f.primal,
        dual=f.dual,
        complementarity=f.complementarity,
        complementarity_sum=worse(comp_sum / u_s / p1) if p1 > 0 else 0.0,
        kkt_error=f.kkt_error,
        objective=objective,
        u_scale=u_s,
        p_scale=p_s,
        equality_abs=0.0 if load is None else f.equality * equality_scale(float(load), p_s),
        equality=f.equality,
        multiplier=f.multiplier if constraints.load_control else math.nan,
    )


def _constraints_of(qp: Any) -> Constraints:
    c = getattr(qp, "constraints", None)
    return Constraints() if c is None else c


def _complementarity_sum(p: np.ndarray, w: np.ndarray, constraints: Constraints) -> float:
    """w'p, plus on bounded elements -sum of min(w, 0)(u - p): both bounds' products."""
    if not constraints.bounded:
        return float(w @ p)
    u = constraints.upper_or_inf(p.size)
    bounded = np.isfinite(u)
    lower = float(np.where(bounded, np.maximum(w, 0.0), w) @ p)
    upper = float(np.sum(np.where(bounded, np.maximum(-w, 0.0) * (u - p), 0.0)))
    return lower + upper


def relative_error(p: np.ndarray, p_ref: np.ndarray) -> float:
    """||p - p_ref||_inf / ||p_ref||_inf (absolute when p_ref = 0)."""
    p = np.asarray(p, dtype=np.float64)
    p_ref = np.asarray(p_ref, dtype=np.float64)
    d = float(np.max(np.abs(p - p_ref), initial=0.0))
    s = float(np.max(np.abs(p_ref), initial=0.0))
    return d / s if s > 0 else d


def relative_load_error(load: float, load_ref: float) -> float:
    return abs(load - load_ref) / abs(load_ref) if load_ref != 0 else abs(load - load_ref)
