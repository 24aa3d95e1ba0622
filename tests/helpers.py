"""What the test modules share (test modules never import each other).

* ``REPO``, ``TESTS``: the repository and the tests folder, wherever a test module lives;
* the throw-away solvers ``test-*`` (registered on import -- tests/conftest.py imports
  this module, and a ``contactbench run --solvers tests.helpers:NAME`` subprocess with
  the repository on ``PYTHONPATH`` registers them too) and ``DummySolver`` (not
  registered: tests register and unregister it);
* a fabricated tidy table for the report tests (``fabricate_table``, ``report_row``,
  ``trace_json``, ``write_out``);
* ``loop_context``: the solve context the tests hand a solver loop directly;
* ``top_step``: the paper's top displacement step on a small RMD surface.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import replace
import os
import time
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import pytest
from hypothesis import strategies as st
import scipy.linalg as sla
from scipy.optimize import nnls

from contactbench.harness.report.style import FAMILY_SLOTS
from contactbench.harness.table.schema import ALL_COLUMNS
from contactbench.problems.instances import QP, ContactInstance, InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import spectral_norm_estimate
from contactbench.problems.operators_gpu import ArrayFFTOperator, ArrayKernelTransform
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import Capabilities, Outcome, Param, ProblemTraits, SolveContext, Solver, register
from contactbench.solvers.base import Deadline, SolveAborted, Trace
from contactbench.solvers.registry import get_solver
from contactbench.harness.cli import main as cli_main

TESTS = Path(__file__).resolve().parent
REPO = TESTS.parent


# ---------------------------------------------------------------------------
# Throw-away solvers
# ---------------------------------------------------------------------------


class DummySolver(Solver):
    """Clips ubar at zero (exact for H = I); dense only; not registered on import."""

    name = "test-dummy"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), exact=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(p=np.maximum(ctx.qp.ubar, 0.0), iterations=1, converged=True)


def dense_exact_solution(qp: QP) -> np.ndarray:
    """scipy's NNLS on the Cholesky factor: with H = L L', 1/2 p'Hp - ubar'p =
    1/2 ||L'p - L^-1 ubar||^2 + const, so the QP is an NNLS problem (exact)."""
    H = qp.H.to_dense()
    L = np.linalg.cholesky(H)
    b = sla.solve_triangular(L, qp.ubar, lower=True)
    p, _ = nnls(L.T, b, maxiter=50 * qp.n)
    return p


@register(replace=True)
class ExactStub(Solver):
    """Dense exact reference (scipy NNLS on the Cholesky factor); no warm start."""

    name = "test-exact"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True, exact=True, input_format="dense")
    params = (Param("sleep", float, 0.0, "seconds to sleep before solving", low=0.0),)

    def iterate(self, ctx: SolveContext) -> Outcome:
        if ctx.params["sleep"]:
            time.sleep(ctx.params["sleep"])
        return Outcome(dense_exact_solution(ctx.qp), 1, True, "scipy NNLS on the Cholesky factor")


@register(replace=True)
class SleepyStub(ExactStub):
    """The exact solver, slowed down (0.15 s per solve) so a run can be killed mid-way."""

    name = "test-sleepy"

    def iterate(self, ctx: SolveContext) -> Outcome:
        time.sleep(0.15)
        return super().iterate(ctx)


class HangingStub(ExactStub):
    """The exact solver, hanging for five minutes: a run can only end it by killing it."""

    name = "test-hanging"

    def iterate(self, ctx: SolveContext) -> Outcome:
        time.sleep(300.0)
        return super().iterate(ctx)


@register(replace=True)
class WarmPGStub(Solver):
    """Matrix-free projected gradient (Nesterov-accelerated, restart on increase),
    primal warm start; info["warm_given"] says whether a warm start arrived."""

    name = "test-warm-pg"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), warm_start="primal")

    def iterate(self, ctx: SolveContext) -> Outcome:
        qp = ctx.qp
        L = spectral_norm_estimate(qp.H, iters=50)
        p = np.zeros(qp.n) if ctx.p0 is None else ctx.p0
        y, p_old, t = p.copy(), p.copy(), 1.0
        it = 0
        for it in range(1, ctx.max_iter + 1):
            g = qp.H.matvec(y) - qp.ubar
            p = np.maximum(y - g / L, 0.0)
            t_new = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
            y = p + (t - 1) / t_new * (p - p_old)
            p_old, t = p, t_new
            if it % 10 == 0:
                res = ctx.kkt(p, qp.H.matvec(p) - qp.ubar)
                ctx.record(it, res)
                if res <= 0.1 * ctx.tol:
                    break
        w = qp.H.matvec(p) - qp.ubar
        return Outcome(p, it, ctx.kkt(p, w) <= ctx.tol, w=w, info={"warm_given": ctx.p0 is not None})

    def default_max_iter(self, n: int) -> int:
        return 20000


