"""The skip policy: the one interpreter of what a solver says it can serve.

Before a solve the harness asks, in order (the first "no" is the recorded reason, in
words, with the estimate):

1. can the solver be loaded, and is it available (``Solver.availability``)?  Then the
   profile: a solver whose declared accuracy floor is above the profile's check is not run
   under it (``Profile.floor_skip``), whatever n;
2. ``capabilities.max_n`` against the trial-set size n;
3. the operator: a solver that needs the dense H (``needs_dense``, or no "fft" among its
   ``operators``) is given one; a solver that needs the FFT operator cannot run on a
   scene that builds a dense H;
4. memory: the dense H (if the harness must assemble it) plus ``memory_estimate(n)``
   against the memory budget;
5. the solver's own ``skip(traits)`` on the problem's ``ProblemTraits`` (n, operator,
   geometry, surface, periodicity, kernel), then its ``skip_params(traits, params)`` with
   the variant's resolved parameters -- e.g. a CMR variant needs the coarse levels it asks;
6. time: along a load history the solver's own finished steps, extrapolated by the
   measured growth (``extrapolated_time``); else its ``time_estimate(n, operator)``,
   under load control corrected by ``problem_time_estimate``; against the time limit.
   After a timeout, larger steps of that solver are skipped.

A model that raises, or gives what no estimate is (NaN, a negative number, a non-number:
``model_value``), fails the solver's rows naming it: a defect of its declaration, neither a
reason to skip nor leave to run.

A solver's ``time_estimate(n, operator)`` models displacement control: a trial set of
n unknowns inside a padded FFT grid of ``FFT_POINTS_PER_UNKNOWN`` (28) points per unknown,
at its typical iteration count.  A product costs the problem's whole padded grid whatever
n is, so the estimate is scaled by that grid's matvec cost over the model's
(``fft_points_per_unknown``: the first step of a sweep on an 8193^2 grid has n = 14,531 in
a grid of 18,000 padded points per unknown); under load control the trial set is the whole
grid (n = N^2, ``WHOLE_GRID_FFT_POINTS`` points per unknown), and a solver may take another
iteration count (``LOAD_CONTROL_ITERATION_RATIO``).  A model not priced in FFT products
(``Solver.time_scales_with_grid`` False: dense rows, a factorisation) is not rescaled.

``skip_decision`` answers one question; ``SkipPolicy`` adds the rows of the earlier
steps of the same sequence, the same rows whether a run is resumed or not.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from contactbench.solvers._kit import (FFT_POINTS_PER_UNKNOWN, TYPICAL_PK_LOAD_ITERATIONS, WHOLE_GRID_FFT_POINTS,
                                       matvec_seconds)
from contactbench.solvers._loading import availability_failure
from contactbench.solvers.base import Capabilities, ProblemTraits, Solver
from contactbench.solvers.pk import TYPICAL_PK_ITERATIONS
from contactbench.solvers.reference import BVLS_FACTORISATIONS, BVLS_LOAD_FACTORISATIONS
from contactbench.solvers.registry import load_solver

from ..profiles import get_profile
from ..table.schema import ANSWERED
from .isolation import SOLVER_FAULTS

GiB = float(2**30)

#: Growth exponent of solve time with n used to extrapolate an observed solve (the
#: floor; with two observed steps the measured exponent is used, up to the cap: dense
#: factorisations grow like n^3, and a single jump between two steps must not condemn
#: a solver -- the paper's NNLS goes 2.3 s -> 29 s -> 38 s -> 78 s -> 114 s at 512^2).
OBSERVED_TIME_EXPONENT = 1.5
OBSERVED_EXPONENT_CAP = 3.0
#: An extrapolated time above this fraction of the limit counts as hopeless.
OBSERVED_SKIP_FRACTION = 1.0

#: Iterations under load control over those the solver's ``time_estimate`` assumes, by
#: registry name (a solver not named keeps its model's count).
LOAD_CONTROL_ITERATION_RATIO: dict[str, float] = {"pk": TYPICAL_PK_LOAD_ITERATIONS / TYPICAL_PK_ITERATIONS,
                                                  "bvls": BVLS_LOAD_FACTORISATIONS / BVLS_FACTORISATIONS}

Observation = tuple[int, float]  # (n, solve seconds) of one finished step


@dataclass(frozen=True)
class Decision:
    """Run the variant with ``operator`` ("fft"/"dense"), or skip it for ``reason``; or,
    ``failed``, record it as failed for ``reason``: the solver's own model or skip check
    raised (a defect of the solver, not a capability it declares)."""

    operator: str = ""
    reason: str = ""
    failed: bool = False

    @property
    def skip(self) -> bool:
        return bool(self.reason)


def extrapolated_time(history: Sequence[Observation], n: int) -> tuple[float, float]:
    """(predicted seconds at n, exponent used) from the last one or two finished steps of
    the same solver: t_last (n / n_last)^e, with e measured between the last two steps
    when both are long enough to time (> 0.05 s) and n grew, clamped to [1.5, 3]."""
    n1, t1 = history[-1]
    e = OBSERVED_TIME_EXPONENT
    if len(history) >= 2:
        n0, t0 = history[-2]
        if n1 > 1.1 * n0 and t0 > 0.05 and t1 > 0:
            e = min(OBSERVED_EXPONENT_CAP, max(e, math.log(t1 / t0) / math.log(n1 / n0)))
    return t1 * max(1.0, n / n1) ** e, e


def fft_points_per_unknown(traits: ProblemTraits) -> float:
    """Padded FFT grid points per unknown of the problem ``traits`` describe: from its grid
    where the side is known (2N x 2N padded, aperiodic; N x N, periodic), else the model's
    typical figure (``FFT_POINTS_PER_UNKNOWN`` for a trial set, ``WHOLE_GRID_FFT_POINTS``
    under load control, where the trial set is the whole grid)."""
    pad = WHOLE_GRID_FFT_POINTS[bool(traits.periodic)]
    if traits.surface_side > 0 and traits.n > 0:
        return pad * traits.surface_side**2 / traits.n
    return pad if traits.load_control else FFT_POINTS_PER_UNKNOWN


def checked_availability(solver: Solver) -> tuple[bool, str, bool]:
    """(available, reason, failed): what ``solver.availability()`` answers, or, when it
    raises (an answer that is no pair raises too: ``solvers.base.read_availability``),
    (False, "its availability() failed: ...", True) -- a defect of the solver, whose rows
    fail naming it, not a reason to skip them."""
    try:
        ok, why = solver.availability()
    except SOLVER_FAULTS as exc:
        return False, availability_failure(exc), True
    return bool(ok), str(why), False


class ModelValueError(ValueError):
    """A solver's time or memory model gave what no estimate is (``model_value``)."""


