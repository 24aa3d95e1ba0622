"""Throw-away solvers for the harness tests (registered only when this module is
imported: by the harness tests, or by a ``contactbench run --solvers
test_harness_solvers:NAME`` subprocess with tests/ on PYTHONPATH), plus checks that
the two honest ones are right -- the harness tests rely on them."""

from __future__ import annotations

import os
import time

import numpy as np
import scipy.linalg as sla
from scipy.optimize import nnls

from contactbench.problems.kkt import kkt_check
from contactbench.problems.instances import QP, counterexample
from contactbench.problems.operators import spectral_norm_estimate
from contactbench.solvers import Capabilities, Outcome, Param, SolveContext, Solver, SolverSettings, register


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


def test_exact_solver_is_exact_on_the_counterexample() -> None:
    inst = counterexample(25, seed=1)
    p = ExactStub().solve(inst.qp, SolverSettings()).p
    assert kkt_check(inst, p).kkt_error < 1e-10


def test_warm_pg_reaches_the_exact_answer() -> None:
    inst = counterexample(16, seed=2)
    res = WarmPGStub().solve(inst.qp, SolverSettings(tol=1e-9))
    p_ref = dense_exact_solution(inst.qp)
    assert np.max(np.abs(res.p - p_ref)) <= 1e-6 * np.max(p_ref)
