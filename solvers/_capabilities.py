"""What a solver can serve and what it promises (not a solver module: the registry skips
"_" names): ``Capabilities``, the record the skip policy and the conformance battery
read, and its promise (``check_promise``).  ``Capabilities`` and the promise's functions
are imported from solvers/base.py as well.

A ``Capabilities`` is checked when it is made (``capability_problems``): a field of the
wrong kind or outside its values (an operator kind the skip policy does not know, a warm
start other than ``WARM_KINDS``, a size limit below 1, a flag that is not a bool) is a
``ValueError`` naming each field, in one line -- a solver module that declares one does
not import, and is refused before anything runs.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Literal, get_args

import numpy as np

WarmKind = Literal["none", "primal", "primal-dual"]
#: The warm starts a solver can take (``Capabilities.warm_start``).
WARM_KINDS: tuple[str, ...] = get_args(WarmKind)
#: The operator kinds the skip policy hands a solver (``Capabilities.operators``): the
#: dense n x n block and the matrix-free FFT operator.
SERVED_OPERATORS: tuple[str, ...] = ("dense", "fft")
#: What a solver hands its backend (``Capabilities.input_format``; shown by ``list solvers``).
INPUT_FORMATS: tuple[str, ...] = ("operator", "dense", "sparse", "kernel-table")
#: The yes-or-no fields of ``Capabilities``.
FLAGS: tuple[str, ...] = ("needs_dense", "exact", "needs_geometry", "load_control", "bounds")


#: What a solver promises the conformance battery (``Capabilities.promise``): "exact",
#: or a float, the scaled KKT error it can reach.
Promise = Literal["exact"] | float


def check_promise(promise: Any) -> Promise:
    """``promise`` if it is "exact" or a float f with 0 < f < 1, else ``ValueError`` naming the rule (p = 0
    has scaled KKT error exactly 1: a floor of 1 or more would accept it on every case)."""
    if promise == "exact" and isinstance(promise, str):
        return "exact"
    if isinstance(promise, (int, float)) and not isinstance(promise, bool) and 0 < promise < 1:  # NaN fails too
        return float(promise)
    raise ValueError(f"a solver's promise is \"exact\" or a positive scaled KKT floor (a float) below 1, got "
                     f"{promise!r} (the trivial answer p = 0 has scaled KKT error 1: a floor >= 1 would accept it)")


def promised_tol(promise: Promise, check_tol: float) -> float:
    """The scaled KKT error a case with ``check_tol`` holds a solver with ``promise`` to: check_tol
    for "exact", else max(check_tol, floor) (validate counts a floor up to its ``PROMISE_BOUND``)."""
    return float(check_tol) if promise == "exact" else max(float(check_tol), float(promise))


def describe_promise(promise: Promise) -> str:
    return "exact" if promise == "exact" else f"scaled KKT floor {float(promise):g}"


@dataclass(frozen=True)
class Capabilities:
    """What a solver can serve, and what it promises; the harness's skip policy and the
    conformance battery read it.

    operators    : operator kinds it accepts, a non-empty frozenset of ``SERVED_OPERATORS``.
    needs_dense  : it needs H assembled as an n x n array.
    warm_start   : "none", "primal" or "primal-dual".
    exact        : finite termination -- its answer is exact up to round-off (``run``
                   may keep it as a step's reference answer).
    promise      : what ``contactbench validate`` holds it to on every case it does not
                   skip (docs/verdicts.md): "exact" -- solved to the case's ``check_tol``;
                   a float f -- solved to scaled KKT error max(check_tol, f), the floor
                   the method can reach (a backend that cannot reach 1e-8, say).
    max_n        : hard size limit, an integer >= 1 (None: none besides the memory model).
    input_format : what it hands its backend, one of ``INPUT_FORMATS``.
    needs_geometry : it needs the QP's grid geometry (positions, surface levels).
    load_control : it poses the load equality sum(p) = P (load control).
    bounds       : it poses finite upper bounds 0 <= p <= u (a hardness).
    """

    operators: frozenset[str] = frozenset({"dense", "fft"})
    needs_dense: bool = False
    warm_start: WarmKind = "none"
    exact: bool = False
    max_n: int | None = None
    input_format: str = "operator"
    needs_geometry: bool = False
    promise: Promise = "exact"
    load_control: bool = False
    bounds: bool = False

    def __post_init__(self) -> None:
        """``ValueError`` naming every field that is not as above (``capability_problems``)."""
        problems = capability_problems(self)
        if problems:
            given = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                              if getattr(self, f.name) is not f.default)
            raise ValueError(f"Capabilities({given}): " + "; ".join(problems))
        object.__setattr__(self, "promise", check_promise(self.promise))
        for flag in FLAGS:
            object.__setattr__(self, flag, bool(getattr(self, flag)))

    @property
    def accuracy_floor(self) -> float | None:
        """The promised floor (None: "exact", the case's tolerance)."""
        return None if self.promise == "exact" else float(self.promise)

    def promised_tol(self, check_tol: float) -> float:
        """The scaled KKT error a case with ``check_tol`` holds this solver to."""
        return promised_tol(self.promise, check_tol)

    def describe(self) -> str:
        parts = [
            "ops=" + "/".join(sorted(self.operators)),
            "needs-dense-H" if self.needs_dense else "matrix-free",
            f"warm={self.warm_start}",
            "exact" if self.exact else "iterative",
            "promise=" + (self.promise if self.promise == "exact" else f"floor {self.promise:g}"),
            f"input={self.input_format}",
        ]
        parts += [flag for flag, on in (("needs-geometry", self.needs_geometry), ("load-control", self.load_control),
                                        ("bounds", self.bounds)) if on]
        if self.max_n:
            parts.append(f"max_n={self.max_n}")
        return ", ".join(parts)


def capability_problems(caps: Capabilities) -> list[str]:
    """What is wrong with the fields of ``caps`` (none: []): its ``operators`` a non-empty
    frozenset of ``SERVED_OPERATORS``, its ``warm_start`` one of ``WARM_KINDS``, its
    ``max_n`` None or an integer >= 1, its ``input_format`` one of ``INPUT_FORMATS``, its
    ``FLAGS`` bools and its ``promise`` as ``check_promise`` requires."""
    problems: list[str] = []
    ops = caps.operators
    if not isinstance(ops, frozenset) or not ops or not ops <= set(SERVED_OPERATORS):
        problems.append(f"operators is a non-empty frozenset of {', '.join(map(repr, SERVED_OPERATORS))}")
    if caps.warm_start not in WARM_KINDS or not isinstance(caps.warm_start, str):
        problems.append(f"warm_start is one of {', '.join(map(repr, WARM_KINDS))}")
    n = caps.max_n
    if n is not None and (isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1):
        problems.append("max_n is None or an integer >= 1")
    if caps.input_format not in INPUT_FORMATS or not isinstance(caps.input_format, str):
        problems.append(f"input_format is one of {', '.join(map(repr, INPUT_FORMATS))}")
    problems += [f"{flag} is True or False" for flag in FLAGS if not isinstance(getattr(caps, flag), (bool, np.bool_))]
    try:
        check_promise(caps.promise)
    except ValueError as exc:
        problems.append(str(exc))
    return problems
