"""The solver extension point: one settings record, one result record, one base class,
and one solve lifecycle.

A solver sees only ``QP`` (the operator H, the vector ubar and, for the few solvers that
need positions, the grid geometry).  It never judges its own answer for the report and
never times itself for it: the harness does both.

The lifecycle (``Solver.solve``, a template method; subclasses implement ``iterate``)
-----------------------------------------------------------------------------------------
1. validate the QP (``check_qp``) and the parameters (``Solver.resolve_params``: an
   unknown or ill-typed key is refused with the allowed keys in the message);
2. resolve one numeric tolerance (``SolverSettings.tol``, else the class's
   ``default_tol``) and one iteration limit (``max_iter``, else ``default_max_iter(n)``,
   None or an integer >= 0: ``read_max_iter``);
3. apply the one warm-start policy (``warm_point``): a warm p must have length n and be
   finite (else ``ProblemInputError``), negative entries are clipped to 0; a solver
   whose ``capabilities.warm_start`` is "none" is handed no warm start, and its result
   says ``warm_started=False``;
4. start one deadline, one trace and one matvec count (``SolveContext``); return p = 0
   at once when ubar <= 0 (no contact) and no load is imposed, or when a load of 0 is
   imposed (p = 0 is then the only feasible answer); at an iteration limit of 0, return
   the start (the warm p, else 0) with 0 iterations, not converged, status max_iter,
   ``iterate`` not called (``ZERO_LIMIT_NOTE``);
5. call the solver's own ``iterate(ctx)``, which returns an ``Outcome`` whose fields are
   of their kinds (``read_outcome``; its p is the judge's to read);
6. build the ``SolveResult``: w = Hp - ubar (unless the outcome carries it), the status
   from the small ``Status`` enum, the matvec count, and a trace whose last point is the
   final iterate's scaled KKT error; a count or time the results table cannot hold (a
   negative or float ``add_matvecs``, a NaN ``add_setup_time``: ``account_problems``) is
   a ``SolverReturnError`` naming it, which fails the row.

Bounds and load control (``problems.constraints``)
--------------------------------------------------
A QP may carry upper bounds (a hardness) and a load equality sum(p) = P.  A solver poses
them only if its ``Capabilities`` say so (``bounds``, ``load_control``; both default to
False, so a solver that says nothing is skipped with the reason -- ``constraint_skip``
-- and ``solve`` refuses such a QP).  Under load control the approach Delta is the
equality's multiplier: an ``Outcome`` may carry it (``multiplier``), else ``finish``
fits it from the answer (``problems.constraints.fit_multiplier``); ``SolveResult``
reports it as ``multiplier`` and its w is Hp - ubar - Delta.  A warm start is clipped
to the box.

What a solver's own methods answer is read as their contracts say, whoever asks: an
answer that is none (``skip`` answering 1, ``availability`` a bare True) is a
``SolverReturnError`` naming the solver, the method and the answer, which fails its rows.

Adding a solver = one file in ``solvers/`` with a ``Solver`` subclass decorated by
``@register`` (``contactbench.solvers.register``); see docs/adding-a-solver.md.
"""

from __future__ import annotations

import inspect
import reprlib
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, ClassVar

import numpy as np

from contactbench.problems.errors import COUNT_MAX, ProblemInputError, check_nonnegative, check_positive, is_count
from contactbench.problems.instances import QP
from contactbench.problems.constraints import Constraints, fit_multiplier
from contactbench.problems.kkt import constrained_kkt_error
from contactbench.problems.operators import ContactOperator

from ._answers import COUNT_RULE, HOOK_READERS, account_problems, is_plain_count, is_real, is_seconds, read_through
from ._answers import SolverReturnError as SolverReturnError, read_availability as read_availability
from ._answers import read_max_iter as read_max_iter, read_reason as read_reason
from ._capabilities import Capabilities, WarmKind
from ._capabilities import Promise as Promise, check_promise as check_promise, describe_promise as describe_promise
from ._capabilities import promised_tol as promised_tol
from ._params import Param, ParamError