@register(replace=True)
class CrashStub(Solver):
    """Aborts the process (a segfault stand-in)."""

    name = "test-crash"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        os.abort()


@register(replace=True)
class HangStub(Solver):
    """Never returns."""

    name = "test-hang"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        time.sleep(3600)
        raise AssertionError("unreachable")


@register(replace=True)
class RaiseStub(Solver):
    """Raises."""

    name = "test-raise"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise RuntimeError("deliberate failure in test-raise")


@register(replace=True)
class ForgedAbortStub(Solver):
    """Raises a ``SolveAborted`` whose status it set to "solved" after building it."""

    name = "test-forged-abort"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        exc = SolveAborted("crashed", "forged status")
        exc.status = "solved"
        raise exc


class OwnExitStub(Solver):
    """Raises ``raised`` from its own code: an exception that is not an Exception (no Ctrl-C
    was pressed, nothing called os._exit)."""

    family = "test"
    raised: ClassVar[type[BaseException]] = KeyboardInterrupt

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise self.raised(3) if self.raised is SystemExit else self.raised()


@register(replace=True)
class InterruptStub(OwnExitStub):
    name = "test-interrupt"


@register(replace=True)
class ExitStub(OwnExitStub):
    name = "test-exit"
    raised = SystemExit


@register(replace=True)
class GeneratorExitStub(OwnExitStub):
    name = "test-generator-exit"
    raised = GeneratorExit


@register(replace=True)
class BuggySkipStub(ExactStub):
    """The exact solver whose own ``skip`` raises: a defect of the solver, not a capability."""

    name = "test-buggy-skip"
    capabilities = replace(ExactStub.capabilities, exact=False)  # not in the exact solvers' battery

    def skip(self, traits: ProblemTraits) -> str | None:
        raise RuntimeError("a bug in skip")


@register(replace=True)
class SkipExitStub(BuggySkipStub):
    """Its ``skip`` calls sys.exit: a fault of the solver, not the end of the run."""

    name = "test-skip-exit"

    def skip(self, traits: ProblemTraits) -> str | None:
        raise SystemExit(2)


@register(replace=True)
class TimeModelRaiseStub(BuggySkipStub):
    """Its time model raises (its ``skip`` is the base's)."""

    name = "test-time-raise"

    def skip(self, traits: ProblemTraits) -> str | None:
        return None

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        raise RuntimeError("a bug in the time model")


@register(replace=True)
class TinyStub(ExactStub):
    """Dense-only with a hard size limit of 10 unknowns."""

    name = "test-tiny"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True, exact=True, max_n=10)


@register(replace=True)
class SlowModelStub(ExactStub):
    """Its time model predicts a day per solve."""

    name = "test-slow-model"

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 86400.0


@register(replace=True)
class PessimistStub(ExactStub):
    """Its static time model is hopeless beyond 3 unknowns (it cannot know it is fast)."""

    name = "test-pessimist"

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 86400.0 if n > 3 else 0.0


@register(replace=True)
class MissingStub(ExactStub):
    """Reports its backend as not installed."""

    name = "test-missing"

    def availability(self) -> tuple[bool, str]:
        return False, "package 'nonexistent-backend' is not installed"


# ---------------------------------------------------------------------------
# A fabricated tidy table for the report tests
# ---------------------------------------------------------------------------


# Time factors against NNLS+GP in the fabricated paper-sweep (the paper's claims).
SWEEP_FACTORS = {"nnls-gp": 1.0, "nnls": 3.0, "pk": 26.0, "greedy-cg": 100.0, "admm": 90.0, "fast-pdas": 0.25}


def top_step(N: int, kernel: str = "bcc", periodic: bool = False, seed: int = 2) -> ContactInstance:
    """The paper's top displacement step on an N^2 RMD surface (H 0.7, L = 100 um, E* = 1 GPa)."""
    s = rmd_surface_n(N, 0.7, length=100e-6, seed=seed)
    return InstanceBuilder(s, 1e9, kernel, periodic=periodic).build(paper_max_displacement(s))


