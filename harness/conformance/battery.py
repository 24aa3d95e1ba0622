"""Conformance check: run any solver through the stress battery and judge every answer.

``contactbench validate MODULE:NAME|NAME`` (``main``) and the Python API ``validate``
run a solver -- registered, or given by import path -- on every case of the battery
(``harness.conformance.cases``: conditioning, units, edge cases, random LCPs, float32
input, perturbation, paper Example 1 at n = 400, full packing, periodic whole grids,
constrained and rectangular problems, a few small cases solved under an iteration limit of
``cases.ITERATION_LIMIT``, ``iteration-limit``, and a few cases solved from a warm start that
is not their answer, ``warm-start``, for solvers that take one).
Every answer is judged by the one judge, ``harness.judging.judge``, at the tolerance the
solver promises (``Capabilities.promise``, docs/verdicts.md): "exact" -- the case's
profile's ``check_tol``, the threshold ``run`` uses for "solved", so a solve that ``run``
calls solved is never WRONG here, and a WRONG one is never solved there; a float floor
f -- max(check_tol, min(f, ``PROMISE_BOUND``)).  A promise loosens the KKT test, up to
``PROMISE_BOUND``, the loosest threshold at which ``run`` calls an answer solved (its
profiles' largest ``check_tol``); a floor declared above it is held to the bound, and the
table says so.  Beside the judge's KKT test, the answer is compared with the
exact reference (``p_tolerance``, a gross-error bound).  The problem is sealed before
each solve (``harness.judging.ProblemSeal``): a solver that writes into it is WRONG.

Row statuses (one row per solve):

``pass``         the judge's reading is "pass".
``WRONG``        the judge reads the answer "wrong": the solver claimed convergence
                 and the answer is inaccurate (scaled KKT error above the promised
                 tolerance) or no answer (non-finite, wrong shape or dtype); or the
                 solver wrote into the problem it was handed.
``unconverged``  inaccurate or no answer, and the solver did not claim convergence.
``flagged``      the KKT test accepts the answer but a conformance extra does not: p is
                 beyond ``p_tolerance`` of the exact reference (a solver's p reaches the
                 judge as float64, ``solvers.base.readable_answer``: the judge's dtype
                 note is for an array judged directly), or the solver reports fewer
                 iterations than its own trace records (the table's count would
                 flatter it); in ``iteration-limit``, it reports more iterations than
                 its limit (times the stages ``info["stages"]`` lists where it declares
                 ``limit_per_stage``), whether or not the answer is accepted (an
                 unaccepted one's row says so); and on comparison rows, unit systems disagree by
                 more than 1e-8, or a 1e-6 perturbation of ubar moved p by more than
                 10 cond(H) x 1e-6 (a chaotic active set).  The row and the headline
                 name which (``VerdictRow.flags``).
``refused``      it raised ProblemInputError / MemoryBudgetError / NotImplementedError
                 (or, for float32 input, a ValueError/TypeError naming the dtype).
``crashed``      any other exception (a ``SolveAborted`` with a status that class does not
                 allow included), or the worker process died.
``timeout``      no answer within the time limit (the worker is killed).
``skipped``      the solver cannot take the case (operator kind, max_n, a warm start it
                 does not take, its own ``skip``), or a comparison row whose steps did
                 not all pass.  ``own_skip`` marks a skip the solver's own ``skip``,
                 ``skip_params`` or memory model made, where the capabilities it
                 declares alone would have run the case (``cases.declared_skip``).

Outcomes (one per solver; ``VerdictTable.outcome``) and exit codes of ``main``:

``wrong``        any WRONG row (exit 1);
``incomplete``   solves left unsolved -- unconverged (outside ``iteration-limit``, where
                 stopping at the limit is the answer asked for), timeout, crashed, or
                 refused outside the float32 case -- by any solver: exit 3, listing them;
``untested``     none of these, and either no answer of the solver's own judged
                 (``VerdictTable.judged``; in ``iteration-limit`` an answer stopped at the
                 limit counts: ``limit_answers``): every selected case skipped for a capability
                 it declares, refused where refusing is allowed (float32), or answered by
                 the lifecycle without calling it (ubar <= 0: p = 0); or its own skips
                 left a whole group of the selection untried (the coverage rule below)
                 -- exit 4;
``conforms``     none of these: every case solved to what the solver promises, or skipped
                 for a capability it declares, at least one answer of its own accepted,
                 and every group of the selection tried (exit 0); the headline states the
                 promise and, when rows are flagged, how many of them and why.

Coverage: a solver must be handed at least one solve in each group of the selection
(``cases.BATTERY_GROUPS``) that the capabilities it declares do not rule out.  A group
whose every solve was skipped, at least one of them by the solver's own ``skip``,
``skip_params`` or memory model (``own_skip``), is untried
(``VerdictTable.untried_groups``): the solver is UNTESTED there, and the headline names
the groups -- a ``skip`` can narrow the battery, never choose the part it is judged on.
``--strict`` also fails (exit 1) on crashes, timeouts and flagged rows.  Bad input (an
unknown solver, an import path that does not load, a solver declaration that cannot be
used (``solvers.registry.check_declaration``), no case selected, a promise that is not
"exact" or a floor below 1, a --timeout that is not a finite number > 0, a --csv or --out
that is empty or cannot be written) exits 2 with one line, before anything runs.

``--command 'CMD {problem} {solution}' [--inputs dense|kernel]`` validates an outside
program over the file protocol (``contactbench.solvers.external``,
docs/external-solvers.md): the cases its inputs do not allow are skipped, each with its
reason, and listed after the table ("left out").  An external program claims
convergence with ``"status"`` "converged", "solved" or "optimal", or no status
(``contactbench.solvers.external``).
``--out DIR`` writes the conformance report (``harness.conformance.report``:
DIR/verdicts.csv and DIR/conformance.md) into a new or empty folder or a conformance
report folder, never into another one; the exit status is the same.

For pytest: ``assert_conforms(solver)`` raises AssertionError, its verdict line first and
then the table, unless the solver conforms over the battery (an untested solver does
not).  Case by case, parametrize over ``conformance_cases()`` (``ids=str``: each case by
its name; a case may be given by its name too) and call
``harness.pytest_plugin.case_conforms(solver, case)``: a case the
solver is not handed (a declared capability rules it out, its own skip, or the lifecycle
answers it) is a pytest skip with the reason, as the coverage rule belongs to the battery.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, Iterable

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import ContactInstance
from contactbench.problems.kkt import SCALED_PARTS
from contactbench.problems.scenes.base import InstanceSpec
from contactbench.problems.scenes.stress import GROUPS, build_battery_spec
from contactbench.solvers.base import Promise, Solver, describe_promise, promised_tol
from contactbench.solvers.registry import load_solver

from .declared import declaration_of, in_a_child, names_user_code
from .cases import (
    BATTERY_GROUPS,
    DEFAULT_TIMEOUT,
    LIMIT_GROUP,
    REFUSABLE_GROUPS,
    ConformanceCase,
    Reference,
    CaseAnswer,
    CaseRunner,
    cached_reference,
    check_timeout,
    conformance_cases,
    exact_reference,
    warm_start_of,
)
from ..judging import Verdict, judge, read_answer
from ..profiles import PROFILES, get_profile

__all__ = ["BATTERY_GROUPS", "ConformanceCase", "GROUPS", "PROMISE_BOUND", "Reference", "VerdictRow", "VerdictTable", "assert_conforms",
           "build_battery_spec", "conformance_cases", "exact_reference", "p_tolerance", "record_columns", "validate"]

#: Agreement required across unit systems (P/(E A) relative, scaled KKT figures absolute).
UNITS_AGREEMENT = 1e-8
#: A perturbation may move p by at most this many times cond(H) eps.
PERTURBATION_FACTOR = 10.0
#: ``p_tolerance`` = clip(P_TOL_FACTOR cond sqrt(check_tol), P_TOL_RANGE).
P_TOL_FACTOR = 10.0
P_TOL_RANGE = (1e-4, 0.05)
#: The loosest scaled KKT error a promise may hold a solver to: the loosest threshold at
#: which ``run`` calls an answer solved (module doc).
PROMISE_BOUND = max(profile.check_tol for profile in PROFILES.values())
#: What a flagged row's ``flags`` name, in the headline's words.
FLAG_WORDS = {"reference": "off the exact reference", "dtype": "not float64",
              "comparison": "failing a comparison", "count": "an iteration count below its own trace",
              "limit": "more iterations than its iteration limit"}

#: Statuses of a solve that produced an answer (the comparison rows need one per step).
ANSWERED = ("pass", "WRONG", "unconverged", "flagged")
#: Statuses of a solve that no solver may leave (besides WRONG): the case is unsolved.
UNSOLVED = ("unconverged", "timeout", "crashed")
#: The flags of a row's iteration count (``FLAG_WORDS``), the only ones an answer the KKT
#: test does not accept is flagged for.
COUNT_FLAGS = ("count", "limit")
#: Statuses that ``--strict`` also fails on.
STRICT_FAILING = ("crashed", "timeout", "flagged")
#: Exit code of each outcome (``main``); bad input is ``arguments.EXIT_BAD_INPUT``.
EXIT_CODES = {"conforms": 0, "wrong": 1, "strict": 1, "incomplete": 3, "untested": 4}


# ---------------------------------------------------------------------------
# One row per solve
# ---------------------------------------------------------------------------


@dataclass
class VerdictRow:
    """One row of the verdict table: a solve (step >= 0) or a comparison (step -1)."""

    solver: str
    case: str
    group: str
    step: int
    n: int
    status: str
    claimed: bool | None = None
    kkt_error: float = float("nan")
    p_rel_error: float = float("nan")
    iterations: int | None = None
    time_s: float = float("nan")
    cond: float = float("nan")
    check_tol: float = float("nan")
    dim_load: float = float("nan")
    ref_time_s: float = float("nan")  # seconds the exact reference took (nan: known solution)
    kkt: dict[str, float] = field(default_factory=dict)
    message: str = ""
    detail: str = ""
    iterated: bool = True  # False: answered by the lifecycle, without calling the solver
    own_skip: bool = False  # skipped by the solver's own skip, skip_params or memory model (module doc)
    flags: str = ""  # a flagged row: what failed, ``FLAG_WORDS``' keys joined by "+"

    @property
    def label(self) -> str:
        return self.case if self.step < 0 else f"{self.case}@{self.step}"


def held_promise(promise: Promise) -> Promise:
    """The promise a solver is held to: "exact", or its floor up to ``PROMISE_BOUND``."""
    return promise if promise == "exact" else min(float(promise), PROMISE_BOUND)


def promise_text(promise: Promise) -> str:
    """The promise in words, and the bound it is held to where it is looser."""
    held = held_promise(promise)
    text = describe_promise(promise)
    return text if held == promise else f"{text}, held to {held:g}, the loosest threshold run calls solved"


def p_tolerance(cond: float, check_tol: float) -> float:
    """Allowed ||p - p_ref||_inf / ||p_ref||_inf: a gross-error check beside the KKT test.

    The scaled KKT error does not bound the error in p by cond * kkt where points are
    nearly degenerate (p_i and w_i both small: complementarity is quadratic there), so
    the bound uses sqrt(check_tol): clip(P_TOL_FACTOR cond sqrt(check_tol), P_TOL_RANGE)."""
    c = cond if np.isfinite(cond) else 1e6
    lo, hi = P_TOL_RANGE
    return float(min(hi, max(lo, P_TOL_FACTOR * c * math.sqrt(check_tol))))


def row_status(v: Verdict) -> str:
    """The row status of the judge's verdict (module doc): WRONG exactly when the judge
    reads "wrong" and its status is not "solved" (a solved answer off the reference is
    flagged)."""
    if v.reading == "pass":
        return "pass"
    if v.status == "solved":
        return "flagged"
    return "WRONG" if v.reading == "wrong" else "unconverged"


def judge_solve(out: CaseAnswer, inst: ContactInstance, ref: Reference | None, case: ConformanceCase,
                step: int, solver: str, promise: Promise = "exact") -> VerdictRow:
    """The row of one solve: the judge's verdict at the promised tolerance (the case's
    check_tol, or the solver's floor above it, held to ``PROMISE_BOUND``), read as in the
    module doc."""
    check_tol = promised_tol(held_promise(promise), get_profile(case.profile).check_tol)
    row = VerdictRow(solver, case.name, case.group, step, inst.n, out.kind, time_s=out.time_s, check_tol=check_tol,
                     cond=ref.cond if ref else float("nan"), message=out.message, detail=out.detail,
                     ref_time_s=ref.time_s if ref else float("nan"), own_skip=out.own_skip)
    if out.kind != "ok":
        return row
    p_ref = ref.p if ref is not None and ref.trusted else None
    p_tol = p_tolerance(ref.cond, check_tol) if ref is not None and p_ref is not None else None
    v = judge(inst, out.p, bool(out.converged), check_tol, p_ref, p_tol, tampered=out.tampered,
              multiplier=out.multiplier)
    row.claimed, row.iterations, row.iterated = bool(out.converged), out.iterations, out.iterated
    row.kkt_error = v.kkt_error
    row.p_rel_error = float(v.figures.get("p_rel_error", float("nan")))
    row.dim_load = float(v.figures.get("dim_load", float("nan")))
    if v.kkt is not None:
        row.kkt = {k: float(getattr(v.kkt, k)) for k in SCALED_PARTS}
    row.status = row_status(v)
    undercount = out.iterations is not None and out.traced > out.iterations
    if undercount and row.status in ("pass", "flagged"):  # (the count is the table's; the answer is right)
        v.problems.append(f"it reports {out.iterations} iterations where its own trace reaches iteration {out.traced}")
        v.kinds.append("count")
        row.status = "flagged"
    over = over_limit(out, case)
    if over and row.status in ("pass", "flagged", "unconverged"):  # (a claimed wrong answer stays WRONG)
        v.problems.append(over)
        v.kinds.append("limit")
        row.status = "flagged"
    if row.status == "flagged":  # (an answer not accepted is flagged for its count alone: off the reference, as expected)
        kinds = v.kinds if v.status == "solved" else [k for k in v.kinds if k in COUNT_FLAGS]
        row.flags = "+".join(k for k in kinds if k in FLAG_WORDS)
        lead = "the KKT test accepts it, but " if v.status == "solved" else "not converged, and "
        row.message = lead + "; ".join(v.problems)
    elif row.status == "unconverged":
        row.message = f"{v.message()} (solver status: {out.solver_status})"
    else:
        row.message = v.message()
    if not out.iterated:
        row.message = "ubar <= 0: p = 0 given by the lifecycle, the solver not called (judges nothing of it)"
    return row


def over_limit(out: CaseAnswer, case: ConformanceCase) -> str:
    """What the answer of a case solved under an iteration limit (``case.max_iter``) reports
    beyond it: more iterations than the limit times ``out.stages`` ("" none, or no limit)."""
    if case.max_iter is None or out.iterations is None:
        return ""
    allowed = case.max_iter * max(1, out.stages)
    if out.iterations <= allowed:
        return ""
    stages = f" x {out.stages} stages = {allowed}" if out.stages > 1 else ""
    return f"it reports {out.iterations} iterations under max_iter {case.max_iter}{stages}"


def _comparison_row(rows: list[VerdictRow], case: ConformanceCase, solver: str, **kw: Any) -> VerdictRow:
    return VerdictRow(solver, case.name, case.group, -1, rows[0].n if rows else 0, "skipped", **kw)


def _steps_verdict(rows: list[VerdictRow], ok: bool) -> str:
    """A comparison row passes only when every step beneath it passed."""
    if not ok:
        return "flagged"
    return "pass" if all(r.status == "pass" for r in rows) else "skipped"


def _steps_note(rows: list[VerdictRow]) -> str:
    bad = Counter(r.status for r in rows if r.status != "pass")
    if not bad:
        return ""
    counts = ", ".join(f"{s} {k}" for s, k in sorted(bad.items()))
    return f"; no verdict: {sum(bad.values())} of {len(rows)} steps did not pass ({counts})"


def units_agreement(rows: list[VerdictRow], case: ConformanceCase, solver: str) -> VerdictRow:
    """Do the scaled KKT figures and P/(E A) agree across the unit systems / moduli?"""
    v = _comparison_row(rows, case, solver, check_tol=UNITS_AGREEMENT)
    if not rows or any(r.status not in ANSWERED for r in rows):
        v.message = "not compared: not every unit system produced an answer"
        return v
    loads = np.array([r.dim_load for r in rows])
    figures = [r.kkt_error for r in rows] + [r.kkt.get(k, np.nan) for r in rows for k in SCALED_PARTS]
    if not (np.all(np.isfinite(loads)) and np.all(np.isfinite(figures))):
        v.message = "not compared: a unit system's P/(EA) or scaled KKT figures are not finite" + _steps_note(rows)
        return v
    load_spread = float(np.ptp(loads) / max(np.max(np.abs(loads)), 1e-300))
    kkt_spread = max(float(np.ptp([r.kkt.get(k, np.nan) for r in rows])) for k in SCALED_PARTS)
    kkt_spread = max(kkt_spread, float(np.ptp([r.kkt_error for r in rows])))
    v.kkt_error, v.p_rel_error = kkt_spread, load_spread
    ok = bool(load_spread <= UNITS_AGREEMENT and kkt_spread <= UNITS_AGREEMENT)
    v.status, v.flags = _steps_verdict(rows, ok), "" if ok else "comparison"
    v.message = (f"P/(EA) spread {load_spread:.1e}, scaled-KKT spread {kkt_spread:.1e} "
                 f"({'within' if ok else 'beyond'} {UNITS_AGREEMENT:g})" + _steps_note(rows))
    return v


def perturbation_check(rows: list[VerdictRow], ps: list[np.ndarray | None], insts: list[ContactInstance],
                       refs: list[Reference], case: ConformanceCase, solver: str) -> VerdictRow:
    """Does p move by at most ~cond eps when ubar moves by eps (relative, 2-norms)?"""
    v = _comparison_row(rows, case, solver, cond=refs[0].cond)
    if any(p is None for p in ps) or any(r.status not in ANSWERED for r in rows):
        v.message = "not compared: not both solves produced an answer"
        return v
    u0, u1 = (np.asarray(i.qp.ubar, dtype=np.float64) for i in insts)
    eps = float(np.linalg.norm(u1 - u0) / np.linalg.norm(u0))
    p0, p1 = (np.asarray(p, dtype=np.float64) for p in ps)
    move = float(np.linalg.norm(p1 - p0) / max(np.linalg.norm(p0), 1e-300))
    ref_move = float(np.linalg.norm(refs[1].p - refs[0].p) / np.linalg.norm(refs[0].p))
    flips = int(np.count_nonzero(insts[0].contact_mask(p0) != insts[1].contact_mask(p1)))
    ref_flips = int(np.count_nonzero(insts[0].contact_mask(refs[0].p) != insts[1].contact_mask(refs[1].p)))
    amplification = move / eps
    v.kkt_error = max(r.kkt_error for r in rows)
    v.p_rel_error = move
    ok = bool(amplification <= PERTURBATION_FACTOR * refs[0].cond)
    v.status, v.flags = _steps_verdict(rows, ok), "" if ok else "comparison"
    v.message = (f"eps {eps:.0e}: p moved {move:.1e} (exact {ref_move:.1e}), amplification {amplification:.3g} "
                 f"vs cond {refs[0].cond:.3g}; active-set flips {flips} (exact {ref_flips})"
                 + ("" if ok else " -- chaotic") + _steps_note(rows))
    return v


# ---------------------------------------------------------------------------
# The table of one solver, and its outcome
# ---------------------------------------------------------------------------


@dataclass
class VerdictTable:
    """All verdicts of one solver's validation run (module doc)."""

    solver: str
    mode: str
    promise: Promise = "exact"
    rows: list[VerdictRow] = field(default_factory=list)
    available: bool = True
    note: str = ""

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.rows)

    @property
    def solves(self) -> list[VerdictRow]:
        """The rows of solves the solver was handed (not comparisons, not skipped)."""
        return [r for r in self.rows if r.step >= 0 and r.status != "skipped"]

    @property
    def judged(self) -> list[VerdictRow]:
        """The solves that judged the solver itself: answers of its own (not the
        lifecycle's p = 0 where ubar <= 0) that the judge accepted (a row flagged for its
        iteration count alone may hold an answer the KKT test does not accept)."""
        return [r for r in self.solves if r.iterated and (r.status == "pass" or (
            r.status == "flagged" and math.isfinite(r.kkt_error) and r.kkt_error <= r.check_tol))]

    @property
    def limit_answers(self) -> list[VerdictRow]:
        """The solves of ``LIMIT_GROUP`` answered by the solver itself and not wrong: that
        group judges whether it keeps to its limit, and an unconverged answer at the limit
        is the answer it asks for (its rows are flagged where the limit was not kept)."""
        return [r for r in self.solves if r.group == LIMIT_GROUP and r.iterated
                and r.status in ("pass", "unconverged", "flagged")]

    @property
    def wrong(self) -> list[VerdictRow]:
        return [r for r in self.rows if r.status == "WRONG"]

    @property
    def untried_groups(self) -> list[str]:
        """The groups of the selection in which the solver was handed no solve, at least one
        of them skipped by its own skip, skip_params or memory model (module doc, coverage)."""
        steps = [r for r in self.rows if r.step >= 0]
        groups = [g for g in BATTERY_GROUPS if any(r.group == g for r in steps)]
        return [g for g in groups if all(r.status == "skipped" for r in steps if r.group == g)
                and any(r.own_skip for r in steps if r.group == g)]

    @property
    def unsolved(self) -> list[VerdictRow]:
        """Solves without a correct answer (besides WRONG ones): what no solver may leave
        (an unconverged answer at the limit of ``LIMIT_GROUP`` is the answer it asks for)."""
        return [r for r in self.solves if (r.status in UNSOLVED and not (r.status == "unconverged"
                and r.group == LIMIT_GROUP)) or (r.status == "refused" and r.group not in REFUSABLE_GROUPS)]

    def outcome(self, strict: bool = False) -> str:
        """"wrong", "strict" (only with ``strict``), "incomplete", "untested" or "conforms"
        (module doc)."""
        if self.wrong:
            return "wrong"
        if strict and any(r.status in STRICT_FAILING for r in self.rows):
            return "strict"
        if self.unsolved:
            return "incomplete"
        return "conforms" if (self.judged or self.limit_answers) and not self.untried_groups else "untested"

    @property
    def ok(self) -> bool:
        return self.outcome() == "conforms"

    def exit_code(self, strict: bool = False) -> int:
        return EXIT_CODES[self.outcome(strict)]

    def headline(self, strict: bool = False) -> str:
        solves, unsolved = len(self.solves), self.unsolved
        labels = ", ".join(r.label for r in unsolved)
        outcome = self.outcome(strict)
        if outcome == "wrong":
            return (f"WRONG: {len(self.wrong)} of {solves} solves wrong (a failing answer claimed as converged, "
                    f"or a write into the problem): {', '.join(r.label for r in self.wrong)}")
        if outcome == "strict":
            bad = [r.label for r in self.rows if r.status in STRICT_FAILING]
            return f"FAILS (--strict): {len(bad)} crashed, timed-out or flagged row(s): {', '.join(bad)}"
        if outcome == "incomplete":
            return f"INCOMPLETE: leaves {len(unsolved)} of {solves} solves unsolved: {labels}"
        untried = self.untried_groups
        if outcome == "untested" and untried:
            own = sum(r.own_skip for r in self.rows)
            groups = f"{len(untried)} groups" if len(untried) > 1 else "a group"
            return (f"UNTESTED: its own skip left {groups} of the battery untried ({', '.join(untried)}; "
                    f"{own} solves skipped by its own skip, skip_params or memory model, {len(self.judged)} of its "
                    "answers judged) -- a skip may narrow the battery, not choose it; --group names the groups to "
                    "validate")
        if outcome == "untested":
            return (f"UNTESTED: no answer of the solver's own was judged ({solves} solves) -- every selected case "
                    "skipped for a declared capability, refused where refusing is allowed, or answered without "
                    "calling the solver (ubar <= 0: p = 0)")
        flagged = [r for r in self.rows if r.status == "flagged"]
        if flagged:
            kinds = {k for r in flagged for k in r.flags.split("+") if k}
            why = " or ".join(FLAG_WORDS[k] for k in FLAG_WORDS if k in kinds) or "failing a conformance extra"
            accepted = all(math.isfinite(r.kkt_error) and r.kkt_error <= r.check_tol for r in flagged)
            return (f"CONFORMS to its promise ({promise_text(self.promise)}): {len(flagged)} of {len(self.rows)} "
                    f"rows flagged -- {'accepted by the KKT test, but ' if accepted else ''}{why}")
        limited = sum(r.status == "unconverged" and r.group == LIMIT_GROUP for r in self.solves)
        if limited == solves:
            return (f"CONFORMS: every solve stopped at the iteration limit of {LIMIT_GROUP} as asked ({limited} of "
                    f"{solves}), none claimed as converged -- that group judges the limit, not the answers")
        stopped = f", {limited} stopped at the limit of {LIMIT_GROUP} as asked" if limited else ""
        return (f"CONFORMS: every solve correct to its promise ({promise_text(self.promise)}; {solves - limited} of "
                f"{solves - limited}){stopped}")

    def summary(self, strict: bool = False) -> str:
        statuses = ("pass", "WRONG", "unconverged", "flagged", "refused", "crashed", "timeout", "skipped")
        counts = ", ".join(f"{s} {self.count(s)}" for s in statuses if self.count(s))
        return f"{self.solver} [{self.mode}]: {self.headline(strict)} (rows: {counts or 'none'})"

    def format(self, strict: bool = False) -> str:
        width = max([len(r.label) for r in self.rows] + [4])
        head = (f"{'case':{width}s} {'n':>5s} {'status':11s} {'claim':5s} {'kkt_error':>9s} {'err_ref':>9s} "
                f"{'iters':>6s} {'time_s':>7s}  note")
        promise = promise_text(self.promise)
        lines = [f"conformance of solver {self.solver!r} ({self.mode} battery, promise: {promise})"]
        if self.note:
            lines.append(self.note)
        lines += [head, "-" * len(head)]
        for r in self.rows:
            claim = "" if r.claimed is None else ("yes" if r.claimed else "no")
            it = "" if r.iterations is None else str(r.iterations)
            lines.append(f"{r.label:{width}s} {r.n:5d} {r.status:11s} {claim:5s} {_num(r.kkt_error)} "
                         f"{_num(r.p_rel_error)} {it:>6s} {_num(r.time_s, '7.3f')}  {r.message}")
        lines.append(self.summary(strict))
        return "\n".join(lines)

    def records(self, strict: bool = False) -> list[dict[str, Any]]:
        """One dict a row, keyed by ``record_columns`` (in that order), with the table's
        ``outcome`` under ``strict`` as the exit status reads it."""
        outcome, columns = self.outcome(strict), record_columns()
        out = []
        for r in self.rows:
            d = {**asdict(r), "label": r.label, "outcome": outcome}
            out.append({k: d[k] for k in columns})
        return out

    def to_frame(self, strict: bool = False) -> Any:
        import pandas as pd

        return pd.DataFrame(self.records(strict), columns=record_columns())


