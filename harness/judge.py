"""The judge: the one place that turns an answer into a verdict.

``run``, ``validate``, the Dask executor and the benchmark scripts all call ``judge``.
A verdict carries two readings of one answer:

* ``status``  -- the table's reading: "solved" when the scaled KKT error
  (``contactbench.problems.kkt.kkt_check``, recomputed from H and p, never the solver's
  own figure) is at most the profile's ``check_tol``, else "inaccurate";
* ``reading`` -- the conformance reading, which also weighs the solver's own claim:
  "pass" (solved, and p within ``p_tol`` of the reference when one is given),
  "wrong" (not that, while the solver claimed convergence: a wrong answer), or
  "unconverged" (not that, and the solver said so: an honest failure).

Where an answer is unusable (wrong length, non-finite) the verdict says so in
``problems`` and its kkt_error is inf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contactbench.problems.instances import CONTACT_TOL, ContactInstance
from contactbench.problems.kkt import KKTReport, kkt_check, relative_error, relative_load_error

from .schema import VERDICTS as READINGS  # the table contract names the readings


@dataclass
class Verdict:
    """The judge's verdict on one answer (module doc)."""

    status: str  # "solved" | "inaccurate"
    reading: str  # "pass" | "wrong" | "unconverged"
    claimed: bool
    kkt: KKTReport | None
    figures: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def kkt_error(self) -> float:
        return float("inf") if self.kkt is None else float(self.kkt.kkt_error)

    @property
    def correct_claim(self) -> bool:
        return self.claimed == (self.status == "solved")

    def message(self) -> str:
        text = "; ".join(self.problems)
        if self.reading == "wrong":
            text += " -- while claiming convergence"
        elif self.reading == "pass" and not self.claimed:
            text = "correct, though the solver did not claim convergence"
        return text


def judge(inst: ContactInstance, p: Any, claimed: bool, check_tol: float, p_ref: np.ndarray | None = None,
          p_tol: float | None = None, analytic_load: float | None = None) -> Verdict:
    """The verdict on answer ``p`` of instance ``inst`` (module doc).  ``claimed`` is the
    solver's own convergence claim; ``p_ref`` an exact reference answer; ``p_tol`` the
    allowed ||p - p_ref||_inf / ||p_ref||_inf for a "pass" (None: not checked)."""
    problems: list[str] = []
    arr = None if p is None else np.asarray(p)
    if arr is None or arr.shape != (inst.n,):
        problems.append(f"returned p of shape {None if arr is None else arr.shape}, expected ({inst.n},)")
        return _verdict(None, claimed, problems, {})
    if arr.dtype != np.float64:
        problems.append(f"returned {arr.dtype} p (input ubar was {np.asarray(inst.qp.ubar).dtype})")
    pf = arr.astype(np.float64, copy=False)
    kkt = kkt_check(inst, pf)
    if not np.all(np.isfinite(pf)):
        problems.append("p has non-finite entries")
        return _verdict(kkt, claimed, problems, {"kkt_error": kkt.kkt_error})
    figures = answer_figures(inst, pf, kkt, p_ref, analytic_load, check_tol)
    if not kkt.kkt_error <= check_tol:
        problems.append(f"kkt_error {kkt.kkt_error:.2e} > check_tol {check_tol:.0e}")
    if p_ref is not None and p_tol is not None and not figures["p_rel_error"] <= p_tol:
        problems.append(f"p is {figures['p_rel_error']:.2e} off the exact reference (allowed {p_tol:.1e})")
    return _verdict(kkt, claimed, problems, figures, solved=kkt.kkt_error <= check_tol)


def _verdict(kkt: KKTReport | None, claimed: bool, problems: list[str], figures: dict[str, Any],
             solved: bool = False) -> Verdict:
    status = "solved" if solved else "inaccurate"
    reading = "pass" if not problems else ("wrong" if claimed else "unconverged")
    return Verdict(status, reading, bool(claimed), kkt, figures, problems)


def answer_figures(inst: ContactInstance, p: np.ndarray, kkt: KKTReport, p_ref: np.ndarray | None,
                   analytic_load: float | None, check_tol: float = CONTACT_TOL) -> dict[str, Any]:
    """The table's figures of an answer: KKT figures, load, contact fraction and the
    errors against the reference / closed form (column names of ``harness.schema``).
    The contact fraction and its flag ``contact_uncertain`` are read at the judge's
    ``check_tol`` (``ContactInstance.contact_mask``: p_i > check_tol x p_s)."""
    load = inst.load(p)
    out: dict[str, Any] = {
        "primal_residual": kkt.primal,
        "dual_residual": kkt.dual,
        "complementarity": kkt.complementarity,
        "complementarity_sum": kkt.complementarity_sum,
        "kkt_error": kkt.kkt_error,
        "objective": kkt.objective,
        "load": load,
        "dim_load": inst.dimensionless_load(p),
        "contact_fraction": inst.contact_fraction(p, check_tol),
        "contact_uncertain": inst.contact_uncertain(p, check_tol),
    }
    if p_ref is not None:
        out["p_rel_error"] = relative_error(p, p_ref)
        out["load_rel_error"] = relative_load_error(load, float(np.sum(p_ref)))
    if analytic_load is not None and math.isfinite(analytic_load):
        out["analytic_load_rel_error"] = relative_load_error(load, analytic_load)
        if p_ref is None:
            out["load_rel_error"] = out["analytic_load_rel_error"]
    return out
