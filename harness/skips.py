"""The skip policy: the one interpreter of what a solver says it can serve.

Before a solve the harness asks, in order (the first "no" is the recorded reason, in
words, with the estimate):

1. can the solver be loaded, and is it available (``Solver.availability``)?
2. ``capabilities.max_n`` against the trial-set size n;
3. the operator: a solver that needs the dense H (``needs_dense``, or no "fft" among its
   ``operators``) is given one; a solver that needs the FFT operator cannot run on a
   scene that builds a dense H;
4. memory: the dense H (if the harness must assemble it) plus ``memory_estimate(n)``
   against the memory budget;
5. the solver's own ``skip(traits)`` on the problem's ``ProblemTraits`` (n, operator,
   geometry, surface, periodicity, kernel) -- e.g. CMR needs the surface's coarse levels;
6. time: along a load history the solver's own finished steps, extrapolated by the
   measured growth (``extrapolated_time``); else its ``time_estimate(n, operator)``;
   against the time limit.  After a timeout, larger steps of that solver are skipped.

``skip_decision`` answers one question; ``SkipPolicy`` adds what one job has observed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

from contactbench.solvers.base import ProblemTraits, Solver
from contactbench.solvers.registry import load_solver

GiB = float(2**30)

#: Growth exponent of solve time with n used to extrapolate an observed solve (the
#: floor; with two observed steps the measured exponent is used, up to the cap: dense
#: factorisations grow like n^3, and a single jump between two steps must not condemn
#: a solver -- the paper's NNLS goes 2.3 s -> 29 s -> 38 s -> 78 s -> 114 s at 512^2).
OBSERVED_TIME_EXPONENT = 1.5
OBSERVED_EXPONENT_CAP = 3.0
#: An extrapolated time above this fraction of the limit counts as hopeless.
OBSERVED_SKIP_FRACTION = 1.0

Observation = tuple[int, float]  # (n, solve seconds) of one finished step


@dataclass(frozen=True)
class Decision:
    """Run the variant with ``operator`` ("fft"/"dense"), or skip it for ``reason``."""

    operator: str = ""
    reason: str = ""

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


def skip_decision(base: str, traits: ProblemTraits, time_limit: float, memory_budget: float,
                  observed: Sequence[Observation] | None = None) -> Decision:
    """Whether solver ``base`` (registry name or ``module:NAME``) can serve a problem
    with these traits within the limits (module doc, steps 1-6).  ``observed`` = the
    (n', seconds) of the same solver's last one or two finished steps of the load
    sequence: when given it replaces the static time model (which cannot know about
    warm starts)."""
    try:
        solver = load_solver(base)
    except Exception as exc:
        return Decision(reason=f"solver {base!r} cannot be loaded: {exc}")
    ok, why = solver.availability()
    if not ok:
        return Decision(reason=f"not available: {why}")
    d = capability_decision(solver, traits, memory_budget)
    if d.skip:
        return d
    return time_decision(solver, traits, d.operator, time_limit, observed)


def capability_decision(solver: Solver, traits: ProblemTraits, memory_budget: float) -> Decision:
    """Steps 2-5 of the module doc for a loaded, available solver: max_n, the operator
    it is given, memory, and its own ``skip``.  No time model (``validate`` uses this:
    a solver cannot skip its way out of a conformance case)."""
    n, caps = traits.n, solver.capabilities
    if caps.max_n is not None and n > caps.max_n:
        return Decision(reason=f"trial set n = {n} exceeds the solver's limit max_n = {caps.max_n}")
    wants_dense = caps.needs_dense or "fft" not in caps.operators
    if traits.operator == "dense":
        if "dense" not in caps.operators:
            return Decision(reason="the solver needs the matrix-free FFT operator; this scene builds a dense H")
        operator = "dense"
    else:
        operator = "dense" if wants_dense else "fft"
    dense_bytes = 8.0 * n * n if operator == "dense" and traits.operator != "dense" else 0.0
    try:
        own_bytes = float(solver.memory_estimate(n))
    except Exception as exc:
        return Decision(reason=f"memory model failed: {exc}")
    if dense_bytes > memory_budget:
        return Decision(reason=(f"needs dense H: {n} x {n} float64 = {dense_bytes / GiB:.3g} GiB "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    if dense_bytes + own_bytes > memory_budget:
        return Decision(reason=(f"memory estimate {(dense_bytes + own_bytes) / GiB:.3g} GiB at n = {n} "
                                f"exceeds the memory budget of {memory_budget / GiB:.3g} GiB"))
    try:
        own_reason = solver.skip(traits)
    except Exception as exc:
        return Decision(reason=f"skip check failed: {exc}")
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
        t_est = solver.time_estimate(n, operator)  # type: ignore[attr-defined]
    except Exception as exc:
        return Decision(reason=f"time model failed: {exc}")
    if t_est is not None and t_est > time_limit:
        return Decision(reason=(f"predicted solve time {t_est:.3g} s at n = {n} ({operator} operator) "
                                f"exceeds the time limit of {time_limit:.3g} s"))
    return Decision(operator=operator)


@dataclass
class SkipPolicy:
    """``skip_decision`` plus what one job has seen of each (variant, profile): its
    first timeout (larger steps are skipped) and its last two finished solves along the
    load history (the time prediction for the next step)."""

    time_limit: float
    memory_budget: float
    too_slow: dict[tuple[str, str], tuple[int, int]] = field(default_factory=dict)  # -> (step, n)
    observed: dict[tuple[str, str], list[Observation]] = field(default_factory=dict)

    def decide(self, base: str, key: tuple[str, str], traits: ProblemTraits) -> Decision:
        d = skip_decision(base, traits, self.time_limit, self.memory_budget, self.observed.get(key))
        slow = self.too_slow.get(key)
        if not d.skip and slow is not None and traits.n >= slow[1]:
            return Decision(reason=f"predicted over the {self.time_limit:g} s limit: it timed out at step "
                                   f"{slow[0]} with n = {slow[1]}, and this step has n = {traits.n}")
        return d

    def note(self, key: tuple[str, str], step: int, n: int, status: str, seconds: float | None,
             load_history: bool) -> None:
        """Record a finished solve of ``key`` (a timeout, or an answer's time)."""
        if status == "timeout":
            self.too_slow.setdefault(key, (step, n))
        elif status in ("solved", "inaccurate") and load_history and seconds is not None:
            seen = self.observed.setdefault(key, [])
            seen[:] = (seen + [(n, float(seconds))])[-2:]
