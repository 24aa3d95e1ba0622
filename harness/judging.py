"""The judge: the one place that turns an answer into a verdict (docs/verdicts.md).

``run`` (the worker), ``validate``, ``solve_sequence``, pytest-benchmark and the
benchmark scripts all call ``judge``.  A verdict carries two readings of one answer:

* ``status``  -- the table's reading: "solved" when the scaled KKT error
  (``contactbench.problems.kkt.kkt_check``, recomputed from the harness's own H and
  ubar, never the solver's w or figure) is at most the profile's ``check_tol``;
  "inaccurate" when it is not; "failed" when the answer is no answer (``read_answer``:
  not a length-n vector of finite real numbers) or the solver wrote into the problem it
  was handed (``ProblemSeal``);
* ``reading`` -- the conformance reading, which also weighs the solver's own claim:
  "pass" (solved, and p within ``p_tol`` of the reference when one is given),
  "wrong" (not that, while the solver claimed convergence; and any answer of a solver
  that wrote into its problem), or "unconverged" (not that, and the solver said so).

Every figure is NaN- and overflow-safe (``problems.kkt``): nothing non-finite can make a
verdict better.  The scales come from the problem, never from the candidate.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from contactbench.problems.errors import check_positive
from contactbench.problems.instances import CONTACT_TOL, ContactInstance
from contactbench.problems.kkt import KKTReport, kkt_check, relative_error, relative_load_error

from .table.schema import VERDICTS as READINGS  # the table contract names the readings

__all__ = ["READINGS", "ProblemSeal", "UnreadAnswer", "Verdict", "answer_figures", "judge", "portable_answer",
           "read_answer", "shown_apart"]


@dataclass
class Verdict:
    """The judge's verdict on one answer (module doc).  ``usable``: the answer was a
    length-n vector of finite real numbers and the problem was left as handed.
    ``kinds`` names each of ``problems``, in order: "answer" (no answer), "tampered",
    "dtype" (p not float64), "kkt" (above check_tol), "reference" (beyond p_tol)."""

    status: str  # "solved" | "inaccurate" | "failed"
    reading: str  # "pass" | "wrong" | "unconverged"
    claimed: bool
    kkt: KKTReport | None
    figures: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    tampered: bool = False  # the solver wrote into the problem it was handed
    kinds: list[str] = field(default_factory=list)

    @property
    def kkt_error(self) -> float:
        return math.inf if self.kkt is None else float(self.kkt.kkt_error)

    @property
    def usable(self) -> bool:
        return self.status != "failed"

    @property
    def correct_claim(self) -> bool:
        return self.claimed == (self.status == "solved")

    def message(self) -> str:
        text = "; ".join(self.problems)
        if self.reading == "wrong" and self.claimed:
            text += " -- while claiming convergence"
        elif self.reading == "pass" and not self.claimed:
            text = "correct, though the solver did not claim convergence"
        return text


# ---------------------------------------------------------------------------
# The problem a solver was handed: sealed before the solve, checked after
# ---------------------------------------------------------------------------


def _defining_arrays(qp: Any) -> list[tuple[str, np.ndarray]]:
    """ubar, the upper bounds (a hardness) and the numpy arrays that define the operator:
    its public array attributes and those of its public helper objects (an FFT operator's
    kernel transform)."""
    out: list[tuple[str, np.ndarray]] = [("ubar", np.asarray(qp.ubar))]
    upper = getattr(getattr(qp, "constraints", None), "upper", None)
    if upper is not None:
        out.append(("upper", np.asarray(upper)))
    for where, part in _operator_parts(qp):
        out += [(f"{where}.{k}", v) for k, v in sorted(vars(part).items())
                if not k.startswith("_") and isinstance(v, np.ndarray)]
    return out


def _digest(arr: np.ndarray) -> str:
    h = hashlib.sha1(usedforsecurity=False)  # a fingerprint, not a defence against crafted collisions
    h.update(f"{arr.dtype.str}{arr.shape}".encode())
    h.update(memoryview(np.ascontiguousarray(arr)).cast("B"))
    return h.hexdigest()


def _operator_parts(qp: Any) -> list[tuple[str, Any]]:
    """The operator and its public helper objects (an FFT operator's kernel transform),
    named as the seal names them."""
    H = qp.H
    return [("H", H)] + [(f"H.{name}", value) for name, value in sorted(vars(H).items())
                         if not name.startswith("_") and hasattr(value, "__dict__") and not isinstance(value, type)]


def _methods(qp: Any) -> tuple[tuple[type, str, Any], ...]:
    """(class, name, attribute) of every method and descriptor the classes of the operator
    and its helpers define (their MROs, ``object`` aside): what a product runs."""
    classes = dict.fromkeys(c for _, part in _operator_parts(qp) for c in type(part).__mro__ if c is not object)
    return tuple((c, name, value) for c in classes for name, value in vars(c).items()
                 if callable(value) or isinstance(value, (staticmethod, classmethod, property)))


def _shadowing(qp: Any) -> tuple[tuple[Any, str, str, Any], ...]:
    """(object, attribute, seal name, value) of each attribute set on the operator or a
    helper object that hides a method of its class (``H.matvec = ...``)."""
    return tuple((part, name, f"{where}.{name}", value) for where, part in _operator_parts(qp)
                 for name, value in vars(part).items() if callable(getattr(type(part), name, None)))


@dataclass(frozen=True)
class ProblemSeal:
    """A fingerprint of the problem handed to a solver -- ubar and the operator's
    defining arrays (``_defining_arrays``), and the methods its products run (``_methods``)
    -- taken before the solve; ``broken(qp)`` after it says what the solver changed ("" when
    nothing): an array written into, a method of the operator's classes replaced, or one
    hidden by an attribute of the object (``_shadowing``).  ``mend(qp)`` puts the methods
    back, so the solves after it in the same process run the code they were written for."""

    digests: tuple[tuple[str, str], ...]
    methods: tuple[tuple[type, str, Any], ...] = ()
    hiding: tuple[tuple[str, Any], ...] = ()  # (seal name, value): what hid a method when sealed

    @classmethod
    def of(cls, qp: Any) -> ProblemSeal:
        hiding = tuple((where, value) for _, _, where, value in _shadowing(qp))
        return cls(tuple((name, _digest(a)) for name, a in _defining_arrays(qp)), _methods(qp), hiding)

    def _new_hiding(self, qp: Any) -> list[tuple[Any, str, str, Any]]:
        """``_shadowing``'s entries that were not there, as they are, when sealed."""
        sealed = dict(self.hiding)
        return [(part, name, where, value) for part, name, where, value in _shadowing(qp)
                if where not in sealed or sealed[where] is not value]

    def broken(self, qp: Any) -> str:
        now = {name: _digest(a) for name, a in _defining_arrays(qp)}  # (the arrays; the methods below)
        before = dict(self.digests)
        changed = [name for name in before if now.get(name) != before[name]]
        changed += [name for name in now if name not in before]
        changed += [f"{c.__qualname__}.{name}" for c, name, value in self.methods
                    if vars(c).get(name) is not value]
        changed += [where for _, _, where, _ in self._new_hiding(qp)]
        return f"the solver wrote into the problem it was handed ({', '.join(changed)} changed)" if changed else ""

    def mend(self, qp: Any) -> None:
        """The operator's methods as they were sealed: class attributes put back, attributes
        of the object that hide one removed (its arrays stay as the solver left them: the
        harness drops that problem)."""
        for c, name, value in self.methods:
            if vars(c).get(name) is not value:
                setattr(c, name, value)
        sealed = dict(self.hiding)
        for part, name, where, _ in self._new_hiding(qp):
            if where in sealed:
                setattr(part, name, sealed[where])
            else:
                delattr(part, name)


# ---------------------------------------------------------------------------
# The verdict
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class UnreadAnswer:
    """An answer ``read_answer`` refuses in the process that made it (a worker), carried as
    the reason alone: what it held may not cross a process boundary (an object array of
    functions).  ``read_answer`` reads it as no answer, for that reason."""

    why: str


def portable_answer(p: Any, n: int) -> np.ndarray | UnreadAnswer:
    """``p`` as a worker sends it to be judged: the plain array ``read_answer`` reads (its
    dtype kept, which the judge notes), or an ``UnreadAnswer`` with the reason it refuses
    it -- so the verdict is the same whether the solve ran in a worker or in-process."""
    pf, why = read_answer(p, n)
    return UnreadAnswer(why) if pf is None else np.asarray(p)


def read_answer(p: Any, n: int) -> tuple[np.ndarray | None, str]:
    """(p as float64, "") when ``p`` is a length-``n`` vector of finite real numbers
    (float or integer dtype), else (None, what is wrong with it)."""
    if p is None:
        return None, "returned no p"
    if isinstance(p, UnreadAnswer):
        return None, p.why
    try:
        arr = np.asarray(p)
    except Exception as exc:  # an object that numpy cannot even wrap
        return None, f"returned a p that cannot be read as an array ({type(exc).__name__})"
    if arr.dtype.kind not in "biuf":
        return None, f"returned p of dtype {arr.dtype}, which is not real numbers"
    if arr.shape != (n,):
        if arr.ndim == 1:
            return None, f"returned p of wrong length {arr.size}, expected n = {n}"
        return None, f"returned p of shape {arr.shape}, expected ({n},)"
    pf = arr.astype(np.float64, copy=False)
    if not np.all(np.isfinite(pf)):
        bad = int(np.count_nonzero(~np.isfinite(pf)))
        return None, f"p has {bad} NaN/inf entr{'y' if bad == 1 else 'ies'} of {n}"
    return pf, ""


def judge(inst: ContactInstance, p: Any, claimed: bool, check_tol: float, p_ref: np.ndarray | None = None,
          p_tol: float | None = None, analytic_load: float | None = None, *, tampered: str = "") -> Verdict:
    """The verdict on answer ``p`` of instance ``inst`` (module doc).  ``claimed`` is the
    solver's own convergence claim; ``p_ref`` an exact reference answer; ``p_tol`` the
    allowed ||p - p_ref||_inf / ||p_ref||_inf for a "pass" (None: not checked);
    ``tampered`` what ``ProblemSeal.broken`` found the solver changed ("" nothing).
    ``inst`` must be the harness's own copy of the problem; ``check_tol`` a finite number
    > 0 (``ProblemInputError``: an infinite one would pass p = 0, a NaN fail everything)."""
    check_positive("the judge's check_tol", check_tol)
    claimed = bool(claimed)
    if tampered:
        verdict = _failed(claimed, tampered, reading="wrong", kind="tampered")
        verdict.tampered = True
        return verdict
    pf, why = read_answer(p, inst.n)
    if pf is None:
        return _failed(claimed, why)
    problems: list[str] = []
    kinds: list[str] = []
    ubar_dtype = np.asarray(inst.qp.ubar).dtype
    if np.asarray(p).dtype != np.float64:
        problems.append(f"returned {np.asarray(p).dtype} p (input ubar was {ubar_dtype})")
        kinds.append("dtype")
    kkt = kkt_check(inst, pf)
    with np.errstate(all="ignore"):  # a huge answer's load may overflow: a figure, not a verdict
        figures = answer_figures(inst, pf, kkt, p_ref, analytic_load, check_tol)
    solved = kkt.passes(check_tol)
    if not solved:
        value, limit = shown_apart(kkt.kkt_error, check_tol)
        problems.append(f"kkt_error {value} > check_tol {limit}")
        kinds.append("kkt")
    if p_ref is not None and p_tol is not None and not figures["p_rel_error"] <= p_tol:
        value, limit = shown_apart(figures["p_rel_error"], p_tol)
        problems.append(f"p is {value} off the exact reference (allowed {limit})")
        kinds.append("reference")
    reading = "pass" if not problems else ("wrong" if claimed else "unconverged")
    return Verdict("solved" if solved else "inaccurate", reading, claimed, kkt, figures, problems, kinds=kinds)


def shown_apart(value: float, limit: float) -> tuple[str, str]:
    """``value`` and the ``limit`` it is compared with, each to the same number of
    significant digits -- 3, or as many more as tell them apart -- so that a message
    "value > limit" never reads as its opposite or as a tie."""
    for digits in range(3, 18):
        shown = f"{value:.{digits}g}", f"{limit:.{digits}g}"
        if shown[0] != shown[1]:
            return shown
    return repr(float(value)), repr(float(limit))


def _failed(claimed: bool, why: str, reading: str | None = None, kind: str = "answer") -> Verdict:
    """The verdict on no answer: status "failed", wrong if claimed (or ``reading``)."""
    figures = {"kkt_error": math.inf, "error": why}
    return Verdict("failed", reading or ("wrong" if claimed else "unconverged"), claimed, None, figures, [why],
                   kinds=[kind])


def answer_figures(inst: ContactInstance, p: np.ndarray, kkt: KKTReport, p_ref: np.ndarray | None,
                   analytic_load: float | None, check_tol: float = CONTACT_TOL) -> dict[str, Any]:
    """The table's figures of an answer: KKT figures, load, contact fraction and the
    errors against the reference / closed form (column names of ``harness.table.schema``).
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
    constraints = inst.qp.constraints
    if constraints.load_control:  # the answer's approach: the equality's multiplier as the judge fits it
        out["delta"] = kkt.multiplier
        out["load_residual"] = kkt.equality
    if constraints.bounded:
        out["plastic_fraction"] = inst.plastic_fraction(p, check_tol)
    if p_ref is not None:
        out["p_rel_error"] = relative_error(p, p_ref)
        out["load_rel_error"] = relative_load_error(load, float(np.sum(p_ref)))
    if analytic_load is not None and math.isfinite(analytic_load):
        out["analytic_load_rel_error"] = relative_load_error(load, analytic_load)
        if p_ref is None:
            out["load_rel_error"] = out["analytic_load_rel_error"]
    return out