#: The default tolerance of a solver that declares none: the scaled KKT error of
#: ``contactbench.problems.kkt`` (the harness's "high" profile checks 1e-8).
DEFAULT_TOL = 1e-8


class Status(str, Enum):
    """Why a solve stopped, in the solver's own words (the harness judges separately)."""

    CONVERGED = "converged"  # the solver's stopping test passed
    MAX_ITER = "max_iter"  # iteration limit reached first
    TIME_LIMIT = "time_limit"  # SolverSettings.time_limit reached first
    STALLED = "stalled"  # no further progress possible (breakdown, cycling, stagnation)
    FAILED = "failed"  # no usable answer (a backend error, a non-finite iterate)


class SolveAborted(RuntimeError):
    """A solve that ended without an answer, in a way the harness records as the row's
    status: ``status`` is "timeout" (killed at its time limit, e.g. an external program)
    or "crashed" (it died: a signal, a segfault).  Any other exception is "failed"."""

    def __init__(self, status: str, message: str) -> None:
        if status not in ("timeout", "crashed"):
            raise ValueError(f"SolveAborted status must be 'timeout' or 'crashed', got {status!r}")
        super().__init__(message)
        self.status = status


@dataclass
class SolverSettings:
    """What the harness asks of one solve.

    tol        : the scaled KKT error to stop at (None: the solver's ``default_tol``);
    max_iter   : iteration limit (None: the solver's ``default_max_iter(n)``);
    time_limit : seconds from the start of ``solve`` (None: no limit);
    params     : the solver's declared parameters (``Solver.params``), by name;
    check_tol  : the scaled KKT error the caller judges the answer at (None: not said).
                 A solver that leaves its stopping test to a backend (``default_tol``
                 None) derives the backend's tolerances from it when no ``tol`` is asked,
                 and claims convergence only on an answer that meets it.
    """

    tol: float | None = None
    max_iter: int | None = None
    time_limit: float | None = None
    params: dict[str, Any] = field(default_factory=dict)
    check_tol: float | None = None

    def __post_init__(self) -> None:
        """``ProblemInputError`` naming the field: tol and check_tol finite and > 0,
        max_iter an integer >= 0, time_limit finite and >= 0 (each or None)."""
        for name, check in (("tol", check_positive), ("check_tol", check_positive), ("time_limit", check_nonnegative)):
            if getattr(self, name) is not None:
                check(f"SolverSettings.{name}", getattr(self, name))
        m = self.max_iter
        if m is not None and (isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 0):
            raise ProblemInputError(f"SolverSettings.max_iter is an integer >= 0 or None, got {m!r}")


@dataclass
class WarmStart:
    """Initial point mapped onto the current trial set by grid position: p (primal),
    w (dual / gap, where a solver uses one).  Either may be None."""

    p: np.ndarray | None = None
    w: np.ndarray | None = None


#: ``SolveResult.info`` key of the lifecycle's own answer (a solver can set it: the harness asks the function below).
WITHOUT_ITERATE = "answered_without_iterate"


def answered_without_iterate(qp: QP) -> bool:
    """Whether the lifecycle answers ``qp`` itself, p = 0, without calling ``iterate``
    (module doc, step 4): ubar <= 0 (no contact) and no load imposed, or a load of 0
    imposed (sum p = 0 with p >= 0 leaves p = 0 alone)."""
    if qp.constraints.load_control:
        return float(qp.constraints.load) == 0.0
    return bool(np.max(qp.ubar, initial=0.0) <= 0.0)


#: The message of the lifecycle's answer at ``max_iter`` 0 (module doc, step 4): no solver
#: is called, whatever it would make of a zero limit (some refuse it, some read it as their
#: default, some take a step regardless).
ZERO_LIMIT_NOTE = "max_iter 0: the start returned, the solver not called"


def without_iterate_text(qp: QP) -> str:
    """The message of the lifecycle's own answer p = 0 (``answered_without_iterate``)."""
    return "load 0: p = 0, the only feasible answer" if qp.constraints.load_control else "ubar <= 0: no contact, p = 0"


