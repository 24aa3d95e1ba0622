"""Conformance check: run any solver through the stress battery and judge every answer.

``contactbench validate MODULE:NAME|NAME`` (``main``) and the Python API ``validate``
run a solver -- registered, or given by import path -- on every recipe of the stress
battery (``problems.scenes.stress``: conditioning, units, edge cases, random LCPs,
float32 input, perturbation).  Each answer is judged here, never by the solver:

* ``harness.kkt.kkt_check`` recomputes w = H p - ubar and the scaled KKT figures;
* the error ``||p - p_ref||_inf / ||p_ref||_inf`` against an exact reference that is
  computed here, independently of the registry (a judge must not be a contestant):
  the known solution where a recipe is built from one (near-touching points), else
  Lawson-Hanson NNLS (scipy) on the Cholesky factor of the dense H (H = L L',
  min 1/2 p'Hp - ubar'p = 1/2 ||L'p - L^{-1} ubar||^2 + const), polished by a solve
  on the support and block principal pivoting until the KKT error is at round-off.

Verdicts (one row per solve):

``pass``         the KKT error is within ``SLACK`` x the profile's check_tol and p is
                 within ``p_tolerance`` (a gross-error bound, at most 5 %) of the reference.
``WRONG``        the solver claimed convergence but the answer fails either test (or it
                 returned float32 p for float32 input) -- the one verdict that makes
                 ``validate`` exit non-zero.
``unconverged``  an honest failure: it failed and did not claim success.
``refused``      it raised ProblemInputError / MemoryBudgetError / NotImplementedError
                 (or, for float32 input, a ValueError/TypeError naming the dtype).
``crashed``      any other exception, or the worker process died.
``timeout``      no answer within the time limit (the worker is killed).
``skipped``      the solver cannot take the case (operator kind, max_n, unavailable).
``flagged``      a comparison row: unit systems disagree by more than 1e-8, or a
                 perturbation moved p by more than 10 cond(H) eps (chaotic active set).

Each solve runs in a forked worker (``harness.isolation.IsolatedWorker``) with a hard
wall-clock limit, so a hanging solver cannot hang ``validate``.

For pytest: ``conformance_cases()`` lists the recipes (parametrize over them) and
``assert_conforms(solver)`` raises AssertionError with the verdict table when a solver
returns a wrong answer while claiming success.
"""

from __future__ import annotations

import argparse
import fnmatch
import math
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np
from scipy.linalg import cho_factor, cho_solve, cholesky, solve_triangular
from scipy.optimize import nnls

from contactbench.problems.kkt import KKTReport, kkt_check, relative_error
from contactbench.problems.errors import MemoryBudgetError, ProblemInputError
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes.base import InstanceSpec
from contactbench.problems.scenes.stress import GROUPS, battery_specs, build_battery_spec, condition_number
from contactbench.solvers.base import Solver, SolverSettings

from .profiles import PROFILES
from contactbench.solvers.registry import all_solvers, load_solver

#: Tolerance multiplier between the profile's check_tol and the wrong-claim threshold.
SLACK = 10.0
#: Agreement required across unit systems (P/(E A) relative, scaled KKT figures absolute).
UNITS_AGREEMENT = 1e-8
#: A perturbation may move p by at most this many times cond(H) eps.
PERTURBATION_FACTOR = 10.0
#: Default per-solve time limits (s) by mode.
DEFAULT_TIMEOUT = {"fast": 20.0, "full": 60.0, "scene": 120.0}
#: Largest n the exact reference assembles densely.
REFERENCE_MAX_N = 4096

FAILING = ("WRONG",)
STRICT_FAILING = ("WRONG", "crashed", "timeout", "flagged")


