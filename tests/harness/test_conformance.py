"""`contactbench validate` tells a solver's author the truth, judged by the one judge."""

from __future__ import annotations

import time
from typing import Iterator
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.command import main as validate_main
from contactbench.harness import get_profile
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.lcp import exact_solution, exact_solution_on_subset
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver
from contactbench.solvers.registry import all_solvers, register, unregister
from tests.helpers import refused_in_one_line

HERE = __name__  # "tests.test_conformance": the import path of the solvers below


def exact_p(ctx: SolveContext) -> np.ndarray:
    """The exact answer on the dense H (computed in float64); on a periodic whole grid,
    where H is singular, on a proper subset, certified on the whole grid."""
    g = ctx.qp.geometry
    if not ctx.qp.constraints.plain:  # bounds or a load: the certified mixed-LCP solve
        return constrained_exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64),
                                          ctx.qp.constraints).p
    if g is not None and g.periodic:
        return exact_solution_on_subset(ctx.qp).p
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


class GoodSolver(Solver):
    """Correct: the exact LCP solution on the dense H (a warm start it takes, and does not need)."""

    name = "test-conf-good"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True, load_control=True, bounds=True, warm_start="primal")

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 1, True)


class ClipSolver(Solver):
    """Wrong: unconstrained solve, then p clipped at 0 -- and claims success."""

    name = "test-conf-clip"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        p = np.linalg.solve(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64))
        return Outcome(np.maximum(p, 0.0), 1, True)


class GreedySolver(Solver):
    """Wrong: the greedy active-set loop of paper section 3 (solve on the set, drop the
    negative entries, never re-admit) -- claims success (paper Example 1 refutes it)."""

    name = "test-conf-greedy"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        H, u = ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)
        S, p = np.arange(u.size), np.zeros_like(u)
        for it in range(u.size + 1):
            x = np.linalg.solve(H[np.ix_(S, S)], u[S]) if S.size else np.zeros(0)
            if np.all(x >= 0):
                break
            S = S[x >= 0]
        p[S] = x
        return Outcome(p, it + 1, True)


class SloppySolver(Solver):
    """Claims convergence with a scaled KKT error of 5 x the mid profile's check_tol
    (within the 10 x slack of the old battery, outside what `run` calls solved)."""

    name = "test-conf-sloppy"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        p = exact_p(ctx)
        off = np.flatnonzero(p == 0)
        u_s = max(float(np.max(np.abs(ctx.qp.ubar))), float(np.max(np.abs(ctx.qp.H.matvec(p)))))
        p[off[0]] = -5 * get_profile("mid").check_tol * u_s / float(np.max(ctx.qp.H.diagonal()))
        return Outcome(p, 1, True)