def loop_context(qp: QP, max_iter: int = 400, tol: float = 1e-9, p0: np.ndarray | None = None) -> SolveContext:
    """A context for calling a solver loop (``_ccg.bugnicourt`` and the like) directly: no
    deadline, a fresh trace, ``diag_max`` from H's diagonal."""
    return SolveContext(qp=qp, tol=tol, max_iter=max_iter, params={}, p0=p0, warm=None, deadline=Deadline(None),
                        trace=Trace(), diag_max=float(np.max(qp.H.diagonal())))


def pcg_iterations(H: np.ndarray, b: np.ndarray, prec, tol: float = 1e-10, max_iter: int = 400) -> int:
    """Preconditioned CG iterations on the dense SPD system H x = b from 0 until the
    residual's 2-norm falls by ``tol`` (``prec``: r -> z); ``max_iter`` where it does not."""
    x, r = np.zeros_like(b), b.copy()
    z = prec(r)
    d, rz = z.copy(), r @ z
    for it in range(1, max_iter):
        q = H @ d
        a = rz / (d @ q)
        x += a * d
        r -= a * q
        if np.linalg.norm(r) <= tol * np.linalg.norm(b):
            return it
        z = prec(r)
        rz, rz_old = r @ z, rz
        d = z + (rz / rz_old) * d
    return max_iter


def report_row(**kw: Any) -> dict[str, Any]:
    """One judged row with every schema column: plausible defaults, ``kw`` on top; a
    skipped row has no figures, and ``correct_claim`` follows status and claim."""
    row: dict[str, Any] = {c: np.nan for c in ALL_COLUMNS}
    row.update(
        instance="i0", step=0, repeat=0, warm_start=False, status="solved", skip_reason="", profile="default",
        build_time_s=0.01, iterations=10, primal_residual=0.0, dual_residual=1e-12, complementarity=1e-12,
        kkt_error=1e-10, load=1.0, load_rel_error=1e-12, p_rel_error=1e-11, contact_fraction=0.1,
        peak_mem_mb=50.0, params="{}", family="paper", solver_status="converged", solver_converged=True,
        solver_message="", check_tol=1e-8, time_limit_s=60.0, error="", trace="[]", kernel="bcc",
        periodic=False, operator="fft", reference_solver="nnls", host="synthetic", timestamp="2025-01-01T00:00:00",
    )
    row.update(kw)
    row.setdefault("base_solver", row["solver"])
    if row["base_solver"] != row["base_solver"]:
        row["base_solver"] = row["solver"]
    if row["status"] == "skipped":
        for c in ("solve_time_s", "iterations", "kkt_error", "p_rel_error", "load_rel_error", "primal_residual",
                  "dual_residual", "complementarity", "load", "contact_fraction", "peak_mem_mb"):
            row[c] = np.nan
        row["solver_converged"] = None
        row["solver_status"] = ""
    row["correct_claim"] = (None if row["solver_converged"] is None
                            else bool(row["solver_converged"]) == (row["status"] == "solved"))
    return row


def trace_json(total: float, iters: int = 12) -> str:
    """A stored convergence trace: ``iters`` points up to ``total`` seconds, the residual
    falling ten decades."""
    its = np.arange(1, iters + 1)
    return json.dumps([[int(i), total * i / iters, float(10.0 ** (-i * 10 / iters))] for i in its])