# ---------------------------------------------------------------------------
# Cases
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ConformanceCase:
    """One battery recipe (an InstanceSpec of the stress scenes) with its verdict profile."""

    spec: InstanceSpec

    @property
    def name(self) -> str:
        return self.spec.instance

    @property
    def group(self) -> str:
        return str(self.spec.params["group"])

    @property
    def profile(self) -> str:
        return str(self.spec.params.get("profile", "mid"))

    @property
    def compare(self) -> str:
        return str(self.spec.params.get("compare", "none"))

    def __str__(self) -> str:
        return self.name


def conformance_cases(mode: str = "fast", groups: Sequence[str] | None = None,
                      pattern: str | None = None) -> list[ConformanceCase]:
    """The battery's recipes: ``mode`` "fast" (the test-suite subset, a few seconds per
    solver) or "full"; optionally only some ``groups`` or names matching ``pattern``
    (fnmatch, e.g. ``"edge/*"``)."""
    specs = battery_specs(mode, tuple(groups) if groups else GROUPS, scene="stress")
    cases = [ConformanceCase(s) for s in specs]
    if pattern:
        cases = [c for c in cases if fnmatch.fnmatch(c.name, pattern) or fnmatch.fnmatch(c.group, pattern)]
    return cases


# ---------------------------------------------------------------------------
# Exact reference
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Reference:
    """The exact solution of one instance and what it took to trust it."""

    p: np.ndarray
    kkt_error: float
    cond: float
    method: str


def _support_solve(H: np.ndarray, ubar: np.ndarray, support: np.ndarray) -> np.ndarray:
    """p with p_S = H_SS^{-1} ubar_S on the support S, zero elsewhere."""
    p = np.zeros_like(ubar)
    if support.any():
        S = np.flatnonzero(support)
        p[S] = cho_solve(cho_factor(H[np.ix_(S, S)]), ubar[S])
    return p


def block_principal_pivoting(H: np.ndarray, ubar: np.ndarray, support: np.ndarray, max_iter: int = 100) -> np.ndarray:
    """Refine a support guess into the exact LCP solution (Kostreva's block principal
    pivoting; Judice & Pires 1994): solve on the support, move every infeasible index
    across (p_i < 0 out, w_i < 0 in) -- with Murty's single least-index pivot after
    three non-improving block steps, which terminates for P-matrices."""
    S = support.copy()
    best, backup = np.inf, 3
    for _ in range(max_iter):
        p = _support_solve(H, ubar, S)
        w = H @ p - ubar
        scale = max(float(np.max(np.abs(ubar), initial=0.0)), 1e-300)
        bad = (S & (p < 0)) | (~S & (w < -1e-14 * scale))
        nbad = int(bad.sum())
        if nbad == 0:
            return np.maximum(p, 0.0)
        if nbad < best:
            best, backup = nbad, 3
            S = S ^ bad
        elif backup > 0:
            backup -= 1
            S = S ^ bad
        else:
            S[np.flatnonzero(bad)[-1]] ^= True
    return np.maximum(_support_solve(H, ubar, S), 0.0)


def exact_reference(inst: ContactInstance) -> Reference:
    """The exact solution of ``inst`` (see module doc); cond(H) is computed with it."""
    qp = inst.qp
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    cond = condition_number(qp.H) if qp.n <= REFERENCE_MAX_N else float("nan")
    if "p_exact" in inst.meta:
        p = np.asarray(inst.meta["p_exact"], dtype=np.float64)
        return Reference(p, kkt_check(qp, p).kkt_error, cond, "known solution")
    if qp.n > REFERENCE_MAX_N:
        raise MemoryBudgetError(f"exact reference for n = {qp.n} (dense limit {REFERENCE_MAX_N})",
                                8.0 * qp.n**2, 8.0 * REFERENCE_MAX_N**2)
    H = np.asarray(qp.H.to_dense(), dtype=np.float64)
    L = cholesky(H, lower=True)
    p, _ = nnls(L.T, solve_triangular(L, ubar, lower=True), maxiter=50 * max(qp.n, 10))
    p = block_principal_pivoting(H, ubar, p > 0)
    return Reference(p, kkt_check(qp, p).kkt_error, cond, "nnls+bpp")