class EarlyStopSolver(Solver):
    """Honest but unfinished: three projected-gradient steps, no claim; declared exact."""

    name = "test-conf-early"
    family = "test"
    capabilities = Capabilities(exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        H, u = ctx.qp.H, np.asarray(ctx.qp.ubar, dtype=np.float64)
        p, step = np.zeros(ctx.n), 1.0 / float(np.max(H.matvec(np.ones(ctx.n))))
        for _ in range(3):
            p = np.maximum(p - step * (H.matvec(p) - u), 0.0)
        return Outcome(p, 3, False, "stopped after three steps")


class EarlyStopIterative(EarlyStopSolver):
    name = "test-conf-early-iterative"
    capabilities = Capabilities(exact=False)


class HalfSolver(GoodSolver):
    """Uniformly wrong: half the exact answer in every unit system -- and claims success."""

    name = "test-conf-half"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(0.5 * exact_p(ctx), 1, True)


class Float32Solver(GoodSolver):
    """Wrong: silently answers in the input's float32 precision and claims success."""

    name = "test-conf-f32"

    def iterate(self, ctx: SolveContext) -> Outcome:
        dtype = np.asarray(ctx.qp.ubar).dtype
        A = np.flatnonzero(exact_p(ctx) > 0)  # the right contact set, solved in the input's dtype
        H, p = ctx.qp.H.to_dense().astype(dtype), np.zeros(ctx.n, dtype=dtype)
        p[A] = np.linalg.solve(H[np.ix_(A, A)], np.asarray(ctx.qp.ubar)[A])
        return Outcome(p, 1, True)


class RefuseFloat32Solver(GoodSolver):
    """Correct: refuses float32 input with a clear message."""

    name = "test-conf-refuse32"

    def iterate(self, ctx: SolveContext) -> Outcome:
        if np.asarray(ctx.qp.ubar).dtype != np.float64:
            raise ProblemInputError(f"ubar must be float64, got {np.asarray(ctx.qp.ubar).dtype}")
        return super().iterate(ctx)


class AbsoluteThresholdSolver(GoodSolver):
    """Unit-dependent: drops every force below 5e-3 in whatever unit it is given."""

    name = "test-conf-abs"

    def iterate(self, ctx: SolveContext) -> Outcome:
        p = exact_p(ctx)
        return Outcome(np.where(p < 5e-3, 0.0, p), 1, True)


class HangingSolver(Solver):
    name = "test-conf-hang"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        time.sleep(60)
        return Outcome(np.zeros(ctx.n), 1, True)


class CrashingSolver(Solver):
    name = "test-conf-crash"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise RuntimeError("boom")


def cases(pattern: str) -> list[cf.ConformanceCase]:
    out = cf.conformance_cases("fast", pattern=pattern)
    assert out, pattern
    return out


def test_battery_holds_example_1_at_n400_and_full_packing() -> None:
    ex1 = cases("counterexample")
    assert {c.spec.params["n"] for c in ex1} == {400}
    assert len({c.spec.params["seed"] for c in ex1}) >= 3
    inst = cf.build_battery_spec(ex1[0].spec).at(0)
    assert inst.n == 400 and inst.meta["family"] == "counterexample"
    packing = cases("packing")
    assert {c.spec.params["kernel"] for c in packing} == {"bcc", "love"}
    for c in packing:
        inst = cf.build_battery_spec(c.spec).at(0)
        assert inst.n == inst.total_elements and np.all(cf.exact_reference(inst).p > 0)


@pytest.mark.slow
def test_correct_solver_conforms_on_the_whole_fast_battery() -> None:
    table = cf.validate(GoodSolver())
    assert table.outcome(strict=True) == "conforms" and table.exit_code(strict=True) == 0, table.format()
    assert table.count("pass") == len(table.rows)
    assert {r.group for r in table.rows} == set(cf.BATTERY_GROUPS)
    assert "CONFORMS" in table.summary()


def test_clipping_solver_is_caught() -> None:
    table = cf.validate(ClipSolver(), cases("random"))
    assert table.outcome() == "wrong" and table.exit_code() == 1
    assert table.wrong and all(r.claimed for r in table.wrong)
    with pytest.raises(AssertionError, match="WRONG"):
        cf.assert_conforms(ClipSolver(), cases("random"))


def test_greedy_false_claim_on_example_1_at_n400_is_caught() -> None:
    table = cf.validate(GreedySolver(), cases("counterexample"))
    assert table.exit_code() == 1, table.format()
    w = table.wrong[0]
    assert w.kkt_error > w.check_tol and "claiming convergence" in w.message


def test_wrong_claim_threshold_is_the_check_tol_of_run() -> None:
    """5 x check_tol claimed as converged: WRONG (the old 10 x slack would pass it)."""
    table = cf.validate(SloppySolver(), cases("counterexample/*-s0"))
    row = table.rows[0]
    assert row.check_tol == get_profile("mid").check_tol
    assert row.check_tol < row.kkt_error < 10 * row.check_tol
    assert row.status == "WRONG" and table.exit_code() == 1


def test_an_answer_run_calls_solved_is_never_wrong_even_off_the_reference() -> None:
    """The reference comparison is an extra: where it disagrees with a KKT pass the row is
    flagged (``--strict`` fails it), never WRONG."""
    from contactbench.harness.judging import judge

    inst = cf.build_battery_spec(cases("counterexample/*-s0")[0].spec).at(0)
    p = cf.exact_reference(inst).p
    v = judge(inst, p, True, get_profile("mid").check_tol, p_ref=1.5 * p, p_tol=1e-3)
    assert (v.status, v.reading) == ("solved", "wrong")
    assert cf.row_status(v) == "flagged"
    assert cf.STRICT_FAILING.count("flagged") == 1


def test_a_solver_that_leaves_cases_unsolved_is_incomplete_not_conforming() -> None:
    table = cf.validate(EarlyStopSolver(), cases("counterexample"))
    assert table.outcome() == "incomplete" and table.exit_code() == 3
    assert all(r.status == "unconverged" for r in table.rows)
    summary = table.summary()
    assert "CONFORMS" not in summary and "INCOMPLETE" in summary
    assert f"leaves {len(table.rows)} of {len(table.rows)}" in summary
    assert all(r.label in summary for r in table.rows)
    with pytest.raises(AssertionError, match="INCOMPLETE"):
        cf.assert_conforms(EarlyStopSolver(), cases("counterexample"))
    # Not declared exact (finite termination) makes no difference: unsolved is incomplete.
    other = cf.validate(EarlyStopIterative(), cases("counterexample"))
    assert other.outcome() == "incomplete" and other.exit_code() == 3
    assert "CONFORMS" not in other.summary() and f"leaves {len(other.rows)} of {len(other.rows)}" in other.summary()


def test_comparison_row_never_passes_over_wrong_steps_and_notes_are_whole() -> None:
    table = cf.validate(HalfSolver(), cases("units/unit-systems*"))
    steps = [r for r in table.rows if r.step >= 0]
    agreement = [r for r in table.rows if r.step < 0][0]
    assert steps and all(r.status == "WRONG" for r in steps)
    assert agreement.status != "pass" and "did not pass" in agreement.message
    assert table.summary().startswith("test-conf-half [fast]: WRONG")
    text = table.format()
    assert all(r.message and r.message in text for r in table.rows)


def test_cli_exit_codes_by_name_and_import_path(capsys: pytest.CaptureFixture[str]) -> None:
    register(ClipSolver, replace=True)
    try:
        assert validate_main(["test-conf-clip", "--cases", "random/bcc-n64-d1*"]) == 1
    finally:
        unregister("test-conf-clip")
    assert validate_main([f"{HERE}:GoodSolver", "--cases", "random/bcc-n64-d1*"]) == 0
    assert validate_main([f"{HERE}:EarlyStopSolver", "--cases", "random/bcc-n64-d1*", "--quiet"]) == 3
    out = capsys.readouterr().out
    assert "WRONG" in out and "CONFORMS" in out and "kkt_error" in out and "INCOMPLETE" in out


@pytest.mark.parametrize("argv, words", [
    (["no-such-solver"], "unknown solver 'no-such-solver'"),
    ([f"{HERE}:NoSuchSolver"], "has no attribute 'NoSuchSolver'"),
    (["no_such_module_xyz:Solver"], "cannot import 'no_such_module_xyz'"),
    ([f"{HERE}:GoodSolver", "--cases", "no-such-case*"], "no case matches"),
    ([], "name a solver"),
])
def test_bad_input_exits_2_with_a_clear_message(argv: list[str], words: str,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(argv) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


@pytest.fixture
def package_solvers_only() -> Iterator[None]:
    """The registry holds the package's own solvers only for the test (the tests' stubs,
    registered by other modules, are put back after): ``--all`` then runs what a user's
    ``validate --all`` runs."""
    stubs = {name: s for name, s in all_solvers().items() if not type(s).__module__.startswith("contactbench.")}
    for name in stubs:
        unregister(name)
    try:
        yield
    finally:
        for s in stubs.values():
            register(s, replace=True)


@pytest.mark.slow
@pytest.mark.usefixtures("package_solvers_only")
def test_list_help_and_all_quiet(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["--list"]) == 0
    listed = capsys.readouterr().out
    assert "counterexample/example1-n400-s0" in listed and "packing/all-in-contact-bcc" in listed
    assert validate_main(["--help"]) == 0
    helptext = capsys.readouterr().out
    assert all(opt in helptext for opt in ("--all", "--quiet", "--list", "--strict", "--cases", "exit status"))
    code = validate_main(["--all", "--quiet", "--cases", "edge/single-point*"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == sum(s.availability()[0] for s in all_solvers().values())
    assert lines == ours_only(lines) and all("CONFORMS" in line or "UNTESTED" in line for line in lines)
    assert any("CONFORMS" in line for line in lines) and code == 0
    # Delta = 0: ubar <= 0, the lifecycle answers p = 0 without calling any solver
    code = validate_main(["--all", "--quiet", "--cases", "edge/delta0*"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines and all("UNTESTED" in line for line in lines) and code == 4


def ours_only(lines: list[str]) -> list[str]:
    """The summary lines of the package's own solvers (not the tests' stubs)."""
    return [line for line in lines if type(all_solvers()[line.split(" [")[0]]).__module__.startswith("contactbench.")]


def test_validate_judges_a_variant_by_its_own_parameters_and_a_raising_skip_as_a_crash() -> None:
    """``validate --params`` asks ``skip_params`` with the given parameters (a CMR variant
    asking a coarse level of 64 on the float32 case is skipped, so nothing is judged: it was run
    and refused, and read CONFORMS); a ``skip`` that raises is the solver's crash, not a
    capability it declares (it read UNTESTED, or CONFORMS beside another solver)."""
    table = cf.validate("cmr+nnls", cases("precision"), params={"coarsest": 64})
    assert {r.status for r in table.rows} == {"skipped"} and table.outcome() == "untested", table.format()
    assert "coarsest level of 64" in table.rows[0].message
    buggy = cf.validate("test-buggy-skip", cases("random/spd-n30-s0*"))
    assert {r.status for r in buggy.solves} == {"crashed"} and buggy.exit_code() == 3, buggy.format()
    assert "skip check failed: RuntimeError: a bug in skip" in buggy.rows[0].message
    quitting = cf.validate("test-skip-exit", cases("random/spd-n30-s0*"), isolate=False)  # sys.exit in skip
    assert {r.status for r in quitting.solves} == {"crashed"} and quitting.exit_code() == 3, quitting.format()
    records = quitting.records(strict=True)
    assert {r["outcome"] for r in records} == {"strict"} and quitting.exit_code(strict=True) == 1  # as the CSV says


def test_a_solver_that_skips_every_case_is_untested_not_conforming() -> None:
    """A solver whose declared capabilities skip every selected case (max_n = 1 here) was
    judged on nothing: "UNTESTED", exit 4 -- it read CONFORMS with exit 0, so a solver could
    declare its way past the battery; assert_conforms refuses it too."""

    class Tiny(Solver):
        name = "test-tiny"
        capabilities = Capabilities(max_n=1)

        def iterate(self, ctx: SolveContext) -> Outcome:
            raise AssertionError("never handed a case")

    table = cf.validate(Tiny(), cases("random/spd-n30-s0*"))
    assert table.outcome() == "untested" and table.exit_code() == 4, table.format()
    assert "UNTESTED" in table.headline() and "CONFORMS" not in table.summary()
    with pytest.raises(AssertionError, match="UNTESTED"):
        cf.assert_conforms(Tiny(), cases("random/spd-n30-s0*"))


def test_hanging_solver_times_out_without_hanging_validate() -> None:
    t0 = time.perf_counter()
    table = cf.validate(HangingSolver(), cases("edge/single-point*"), timeout=0.5)
    assert [r.status for r in table.rows] == ["timeout"]
    assert time.perf_counter() - t0 < 30
    assert table.outcome() == "incomplete" and table.exit_code() == 3 and table.exit_code(strict=True) == 1


def test_crash_is_reported_not_hidden() -> None:
    table = cf.validate(CrashingSolver(), cases("edge/single-point*"))
    row = table.rows[0]
    assert row.status == "crashed" and row.message == "RuntimeError: boom" and "Traceback" in row.detail
    assert table.outcome() == "incomplete" and table.exit_code() == 3 and table.exit_code(strict=True) == 1


def test_float32_is_solved_in_float64_refused_or_caught() -> None:
    prec = cases("precision")
    assert cf.validate(GoodSolver(), prec).rows[0].status == "pass"
    refused = cf.validate(RefuseFloat32Solver(), prec)
    assert refused.rows[0].status == "refused" and "float32" in refused.rows[0].message
    # refusing float32 is allowed, even for an exact solver -- but a refusal judges nothing
    assert refused.outcome() == "untested" and refused.exit_code() == 4
    silent = cf.validate(Float32Solver(), prec)
    assert silent.rows[0].status == "WRONG" and silent.exit_code() == 1


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
    rows = [cf.VerdictRow("x", case.name, case.group, k, insts[k].n, "pass", kkt_error=0.0) for k in range(2)]
    calm = cf.perturbation_check(rows, [refs[0].p, refs[1].p], insts, refs, case, "x")
    assert calm.status == "pass"
    jump = refs[1].p.copy()
    jump[np.argmax(jump)] *= 1.01  # 1 % jump for a 1e-6 perturbation
    assert cf.perturbation_check(rows, [refs[0].p, jump], insts, refs, case, "x").status == "flagged"


def test_exact_reference_recovers_the_known_solution() -> None:
    inst = cf.build_battery_spec(cases("edge/near-touching*")[0].spec).at(0)
    p_star = inst.meta.pop("p_exact")
    ref = cf.exact_reference(inst)
    assert ref.method == "nnls+bpp" and ref.trusted
    assert ref.kkt_error < 1e-12
    assert np.max(np.abs(ref.p - p_star)) <= 1e-10 * np.max(p_star)


def test_run_and_validate_give_the_same_verdict_on_the_same_solve(run_harness) -> None:
    """`run` (status solved/inaccurate, verdict) and `validate` (row status) agree per solve."""
    names = {"GoodSolver": "test-conf-good", "SloppySolver": "test-conf-sloppy",
             "EarlyStopSolver": "test-conf-early"}
    table = run_harness(["stress-counterexample"], solvers=[f"{HERE}:{k}" for k in names], extra={"mode": "fast"},
                        profiles=("mid",), reference="none", warmup=False, timeout=60.0)
    expected = {"pass": ("solved", "pass"), "WRONG": ("inaccurate", "wrong"),
                "unconverged": ("inaccurate", "unconverged")}
    seen = set()
    for cls in (GoodSolver, SloppySolver, EarlyStopSolver):
        for row in cf.validate(cls(), cases("counterexample")).rows:
            ran = table[(table["solver"] == row.solver) & (table["instance"] == row.case)]
            assert len(ran) == 1, (row.solver, row.case)
            assert (ran["status"].iloc[0], ran["verdict"].iloc[0]) == expected[row.status], (row.solver, row.case)
            seen.add(row.status)
    assert seen == set(expected)


EXACT = {name: s for name, s in all_solvers().items() if s.capabilities.exact}


@pytest.mark.parametrize("name", sorted(EXACT))
def test_every_exact_registered_solver_solves_every_case_of_the_fast_battery(name: str) -> None:
    solver = EXACT[name]
    ok, why = solver.availability()
    if not ok:
        pytest.skip(why)
    table = cf.validate(solver)
    assert table.outcome() == "conforms", table.format()
    assert table.count("pass") > 0 and not table.unsolved, table.format()


# ---------------------------------------------------------------------------
# The command line refuses bad input in one line before anything runs
# ---------------------------------------------------------------------------

QUICK_CASE = "edge/single-point*"


class ExitingSolver(Solver):
    """Calls sys.exit(0) in the middle of a solve."""

    name = "test-conf-exit"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise SystemExit(0)


class InterruptedSolver(Solver):
    """A solve interrupted by Ctrl-C."""

    name = "test-conf-interrupt"
    family = "test"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise KeyboardInterrupt


def nothing_may_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any solve of the command line fail the test."""
    from contactbench.harness.conformance import command

    def ran(*args: object, **kw: object) -> None:
        raise AssertionError("the battery ran before the input was checked")

    monkeypatch.setattr(command, "validate", ran)


def test_a_promise_of_one_or_more_is_refused_because_p0_meets_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.solvers.base import check_promise
    from contactbench.solvers.external import load_manifest

    assert check_promise(0.5) == 0.5
    for bad in (1, 1.0, 10.0, float("inf")):
        with pytest.raises(ValueError, match=r"p = 0 has scaled KKT error 1"):
            check_promise(bad)
    with pytest.raises(ValueError, match=r"floor \(a float\) below 1"):
        Capabilities(promise=10.0)
    manifest = tmp_path / "m.toml"
    manifest.write_text('[[solver]]\nname = "zero-ext"\ncommand = "prog {problem} {solution}"\npromise = 1.0\n')
    with pytest.raises(ProblemInputError, match=r"entry 1: .*p = 0 has scaled KKT error 1"):
        load_manifest(manifest)
    (tmp_path / "cb_promise_ten.py").write_text(
        "import numpy as np\n"
        "from contactbench.solvers import Capabilities, Outcome, Solver\n"
        "class Zero(Solver):\n"
        "    name = 'cb-zero'\n"
        "    capabilities = Capabilities(promise=10.0)\n"
        "    def iterate(self, ctx):\n"
        "        return Outcome(np.zeros(ctx.n), 1, True)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    nothing_may_run(monkeypatch)
    assert "floor (a float) below 1" in refused_in_one_line(["cb_promise_ten:Zero", "--cases", QUICK_CASE], capsys)


def test_the_trivial_answer_claimed_as_converged_is_wrong_under_any_legal_promise() -> None:
    class Zero(Solver):
        name = "test-conf-zero"
        family = "test"
        capabilities = Capabilities(promise=0.999)

        def iterate(self, ctx: SolveContext) -> Outcome:
            return Outcome(np.zeros(ctx.n), 1, True)

    table = cf.validate(Zero(), cases(QUICK_CASE), isolate=False)
    assert [r.status for r in table.rows] == ["WRONG"] and table.rows[0].kkt_error == pytest.approx(1.0)
    assert table.exit_code() == 1


@pytest.mark.parametrize("where", ["missing-folder", "a-folder"])
def test_a_csv_path_that_cannot_be_written_is_refused_before_anything_runs(
        where: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "no" / "such" / "x.csv" if where == "missing-folder" else tmp_path
    out = tmp_path / "report"
    nothing_may_run(monkeypatch)
    line = refused_in_one_line([f"{HERE}:GoodSolver", "--cases", QUICK_CASE, "--csv", str(path), "--out", str(out)],
                               capsys)
    assert "--csv" in line and ("no such folder" in line if where == "missing-folder" else "is a folder" in line)
    assert not out.exists()


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "0", "-1", "abc", "1e300"])
def test_a_timeout_that_is_not_a_finite_positive_number_is_refused(
        value: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    nothing_may_run(monkeypatch)
    line = refused_in_one_line([f"{HERE}:GoodSolver", "--cases", QUICK_CASE, f"--timeout={value}"], capsys)
    assert "--timeout" in line and ("finite number > 0" in line or "not a number" in line) and value in line


def test_the_python_api_refuses_a_non_finite_timeout_too() -> None:
    for bad in (float("nan"), float("inf"), 0.0, -1.0, 1e300):
        with pytest.raises(ValueError, match="finite number of seconds > 0"):
            cf.validate(GoodSolver(), cases(QUICK_CASE), timeout=bad)


@pytest.mark.parametrize("argv, words", [
    (["--bogus"], "unrecognized arguments: --bogus"),
    (["--params", "not json"], "argument --params: not JSON"),
    (["--group", "nosuch"], "argument --group: invalid choice 'nosuch'"),
    (["--timeout", "abc"], "argument --timeout"),
    (["--cases", ""], "argument --cases: '' names no case"),
])
def test_usage_errors_are_one_line(argv: list[str], words: str, monkeypatch: pytest.MonkeyPatch,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    nothing_may_run(monkeypatch)
    assert words in refused_in_one_line([f"{HERE}:GoodSolver", *argv], capsys)


def test_out_refuses_a_folder_that_is_not_a_conformance_report_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness.conformance.report import ReportFolderError, write_conformance_report

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "conformance.md").write_text("my own notes\n")
    (mine / "verdicts.csv").write_text("a,b\n1,2\n")
    results = tmp_path / "results"  # what `contactbench run` leaves
    results.mkdir()
    (results / ".contactbench-run.json").write_text('{"format": 1, "runs": []}')
    (results / "rows.jsonl").write_text("")
    a_file = tmp_path / "a-file"
    a_file.write_text("mine\n")
    with monkeypatch.context() as m:
        nothing_may_run(m)
        for folder in (mine, results, a_file):
            line = refused_in_one_line([f"{HERE}:GoodSolver", "--cases", QUICK_CASE, "--out", str(folder)], capsys)
            assert f"--out {folder}" in line
    assert (mine / "conformance.md").read_text() == "my own notes\n"
    assert sorted(p.name for p in results.iterdir()) == [".contactbench-run.json", "rows.jsonl"]
    with pytest.raises(ReportFolderError, match="not a conformance report folder"):
        write_conformance_report([], mine)
    assert (mine / "conformance.md").read_text() == "my own notes\n"


def test_out_writes_again_into_its_own_report_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    argv = [f"{HERE}:GoodSolver", "--cases", QUICK_CASE, "--quiet", "--no-isolate", "--out", str(out)]
    assert validate_main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == [".contactbench-conformance", "conformance.md", "verdicts.csv"]
    (out / "notes.txt").write_text("the user's, beside the marker\n")
    assert validate_main(argv) == 0
    (out / "notes.txt").unlink()
    (out / ".contactbench-conformance").unlink()  # validate's two files and nothing else: still its folder
    assert validate_main(argv) == 0
    assert (out / "conformance.md").read_text().startswith("# Conformance report")
    capsys.readouterr()


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solver_that_calls_sys_exit_is_a_crash_row(isolate: bool) -> None:
    table = cf.validate(ExitingSolver(), cases(QUICK_CASE), isolate=isolate)
    row = table.rows[0]
    assert row.status == "crashed" and row.message == "SystemExit: 0", table.format()
    assert table.exit_code() == 3


def test_no_isolate_lets_ctrl_c_interrupt_and_its_help_warns_of_a_process_exit(
        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(KeyboardInterrupt):
        cf.validate(InterruptedSolver(), cases(QUICK_CASE), isolate=False)
    assert validate_main(["--help"]) == 0
    assert "os._exit" in " ".join(capsys.readouterr().out.split())


def test_case_selection_each_case_once_and_list_refuses_an_empty_selection(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    once = cf.conformance_cases("fast", ["edge"])
    assert cf.conformance_cases("fast", ["edge", "edge"]) == once
    assert validate_main(["--list", "--group", "edge", "--group", "edge"]) == 0
    listed = capsys.readouterr().out.strip().splitlines()
    assert len(listed) == len(once) == len(set(listed))
    nothing_may_run(monkeypatch)
    for argv in (["--list", "--cases", "nomatch"], [f"{HERE}:GoodSolver", "--cases", "nomatch"]):
        assert "no case matches 'nomatch' in the groups" in refused_in_one_line(argv, capsys)


def test_an_empty_selection_of_cases_is_refused_not_passed() -> None:
    """A filter with a typo selects nothing: the battery of no case would conform (greedy-cg,
    WRONG on Example 1, passed); the API refuses it as the command line does."""
    from contactbench.problems.errors import ProblemInputError

    nothing = [c for c in cf.conformance_cases("fast") if c.name.startswith("counterexmaple")]
    with pytest.raises(ProblemInputError, match="no conformance case"):
        cf.assert_conforms("greedy-cg", nothing)
    with pytest.raises(ProblemInputError, match="no conformance case"):
        cf.validate("pk", [])
