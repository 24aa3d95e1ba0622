"""The solver extension point: one result record, one settings record, one base class.

A solver sees only ``QP`` (the operator H, the vector ubar and, for the few solvers
that need positions, the grid geometry).  It never times itself for the report and
never judges its own answer: the harness does both.  It may report its own internal
time, status and a cheap convergence trace.

Adding a solver = one file in ``solvers/`` with a ``Solver`` subclass decorated by
``@register`` (see ``solvers.registry``) -- nothing else changes.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from contactbench.problems.instances import QP

WarmKind = Literal["none", "primal", "primal-dual"]


@dataclass(frozen=True)
class Profile:
    """A named accuracy target.

    tol       : the tolerance handed to solvers (None: the solver's own default).
    check_tol : the scaled kkt_error at which the harness counts the answer as solved.
    """

    name: str
    tol: float | None
    check_tol: float


PROFILES: dict[str, Profile] = {
    "default": Profile("default", None, 1e-6),
    "low": Profile("low", 1e-3, 1e-3),
    "mid": Profile("mid", 1e-6, 1e-6),
    "high": Profile("high", 1e-9, 1e-8),
}


def get_profile(name: str) -> Profile:
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown profile {name!r}; choose one of {', '.join(PROFILES)}") from None


@dataclass
class SolverSettings:
    """What the harness asks for.  ``params`` are solver-specific knobs (e.g. the number
    K of gradient-projection steps); ``tol`` overrides the profile's tolerance."""

    profile: str = "default"
    tol: float | None = None
    max_iter: int | None = None
    time_limit: float | None = None
    params: dict[str, Any] = field(default_factory=dict)

    def tolerance(self, default: float) -> float:
        """The tolerance to use: explicit tol, else the profile's, else ``default``."""
        if self.tol is not None:
            return float(self.tol)
        t = get_profile(self.profile).tol
        return float(default if t is None else t)

    def param(self, name: str, default: Any) -> Any:
        return self.params.get(name, default)


@dataclass
class WarmStart:
    """Initial point mapped onto the current trial set by grid position: p (primal),
    w (dual / gap, where a solver uses one).  Either may be None."""

    p: np.ndarray | None = None
    w: np.ndarray | None = None


@dataclass
class SolveResult:
    """One record for every solver (like scipy's OptimizeResult).

    converged/status/message are the solver's *own* claim; the harness records them
    beside its own verdict.  trace holds (iteration, elapsed seconds, residual).
    """

    p: np.ndarray
    w: np.ndarray | None = None
    iterations: int = 0
    converged: bool = False
    status: str = "unknown"
    message: str = ""
    solve_time: float = float("nan")
    setup_time: float = float("nan")
    matvecs: int = 0
    warm_started: bool = False
    trace: list[tuple[int, float, float]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Capabilities:
    """What a solver can serve; the harness uses it to skip pairs with a reason.

    operators   : operator kinds it accepts ("dense", "fft").
    needs_dense : it needs H assembled as an n x n array (dense or its own sparse copy).
    warm_start  : "none", "primal" or "primal-dual".
    exact       : finite termination / reaches round-off (a reference candidate).
    max_n       : hard size limit (None: none besides the memory model).
    """

    operators: frozenset[str] = frozenset({"dense", "fft"})
    needs_dense: bool = False
    warm_start: WarmKind = "none"
    exact: bool = False
    max_n: int | None = None
    input_format: str = "operator"  # "operator", "dense" or "sparse"
    #: Best scaled KKT error the method can reach (e.g. a backend's regularisation floor);
    #: None when it can reach round-off.
    accuracy_floor: float | None = None

    def describe(self) -> str:
        parts = [
            "ops=" + "/".join(sorted(self.operators)),
            "needs-dense-H" if self.needs_dense else "matrix-free",
            f"warm={self.warm_start}",
            "exact" if self.exact else "iterative",
            f"input={self.input_format}",
        ]
        if self.max_n:
            parts.append(f"max_n={self.max_n}")
        if self.accuracy_floor:
            parts.append(f"floor={self.accuracy_floor:g}")
        return ", ".join(parts)


class Solver(ABC):
    """Base class.  Subclasses set ``name``, ``family``, ``capabilities`` and implement
    ``solve``; they may refine ``availability``, ``memory_estimate`` and
    ``time_estimate`` (used to skip hopeless pairs before attempting them)."""

    name: ClassVar[str] = ""
    family: ClassVar[str] = "other"  # "paper", "qp", "fast", "wrapper", "reference", "test"
    description: ClassVar[str] = ""
    capabilities: ClassVar[Capabilities] = Capabilities()

    def availability(self) -> tuple[bool, str]:
        """(available, reason).  Override to check optional imports."""
        return True, "available"

    def memory_estimate(self, n: int) -> float:
        """Peak extra bytes the solve needs beyond the operator (default: a few vectors,
        or an n x n matrix when the solver needs dense H)."""
        if self.capabilities.needs_dense:
            return 8.0 * n * n
        return 16.0 * 8.0 * n

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """Predicted seconds for one solve at size n, or None when unknown."""
        return None

    @abstractmethod
    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        """Solve min 1/2 p'Hp - ubar'p, p >= 0."""

    def __repr__(self) -> str:
        return f"<Solver {self.name} ({self.family})>"


class Trace:
    """Cheap (iteration, elapsed, residual) recorder shared by iterative solvers."""

    def __init__(self, every: int = 1) -> None:
        self.t0 = time.perf_counter()
        self.every = max(1, every)
        self.points: list[tuple[int, float, float]] = []

    def record(self, it: int, residual: float) -> None:
        if it % self.every == 0:
            self.points.append((int(it), time.perf_counter() - self.t0, float(residual)))

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0