_REFERENCES: dict[tuple[str, str, int], Reference] = {}


def cached_reference(spec: InstanceSpec, step: int, inst: ContactInstance) -> Reference:
    """References are deterministic per recipe: compute each once per process."""
    key = (spec.instance, spec.params_json(), step)
    if key not in _REFERENCES:
        _REFERENCES[key] = exact_reference(inst)
    return _REFERENCES[key]


# ---------------------------------------------------------------------------
# Running one solve (in a worker process)
# ---------------------------------------------------------------------------


@dataclass
class SolveOutcome:
    """What one solve produced, as seen from the parent process."""

    kind: str  # "ok", "raised", "timeout", "crashed", "skipped"
    p: np.ndarray | None = None
    converged: bool | None = None
    iterations: int | None = None
    solver_status: str = ""
    message: str = ""
    error_type: str = ""
    time_s: float = float("nan")


def operator_kind(qp: QP) -> str:
    return "dense" if isinstance(qp.H, DenseOperator) else "fft"


def adapt_to_solver(qp: QP, solver: Solver) -> QP | str:
    """The QP in a form the solver accepts, or the reason it cannot take it."""
    caps = solver.capabilities
    if caps.max_n is not None and qp.n > caps.max_n:
        return f"n = {qp.n} exceeds the solver's max_n = {caps.max_n}"
    if caps.needs_dense and qp.n > REFERENCE_MAX_N:
        return f"the solver needs dense H; n = {qp.n} is beyond the battery's dense limit {REFERENCE_MAX_N}"
    kind = operator_kind(qp)
    if kind in caps.operators:
        return qp
    if kind == "fft" and "dense" in caps.operators:
        return QP(DenseOperator(qp.H.to_dense()), qp.ubar, qp.geometry)
    return f"the solver accepts {'/'.join(sorted(caps.operators))} operators; this case has a {kind} operator"


def _is_refusal(exc: BaseException, group: str) -> bool:
    if isinstance(exc, (ProblemInputError, MemoryBudgetError, NotImplementedError)):
        return True
    text = str(exc).lower()
    return group == "precision" and isinstance(exc, (ValueError, TypeError)) and any(
        w in text for w in ("float32", "dtype", "precision", "single"))


def _solve_message(solver: Solver, msg: tuple[InstanceSpec, int, float | None]) -> dict[str, Any]:
    """Worker side: rebuild the instance from its recipe, solve, report plain data."""
    spec, step, time_limit = msg
    inst = build_battery_spec(spec).at(step)
    qp = adapt_to_solver(inst.qp, solver)
    if isinstance(qp, str):
        return {"kind": "skipped", "message": qp}
    settings = SolverSettings(tol=PROFILES[str(spec.params.get("profile", "mid"))].tol, time_limit=time_limit)
    t0 = time.perf_counter()
    try:
        res = solver.solve(qp, settings, None)
    except Exception as exc:  # a row, not a harness failure
        kind = "refused" if _is_refusal(exc, str(spec.params["group"])) else "raised"
        return {"kind": kind, "error_type": type(exc).__name__, "time_s": time.perf_counter() - t0,
                "message": f"{type(exc).__name__}: {exc}" + ("" if kind == "refused" else
                                                            "\n" + traceback.format_exc(limit=4))}
    elapsed = time.perf_counter() - t0
    return {"kind": "ok", "p": np.asarray(res.p), "converged": bool(res.converged), "iterations": int(res.iterations),
            "solver_status": str(res.status), "message": str(res.message), "time_s": elapsed}


class _SolverHandler:
    def __init__(self, solver: Solver) -> None:
        self.solver = solver

    def __call__(self, msg: Any) -> dict[str, Any]:
        return _solve_message(self.solver, msg)