def model_value(value: object, what: str) -> float:
    """``value``, what a solver's ``what`` model (``time_estimate``, ``memory_estimate``)
    returned, as a float: a real number, not NaN and not negative (infinity says "never
    within any limit"); else a ``ModelValueError`` naming it, which the policy records as
    the model's failure (a bug of the solver's declaration, not a reason to run or skip)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ModelValueError(f"{what} returned {value!r} ({type(value).__name__}), not a number of "
                              f"{'seconds' if what == 'time_estimate' else 'bytes'}")
    out = float(value)
    if math.isnan(out) or out < 0.0:
        raise ModelValueError(f"{what} returned {out!r}; an estimate is a number >= 0")
    return out


def problem_time_estimate(solver: Solver, traits: ProblemTraits, operator: str) -> float | None:
    """The solver's ``time_estimate(n, operator)`` for the problem ``traits`` describe:
    unless its model is not in products (``Solver.time_scales_with_grid``), scaled by the matvec cost of the problem's own FFT grid over the model's typical one (a
    product costs the whole padded grid whatever n is: the first step of a sweep on a large
    grid has a small n and a large grid), and under load control by
    ``LOAD_CONTROL_ITERATION_RATIO`` (module doc).  None when the solver has no model."""
    t = solver.time_estimate(traits.n, operator)
    if t is None:
        return t
    t = model_value(t, "time_estimate")
    n = traits.n
    matvec_ratio = 1.0
    if solver.time_scales_with_grid:
        matvec_ratio = (matvec_seconds(n, operator, fft_points_per_unknown(traits))
                        / matvec_seconds(n, operator, FFT_POINTS_PER_UNKNOWN))
    iterations = LOAD_CONTROL_ITERATION_RATIO.get(solver.name, 1.0) if traits.load_control else 1.0
    return float(t) * matvec_ratio * iterations


def skip_decision(base: str, traits: ProblemTraits, time_limit: float, memory_budget: float,
                  observed: Sequence[Observation] | None = None, params: dict[str, Any] | None = None,
                  floor: Callable[[Solver], str | None] | None = None) -> Decision:
    """Whether solver ``base`` (registry name or ``module:NAME``) can serve a problem
    with these traits within the limits (module doc, steps 1-6).  ``observed`` = the
    (n', seconds) of the same solver's last one or two finished steps of the load
    sequence: when given it replaces the static time model (which cannot know about
    warm starts).  ``params``: the variant's own parameters (``capability_decision``).
    ``floor``: why the profile does not run the solver (``Profile.floor_skip``), asked
    once it is loaded and available, before steps 2-6 (a reason that holds at every n)."""
    try:
        solver = load_solver(base)
    except Exception as exc:
        return Decision(reason=f"solver {base!r} cannot be loaded: {exc}")
    ok, why, failed = checked_availability(solver)
    if failed:
        return Decision(reason=why, failed=True)
    if not ok:
        return Decision(reason=f"not available: {why}")
    beyond_reach = floor(solver) if floor is not None else None
    if beyond_reach:
        return Decision(reason=beyond_reach)
    d = capability_decision(solver, traits, memory_budget, params)
    if d.skip:
        return d
    return time_decision(solver, traits, d.operator, time_limit, observed)


def offered_operator(caps: Capabilities, scene_operator: str) -> str | None:
    """The operator ("dense" or "fft") a solver of capabilities ``caps`` is given on a step
    whose scene builds ``scene_operator``: the scene's dense H (None: the solver takes no
    dense H), else the FFT operator unless the solver needs a dense H (``needs_dense``, or
    no "fft" among its ``operators``)."""
    if scene_operator == "dense":
        return "dense" if "dense" in caps.operators else None
    return "dense" if caps.needs_dense or "fft" not in caps.operators else "fft"


def capability_decision(solver: Solver, traits: ProblemTraits, memory_budget: float,
                        params: dict[str, Any] | None = None) -> Decision:
    """Steps 2-5 of the module doc for a loaded, available solver: max_n, the operator
    it is given, memory, and its own ``skip`` and ``skip_params`` (with ``params``
    resolved: the variant's, or the defaults).  No time model (``validate`` uses this:
    a solver cannot skip its way out of a conformance case)."""
    n, caps = traits.n, solver.capabilities
    if caps.max_n is not None and n > caps.max_n:
        return Decision(reason=f"trial set n = {n} exceeds the solver's limit max_n = {caps.max_n}")
    operator = offered_operator(caps, traits.operator)
    if operator is None:
        return Decision(reason="the solver needs the matrix-free FFT operator; this scene builds a dense H")
    dense_bytes = 8.0 * n * n if operator == "dense" else 0.0  # the step's dense H, the scene's own included
    try:
        own_bytes = model_value(solver.memory_estimate(n), "memory_estimate")
    except (*SOLVER_FAULTS, ModelValueError) as exc:
        return Decision(reason=f"memory model failed: {type(exc).__name__}: {exc}", failed=True)
    if dense_bytes > memory_budget:
        return Decision(reason=(f"needs dense H: {n} x {n} float64 = {dense_bytes / GiB:.3g} GiB "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    if dense_bytes + own_bytes > memory_budget:
        return Decision(reason=(f"memory estimate {(dense_bytes + own_bytes) / GiB:.3g} GiB at n = {n} "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    try:
        own_reason = solver.skip(traits) or solver.skip_params(traits, solver.resolve_params(params))
    except SOLVER_FAULTS as exc:
        return Decision(reason=f"skip check failed: {type(exc).__name__}: {exc}", failed=True)
    if own_reason:
        return Decision(reason=str(own_reason))
    return Decision(operator=operator)


def time_decision(solver: object, traits: ProblemTraits, operator: str, time_limit: float,
                  observed: Sequence[Observation] | None) -> Decision:
    """Step 6 of the module doc: the observed growth, else the solver's time model."""
    n = traits.n
    history = [(int(a), float(b)) for a, b in (observed or []) if a > 0]
    if history:
        t_obs, e = extrapolated_time(history, n)
        if t_obs > OBSERVED_SKIP_FRACTION * time_limit:
            n1, t1 = history[-1]
            return Decision(reason=(f"predicted solve time {t_obs:.3g} s at n = {n} from {t1:.3g} s at n = {n1} on "
                                    f"the previous step (time ~ n^{e:.2g}), over the time limit of {time_limit:.3g} s"))
        return Decision(operator=operator)
    try:
        t_est = problem_time_estimate(solver, traits, operator)  # type: ignore[arg-type]
    except (*SOLVER_FAULTS, ModelValueError) as exc:
        return Decision(reason=f"time model failed: {type(exc).__name__}: {exc}", failed=True)
    if t_est is not None and t_est > time_limit:
        control = ", load control" if traits.load_control else ""
        return Decision(reason=(f"predicted solve time {t_est:.3g} s at n = {n} ({operator} operator{control}) "
                                f"exceeds the time limit of {time_limit:.3g} s"))
    return Decision(operator=operator)