def fabricate_table(seed: int = 0) -> pd.DataFrame:
    """A small plausible results table with every schema column: paper-sweep,
    greedy-linear-solvers, gp-k-sweep, counterexample and hertz rows, with skips, a
    timeout, a crash, inaccurate answers, false claims and traces.  Timings follow simple
    models (stated inline) so a report's computed ratios can be checked against values
    recomputed from the same table."""
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    # paper-sweep: 10 steps, n grows, t = f * 2e-3 * (n/1000)^1.3 (pk's and fast's warm start).
    for prof, tol in (("high", 1e-8), ("default", 1e-6)):
        for k in range(10):
            n = int(300 * (k + 1) ** 1.2)
            dim_load = 1e-4 * 10 ** (k * 2.2 / 9)
            for s, f in SWEEP_FACTORS.items():
                t = f * 2e-3 * (n / 1000) ** 1.3
                kw: dict[str, Any] = dict(scene="paper-sweep", instance="rmd-H0.7-N64-s0", step=k, n=n, N=64,
                                          surface_family="rmd", hurst=0.7, seed=0,
                                          delta=1e-7 * (k + 1), solver=s, profile=prof, check_tol=tol,
                                          solve_time_s=t, dim_load=dim_load, load=dim_load * 1e-8,
                                          warm_start=(k > 0 and s in ("pk", "nnls-gp", "fast-pdas")),
                                          iterations=int(20 * f), trace=trace_json(t),
                                          kkt_error=tol * 10 ** rng.uniform(-3, -0.5),
                                          p_rel_error=tol * 10 ** rng.uniform(-2, 0.5),
                                          family="fast" if s.startswith("fast") else "paper")
                if s == "admm" and prof == "default" and k == 4:
                    kw.update(status="inaccurate", kkt_error=3e-4, p_rel_error=2e-3, solver_converged=True)
                rows.append(report_row(**kw))
    # greedy-linear-solvers: time ratios chol/cg = 0.65, gs/cg = 3.0; chol skipped at the largest n.
    for n in (100, 400, 1600, 6400, 25600):
        tcg = 1e-4 * (n / 100) ** 1.5
        for s, f in (("greedy-cg", 1.0), ("greedy-gs", 3.0), ("greedy-chol", 0.65)):
            kw = dict(scene="greedy-linear-solvers", instance=f"n{n}", n=n, N=int(np.sqrt(n)) * 2, solver=s,
                      solve_time_s=tcg * f * (1 + 0.02 * rng.standard_normal()), dim_load=1e-3)
            if s == "greedy-chol" and n == 25600:
                kw.update(status="skipped", skip_reason="dense submatrix needs 4.9 GiB, over the budget of 4 GiB")
            rows.append(report_row(**kw))
    # gp-k-sweep: total = nnls(K) + gp(K), nnls part falls until K = 100.
    for K in (0, 25, 50, 100, 150, 200):
        for k in range(4):
            n = 400 * (k + 1)
            t = (1e-3 * (n / 400)) * (1 + 3 * max(0.0, 1 - K / 100) ** 2) + 2e-6 * K * (n / 400)
            rows.append(report_row(scene="gp-k-sweep", instance="rmd-H0.7-N64-s0", step=k, n=n, N=64,
                                   surface_family="rmd",
                             solver=f"nnls-gp[K={K}]", base_solver="nnls-gp", params=json.dumps({"K": K}),
                             solve_time_s=t, dim_load=1e-4 * 3 ** k, warm_start=k > 0))
    # counterexample: greedy-cg violates with the independent implementation's rates;
    # osqp sometimes claims convergence wrongly; seed 1 at n = 100 always fails for greedy.
    rates = {25: 0.14, 100: 0.36, 400: 0.52}
    for n, rate in rates.items():
        for seed_ in range(20):
            inst = f"n{n}-s{seed_}"
            for s in ("greedy-cg", "nnls", "osqp"):
                kw = dict(scene="counterexample", instance=inst, n=n, N=int(np.sqrt(n)), solver=s, operator="dense",
                          solve_time_s=1e-5 * n * (3 if s == "osqp" else 1), family="qp" if s == "osqp" else "paper",
                          delta=np.nan)
                bad = (s == "greedy-cg" and (rng.random() < rate or (n == 100 and seed_ == 1))) or \
                      (s == "osqp" and seed_ % 7 == 3)
                if bad:
                    kw.update(status="inaccurate", kkt_error=0.05, p_rel_error=0.2, solver_converged=True)
                rows.append(report_row(**kw))
    # hertz: load error ~ 0.5/N (first order); a crashing and a timing-out solver.
    for N in (16, 32, 64, 128):
        for s in ("nnls", "pk"):
            rows.append(report_row(scene="hertz", instance=f"N{N}-bcc", n=int(0.2 * N * N), N=N, solver=s,
                             solve_time_s=1e-5 * N * N, analytic_load_rel_error=0.5 / N * (1.01 if s == "pk" else 1),
                             dim_load=1e-3))
        rows.append(report_row(scene="hertz", instance=f"N{N}-bcc", n=int(0.2 * N * N), N=N, solver="broken",
                         status="crashed" if N < 64 else "timeout", solve_time_s=np.nan if N < 64 else 60.0,
                         kkt_error=np.nan, p_rel_error=np.nan, load_rel_error=np.nan, iterations=np.nan,
                         solver_converged=None, error="solver process died with signal 6 (SIGABRT)" if N < 64
                         else "no answer within the 60 s limit", family="test", solver_status=""))
    # a repeat, to check folding
    rows.append(report_row(**{**{k: v for k, v in rows[0].items() if k != "correct_claim"}, "repeat": 1,
                        "solve_time_s": rows[0]["solve_time_s"] * 1.3}))
    df = pd.DataFrame(rows, columns=list(ALL_COLUMNS))
    return df


