"""`contactbench validate` against solvers that misbehave on purpose: none of them can
forge a verdict, flood the terminal, leave processes behind or end ``validate`` with a
traceback; a solver declaration it cannot use is one line and exit 2."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.report import markdown_page
from contactbench.harness.judging import judge
from contactbench.harness.run.isolation import ChildProcess
from contactbench.problems.lcp import exact_solution
from contactbench.problems.scenes.stress import build_battery_spec
from contactbench.solvers import Capabilities, Outcome, Param, SolveAborted, SolveContext, Solver, SolveResult, Status
from contactbench.solvers.base import WITHOUT_ITERATE, ProblemTraits
from contactbench.solvers.registry import register
from tests.helpers import process_gone, refused_in_one_line

HERE = __name__  # the import path of the solvers below
ROOT = Path(__file__).resolve().parents[2]
CASE = "counterexample/example1-n400-s0"


def cases() -> list[cf.ConformanceCase]:
    out = cf.conformance_cases("fast", pattern=CASE)
    assert len(out) == 1
    return out


def exact_p(ctx: SolveContext) -> np.ndarray:
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


class ExactSolver(Solver):
    name = "test-attack-exact"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 1, True)


class ForgedPass(ExactSolver):
    name = "test-attack-forged-pass"

    def iterate(self, ctx: SolveContext) -> Outcome:
        exc = SolveAborted("crashed", "forged")
        exc.status = "pass"
        raise exc


class EmptyTimeout(ExactSolver):
    name = "test-attack-empty-timeout"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise SolveAborted("timeout", "")


class UnreadableError(Exception):
    def __str__(self) -> str:
        raise ValueError("the message cannot be read")


class RaisesUnreadable(ExactSolver):
    name = "test-attack-unreadable-error"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise UnreadableError()


class Unpicklable(ExactSolver):
    name = "test-attack-unpicklable"

    def iterate(self, ctx: SolveContext) -> Outcome:
        p = np.empty(ctx.n, dtype=object)
        p[:] = [lambda: 0.0] * ctx.n
        return Outcome(p, 1, True)


class Printer(ExactSolver):
    name = "test-attack-printer"

    def iterate(self, ctx: SolveContext) -> Outcome:
        print("PRINTED-BY-THE-SOLVER")
        print("PRINTED-BY-THE-SOLVER", file=sys.stderr)
        os.write(1, b"WRITTEN-TO-FD-1\n")  # as a C library writes
        os.write(2, b"WRITTEN-TO-FD-2\n")
        return super().iterate(ctx)


class PrintsThenAborts(ExactSolver):
    name = "test-attack-prints-then-aborts"

    def iterate(self, ctx: SolveContext) -> Outcome:
        os.write(2, b"LAST-WORDS-OF-THE-SOLVER\n")
        os.abort()


class LooseHalf(ExactSolver):
    """Half the exact answer, within a promise of 0.9: looser than the bound, which it is held to."""

    name = "test-attack-loose-half"
    capabilities = Capabilities(needs_dense=True, promise=0.9)

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(0.5 * exact_p(ctx), 1, True)


class ExitsInConstructor(ExactSolver):
    name = "test-attack-exits-in-init"

    def __init__(self) -> None:
        raise SystemExit(0)


class AvailabilityRaises(ExactSolver):
    name = "test-attack-availability-raises"

    def availability(self) -> tuple[bool, str]:
        raise RuntimeError("availability broke")


class ParamsOfStrings(ExactSolver):
    name = "test-attack-params-of-strings"
    params = ("step_scale",)  # type: ignore[assignment]


class CapabilitiesNone(ExactSolver):
    name = "test-attack-capabilities-none"
    capabilities = None  # type: ignore[assignment]


class CapabilitiesDict(ExactSolver):
    name = "test-attack-capabilities-dict"
    capabilities = {"promise": "exact"}  # type: ignore[assignment]


class DefaultOutOfRange(ExactSolver):
    name = "test-attack-default-out-of-range"
    params = (Param("step_scale", float, 5.0, "step = step_scale / L", low=0.1, high=1.0),)


class ShortAnswer(ExactSolver):
    name = "test-attack-short-answer"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx)[:-1], 1, True)


class EmptyName(ExactSolver):
    name = ""


class NoneName(ExactSolver):
    name = None  # type: ignore[assignment]


# ---------------------------------------------------------------------------
# What a solve can do to its row
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solve_aborted_status_set_after_construction_is_a_crash_not_a_pass(isolate: bool) -> None:
    table = cf.validate(ForgedPass(), cases(), isolate=isolate)
    row = table.rows[0]
    assert row.status == "crashed" and "'pass'" in row.message and "forged" in row.message, table.format()
    assert table.exit_code() == 3


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solve_aborted_without_a_message_is_a_timeout_row(isolate: bool) -> None:
    table = cf.validate(EmptyTimeout(), cases(), isolate=isolate)
    assert [(r.status, r.message) for r in table.rows] == [("timeout", "timeout")], table.format()


@pytest.mark.parametrize("isolate", [False, True])
def test_an_exception_whose_str_raises_is_a_crash_row_naming_its_type(isolate: bool) -> None:
    table = cf.validate(RaisesUnreadable(), cases(), isolate=isolate)
    row = table.rows[0]
    assert row.status == "crashed" and row.message.startswith("UnreadableError"), table.format()


@pytest.mark.parametrize("isolate", [False, True])
def test_an_answer_that_cannot_be_pickled_is_wrong_in_a_worker_as_in_process(isolate: bool) -> None:
    table = cf.validate(Unpicklable(), cases(), isolate=isolate)
    row = table.rows[0]
    assert row.status == "WRONG" and "dtype object" in row.message, table.format()
    assert "Traceback" not in row.detail and table.exit_code() == 1


def test_a_comparison_of_answers_without_finite_figures_is_not_made_and_warns_nothing() -> None:
    units = cf.conformance_cases("fast", groups=["units"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table = cf.validate(ShortAnswer(), units, isolate=False)
    compared = [r for r in table.rows if r.step == -1]
    assert compared and all(r.status == "skipped" and r.message.startswith("not compared") for r in compared), \
        table.format()
    assert "nan" not in table.format() and table.exit_code() == 1


def test_what_a_solver_prints_in_its_worker_stays_there(capfd: pytest.CaptureFixture[str]) -> None:
    table = cf.validate(Printer(), cases())
    assert table.exit_code() == 0, table.format()
    crashed = cf.validate(PrintsThenAborts(), cases())
    out, err = capfd.readouterr()
    for text in ("PRINTED-BY-THE-SOLVER", "WRITTEN-TO-FD-1", "WRITTEN-TO-FD-2", "LAST-WORDS"):
        assert text not in out + err
    row = crashed.rows[0]
    assert row.status == "crashed" and "LAST-WORDS-OF-THE-SOLVER" in row.detail, crashed.format()


def _start_a_sleeper_and_hang(pid_file: str) -> int:
    """Start a process, write its pid into ``pid_file``, and hang ("" : answer at once)."""
    if not pid_file:
        return 0
    pid = subprocess.Popen(["sleep", "60"]).pid
    Path(pid_file).write_text(str(pid))
    time.sleep(600)
    return 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="process groups and /proc: Linux")
def test_the_processes_a_killed_worker_started_are_killed_with_it(tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    with ChildProcess(lambda: _start_a_sleeper_and_hang) as child:
        assert child.call("", timeout=None).kind == "ok"  # the worker is up
        assert child.call(str(pid_file), timeout=1.0).kind == "timeout"
    pid = int(pid_file.read_text())
    deadline = time.monotonic() + 10.0  # a bounded wait for the kernel, not a claim on speed
    while not process_gone(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    survived = not process_gone(pid)
    if survived:
        os.kill(pid, 9)
    assert not survived, "the worker's child outlived it"


def test_the_judge_never_prints_a_threshold_that_contradicts_its_comparison() -> None:
    inst = build_battery_spec(cases()[0].spec).at(0)
    v = judge(inst, np.zeros(inst.n), True, check_tol=0.96)  # p = 0: scaled KKT error exactly 1
    match = re.search(r"kkt_error (\S+) > check_tol (\S+)", v.message())
    assert match and float(match[1]) > float(match[2]), v.message()


def test_a_promise_looser_than_the_bound_is_held_to_the_bound_and_says_so() -> None:
    table = cf.validate(LooseHalf(), cases())
    assert [r.status for r in table.rows] == ["WRONG"] and table.exit_code() == 1, table.format()
    assert table.rows[0].check_tol == cf.PROMISE_BOUND < 0.9
    assert "scaled KKT floor 0.9, held to 0.001" in table.format()
    page = markdown_page([table])
    assert "judged at max(the case's profile threshold, 0.001)" in page, page


def test_the_promise_bound_is_the_loosest_threshold_run_calls_solved() -> None:
    from contactbench.harness.profiles import PROFILES

    assert cf.PROMISE_BOUND == max(p.check_tol for p in PROFILES.values()) < 0.01


class Float32Answer(ExactSolver):
    """Takes over ``solve`` and hands back the exact answer rounded to float32."""

    name = "test-attack-float32-answer"

    def solve(self, qp: Any, settings: Any = None, warm: Any = None) -> SolveResult:
        res = super().solve(qp, settings, warm)
        return SolveResult(p=res.p.astype(np.float32), iterations=1, converged=True, status="converged")


def test_a_flagged_row_names_its_reason_in_the_headline() -> None:
    table = cf.validate(Float32Answer(), cases(), isolate=False)
    assert [r.status for r in table.rows] == ["flagged"] and table.rows[0].flags == "dtype", table.format()
    line = table.summary()
    assert "accepted by the KKT test, but not float64" in line and "off the exact reference" not in line, line


class SkipsAllButTheSmallest(ExactSolver):
    """Its own ``skip`` leaves it only dense problems of n <= 30."""

    name = "test-attack-skips-all-but-the-smallest"

    def skip(self, traits: ProblemTraits) -> str | None:
        return None if traits.n <= 30 and traits.operator == "dense" else "not my kind of problem"


class DeclaresASmallMaxN(ExactSolver):
    name = "test-attack-declares-max-n-30"
    capabilities = Capabilities(needs_dense=True, exact=True, max_n=30)


def two_groups() -> list[cf.ConformanceCase]:
    return cf.conformance_cases("fast", pattern="random/spd-n30-s0") + cases()


def test_a_solver_whose_own_skip_leaves_a_group_untried_is_untested() -> None:
    table = cf.validate(SkipsAllButTheSmallest(), two_groups(), isolate=False)
    assert table.untried_groups == ["counterexample"] and table.exit_code() == 4, table.format()
    assert table.summary().startswith(f"{SkipsAllButTheSmallest.name} [fast]: UNTESTED: its own skip left a group of the battery untried (counterexample")
    assert "counterexample" in table.summary()


def test_a_group_ruled_out_by_a_declared_capability_leaves_the_solver_conforming() -> None:
    table = cf.validate(DeclaresASmallMaxN(), two_groups(), isolate=False)
    assert table.untried_groups == [] and table.outcome() == "conforms", table.format()


class WrongClaimStalled(ExactSolver):
    name = "test-attack-wrong-claim-stalled"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(1.5 * exact_p(ctx), 1, True, status=Status.STALLED)


class RightClaimStalled(ExactSolver):
    name = "test-attack-right-claim-stalled"

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(exact_p(ctx), 1, True, status=Status.STALLED)


def test_a_claim_of_convergence_is_judged_whatever_status_comes_with_it() -> None:
    wrong = cf.validate(WrongClaimStalled(), cases(), isolate=False)
    assert [r.status for r in wrong.rows] == ["WRONG"] and wrong.rows[0].claimed, wrong.format()
    right = cf.validate(RightClaimStalled(), cases(), isolate=False)
    assert [r.status for r in right.rows] == ["pass"] and right.exit_code() == 0, right.format()


class ForgesTheLifecycle(ExactSolver):
    """Writes the lifecycle's own marker into its result's info."""

    name = "test-attack-forges-the-lifecycle"
    factor = 1.5

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(self.factor * exact_p(ctx), 1, True, info={WITHOUT_ITERATE: True})


class ForgesTheLifecycleRight(ForgesTheLifecycle):
    name = "test-attack-forges-the-lifecycle-right"
    factor = 1.0


@pytest.mark.parametrize("isolate", [False, True])
def test_a_solver_cannot_pass_its_answer_off_as_the_lifecycles(isolate: bool) -> None:
    wrong = cf.validate(ForgesTheLifecycle(), cases(), isolate=isolate)
    row = wrong.rows[0]
    assert row.status == "WRONG" and row.iterated and "lifecycle" not in row.message, wrong.format()
    right = cf.validate(ForgesTheLifecycleRight(), cases(), isolate=isolate)
    assert right.outcome() == "conforms" and right.rows[0].iterated, right.format()


def test_the_summary_of_an_exact_solver_states_its_promise() -> None:
    table = cf.validate(ExactSolver(), cases(), isolate=False)
    assert "CONFORMS: every solve correct to its promise (exact; 1 of 1)" in table.summary()


# ---------------------------------------------------------------------------
# Solvers that cannot be loaded or used: one line, exit 2
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("cls, words", [
    ("ExitsInConstructor", "SystemExit: 0"),
    ("AvailabilityRaises", "'test-attack-availability-raises': its availability() failed: RuntimeError"),
    ("ParamsOfStrings", "'test-attack-params-of-strings': its `params` is ('step_scale',)"),
    ("CapabilitiesNone", "'test-attack-capabilities-none': its `capabilities` is None"),
    ("CapabilitiesDict", "'test-attack-capabilities-dict': its `capabilities` is {'promise': 'exact'}"),
    ("DefaultOutOfRange", "parameter 'step_scale' must lie in [0.1, 1], got 5.0"),
    ("EmptyName", "EmptyName has no name"),
    ("NoneName", "NoneName has no name"),
])
def test_a_solver_declaration_that_cannot_be_used_is_one_line_and_exit_2(
        cls: str, words: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert words in refused_in_one_line([f"{HERE}:{cls}", "--cases", CASE], capsys)


def test_the_registry_refuses_a_default_outside_its_declared_range() -> None:
    with pytest.raises(ValueError, match=r"'test-attack-default-out-of-range'.*'step_scale'.*5\.0"):
        register(DefaultOutOfRange)


def test_a_module_that_exits_at_import_is_one_line_and_exit_2(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "cb_exits_at_import.py").write_text("import sys\nsys.exit(0)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    line = refused_in_one_line(["cb_exits_at_import:Solver", "--cases", CASE], capsys)
    assert "cannot load solver 'cb_exits_at_import:Solver': importing module 'cb_exits_at_import' raised " \
           "SystemExit: 0" in line


@pytest.mark.parametrize("module", ["cb_here.py", "./cb_here.py", "./cb_here", "ABS"])
def test_a_file_path_for_the_module_says_how_to_name_it(
        module: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "cb_here.py").write_text("")
    monkeypatch.chdir(tmp_path)
    module = str(tmp_path / "cb_here.py") if module == "ABS" else module
    line = refused_in_one_line([f"{module}:Solver", "--cases", CASE], capsys)
    assert "is a file path" in line and "name it cb_here:Solver" in line and str(tmp_path.resolve()) in line


def test_a_missing_dependency_is_told_apart_from_a_missing_module(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "cb_needs_a_dependency.py").write_text("import cb_no_such_dependency_xyz\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    line = refused_in_one_line(["cb_needs_a_dependency:Solver", "--cases", CASE], capsys)
    assert "imports 'cb_no_such_dependency_xyz', which is not installed" in line
    assert "run from the folder" not in line


# ---------------------------------------------------------------------------
# The command line
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("option", ["--csv", "--out"])
def test_an_empty_csv_or_out_is_refused(option: str, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused_in_one_line([f"{HERE}:ExactSolver", "--cases", CASE, option, ""], capsys)
    assert f"argument {option}: '' names no file or folder" in line


def test_a_csv_under_a_file_says_it_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "afile").write_text("")
    line = refused_in_one_line([f"{HERE}:ExactSolver", "--cases", CASE, "--csv", str(tmp_path / "afile" / "x.csv")],
                               capsys)
    assert "afile' is a file, not a folder" in line


@pytest.mark.parametrize("argv, words", [
    (["no-such-solver"], "unknown solver 'no-such-solver'"),
    ([f"{HERE}:ExactSolver", "--params", '{"nope": 1}'], "has no parameter 'nope'"),
])
def test_list_refuses_what_a_run_refuses(argv: list[str], words: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert words in refused_in_one_line([*argv, "--list", "--cases", CASE], capsys)


def test_validate_list_into_a_closed_pipe_exits_quietly() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "contactbench.harness.cli", "validate", "--list"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader went away (`| head`) before the first line
    err = proc.stderr.read().decode()
    assert proc.wait() == 141 and "Traceback" not in err, err


# ---------------------------------------------------------------------------
# docs/adding-a-solver.md says what the command does
# ---------------------------------------------------------------------------


def test_the_doc_names_every_group_of_the_battery_and_shows_todays_summary_line() -> None:
    text = (ROOT / "docs" / "adding-a-solver.md").read_text()
    section = text[text.index("It runs the solver through the battery"):text.index("Every answer is judged")]
    assert f"The groups, for `--group`: {', '.join(cf.BATTERY_GROUPS)}." in " ".join(section.split()), section
    summary = next(line.strip() for line in text.splitlines() if line.strip().startswith("example-apg [fast]:"))
    assert re.fullmatch(r"example-apg \[fast\]: CONFORMS: every solve correct to its promise \(exact; (\d+) of \1\)"
                        r"(, \d+ stopped at the limit of iteration-limit as asked)? "
                        r"\(rows: pass \d+(, unconverged \d+)?(, skipped \d+)?\)", summary), summary


#: What the threads ``LeavesAThread`` starts wait on (never set: the worker's end ends them).
NEVER = threading.Event()


class LeavesAThread(ExactSolver):
    """Right answers, and a thread left running after each solve; its message names the
    process and how many such threads it found there at its start."""

    name = "test-attack-leaves-a-thread"

    def iterate(self, ctx: SolveContext) -> Outcome:
        found = sum(t.name == "left-behind" for t in threading.enumerate())
        threading.Thread(target=NEVER.wait, args=(120,), name="left-behind", daemon=True).start()
        return Outcome(exact_p(ctx), 1, True, f"pid {os.getpid()}, found {found}")


def test_a_solve_that_leaves_a_thread_running_is_wrong_and_the_next_case_gets_a_fresh_worker() -> None:
    """A thread a solver leaves could write into its problem while the judge reads it: the
    row is WRONG, naming the thread, and the worker is not reused (the next solve finds no
    thread of the last one)."""
    spec = two_groups()[0].spec
    runner = cf.CaseRunner(LeavesAThread(), 20.0, isolate=True)
    try:
        first, second = runner.solve(spec, 0), runner.solve(spec, 0)
    finally:
        runner.close()
    assert "left 1 thread" in first.threads_left and "'left-behind'" in first.tampered
    assert second.message.endswith("found 0") and second.message.split(",")[0] != first.message.split(",")[0]
    table = cf.validate(LeavesAThread(), two_groups()[:1])
    assert [r.status for r in table.rows] == ["WRONG"] and table.exit_code() == 1, table.format()


class RaisesKeyboardInterrupt(ExactSolver):
    """Raises KeyboardInterrupt itself: in a worker, which ignores SIGINT, no user pressed Ctrl-C."""

    name = "test-attack-raises-keyboard-interrupt"

    def iterate(self, ctx: SolveContext) -> Outcome:
        raise KeyboardInterrupt


def test_a_keyboard_interrupt_a_solver_raises_in_a_worker_is_its_crash(capfd: pytest.CaptureFixture[str]) -> None:
    table = cf.validate(RaisesKeyboardInterrupt(), cases(), isolate=True)
    row = table.rows[0]
    assert row.status == "crashed" and "KeyboardInterrupt" in row.message, table.format()
    assert "worker exited" not in row.message and "Traceback" not in capfd.readouterr().err