@dataclass
class SolveResult:
    """One record for every solver (like scipy's OptimizeResult).

    p            : the answer (length n, the solver's final iterate);
    w            : its gap Hp - ubar - Delta (Delta = 0 without a load equality; recomputed
                   by the lifecycle when the solver gave none);
    multiplier   : under load control, the approach Delta (the equality's multiplier: the
                   solver's own or fitted, module doc); None otherwise;
    iterations   : the solver's own iteration count;
    converged    : the solver's own claim that its stopping test passed;
    status       : a ``Status`` value (as its string);
    message      : one line in words;
    solve_time   : seconds inside ``solve`` (the harness times the call itself as well);
    setup_time   : the part of solve_time before the first iteration (factorisations, ...);
    matvecs      : products with H (or a restriction of it) during the solve;
    warm_started : whether a warm start was used;
    trace        : (iteration, elapsed seconds, scaled KKT error); the last point is the
                   final iterate;
    info         : solver-specific figures (JSON-serialisable).
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
    multiplier: float | None = None


class Deadline:
    """``SolverSettings.time_limit`` as a cheap predicate, started once per solve."""

    def __init__(self, time_limit: float | None, t0: float | None = None) -> None:
        start = time.perf_counter() if t0 is None else t0
        self.t_end = None if time_limit is None else start + float(time_limit)

    def expired(self) -> bool:
        return self.t_end is not None and time.perf_counter() > self.t_end

    def remaining(self) -> float | None:
        """Seconds left (None: no limit)."""
        return None if self.t_end is None else max(0.0, self.t_end - time.perf_counter())


class Trace:
    """Cheap (iteration, elapsed, residual) recorder."""

    def __init__(self, every: int = 1, t0: float | None = None) -> None:
        self.t0 = time.perf_counter() if t0 is None else t0
        self.every = max(1, every)
        self.points: list[tuple[int, float, float]] = []
        self.offset = 0

    def record(self, it: int, residual: float) -> None:
        it += self.offset
        if it % self.every == 0:
            self.points.append((int(it), time.perf_counter() - self.t0, float(residual)))

    def shifted(self, k: int) -> "Trace":
        """The same trace (clock and points) numbering iterations from ``k`` on."""
        view = Trace(self.every, self.t0)
        view.points, view.offset = self.points, self.offset + int(k)
        return view

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0


@dataclass
class Outcome:
    """What ``Solver.iterate`` returns: the final iterate and the solver's own claim.

    status None means: CONVERGED when ``converged``, else TIME_LIMIT when the deadline
    passed, else MAX_ITER."""

    p: np.ndarray
    iterations: int
    converged: bool
    message: str = ""
    w: np.ndarray | None = None  # Hp - ubar (without Delta)
    status: Status | None = None
    info: dict[str, Any] = field(default_factory=dict)
    multiplier: float | None = None  # Delta under load control (None: fitted by ``finish``)


@dataclass
class SolveContext:
    """Everything the lifecycle hands ``iterate``: the problem, the resolved tolerance,
    iteration limit and parameters, the warm start, and the one deadline, trace and
    matvec count of this solve."""

    qp: QP
    tol: float | None  # None only for solvers whose default_tol is None (backend defaults)
    max_iter: int | None  # None only for solvers whose default_max_iter is None (backend defaults)
    params: dict[str, Any]
    p0: np.ndarray | None
    warm: WarmStart | None
    deadline: Deadline
    trace: Trace
    diag_max: float
    info: dict[str, Any] = field(default_factory=dict)
    setup_time: float | None = None
    check_tol: float | None = None  # SolverSettings.check_tol
    _ops: list[tuple[ContactOperator, int]] = field(default_factory=list)
    _extra_matvecs: int = 0
    _ubar_max: float | None = None
    _parent: "SolveContext | None" = None  # a restricted solve counts its products here

    @property
    def n(self) -> int:
        return self.qp.n

    @property
    def warm_started(self) -> bool:
        return self.p0 is not None

    def caller_warm_contact(self) -> float | None:
        """The share of its unknowns in contact (p > 0) in the warm start the caller gave the
        solve this context is part of; None for a cold solve (a restricted round of a cold
        solve starts from the earlier round's answer: not the caller's)."""
        if self._parent is not None:
            return self._parent.caller_warm_contact()
        return None if self.p0 is None else float(np.count_nonzero(self.p0 > 0.0)) / max(self.n, 1)

    def first_p(self) -> np.ndarray:
        """A fresh copy of the start: the warm start ``p0``, or zeros (a cold start)."""
        return np.zeros(self.n) if self.p0 is None else self.p0.copy()

    def expired(self) -> bool:
        return self.deadline.expired()

    def record(self, it: int, residual: float) -> None:
        self.trace.record(it, residual)

    @property
    def constraints(self) -> Constraints:
        return self.qp.constraints

    def kkt(self, p: np.ndarray, w: np.ndarray, multiplier: float | None = None) -> float:
        """The scaled KKT error of (p, w = Hp - ubar): the harness's own formula
        (``problems.kkt.constrained_kkt_error``; under load control with ``multiplier``
        as Delta, fitted when None; w excludes Delta)."""
        return constrained_kkt_error(p, w, self.qp.ubar, self.diag_max, self.qp.constraints, multiplier,
                                     self.ubar_scale())

    def restricted(self, pos: np.ndarray, p0: np.ndarray | None, first: int = 0) -> "SolveContext":
        """This solve on the unknowns at positions ``pos`` only, the others held at 0
        (``QP.restrict``), started at ``p0``, ``first`` iterations already spent: the same
        tolerance, parameters, deadline, trace and matvec count, and the KKT scales of
        the whole problem (so the subset's error is never below the whole one's on the
        same points)."""
        max_iter = None if self.max_iter is None else max(1, self.max_iter - first)
        sub = replace(self, qp=self.qp.restrict(pos), p0=p0, warm=None, max_iter=max_iter, info={},
                      trace=self.trace.shifted(first), _extra_matvecs=0, _ubar_max=self.ubar_scale(), _parent=self)
        self.track(sub.qp.H)
        return sub

    def ubar_scale(self) -> float:
        """max |ubar| of this solve's problem (the KKT error's displacement scale)."""
        if self._ubar_max is None:
            self._ubar_max = float(np.max(np.abs(self.qp.ubar), initial=0.0))
        return self._ubar_max

    def track(self, op: ContactOperator) -> ContactOperator:
        """Count the matvecs of an operator made during the solve (a restriction)."""
        self._ops.append((op, op.matvec_count))
        return op

    def add_matvecs(self, k: int) -> None:
        """Count k products done outside a tracked operator: an integer from 0 to ``COUNT_MAX``
        (else ``SolverReturnError``, which fails the solve naming it)."""
        if not is_plain_count(k):
            raise SolverReturnError(f"the solver counted add_matvecs({reprlib.repr(k)}), not {COUNT_RULE}")
        if self._parent is not None:
            self._parent.add_matvecs(k)
        else:
            self._extra_matvecs += int(k)

    def matvecs(self) -> int:
        """Products of the whole solve so far (a restricted solve's count is its parent's);
        ``SolverReturnError`` where the counts do not add up to one (a tracked operator's
        count set back, or to a number that is no integer)."""
        if self._parent is not None:
            return self._parent.matvecs()
        total = sum((op.matvec_count - c0 for op, c0 in self._ops), self._extra_matvecs)
        if not is_plain_count(total):
            raise SolverReturnError(f"the solve's products with H add up to {reprlib.repr(total)}, not {COUNT_RULE}")
        return int(total)

    def mark_setup_done(self) -> None:
        """Everything so far was set-up (factorisations, assembly): ``setup_time``."""
        self.setup_time = self.trace.elapsed()

    def add_setup_time(self, seconds: float) -> None:
        """Count ``seconds`` spent later on set-up work (e.g. a modelling layer's compile): a
        finite number >= 0 (else ``SolverReturnError``, which fails the solve naming it)."""
        if not is_seconds(seconds):
            raise SolverReturnError(f"the solver counted add_setup_time({reprlib.repr(seconds)}), not a finite "
                                    "number of seconds >= 0")
        self.setup_time = (self.setup_time or 0.0) + float(seconds)


def check_qp(qp: QP) -> None:
    """A QP a solver can be handed: ubar of length n, finite; its constraints posable
    (``Constraints.check``)."""
    ubar = np.asarray(qp.ubar)
    if ubar.ndim != 1 or ubar.size != qp.H.n:
        raise ProblemInputError(f"ubar has shape {ubar.shape}, the operator has n = {qp.H.n}")
    if not np.all(np.isfinite(ubar)):
        raise ProblemInputError("ubar contains non-finite values")
    qp.constraints.check(qp.n)


def constraint_skip(caps: Capabilities, load_control: bool, bounded: bool, name: str = "this solver") -> str | None:
    """Why a solver with ``caps`` cannot pose a problem under load control / with bounds
    (None: it can)."""
    if load_control and not caps.load_control:
        return f"{name} cannot pose load control (the equality sum(p) = P)"
    if bounded and not caps.bounds:
        return f"{name} cannot pose bounded pressures (a hardness)"
    return None


def warm_point(warm: WarmStart | None, n: int, kind: WarmKind, upper: np.ndarray | None = None) -> np.ndarray | None:
    """The one warm-start policy (module doc, step 3): p0 >= 0 of length n (and <= the
    upper bounds, when given), or None."""
    if kind == "none" or warm is None or warm.p is None:
        return None
    p = np.asarray(warm.p, dtype=np.float64)
    if p.shape != (n,):
        raise ProblemInputError(f"warm-start p has shape {p.shape}, the problem has n = {n}")
    if not np.all(np.isfinite(p)):
        raise ProblemInputError("warm-start p contains non-finite values")
    p = np.maximum(p, 0.0)
    return p if upper is None else np.minimum(p, upper)


@dataclass(frozen=True)
class ProblemTraits:
    """What the skip policy knows of a problem before solving it."""

    n: int
    operator: str  # "dense" or "fft"
    has_geometry: bool = True
    has_surface: bool = False  # the instance carries a surface with its coarse levels
    periodic: bool = False
    kernel: str = ""
    surface_side: int = 0  # points per side of the instance's surface (0: none)
    load_control: bool = False  # the QP carries a load equality
    bounded: bool = False  # the QP carries finite upper bounds (a hardness)
    capacity_share: float = 0.0  # P / sum(upper) (``Constraints.capacity_share``; 0: no load or no bound)
    layer: bool = False  # the kernel is an elastic layer of finite thickness (not a half-space)
    rectangular: bool = False  # the grid, or its elements, are known to be rectangular (not N x N squares)
    #: periodic with the whole grid as its trial set: H 1 = 0 there (the q = 0 mode removed), H singular
    whole_periodic_grid: bool = False


def outcome_problems(out: Outcome, n: int) -> list[str]:
    """What is wrong with the fields of ``out`` for a problem of n unknowns (none: []):
    iterations an integer from 0 to ``COUNT_MAX`` (a table's int64), converged a bool, status a ``Status`` or None, message a
    str, info a dict, w None or an array of shape (n,), multiplier None or a real number.
    Its p is the judge's to read (``finish``)."""
    it, w = out.iterations, out.w
    checks = (
        ("iterations", isinstance(it, (int, np.integer)) and is_count(it), f"an integer from 0 to {COUNT_MAX}"),
        ("converged", isinstance(out.converged, (bool, np.bool_)), "True or False"),
        ("status", out.status is None or isinstance(out.status, Status), "a Status or None"),
        ("message", isinstance(out.message, str), "a str"),
        ("info", isinstance(out.info, dict), "a dict"),
        ("w", w is None or getattr(w, "shape", None) == (n,), f"None or an array of shape ({n},)"),
        ("multiplier", out.multiplier is None or is_real(out.multiplier), "None or a real number"),
    )
    return [f"{field_name} is {reprlib.repr(getattr(out, field_name))}, not {rule}"
            for field_name, ok, rule in checks if not ok]


def read_outcome(name: str, out: Any, n: int) -> Outcome:
    """``out``, what ``iterate`` returned, if it is an ``Outcome`` whose fields are as
    ``outcome_problems`` requires; else ``SolverReturnError`` naming each problem."""
    if not isinstance(out, Outcome):
        raise SolverReturnError(f"solver {name!r}: iterate() returned {reprlib.repr(out)}, not an Outcome")
    problems = outcome_problems(out, n)
    if problems:
        raise SolverReturnError(f"solver {name!r}: iterate() returned an Outcome whose " + "; ".join(problems))
    return out


class Solver(ABC):
    """Base class (module doc).  Subclasses set ``name``, ``family``, ``description``,
    ``capabilities`` and ``params`` and implement ``iterate``; they may refine
    ``default_tol``, ``default_max_iter``, ``skip``, ``availability``,
    ``memory_estimate`` and ``time_estimate``.  What ``availability``, ``skip`` and
    ``skip_params`` answer is read as their contracts say (``HOOK_READERS``), and what
    ``default_max_iter`` and ``iterate`` answer by the lifecycle (``read_max_iter``,
    ``read_outcome``): an answer that is none fails with a ``SolverReturnError``."""

    name: ClassVar[str] = ""
    family: ClassVar[str] = "other"  # "paper", "qp", "fast", "wrapper", "reference", "external", ...
    description: ClassVar[str] = ""
    capabilities: ClassVar[Capabilities] = Capabilities()
    #: Declared parameters; anything else in ``SolverSettings.params`` is refused.
    params: ClassVar[tuple[Param, ...]] = ()
    #: Parameter grid for sweeps (benchopt style): name -> values; studies expand it.
    grid: ClassVar[dict[str, tuple[Any, ...]]] = {}
    #: Tolerance on the scaled KKT error when the settings give none (None: the solver
    #: maps "no tolerance asked" to its backend's own defaults, as the QP adapters do).
    default_tol: ClassVar[float | None] = DEFAULT_TOL
    #: Problem families (an instance's ``meta["family"]``) on which the method is known to
    #: claim a wrong answer on some draws: a documented limitation of the method, not a
    #: defect of the code (greedy on the paper's Example 1).  A benchmark of a draw that
    #: shows it is an expected failure.
    refuted_on: ClassVar[frozenset[str]] = frozenset()
    #: Whether ``time_estimate`` prices products of the FFT operator on the typical trial-set
    #: grid (``_kit.matvec_seconds``), so that the skip policy rescales it to the problem's own
    #: padded grid; False for a model the grid does not move (dense rows, a factorisation).
    time_scales_with_grid: ClassVar[bool] = True
    #: Whether ``max_iter`` bounds each stage of the solve (a peer's own semantics: its
    #: levels and precisions, listed in ``info["stages"]``) rather than the iterations it
    #: reports in all, which may then reach max_iter x stages.
    limit_per_stage: ClassVar[bool] = False

    def limit_stages(self, info: Any) -> int:
        """How many times ``max_iter`` the iterations of a solve whose ``info`` is given may
        reach: the stages ``info["stages"]`` lists (at least 1) where the class declares
        ``limit_per_stage``, else 1."""
        if not self.limit_per_stage or not isinstance(info, dict):
            return 1
        try:
            return max(1, len(str(info.get("stages", "")).split()))
        except Exception:  # (a stage list that cannot be read lists none)
            return 1

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Each method of ``HOOK_READERS`` that ``cls`` defines answers through its reader."""
        super().__init_subclass__(**kwargs)
        for attr, read in HOOK_READERS.items():
            method = cls.__dict__.get(attr)
            if inspect.isfunction(method):
                setattr(cls, attr, read_through(attr, method, read))

    @classmethod
    def param_defaults(cls) -> dict[str, Any]:
        """Each declared parameter's default, by name."""
        return {p.name: p.default for p in cls.params}

    def default_max_iter(self, n: int) -> int | None:
        """Iteration limit when the settings give none (None: the backend's own)."""
        return 100_000

    # -- what the harness asks before solving --------------------------------
    def pinned_source(self) -> bytes | None:
        """What a results folder pins of this solver's code (``registry.source_digest``
        hashes it): None, the files of its class and of the modules that file imports from its
        source tree (for a solver from outside the package).  A solver whose code lives
        elsewhere (an outside program) returns it."""
        return None

    def availability(self) -> tuple[bool, str]:
        """(available, reason).  Override to check optional imports."""
        return True, "available"

    def skip(self, traits: ProblemTraits) -> str | None:
        """A reason not to run on a problem with these traits (None: run it).  The
        harness asks this after its own capability checks; subclasses that refine it
        call this first (the constraints the solver cannot pose, ``constraint_skip``)."""
        why = constraint_skip(self.capabilities, traits.load_control, traits.bounded, self.name)
        if why:
            return why
        if self.capabilities.needs_geometry and not traits.has_surface:
            return f"{self.name} needs the instance's surface and its coarse levels; this problem has none"
        return None

    def skip_params(self, traits: ProblemTraits, params: dict[str, Any]) -> str | None:
        """A reason not to run a variant with these resolved parameters (``resolve_params``) on
        a problem with these traits (None: run it); the harness asks it after ``skip``."""
        return None

    def memory_estimate(self, n: int) -> float:
        """Peak extra bytes the solve needs beyond the operator."""
        if self.capabilities.needs_dense:
            return 8.0 * n * n
        return 16.0 * 8.0 * n

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        """Predicted seconds for one solve at size n, or None when unknown."""
        return None

    # -- parameters ---------------------------------------------------------
    def resolve_params(self, given: dict[str, Any] | None) -> dict[str, Any]:
        """Every declared parameter, from ``given`` or its default; an unknown key or a
        bad value is a ``ParamError`` naming the allowed keys."""
        declared = {p.name: p for p in self.params}
        given = dict(given or {})
        unknown = sorted(set(given) - set(declared))
        if unknown:
            allowed = ", ".join(sorted(declared)) or "(none)"
            raise ParamError(f"solver {self.name!r} has no parameter {', '.join(map(repr, unknown))}; "
                             f"allowed: {allowed}")
        return {k: (p.check(given[k]) if k in given else p.default) for k, p in declared.items()}

    # -- the lifecycle --------------------------------------------------------
    def solve(self, qp: QP, settings: SolverSettings | None = None, warm: WarmStart | None = None) -> SolveResult:
        """Solve min 1/2 p'Hp - ubar'p, p >= 0 (module doc).  Not to be overridden."""
        settings = settings or SolverSettings()
        t0 = time.perf_counter()
        check_qp(qp)
        why = constraint_skip(self.capabilities, qp.constraints.load_control, qp.constraints.bounded, self.name)
        if why:
            raise ProblemInputError(why)
        params = self.resolve_params(settings.params)
        tol = settings.tol if settings.tol is not None else self.default_tol
        tol = None if tol is None else float(tol)
        max_iter = (read_max_iter(self.name, qp.n, self.default_max_iter(qp.n)) if settings.max_iter is None
                    else int(settings.max_iter))
        p0 = warm_point(warm, qp.n, self.capabilities.warm_start, qp.constraints.upper)
        ctx = SolveContext(qp=qp, tol=tol, max_iter=max_iter, params=params, p0=p0,
                           warm=warm if self.capabilities.warm_start != "none" else None,
                           deadline=Deadline(settings.time_limit, t0), trace=Trace(t0=t0),
                           diag_max=float(np.max(qp.H.diagonal())), check_tol=settings.check_tol)
        ctx.track(qp.H)
        if answered_without_iterate(qp):
            out = Outcome(np.zeros(qp.n), 0, True, without_iterate_text(qp), info={WITHOUT_ITERATE: True})
        elif max_iter == 0:
            out = Outcome(ctx.first_p(), 0, False, ZERO_LIMIT_NOTE, status=Status.MAX_ITER,
                          info={WITHOUT_ITERATE: True})
        else:
            out = read_outcome(self.name, self.iterate(ctx), qp.n)
        return finish(ctx, out)

    @abstractmethod
    def iterate(self, ctx: SolveContext) -> Outcome:
        """The solver's own iteration from ``ctx.p0`` (None: a cold start), honouring
        ``ctx.tol``, ``ctx.max_iter`` and ``ctx.expired()``."""

    def __repr__(self) -> str:
        return f"<Solver {self.name} ({self.family})>"


def readable_answer(p: Any) -> Any:
    """``p`` as float64 where it can be read as real numbers; else as given (an object,
    string or complex array, or an object NumPy cannot wrap at all, e.g. a device array
    that refuses an implicit copy), for the judge to refuse."""
    try:
        arr = np.asarray(p)
    except Exception:  # (its __array__ raises: the judge names why, harness.judging.read_answer)
        return p
    if arr.dtype.kind in "biuf":
        return arr.astype(np.float64, copy=False)
    return arr


def finish(ctx: SolveContext, out: Outcome) -> SolveResult:
    """The SolveResult of an outcome (module doc, step 6).  The solver's claim
    (``converged``) is passed on as made, whatever status it gives: an unusable p (wrong shape, non-finite,
    unreadable) claimed as converged is the judge's to call wrong, not the lifecycle's to
    turn into an honest failure; unclaimed, its status is FAILED.  A count or time of the
    solve's own account that a table cannot hold (``account_problems``) is a
    ``SolverReturnError`` naming it."""
    qp = ctx.qp
    p = readable_answer(out.p)
    finite = isinstance(p, np.ndarray) and p.shape == (qp.n,) and p.dtype == np.float64 and bool(np.all(np.isfinite(p)))
    w = out.w
    if w is None and finite:
        w = qp.H.matvec(p) - qp.ubar
    multiplier = None
    if qp.constraints.load_control and finite and w is not None:
        multiplier = out.multiplier
        if multiplier is None:
            multiplier = fit_multiplier(w, p, qp.constraints.upper)
    status = out.status or (Status.CONVERGED if out.converged else
                            Status.TIME_LIMIT if ctx.deadline.expired() else Status.MAX_ITER)
    if not finite and status is not Status.CONVERGED:
        status = Status.FAILED
    if finite and w is not None:
        final = ctx.kkt(p, w, multiplier)
        if not ctx.trace.points or ctx.trace.points[-1][0] != out.iterations:
            ctx.trace.points.append((int(out.iterations), ctx.trace.elapsed(), float(final)))
    converged = bool(out.converged)  # a claim beside another status word is still a claim, for the judge
    setup_time, solve_time = 0.0 if ctx.setup_time is None else ctx.setup_time, ctx.trace.elapsed()
    problems = account_problems(out.iterations, ctx.matvecs(), setup_time, solve_time)
    if problems:  # (a count or time a table cannot hold: ``ctx.setup_time`` or the trace's clock set by hand)
        raise SolverReturnError("the solve's own account: " + "; ".join(problems))
    return SolveResult(
        p=p,
        iterations=int(out.iterations),
        converged=converged,
        status=status.value,
        message=out.message or f"{status.value} after {out.iterations} iterations",
        solve_time=solve_time,
        setup_time=float(setup_time),
        matvecs=ctx.matvecs(),
        warm_started=ctx.warm_started,
        trace=list(ctx.trace.points),
        info={**ctx.info, **out.info},
        multiplier=None if multiplier is None else float(multiplier),
        w=w if multiplier is None or w is None else w - multiplier,
    )
