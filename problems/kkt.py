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
every length -> c length).  Two natural scales of the instance are used:

* a displacement scale  u_s = max(||ubar||_inf, ||Hp||_inf)  (length), and
* a force scale         p_s = u_s / max(diag H)  (the force that alone indents one
  element by u_s).

Then  primal = max(0, -min p) / p_s,   dual = max(0, -min w) / u_s,
complementarity = max_i |w_i p_i| / (u_s p_s),  complementarity_sum = |w'p| / (u_s ||p||_1),
and  kkt_error = max(primal, dual, complementarity).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np


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

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def passes(self, tol: float) -> bool:
        return bool(np.isfinite(self.kkt_error) and self.kkt_error <= tol)


@dataclass(frozen=True)
class KKTFigures:
    """The three scaled figures, their max, and the two scales they were scaled by."""

    primal: float
    dual: float
    complementarity: float
    kkt_error: float
    u_scale: float
    p_scale: float


def kkt_figures(p: np.ndarray, w: np.ndarray, ubar: np.ndarray, diag_max: float,
                ubar_max: float | None = None) -> KKTFigures:
    """The scaled KKT figures of ``p`` with gap ``w = Hp - ubar`` (module doc):
    u_s = max(|ubar|_inf, |Hp|_inf), p_s = u_s / max diag H.  ``ubar_max``: |ubar|_inf
    when the caller already has it (a solver testing every iteration)."""
    hp = w + ubar
    hp_max = max(float(np.max(hp, initial=0.0)), -float(np.min(hp, initial=0.0)))
    if ubar_max is None:
        ubar_max = float(np.max(np.abs(ubar), initial=0.0))
    u_s = max(ubar_max, hp_max)
    if u_s == 0.0:
        u_s = 1.0  # ubar = 0 and p = 0: every figure is an exact zero anyway
    p_s = u_s / diag_max
    primal = max(0.0, -float(np.min(p, initial=0.0))) / p_s
    dual = max(0.0, -float(np.min(w, initial=0.0))) / u_s
    np.multiply(w, p, out=hp)
    comp = max(float(np.max(hp, initial=0.0)), -float(np.min(hp, initial=0.0))) / (u_s * p_s)
    return KKTFigures(primal, dual, comp, max(primal, dual, comp), u_s, p_s)


def scaled_kkt_error(p: np.ndarray, w: np.ndarray, ubar: np.ndarray, diag_max: float,
                     ubar_max: float | None = None) -> float:
    """max(primal, dual, complementarity) of ``kkt_figures``: the residual a solver stops on."""
    if p.size == 0:
        return 0.0
    return kkt_figures(p, w, ubar, diag_max, ubar_max).kkt_error


def _as_qp(obj: Any) -> Any:
    return obj.qp if hasattr(obj, "qp") else obj


def kkt_check(problem: Any, p: np.ndarray) -> KKTReport:
    """KKT figures of candidate ``p`` for ``problem`` (a QP or a ContactInstance)."""
    qp = _as_qp(problem)
    p = np.asarray(p, dtype=np.float64)
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    if p.shape != ubar.shape:
        raise ValueError(f"candidate p has shape {p.shape}, the problem has n = {ubar.size}")
    nan = float("nan")
    if not np.all(np.isfinite(p)):
        return KKTReport(nan, nan, nan, nan, np.inf, np.inf, np.inf, np.inf, np.inf, nan, nan, nan)
    Hp = qp.H.matvec(p)
    w = Hp - ubar
    f = kkt_figures(p, w, ubar, float(np.max(qp.H.diagonal())))
    p_s, u_s = f.p_scale, f.u_scale
    comp_sum = abs(float(w @ p))
    p1 = float(np.sum(np.abs(p)))
    return KKTReport(
        primal_abs=f.primal * p_s,
        dual_abs=f.dual * u_s,
        complementarity_abs=f.complementarity * u_s * p_s,
        complementarity_sum_abs=comp_sum,
        primal=f.primal,
        dual=f.dual,
        complementarity=f.complementarity,
        complementarity_sum=comp_sum / (u_s * p1) if p1 > 0 else 0.0,
        kkt_error=f.kkt_error,
        objective=float(0.5 * p @ Hp - ubar @ p),
        u_scale=u_s,
        p_scale=p_s,
    )


def relative_error(p: np.ndarray, p_ref: np.ndarray) -> float:
    """||p - p_ref||_inf / ||p_ref||_inf (absolute when p_ref = 0)."""
    p = np.asarray(p, dtype=np.float64)
    p_ref = np.asarray(p_ref, dtype=np.float64)
    d = float(np.max(np.abs(p - p_ref), initial=0.0))
    s = float(np.max(np.abs(p_ref), initial=0.0))
    return d / s if s > 0 else d


def relative_load_error(load: float, load_ref: float) -> float:
    return abs(load - load_ref) / abs(load_ref) if load_ref != 0 else abs(load - load_ref)