class SolveRunner:
    """Runs solves of one solver with a hard time limit: in a forked worker
    (``harness.isolation``) when ``isolate``, else in-process (no limit)."""

    def __init__(self, solver: Solver, timeout: float | None, isolate: bool = True) -> None:
        self.solver, self.timeout, self.isolate = solver, timeout, isolate
        self.worker: Any = None
        if isolate:
            from contactbench.harness.isolation import IsolatedWorker

            self.worker = IsolatedWorker(lambda: _SolverHandler(solver))

    def solve(self, spec: InstanceSpec, step: int) -> SolveOutcome:
        msg = (spec, step, self.timeout)
        if self.worker is None:
            return _outcome_from_dict(_solve_message(self.solver, msg))
        out = self.worker.call(msg, self.timeout)
        if out.kind == "ok":
            return _outcome_from_dict(out.value)
        if out.kind == "timeout":
            return SolveOutcome("timeout", message=out.detail, time_s=out.elapsed)
        return SolveOutcome("crashed", message=out.detail, time_s=out.elapsed)

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()


def _outcome_from_dict(d: dict[str, Any]) -> SolveOutcome:
    kind = d["kind"]
    if kind == "refused":
        return SolveOutcome("refused", message=d["message"], error_type=d["error_type"], time_s=d["time_s"])
    if kind == "raised":
        return SolveOutcome("crashed", message=d["message"], error_type=d["error_type"], time_s=d["time_s"])
    if kind == "skipped":
        return SolveOutcome("skipped", message=d["message"])
    return SolveOutcome("ok", p=d["p"], converged=d["converged"], iterations=d["iterations"],
                        solver_status=d["solver_status"], message=d["message"], time_s=d["time_s"])


# ---------------------------------------------------------------------------
# Verdicts
# ---------------------------------------------------------------------------


@dataclass
class Verdict:
    """One row of the verdict table."""

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
    kkt: dict[str, float] = field(default_factory=dict)
    message: str = ""

    @property
    def label(self) -> str:
        return self.case if self.step < 0 else f"{self.case}@{self.step}"


def p_tolerance(cond: float, check_tol: float) -> float:
    """Allowed ||p - p_ref||_inf / ||p_ref||_inf: a gross-error check beside the KKT test.

    The scaled KKT error does not bound the error in p by cond * kkt where points are
    nearly degenerate (p_i and w_i both small: complementarity is quadratic there), so
    the bound uses sqrt(check_tol): clip(SLACK cond sqrt(check_tol), 1e-4, 0.05)."""
    c = cond if np.isfinite(cond) else 1e6
    return float(min(0.05, max(1e-4, SLACK * c * math.sqrt(check_tol))))


def judge(out: SolveOutcome, inst: ContactInstance, ref: Reference | None, case: ConformanceCase,
          step: int, solver: str) -> Verdict:
    """The verdict of one solve (see module doc)."""
    check_tol = PROFILES[case.profile].check_tol
    v = Verdict(solver, case.name, case.group, step, inst.n, out.kind, time_s=out.time_s, check_tol=check_tol,
                cond=ref.cond if ref else float("nan"), message=out.message.strip().splitlines()[0] if out.message else "")
    if out.kind != "ok":
        if out.kind == "crashed":
            v.message = out.message.strip()
        return v
    v.claimed, v.iterations = out.converged, out.iterations
    p = out.p
    problems: list[str] = []
    if p is None or p.shape != (inst.n,):
        problems.append(f"returned p of shape {None if p is None else p.shape}, expected ({inst.n},)")
        v.kkt_error = float("inf")
    else:
        rep: KKTReport = kkt_check(inst, p)
        v.kkt_error = rep.kkt_error
        v.kkt = {"primal": rep.primal, "dual": rep.dual, "complementarity": rep.complementarity,
                 "complementarity_sum": rep.complementarity_sum}
        if np.all(np.isfinite(p)):
            v.dim_load = inst.dimensionless_load(np.asarray(p, dtype=np.float64))
        if not rep.kkt_error <= SLACK * check_tol:
            problems.append(f"kkt_error {rep.kkt_error:.2e} > {SLACK:g} x check_tol {check_tol:.0e}")
        if ref is not None and np.all(np.isfinite(p)):
            v.p_rel_error = relative_error(p, ref.p)
            tol = p_tolerance(ref.cond, check_tol)
            if not v.p_rel_error <= tol:
                problems.append(f"p is {v.p_rel_error:.2e} off the exact reference (allowed {tol:.1e})")
        if p.dtype != np.float64:
            problems.append(f"returned {p.dtype} p (input ubar was {np.asarray(inst.qp.ubar).dtype})")
    if not problems:
        v.status = "pass"
        if not out.converged:
            v.message = "correct, though the solver did not claim convergence"
    else:
        v.status = "WRONG" if out.converged else "unconverged"
        v.message = "; ".join(problems) + (" -- while claiming convergence" if out.converged else "")
    return v


