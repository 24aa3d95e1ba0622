"""The conformance check catches wrong solvers and passes correct ones (issue 9)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.linalg import cholesky, solve_triangular
from scipy.optimize import nnls

from contactbench.harness import conformance as cf
from contactbench.problems.kkt import kkt_check
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP
from contactbench.solvers.base import Capabilities, Solver, SolveResult
from contactbench.solvers.registry import all_solvers, register, unregister


def chol_nnls(H: np.ndarray, ubar: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    """min 1/2 p'Hp - ubar'p, p >= 0 as NNLS on the Cholesky factor (computed in ``dtype``)."""
    H, ubar = H.astype(dtype), ubar.astype(dtype)
    L = cholesky(H, lower=True)
    p, _ = nnls(L.T, solve_triangular(L, ubar, lower=True), maxiter=50 * ubar.size + 50)
    return p.astype(dtype)


class GoodSolver(Solver):
    """Correct: NNLS on the Cholesky factor of the dense H, in float64."""

    name = "test-conf-good"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True)

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        p = chol_nnls(qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64))
        return SolveResult(p=p, converged=True, status="solved", iterations=1)


class ClipSolver(Solver):
    """Wrong: unconstrained solve, then p clipped at 0 -- and claims success."""

    name = "test-conf-clip"
    family = "test"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        p = np.linalg.solve(qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64))
        return SolveResult(p=np.maximum(p, 0.0), converged=True, status="solved")


class GreedySolver(Solver):
    """Wrong: the greedy active-set loop of paper section 3 (solve on the set, drop the
    negative entries, never re-admit) -- claims success (paper Example 1 refutes it)."""

    name = "test-conf-greedy"
    family = "test"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        H, u = qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64)
        S = np.arange(u.size)
        p = np.zeros_like(u)
        for it in range(u.size + 1):
            x = np.linalg.solve(H[np.ix_(S, S)], u[S]) if S.size else np.zeros(0)
            if np.all(x >= 0):
                break
            S = S[x >= 0]
        p[S] = x
        return SolveResult(p=p, converged=True, status="solved", iterations=it + 1)


class Float32Solver(Solver):
    """Wrong: silently computes in the input's float32 and claims success."""

    name = "test-conf-f32"
    family = "test"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        dtype = np.asarray(qp.ubar).dtype
        return SolveResult(p=chol_nnls(qp.H.to_dense(), np.asarray(qp.ubar), dtype=dtype), converged=True)


class RefuseFloat32Solver(GoodSolver):
    """Correct: refuses float32 input with a clear message."""

    name = "test-conf-refuse32"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        if np.asarray(qp.ubar).dtype != np.float64:
            raise ProblemInputError(f"ubar must be float64, got {np.asarray(qp.ubar).dtype}")
        return super().solve(qp, settings, warm)


class AbsoluteThresholdSolver(GoodSolver):
    """Unit-dependent: drops every force below 5e-3 in whatever unit it is given (some in N, none in uN)."""

    name = "test-conf-abs"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        res = super().solve(qp, settings, warm)
        res.p = np.where(res.p < 5e-3, 0.0, res.p)
        return res


class HangingSolver(Solver):
    name = "test-conf-hang"
    family = "test"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        time.sleep(60)
        return SolveResult(p=np.zeros(qp.n), converged=True)


class CrashingSolver(Solver):
    name = "test-conf-crash"
    family = "test"

    def solve(self, qp: QP, settings, warm=None) -> SolveResult:
        raise RuntimeError("boom")


def cases(pattern: str) -> list[cf.ConformanceCase]:
    out = cf.conformance_cases("fast", pattern=pattern)
    assert out, pattern
    return out


def test_correct_solver_conforms_on_the_whole_fast_battery() -> None:
    table = cf.validate(GoodSolver())
    assert table.exit_code(strict=True) == 0, table.format()
    assert table.count("pass") == len(table.rows)
    groups = {r.group for r in table.rows}
    assert groups == set(cf.GROUPS)
    cf.assert_conforms(GoodSolver())


def test_clipping_solver_is_caught() -> None:
    table = cf.validate(ClipSolver(), cases("random"))
    assert table.exit_code() == 1
    assert table.wrong and all(r.claimed for r in table.wrong)
    with pytest.raises(AssertionError, match="WRONG"):
        cf.assert_conforms(ClipSolver(), cases("random"))


def test_greedy_false_claim_on_the_counterexample_family_is_caught() -> None:
    table = cf.validate(GreedySolver(), cases("random/bcc-*"))
    assert table.exit_code() == 1, table.format()
    w = table.wrong[0]
    assert w.kkt_error > 10 * w.check_tol and "claiming convergence" in w.message


