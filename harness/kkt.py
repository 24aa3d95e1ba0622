"""The KKT check: the one place that judges an answer.  Used by every part of the harness.

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
    diag_max = float(np.max(qp.H.diagonal()))
    u_s = max(float(np.max(np.abs(ubar), initial=0.0)), float(np.max(np.abs(Hp), initial=0.0)))
    if u_s == 0.0:
        u_s = 1.0  # ubar = 0 and p = 0: every figure is an exact zero anyway
    p_s = u_s / diag_max
    primal_abs = max(0.0, -float(np.min(p)))
    dual_abs = max(0.0, -float(np.min(w)))
    comp = np.abs(w * p)
    comp_max = float(np.max(comp, initial=0.0))
    comp_sum = abs(float(w @ p))
    p1 = float(np.sum(np.abs(p)))
    primal = primal_abs / p_s
    dual = dual_abs / u_s
    complementarity = comp_max / (u_s * p_s)
    complementarity_sum = comp_sum / (u_s * p1) if p1 > 0 else 0.0
    return KKTReport(
        primal_abs=primal_abs,
        dual_abs=dual_abs,
        complementarity_abs=comp_max,
        complementarity_sum_abs=comp_sum,
        primal=primal,
        dual=dual,
        complementarity=complementarity,
        complementarity_sum=complementarity_sum,
        kkt_error=max(primal, dual, complementarity),
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