def units_agreement(rows: list[Verdict], case: ConformanceCase, solver: str) -> Verdict:
    """Do the scaled KKT figures and P/(E A) agree across the unit systems / moduli?"""
    v = Verdict(solver, case.name, case.group, -1, rows[0].n if rows else 0, "skipped",
                check_tol=UNITS_AGREEMENT)
    if not rows or any(r.status not in ("pass", "unconverged", "WRONG") for r in rows):
        v.message = "not every unit system produced an answer"
        return v
    loads = np.array([r.dim_load for r in rows])
    load_spread = float(np.ptp(loads) / max(np.max(np.abs(loads)), 1e-300))
    kkt_spread = max(float(np.ptp([r.kkt.get(k, np.nan) for r in rows])) for k in
                     ("primal", "dual", "complementarity", "complementarity_sum"))
    kkt_spread = max(kkt_spread, float(np.ptp([r.kkt_error for r in rows])))
    v.kkt_error, v.p_rel_error = kkt_spread, load_spread
    ok = load_spread <= UNITS_AGREEMENT and kkt_spread <= UNITS_AGREEMENT
    v.status = "pass" if ok else "flagged"
    v.message = (f"P/(EA) spread {load_spread:.1e}, scaled-KKT spread {kkt_spread:.1e} "
                 f"({'within' if ok else 'beyond'} {UNITS_AGREEMENT:g})")
    return v


def perturbation_check(rows: list[Verdict], ps: list[np.ndarray | None], insts: list[ContactInstance],
                       refs: list[Reference], case: ConformanceCase, solver: str) -> Verdict:
    """Does p move by at most ~cond eps when ubar moves by eps (relative, 2-norms)?"""
    v = Verdict(solver, case.name, case.group, -1, insts[0].n, "skipped", cond=refs[0].cond)
    if any(p is None for p in ps) or any(r.status not in ("pass", "unconverged", "WRONG") for r in rows):
        v.message = "not both solves produced an answer"
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
    ok = amplification <= PERTURBATION_FACTOR * refs[0].cond
    v.status = "pass" if ok else "flagged"
    v.message = (f"eps {eps:.0e}: p moved {move:.1e} (exact {ref_move:.1e}), amplification {amplification:.3g} "
                 f"vs cond {refs[0].cond:.3g}; active-set flips {flips} (exact {ref_flips})"
                 + ("" if ok else " -- chaotic"))
    return v