@dataclass(frozen=True)
class StepRecord:
    """What the skip policy reads of one finished row of a (variant, profile) sequence:
    its step, trial-set size n, status and solve seconds (the row's ``step``, ``n``,
    ``status`` and ``solve_time_s``)."""

    step: int
    n: int
    status: str
    seconds: float | None


@dataclass
class SkipPolicy:
    """``skip_decision`` plus the rows of each (variant, profile) sequence of one job.

    The decision for step k is a function of the plan (limits, traits) and of the rows of
    steps < k of the same (variant, profile) sequence only -- whether those rows were
    produced by this process (``note``) or read back from the journal on resume
    (``note`` too, via ``harness.run.job``) -- never of the order in which cells finished:

    * a timeout at step j < k with n_j <= n_k skips step k ("timed out at step j");
    * else the last two earlier steps with an answer (solved or inaccurate; one
      observation per step: the fastest of its answered repeats) feed
      ``extrapolated_time`` along a load history;
    * else the solver's own time model;
    * and, before any of these, a solver whose declared accuracy floor is above the
      profile's check is skipped (``Profile.floor_skip``: the same reason on every step).
    """

    time_limit: float
    memory_budget: float
    seen: dict[tuple[str, str], dict[int, list[StepRecord]]] = field(default_factory=dict)

    def decide(self, base: str, key: tuple[str, str], traits: ProblemTraits, step: int,
               load_history: bool = True, params: dict[str, Any] | None = None) -> Decision:
        """The decision for ``step`` of sequence ``key`` (class doc) for the variant of
        solver ``base`` with ``params``."""
        observed = self.observations(key, step) if load_history else []
        d = skip_decision(base, traits, self.time_limit, self.memory_budget, observed, params,
                          floor=get_profile(key[1]).floor_skip)
        slow = self.first_timeout(key, step)
        if not d.skip and slow is not None and traits.n >= slow.n:
            return Decision(reason=f"predicted over the {self.time_limit:g} s limit: it timed out at step "
                                   f"{slow.step} with n = {slow.n}, and this step has n = {traits.n}")
        return d

    def note(self, key: tuple[str, str], step: int, n: int | None, status: str, seconds: float | None) -> None:
        """Record one finished row of sequence ``key`` (any status; only timeouts and
        answers with a time count)."""
        if n is None:
            return
        sec = None if seconds is None or not math.isfinite(float(seconds)) else float(seconds)
        self.seen.setdefault(key, {}).setdefault(int(step), []).append(StepRecord(int(step), int(n), str(status), sec))

    def earlier(self, key: tuple[str, str], step: int) -> list[tuple[int, list[StepRecord]]]:
        return sorted((k, recs) for k, recs in self.seen.get(key, {}).items() if k < step)

    def first_timeout(self, key: tuple[str, str], step: int) -> StepRecord | None:
        """The earliest timed-out row of a step before ``step``."""
        for _, recs in self.earlier(key, step):
            for rec in recs:
                if rec.status == "timeout":
                    return rec
        return None

    def observations(self, key: tuple[str, str], step: int) -> list[Observation]:
        """(n, seconds) of the last two steps before ``step`` with an answered repeat
        (one per step: its fastest answered repeat)."""
        out: list[Observation] = []
        for _, recs in self.earlier(key, step):
            times = [r.seconds for r in recs if r.status in ANSWERED and r.seconds is not None]
            if times:
                out.append((recs[0].n, min(times)))
        return out[-2:]