def test_cli_exit_codes_by_name_and_import_path(capsys: pytest.CaptureFixture[str]) -> None:
    register(ClipSolver, replace=True)
    register(GoodSolver, replace=True)
    try:
        assert cf.main(["test-conf-clip", "--cases", "random/bcc-*"]) == 1
        assert cf.main([f"{__name__}:GoodSolver", "--cases", "random/bcc-*"]) == 0
        out = capsys.readouterr().out
        assert "WRONG" in out and "CONFORMS" in out and "kkt_error" in out
    finally:
        unregister("test-conf-clip")
        unregister("test-conf-good")
    assert cf.main(["no-such-solver"]) == 2
    assert cf.main(["--list"]) == 0
    assert cf.main(["test-x", "--cases", "no-such-case*"]) == 2


def test_hanging_solver_times_out_without_hanging_validate() -> None:
    t0 = time.perf_counter()
    table = cf.validate(HangingSolver(), cases("edge/single-point*"), timeout=1.0)
    assert [r.status for r in table.rows] == ["timeout"]
    assert time.perf_counter() - t0 < 30
    assert table.exit_code() == 0 and table.exit_code(strict=True) == 1


def test_crash_is_reported_not_hidden() -> None:
    table = cf.validate(CrashingSolver(), cases("edge/single-point*"))
    assert table.rows[0].status == "crashed" and "boom" in table.rows[0].message
    assert table.exit_code() == 0 and table.exit_code(strict=True) == 1


def test_float32_is_solved_in_float64_refused_or_caught() -> None:
    prec = cases("precision")
    assert cf.validate(GoodSolver(), prec).rows[0].status == "pass"
    refused = cf.validate(RefuseFloat32Solver(), prec).rows[0]
    assert refused.status == "refused" and "float32" in refused.message
    silent = cf.validate(Float32Solver(), prec)
    assert silent.rows[0].status == "WRONG" and silent.exit_code() == 1
    assert "float32" in silent.rows[0].message


def test_unit_dependent_solver_is_flagged_across_unit_systems() -> None:
    good = cf.validate(GoodSolver(), cases("units/unit-systems*"))
    agreement = [r for r in good.rows if r.step < 0]
    assert agreement and agreement[0].status == "pass"
    assert agreement[0].p_rel_error <= cf.UNITS_AGREEMENT
    bad = cf.validate(AbsoluteThresholdSolver(), cases("units/unit-systems*"))
    row = [r for r in bad.rows if r.step < 0][0]
    assert row.status == "flagged" and row.p_rel_error > cf.UNITS_AGREEMENT


def test_perturbation_check_flags_a_solver_that_jumps() -> None:
    case = cases("perturbation")[0]
    seq = cf.build_battery_spec(case.spec)
    insts = [seq.at(0), seq.at(1)]
    refs = [cf.exact_reference(i) for i in insts]
    rows = [cf.Verdict("x", case.name, case.group, k, insts[k].n, "pass", kkt_error=0.0) for k in range(2)]
    calm = cf.perturbation_check(rows, [refs[0].p, refs[1].p], insts, refs, case, "x")
    assert calm.status == "pass"
    jump = refs[1].p.copy()
    jump[np.argmax(jump)] *= 1.01  # 1 % jump for a 1e-6 perturbation
    assert cf.perturbation_check(rows, [refs[0].p, jump], insts, refs, case, "x").status == "flagged"


def test_exact_reference_recovers_the_known_solution() -> None:
    inst = cf.build_battery_spec(cases("edge/near-touching*")[0].spec).at(0)
    p_star = inst.meta.pop("p_exact")
    ref = cf.exact_reference(inst)
    assert ref.method == "nnls+bpp"
    assert ref.kkt_error < 1e-12
    assert np.max(np.abs(ref.p - p_star)) <= 1e-10 * np.max(p_star)


def test_block_principal_pivoting_fixes_a_bad_support() -> None:
    inst = cf.build_battery_spec(cases("random/bcc-n64-d1*")[0].spec).at(0)
    H, u = inst.qp.H.to_dense(), inst.qp.ubar
    p = cf.block_principal_pivoting(H, u, np.ones(u.size, dtype=bool))  # start: everything in contact
    assert kkt_check(inst, p).kkt_error < 1e-12


EXACT = {name: s for name, s in all_solvers().items() if s.capabilities.exact}


@pytest.mark.parametrize("name", sorted(EXACT))
def test_every_exact_registered_solver_passes_the_fast_subset(name: str) -> None:
    solver = EXACT[name]
    ok, why = solver.availability()
    if not ok:
        pytest.skip(why)
    table = cf.validate(solver)
    assert table.exit_code() == 0, table.format()
    assert table.count("pass") > 0, table.format()