@dataclass
class VerdictTable:
    """All verdicts of one validation run."""

    solver: str
    mode: str
    rows: list[Verdict] = field(default_factory=list)
    available: bool = True
    note: str = ""

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.rows)

    @property
    def wrong(self) -> list[Verdict]:
        return [r for r in self.rows if r.status == "WRONG"]

    @property
    def ok(self) -> bool:
        return not self.wrong

    def exit_code(self, strict: bool = False) -> int:
        bad = STRICT_FAILING if strict else FAILING
        return 1 if any(r.status in bad for r in self.rows) else 0

    def summary(self) -> str:
        statuses = ("pass", "WRONG", "unconverged", "refused", "crashed", "timeout", "skipped", "flagged")
        counts = ", ".join(f"{s} {self.count(s)}" for s in statuses if self.count(s))
        verdict = "CONFORMS" if self.ok else f"FAILS: {len(self.wrong)} wrong answer(s) claimed as converged"
        return f"{self.solver} [{self.mode}]: {verdict} ({counts or 'no rows'})"

    def format(self, width: int = 70) -> str:
        head = f"{'case':44s} {'n':>5s} {'status':11s} {'claim':5s} {'kkt_error':>9s} {'err_ref':>9s} {'iters':>6s} {'time_s':>7s}  note"
        lines = [f"conformance of solver {self.solver!r} ({self.mode} battery)", head, "-" * len(head)]
        if self.note:
            lines.insert(1, self.note)
        for r in self.rows:
            claim = "" if r.claimed is None else ("yes" if r.claimed else "no")
            it = "" if r.iterations is None else str(r.iterations)
            msg = r.message.replace("\n", " ")
            lines.append(f"{r.label[:44]:44s} {r.n:5d} {r.status:11s} {claim:5s} {_num(r.kkt_error)} "
                         f"{_num(r.p_rel_error)} {it:>6s} {_num(r.time_s, '7.3f')}  {msg[:width]}")
        lines.append(self.summary())
        return "\n".join(lines)

    def records(self) -> list[dict[str, Any]]:
        out = []
        for r in self.rows:
            d = asdict(r)
            d.pop("kkt")
            d["label"] = r.label
            out.append(d)
        return out

    def to_frame(self) -> Any:
        import pandas as pd

        return pd.DataFrame(self.records())