# the shape harness/table/meta.py writes
META = {"suite": "synthetic", "date": "2025-01-01T00:00:00+00:00", "command": ["contactbench", "run", "all"],
        "git": {"commit": "0123abc", "dirty": False},
        "machine": {"host": "h", "platform": "Linux", "python": "3.11", "cpu": "Synthetic CPU 9000",
                    "logical_cores": 2, "physical_cores": 1},
        "threads": {"env": {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": None},
                    "threadpools": [{"user_api": "blas", "internal_api": "openblas", "num_threads": 1}],
                    "fft_workers": 1},
        "packages": {"numpy": "2.x", "scipy": "1.x"}, "warnings": []}


def every_solver_table() -> pd.DataFrame:
    """``fabricate_table`` with every solver of the project run in the paper sweep (the rows
    of ``fast-pdas`` under each one's name and family, ``style.FAMILY_SLOTS``, each a little
    slower than the last): families of up to 14 solvers, so the figures split into family
    panels with the other families in grey."""
    df = fabricate_table()
    sweep = df[(df["scene"] == "paper-sweep") & (df["solver"] == "fast-pdas")]
    extra = [sweep.assign(solver=s, base_solver=s, family=f, solve_time_s=sweep["solve_time_s"] * (1.0 + 0.37 * i))
             for f, names in FAMILY_SLOTS.items() for i, s in enumerate(names)
             if s not in set(df.loc[df["scene"] == "paper-sweep", "solver"])]
    return pd.concat([df, *extra], ignore_index=True)


def write_out(tmp: Path, df: pd.DataFrame, meta: dict | None = META, fmt: str = "parquet") -> Path:
    """``tmp`` as a results folder: the table (parquet or csv) and ``meta`` as meta.json."""
    tmp.mkdir(parents=True, exist_ok=True)
    if fmt == "parquet":
        df.to_parquet(tmp / "results.parquet", index=False)
    else:
        df.to_csv(tmp / "results.csv", index=False)
    if meta is not None:
        (tmp / "meta.json").write_text(json.dumps(meta))
    return tmp


def run_cli(args: list[str], capsys: Any) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``contactbench ARGS`` run in this process
    (``capsys``: pytest's capture fixture)."""
    try:
        rc = cli_main(args)
    except SystemExit as exc:  # argparse: --version, --help and usage errors
        rc = int(exc.code or 0)
    out, err = capsys.readouterr()
    return rc, out, err


def on_space(builder: Any, qp: QP, space: Any) -> QP:
    """``qp`` with its products in the array ``space`` (an ``ArraySpace``, or a name:
    "numpy", "cupy"), the kernel of ``builder`` (an ``InstanceBuilder``): the device path."""
    op = ArrayFFTOperator(ArrayKernelTransform.from_host(builder.transform, space), qp.geometry.indices,
                          auto_dense=False)
    return QP(op, qp.ubar, qp.geometry, qp.constraints)


def drawn_options(data: Any, name: str) -> dict[str, object]:
    """One value of each option solver ``name`` declares with a list of choices, drawn by a
    hypothesis ``DataObject``; none (the defaults) when ``data`` is None (an ``@example``)."""
    if data is None:
        return {}
    return {p.name: data.draw(st.sampled_from(p.choices), label=f"{name}.{p.name}")
            for p in get_solver(name).params if p.choices}


def refused_in_one_line(argv: list[str], capsys: Any) -> str:
    """The one stderr line of ``contactbench validate ARGV`` refusing its input (exit 2,
    nothing on stdout, no traceback)."""
    from contactbench.harness.conformance.command import main as validate_main

    assert validate_main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("contactbench validate: error: "), captured.err
    assert "Traceback" not in captured.err and not captured.out
    return lines[0]


def process_gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (gone, or a zombie waiting to be reaped; Linux /proc)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def compile_c(source: Path, out: Path, *flags: str, what: str) -> Path:
    """``source`` built into ``out`` by the system C compiler, ``flags`` after it (pytest skips,
    naming ``what``, where there is no compiler)."""
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip(f"no C compiler (cc, gcc or clang) on PATH: {what} cannot be built")
    subprocess.run([cc, "-O2", "-o", str(out), str(source), *flags], check=True, capture_output=True)
    return out