def record_columns() -> list[str]:
    """The columns of a verdict record (``VerdictTable.records``: the rows of validate's
    CSV files), in order: a row's fields but its KKT parts, its label, its table's outcome."""
    return [f.name for f in fields(VerdictRow) if f.name != "kkt"] + ["label", "outcome"]


def _num(x: float | None, fmt: str = "9.2e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return " " * int(fmt.split(".")[0])
    return format(x, fmt)


# ---------------------------------------------------------------------------
# validate / assert_conforms
# ---------------------------------------------------------------------------


def case_named(name: str, mode: str) -> ConformanceCase:
    """The case of the battery whose name (``str(case)``) is ``name``: of the ``mode``'s
    battery first, then of the other modes'; else a one-line ``ProblemInputError``."""
    for m in dict.fromkeys((mode, *DEFAULT_TIMEOUT)):
        found = [c for c in conformance_cases(m) if c.name == name] if m in DEFAULT_TIMEOUT else []
        if found:
            return found[0]
    raise ProblemInputError(f"no conformance case is named {name!r}; give a case of conformance_cases() "
                            "or its name (str(case), e.g. 'conditioning/bcc-n100-d1')")


def as_case(case: Any, mode: str) -> ConformanceCase:
    """A case as given: a ``ConformanceCase``, a stress ``InstanceSpec`` or a case's name
    (``case_named``); anything else is a one-line ``ProblemInputError`` naming what is
    accepted."""
    if isinstance(case, ConformanceCase):
        return case
    if isinstance(case, InstanceSpec):
        return ConformanceCase(case)
    if isinstance(case, str):
        return case_named(case, mode)
    raise ProblemInputError(f"a conformance case is a ConformanceCase (conformance_cases()), an InstanceSpec of the "
                            f"stress battery or a case's name, got {type(case).__name__} {case!r:.80}")


def _as_cases(cases: Iterable[ConformanceCase | InstanceSpec | str] | ConformanceCase | InstanceSpec | str | None,
              mode: str) -> list[ConformanceCase]:
    """The cases to run: the ``mode``'s battery, or ``cases`` (each as ``as_case`` reads
    it; one case alone, or its name, is a selection of one); ``ProblemInputError`` for an
    empty selection (a battery of no case would conform vacuously)."""
    if cases is None:
        return conformance_cases(mode)
    if isinstance(cases, (ConformanceCase, InstanceSpec, str)):
        cases = [cases]
    out = [as_case(c, mode) for c in cases]
    if not out:
        raise ProblemInputError("no conformance case was given (an empty selection: check its filter); "
                                "a battery of no case tests nothing")
    return out


def run_case(runner: CaseRunner, case: ConformanceCase, name: str, promise: Promise = "exact") -> list[VerdictRow]:
    """All verdict rows of one case (one per step, plus a comparison row)."""
    seq = build_battery_spec(case.spec)
    rows, ps, insts, refs = [], [], [], []
    for k in range(len(seq)):
        inst = seq.at(k)
        ref = cached_reference(case.spec, k, inst)
        out = runner.solve(case.spec, k, warm_start_of(case, k, inst), case.max_iter)
        rows.append(judge_solve(out, inst, ref, case, k, name, promise))
        ps.append(read_answer(out.p, inst.n)[0] if out.kind == "ok" else None)
        insts.append(inst)
        refs.append(ref)
    if case.compare == "units":
        rows.append(units_agreement(rows, case, name))
    elif case.compare == "perturbation" and all(r is not None for r in refs):
        rows.append(perturbation_check(rows, ps, insts, refs, case, name))
    return rows


def validate(solver: Solver | str, cases: Iterable[ConformanceCase | InstanceSpec | str] | str | None = None, *,
             mode: str = "fast", timeout: float | None = None, isolate: bool = True,
             progress: Callable[[VerdictRow], Any] | None = None,
             params: dict[str, Any] | None = None, label: str | None = None) -> VerdictTable:
    """Run ``solver`` (an instance, a registry name or ``module:NAME``) through the
    battery (default: the ``mode`` cases; else ``cases``, each a case or its name:
    ``as_case``) with its parameters ``params`` (checked against
    its declared ``Param``s first) and return the verdict table, its rows and summary
    named ``label`` (a variant's, ``name[k=v]``; default the solver's name).  ``timeout``: seconds
    per solve (``check_timeout``; None: the mode's default).  An empty ``cases`` is a
    ``ProblemInputError``.  A solver named by import path is loaded, with ``isolate``, only in
    child processes (``declared.in_a_child``, ``CaseRunner``: a ``declared.LoadFailed``
    where it cannot be), so that nothing its module does reaches the judge."""
    limit = DEFAULT_TIMEOUT.get(mode, 60.0) if timeout is None else check_timeout(timeout)
    selected = _as_cases(cases, mode)
    if isinstance(solver, str) and isolate and names_user_code(solver):  # loaded in children only (declared.py)
        d = in_a_child(declaration_of, solver, params, what=f"loading solver {solver!r}")
    else:
        solver = load_solver(solver)
        d = declaration_of(solver, params)
    name = label or d.name
    table = VerdictTable(name, mode, promise=d.promise)
    if not d.available:
        table.available, table.note = False, f"solver {d.name!r} is not available: {d.why}"
        return table
    runner = CaseRunner(solver, limit, isolate=isolate, params=params)
    try:
        for case in selected:
            new = run_case(runner, case, name, d.promise)
            table.rows.extend(new)
            if progress is not None:
                for r in new:
                    progress(r)
    finally:
        runner.close()
    return table


def assert_conforms(solver: Solver | str, cases: Iterable[ConformanceCase | InstanceSpec | str] | str | None = None, *,
                    mode: str = "fast", strict: bool = False, **kw: Any) -> VerdictTable:
    """For a user's pytest: raise AssertionError (with the table) unless ``solver``
    conforms -- a WRONG row, a case left unsolved, or nothing judged (``strict``: also crashes, timeouts
    and flagged rows)."""
    table = validate(solver, cases, mode=mode, **kw)
    if not table.available:
        raise AssertionError(table.note)
    if table.exit_code(strict):
        raise AssertionError(f"{table.solver}: {table.headline(strict)}\n{table.format(strict)}")
    return table


def left_out_lines(table: VerdictTable) -> list[str]:
    """The cases the solver was not handed (skipped solves), grouped by reason."""
    by_reason: dict[str, list[str]] = {}
    for r in table.rows:
        if r.status == "skipped" and r.step >= 0:
            by_reason.setdefault(r.message or "no reason given", []).append(r.label)
    if not by_reason:
        return []
    total = sum(len(v) for v in by_reason.values())
    lines = [f"left out {total} solve(s) of {table.solver!r}:"]
    lines += [f"  {len(labels)} because {reason}: {', '.join(labels)}" for reason, labels in by_reason.items()]
    return lines