def _num(x: float, fmt: str = "9.2e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return " " * int(fmt.split(".")[0])
    return format(x, fmt)


# ---------------------------------------------------------------------------
# validate / assert_conforms
# ---------------------------------------------------------------------------


def resolve_solver(solver: Solver | str) -> Solver:
    return load_solver(solver) if isinstance(solver, str) else solver


def _as_cases(cases: Iterable[ConformanceCase | InstanceSpec] | None, mode: str) -> list[ConformanceCase]:
    if cases is None:
        return conformance_cases(mode)
    return [c if isinstance(c, ConformanceCase) else ConformanceCase(c) for c in cases]


def run_case(runner: SolveRunner, case: ConformanceCase, name: str) -> list[Verdict]:
    """All verdict rows of one recipe (one per step, plus a comparison row)."""
    seq = build_battery_spec(case.spec)
    rows, ps, insts, refs = [], [], [], []
    for k in range(len(seq)):
        inst = seq.at(k)
        try:
            ref: Reference | None = cached_reference(case.spec, k, inst)
        except MemoryBudgetError:
            ref = None
        out = runner.solve(case.spec, k)
        rows.append(judge(out, inst, ref, case, k, name))
        ps.append(out.p if out.kind == "ok" else None)
        insts.append(inst)
        refs.append(ref)
    if case.compare == "units":
        rows.append(units_agreement(rows, case, name))
    elif case.compare == "perturbation" and all(r is not None for r in refs):
        rows.append(perturbation_check(rows, ps, insts, refs, case, name))
    return rows


def validate(solver: Solver | str, cases: Iterable[ConformanceCase | InstanceSpec] | None = None, *,
             mode: str = "fast", timeout: float | None = None, isolate: bool = True,
             progress: Any = None) -> VerdictTable:
    """Run ``solver`` (an instance, a registry name or ``module:NAME``) through the
    battery (default: the ``mode`` recipes) and return the verdict table."""
    s = resolve_solver(solver)
    table = VerdictTable(s.name, mode)
    available, why = s.availability()
    if not available:
        table.available, table.note = False, f"solver {s.name!r} is not available: {why}"
        return table
    limit = DEFAULT_TIMEOUT.get(mode, 60.0) if timeout is None else timeout
    runner = SolveRunner(s, limit, isolate=isolate)
    try:
        for case in _as_cases(cases, mode):
            new = run_case(runner, case, s.name)
            table.rows.extend(new)
            if progress is not None:
                for r in new:
                    progress(r)
    finally:
        runner.close()
    return table


def assert_conforms(solver: Solver | str, cases: Iterable[ConformanceCase | InstanceSpec] | None = None, *,
                    mode: str = "fast", strict: bool = False, **kw: Any) -> VerdictTable:
    """For a user's pytest: raise AssertionError (with the table) when ``solver``
    returns a wrong answer while claiming success (``strict``: also on crashes,
    timeouts and flagged comparisons)."""
    table = validate(solver, cases, mode=mode, **kw)
    if not table.available:
        raise AssertionError(table.note)
    if table.exit_code(strict):
        raise AssertionError("\n" + table.format())
    return table


# ---------------------------------------------------------------------------
# Command line: contactbench validate
# ---------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="contactbench validate",
        description="Run solvers through the stress battery and judge every answer with the KKT check. "
                    "Exit status 1 when a solver returns a wrong answer while claiming success.")
    ap.add_argument("solvers", nargs="*", help="registry names or import paths module:NAME")
    ap.add_argument("--all", action="store_true", help="every available registered solver")
    ap.add_argument("--full", action="store_true", help="the full battery (default: the fast subset)")
    ap.add_argument("--group", action="append", choices=GROUPS, help="only these groups (repeatable)")
    ap.add_argument("--cases", metavar="GLOB", help="only cases whose name matches, e.g. 'edge/*'")
    ap.add_argument("--timeout", type=float, help="seconds per solve (default: 20 fast, 60 full)")
    ap.add_argument("--strict", action="store_true", help="also fail on crashes, timeouts and flagged comparisons")
    ap.add_argument("--no-isolate", action="store_true", help="solve in-process (no time limit; for debugging)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--csv", metavar="PATH", help="also write the verdict rows as CSV")
    ap.add_argument("--quiet", action="store_true", help="print only the summary line per solver")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    """``contactbench validate``: 0 conforms, 1 wrong answers claimed as converged
    (or, with --strict, crashes/timeouts/flags), 2 usage error, 3 solver unavailable."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    mode = "full" if args.full else "fast"
    cases = conformance_cases(mode, args.group, args.cases)
    if args.list:
        for c in cases:
            print(f"{c.name:44s} group={c.group:13s} profile={c.profile}")
        return 0
    if not cases:
        print("no case matches the selection", file=sys.stderr)
        return 2
    names = list(args.solvers)
    if args.all:
        names += [n for n, s in all_solvers().items() if s.availability()[0] and n not in names]
    if not names:
        print("name a solver (registry name or module:NAME) or pass --all", file=sys.stderr)
        return 2
    code, unavailable, frames = 0, False, []
    for name in names:
        try:
            solver = load_solver(name)
        except (KeyError, ImportError, AttributeError, TypeError) as exc:
            print(f"cannot load solver {name!r}: {exc}", file=sys.stderr)
            return 2
        table = validate(solver, cases, mode=mode, timeout=args.timeout, isolate=not args.no_isolate)
        if not table.available:
            print(table.note, file=sys.stderr)
            unavailable = True
            continue
        print(table.summary() if args.quiet else table.format())
        print()
        code = max(code, table.exit_code(args.strict))
        frames.append(table.to_frame())
    if args.csv and frames:
        import pandas as pd

        pd.concat(frames, ignore_index=True).to_csv(args.csv, index=False)
    return code if code or not unavailable else 3


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
