"""Answers built to fool the judge get exactly the verdict the rules give (docs/verdicts.md),
through the judge, `run`, `validate` (Python API and CLI exit code) and pytest-benchmark's
``settle`` alike; and an outside program that writes "solved" over a clipped answer is
caught by ``validate --command``."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.command import main as validate_main
from contactbench.harness.judging import ProblemSeal, judge
from contactbench.harness import get_profile
from contactbench.harness.pytest_plugin import settle
from contactbench.problems.instances import QP, counterexample
from contactbench.problems.kkt import kkt_figures, scaled_kkt_error
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operators import DenseOperator
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver
from contactbench.solvers.base import check_promise
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.helpers import REPO

HERE = __name__
ROOT = REPO
CASE = "random/spd-n30-s0*"  # one small dense LCP of the battery (n = 30, one step)
TOL = get_profile("mid").check_tol


def exact_of(H: np.ndarray, ubar: np.ndarray) -> np.ndarray:
    return exact_solution(H, np.asarray(ubar, dtype=np.float64)).p


def forge(kind: str, p: np.ndarray) -> np.ndarray:
    """The adversarial answer ``kind`` made from the exact answer ``p``."""
    q = p.copy()
    top = int(np.argmax(p))
    if kind == "exact":
        return q
    if kind == "nan":
        return np.full_like(p, np.nan)
    if kind in ("posinf", "neginf"):
        q[top] = np.inf if kind == "posinf" else -np.inf
        return q
    if kind == "big300":
        q[int(np.argmin(p))] = 1e300
        return q
    if kind == "big308":
        return np.full_like(p, 1e308)
    if kind == "subnormal":
        return p * 1e-310
    if kind == "negative":
        q[int(np.argmin(p))] = -np.max(p)
        return q
    if kind == "dtype":
        return np.array([str(x) for x in p], dtype=object)
    if kind == "shape":
        return p[:-1]
    if kind == "permuted":
        return p[np.roll(np.arange(p.size), 1)]
    if kind in ("up", "down"):
        return p * (1.0 + (1e-3 if kind == "up" else -1e-3))
    raise KeyError(kind)


#: Each answer and what the rules make of it: (status, reading when claimed, reading when not).
FAILED = ("failed", "wrong", "unconverged")
INACCURATE = ("inaccurate", "wrong", "unconverged")
RULES = {
    "exact": ("solved", "pass", "pass"),
    "nan": FAILED, "posinf": FAILED, "neginf": FAILED, "dtype": FAILED, "shape": FAILED,
    "big300": INACCURATE, "big308": INACCURATE, "subnormal": INACCURATE, "negative": INACCURATE,
    "permuted": INACCURATE, "up": INACCURATE, "down": INACCURATE,
    "forged_w": INACCURATE,  # half the answer with w = 0 claimed: the judge computes its own w
    "mutate": ("failed", "wrong", "wrong"),  # wrote into its problem: wrong, claimed or not
}
#: validate's row status of each reading.
ROW = {"pass": "pass", "wrong": "WRONG", "unconverged": "unconverged"}


class Adversary(Solver):
    """Returns ``forge(kind, exact answer)``, claiming convergence when ``claim``."""

    family = "test"
    kind = "exact"
    claim = True
    capabilities = Capabilities(needs_dense=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        H = ctx.qp.H.to_dense()
        p = exact_of(H, ctx.qp.ubar)
        if self.kind == "forged_w":
            return Outcome(0.5 * p, 1, self.claim, w=np.zeros_like(p))
        if self.kind == "mutate":
            ubar = ctx.qp.ubar
            ubar *= 0.5  # writes into the problem it was handed, then solves the easier problem
            return Outcome(exact_of(H, ubar), 1, self.claim)
        return Outcome(forge(self.kind, p), 1, self.claim)


def _adversary(kind: str, claim: bool) -> type[Adversary]:
    name = f"Adv_{kind}_{'claimed' if claim else 'unclaimed'}"
    cls = type(name, (Adversary,), {"kind": kind, "claim": claim, "name": f"adv-{kind}-{'c' if claim else 'u'}"})
    cls.__module__ = HERE
    globals()[name] = cls
    return cls


ADVERSARIES = {(k, c): _adversary(k, c) for k in RULES for c in (True, False)}
PAIRS = sorted(ADVERSARIES)


def expected(kind: str, claim: bool) -> tuple[str, str]:
    status, claimed, unclaimed = RULES[kind]
    return status, claimed if claim else unclaimed


# ---------------------------------------------------------------------------
# The figures and the judge
# ---------------------------------------------------------------------------


def test_overflow_and_nan_only_make_the_figures_worse() -> None:
    ubar, diag = np.array([1.0, -1.0, 0.5]), 2.0
    for p, w in [(np.array([1e308, 0.0, 0.0]), np.array([1e308, 0.0, 0.0])),
                 (np.array([np.nan, 0.0, 0.0]), np.zeros(3)),
                 (np.array([1.0, 0.0, 0.0]), np.array([np.inf, 0.0, -np.inf])),
                 (np.array([1e200, 0.0, 1e200]), np.array([1e200, 1.0, 1e-200]))]:
        f = kkt_figures(p, w, ubar, diag)
        assert f.kkt_error == np.inf and scaled_kkt_error(p, w, ubar, diag) == np.inf
    # the scales are the problem's: a huge candidate does not shrink its own residuals
    a = kkt_figures(np.array([1.0, 0, 0]), np.array([0.0, 1.0, 0.1]), ubar, diag)
    b = kkt_figures(np.array([1e100, 0, 0]), np.array([0.0, 1e100, 0.1]), ubar, diag)
    assert a.u_scale == b.u_scale == 1.0 and a.p_scale == b.p_scale == 0.5


@pytest.fixture(scope="module")
def ex1() -> tuple[object, np.ndarray]:
    inst = counterexample(36, 1)
    return inst, exact_of(inst.qp.H.to_dense(), inst.qp.ubar)


@pytest.mark.parametrize("kind, claim", [pc for pc in PAIRS if pc[0] not in ("forged_w", "mutate")])
def test_the_judge_gives_each_forged_answer_its_verdict(ex1, kind: str, claim: bool) -> None:
    inst, p = ex1
    v = judge(inst, forge(kind, p), claim, TOL)
    assert (v.status, v.reading) == expected(kind, claim), v.message()
    assert v.status == "solved" or not v.kkt_error <= TOL


def test_a_solver_that_writes_into_its_problem_is_caught_by_the_seal(ex1) -> None:
    inst, p = ex1
    qp = QP(DenseOperator(inst.qp.H.to_dense()), inst.qp.ubar.copy(), inst.qp.geometry)
    seal = ProblemSeal.of(qp)
    assert seal.broken(qp) == ""
    qp.ubar[0] += 1e-12
    assert "ubar" in seal.broken(qp)
    v = judge(inst, p, False, TOL, tampered=seal.broken(qp))
    assert (v.status, v.reading, v.tampered) == ("failed", "wrong", True)
    seal = ProblemSeal.of(qp)
    qp.H.H.flags.writeable = True  # (read-only, but a view: a solver can make it writeable)
    qp.H.H[3, 3] *= 1.0 + 1e-15  # the dense operator's matrix
    assert "H.H" in seal.broken(qp)
    fft = counterexample(36, 1, operator="fft").qp
    seal = ProblemSeal.of(fft)
    table = fft.H.transform.table
    old = float(table.flat[0])
    table.flat[0] = old * (1.0 + 1e-15) + 1e-300  # the FFT operator's kernel table
    try:
        assert "H.transform.table" in seal.broken(fft)
    finally:
        table.flat[0] = old
    assert seal.broken(fft) == ""


@settings(max_examples=40, deadline=None)
@given(scale=st.floats(min_value=1e-300, max_value=1e300).filter(lambda c: abs(c - 1.0) >= 1e-3),
       spike=st.floats(min_value=1e3, max_value=1.7e308), index=st.integers(min_value=0, max_value=35),
       claim=st.booleans())
def test_no_scaled_or_spiked_answer_is_ever_solved(ex1, scale: float, spike: float, index: int, claim: bool) -> None:
    inst, p = ex1
    for q in (p * scale, np.where(np.arange(p.size) == index, spike * np.max(p), p)):
        v = judge(inst, q, claim, TOL)
        assert v.status == "inaccurate" and v.reading == ("wrong" if claim else "unconverged")


@settings(max_examples=30, deadline=None)
@given(bad=st.sampled_from([np.nan, np.inf, -np.inf]), index=st.integers(min_value=0, max_value=35),
       claim=st.booleans())
def test_any_non_finite_entry_is_no_answer(ex1, bad: float, index: int, claim: bool) -> None:
    inst, p = ex1
    q = p.copy()
    q[index] = bad
    v = judge(inst, q, claim, TOL)
    assert (v.status, v.reading) == ("failed", "wrong" if claim else "unconverged")


def test_the_lifecycle_keeps_a_claim_on_a_non_finite_answer(ex1) -> None:
    inst, _ = ex1
    res = Adv_nan_claimed().solve(inst.qp)  # noqa: F821 -- made by _adversary
    assert res.converged and res.status == "converged"
    res = Adv_nan_unclaimed().solve(inst.qp)  # noqa: F821
    assert not res.converged and res.status == "failed"


# ---------------------------------------------------------------------------
# validate (Python API, CLI exit code) and pytest-benchmark's settle
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tables() -> dict[tuple[str, bool], cf.VerdictTable]:
    cases = cf.conformance_cases("fast", pattern=CASE)
    assert len(cases) == 1
    return {pc: cf.validate(cls(), cases) for pc, cls in ADVERSARIES.items()}


@pytest.mark.parametrize("kind, claim", PAIRS)
def test_validate_gives_each_adversary_its_verdict(tables, kind: str, claim: bool) -> None:
    table = tables[(kind, claim)]
    reading = expected(kind, claim)[1]
    (row,) = table.rows
    assert row.status == ROW[reading], table.format()
    outcome = {"pass": "conforms", "wrong": "wrong", "unconverged": "incomplete"}[reading]
    assert table.outcome() == outcome and table.outcome(strict=True) == outcome
    assert table.exit_code() == {"conforms": 0, "wrong": 1, "incomplete": 3}[outcome]
    assert ("CONFORMS" in table.summary()) == (outcome == "conforms")


@pytest.mark.parametrize("kind", ["exact", "nan", "big308", "shape", "mutate"])
@pytest.mark.parametrize("claim", [True, False])
def test_validate_cli_exit_code(kind: str, claim: bool, capsys: pytest.CaptureFixture[str]) -> None:
    reading = expected(kind, claim)[1]
    name = ADVERSARIES[(kind, claim)].__name__
    rc = validate_main([f"{HERE}:{name}", "--cases", CASE, "--quiet"])
    assert rc == {"pass": 0, "wrong": 1, "unconverged": 3}[reading], capsys.readouterr().out


def test_settle_gives_each_reading_its_pytest_outcome(ex1) -> None:
    inst, p = ex1
    for kind, claim in PAIRS:
        if kind in ("forged_w", "mutate"):
            continue
        v = judge(inst, forge(kind, p), claim, TOL)
        reading = expected(kind, claim)[1]
        if reading == "pass":
            settle(v, kind)
        elif reading == "wrong":
            with pytest.raises(pytest.fail.Exception, match="wrong"):
                settle(v, kind)
        else:
            with pytest.raises(pytest.xfail.Exception):
                settle(v, kind)


def test_a_solver_that_promises_a_floor_is_held_to_it() -> None:
    assert check_promise("exact") == "exact" and check_promise(1e-7) == 1e-7
    for bad in ("approximate", 0.0, -1.0, float("nan"), True):
        with pytest.raises(ValueError, match="promise"):
            check_promise(bad)
    assert Capabilities(promise=1e-4).promised_tol(1e-8) == 1e-4
    assert Capabilities().promised_tol(1e-8) == 1e-8


# ---------------------------------------------------------------------------
# run
# ---------------------------------------------------------------------------


def test_run_gives_each_adversary_its_verdict(run_harness) -> None:
    names = {f"{HERE}:{cls.__name__}": pc for pc, cls in ADVERSARIES.items()}
    table = run_harness(["paper-sweep"], solvers=list(names), size=16, steps=2, profiles=("mid",),
                        reference="none", warmup=False, timeout=60.0)
    assert len(table) == 2 * len(names)
    for label, (kind, claim) in names.items():
        rows = table[table["solver"] == ADVERSARIES[(kind, claim)].name]
        assert len(rows) == 2, label
        want = expected(kind, claim)
        got = set(zip(rows["status"], rows["verdict"]))
        assert got == {want}, (label, got)
        if want[0] != "solved":
            assert not (rows["kkt_error"].astype(float) <= TOL).any(), label


# ---------------------------------------------------------------------------
# The file protocol: an outside program that writes "solved" over a clipped answer
# ---------------------------------------------------------------------------

CLIPPER = textwrap.dedent('''
    import json, os, sys
    import numpy as np
    problem, solution = sys.argv[1], sys.argv[2]
    head = json.load(open(os.path.join(problem, "problem.json")))
    n = head["n"]
    H = np.fromfile(os.path.join(problem, "H.f64"), dtype="<f8").reshape(n, n)
    ubar = np.fromfile(os.path.join(problem, "ubar.f64"), dtype="<f8")
    p = np.maximum(np.linalg.solve(H, ubar), 0.0)  # the classic wrong answer
    p.astype("<f8").tofile(os.path.join(solution, "p.f64"))
    json.dump({"status": sys.argv[3], "iterations": 1}, open(os.path.join(solution, "solution.json"), "w"))
''')


@pytest.mark.parametrize("word, code", [("solved", 1), ("optimal", 1), ("converged", 1), ("not_converged", 3),
                                        ("done", 3)])
def test_an_outside_program_claiming_solved_over_a_clipped_answer_exits_1(
        tmp_path: Path, word: str, code: int, capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / "clipper.py"
    script.write_text(CLIPPER)
    rc = validate_main(["--command", f"{sys.executable} {script} {{problem}} {{solution}} {word}",
                  "--cases", "counterexample/*-s0"])
    out = capsys.readouterr().out
    assert rc == code, out
    if word == "done":  # not a protocol word: a clear error naming the allowed words, never "not converged"
        assert "not a protocol word" in out and "solved" in out


# ---------------------------------------------------------------------------
# docs/verdicts.md: every shell command shown there runs as shown
# ---------------------------------------------------------------------------


def shell_commands() -> list[tuple[str, int]]:
    """(command, exit status) of each ``$ command`` line of docs/verdicts.md, the status
    from the ``# exit N`` comment that follows it."""
    text = (ROOT / "docs" / "verdicts.md").read_text()
    return [(m.group(1).strip(), int(m.group(2))) for m in re.finditer(r"^\$ (.+?)\s+# exit (\d)$", text, re.MULTILINE)]


@pytest.mark.slow
def test_docs_verdicts_shell_commands_run_with_their_exit_status() -> None:
    commands = shell_commands()
    assert len(commands) >= 3
    for command, code in commands:
        env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
        proc = subprocess.run(command, shell=True, cwd=ROOT, capture_output=True, text=True, timeout=300, env=env,
                              check=False)
        assert proc.returncode == code, (command, proc.stdout[-2000:], proc.stderr[-2000:])


@pytest.mark.parametrize("field, value", [("tol", float("nan")), ("tol", -1.0), ("tol", 0.0), ("check_tol", float("inf")),
                                          ("max_iter", -5), ("max_iter", 2.5), ("max_iter", "10"),
                                          ("time_limit", float("nan")), ("time_limit", -1.0)])
def test_settings_that_cannot_be_meant_are_refused_naming_the_field(field: str, value: object) -> None:
    """nnls at tol -1 crashed inside numpy; pk at tol NaN ran 100,000 iterations; max_iter -5
    gave iterations = -5; time_limit NaN meant no limit."""
    from contactbench.problems.errors import ProblemInputError
    from contactbench.solvers import SolverSettings

    with pytest.raises(ProblemInputError, match=f"SolverSettings.{field}"):
        SolverSettings(**{field: value})  # type: ignore[arg-type]


@pytest.mark.parametrize("check_tol", [float("inf"), float("nan"), -1.0, 0.0])
def test_the_judge_refuses_a_check_tol_that_would_pass_or_fail_everything(check_tol: float) -> None:
    from contactbench.harness.judging import judge
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.instances import counterexample

    inst = counterexample(16, 0)
    with pytest.raises(ProblemInputError, match="check_tol"):
        judge(inst, np.zeros(inst.n), True, check_tol=check_tol)


# ---------------------------------------------------------------------------
# Methods replaced, and writes in the untimed solves of a run
# ---------------------------------------------------------------------------


def test_a_product_replaced_on_the_operator_or_its_class_is_caught_and_put_back(ex1) -> None:
    """A solver that swaps the product the judge runs (on the object, or on its class for
    the whole process) would make any answer pass: the seal names it, and ``mend`` puts the
    sealed code back for the judge and the solves after it."""
    inst, p = ex1
    qp = QP(DenseOperator(inst.qp.H.to_dense()), inst.qp.ubar.copy(), inst.qp.geometry)
    honest = qp.H.matvec(p)
    seal = ProblemSeal.of(qp)
    qp.H.matvec = lambda x: qp.ubar.copy()  # every candidate has w = 0
    assert "H.matvec" in seal.broken(qp)
    seal.mend(qp)
    assert seal.broken(qp) == "" and np.array_equal(qp.H.matvec(p), honest)
    original = DenseOperator.matvec
    try:
        seal = ProblemSeal.of(qp)
        DenseOperator.matvec = lambda self, x: qp.ubar.copy()
        assert "DenseOperator.matvec" in seal.broken(qp)
        seal.mend(qp)
        assert DenseOperator.matvec is original and seal.broken(qp) == ""
    finally:
        DenseOperator.matvec = original


class WritesInItsWarmUp(Solver):
    """Doubles the dense H it is handed the first time it runs in a process (the untimed
    warm-up of a run), then answers the problem it was handed, claimed."""

    name = "test-writes-in-warm-up"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True)
    wrote = False

    def iterate(self, ctx: SolveContext) -> Outcome:
        H = ctx.qp.H.to_dense()
        if not WritesInItsWarmUp.wrote:
            WritesInItsWarmUp.wrote = True
            H.flags.writeable = True  # DenseOperator.to_dense: the operator's own matrix, read-only, a view
            H *= 2.0
        return Outcome(exact_of(H, ctx.qp.ubar), 1, True)


def test_a_write_in_the_untimed_warm_up_is_the_solver_s_and_no_other_solver_s(run_harness) -> None:
    """The warm-up is sealed as the timed solve is: the writer's row is wrong, and the
    solver after it in the same worker gets the problem rebuilt (its error in p small, not 0.5)."""
    table = run_harness(["counterexample"], solvers=[f"{HERE}:WritesInItsWarmUp", "pk"], size=10, seeds=(0,),
                        profiles=("mid",), reference="nnls", warmup=True, timeout=60.0)
    writer = table[table["solver"] == WritesInItsWarmUp.name]
    assert set(zip(writer["status"], writer["verdict"])) == {("failed", "wrong")}, writer["error"].tolist()
    assert writer["error"].str.contains("wrote into the problem").all()
    pk = table[table["solver"] == "pk"]
    assert (pk["status"] == "solved").all() and (pk["p_rel_error"].astype(float) < 1e-3).all()  # (0.5 on 2H)


class ChangesProcessState(Solver):
    """Answers right, claimed, after moving the working folder, raising on every floating
    point error and setting an environment variable: its own business, not the run's."""

    name = "test-changes-process-state"
    family = "test"
    capabilities = Capabilities(needs_dense=False)
    elsewhere = ""

    def iterate(self, ctx: SolveContext) -> Outcome:
        os.chdir(self.elsewhere or os.path.expanduser("~"))
        np.seterr(all="raise")
        os.environ["CONTACTBENCH_TEST_LEFT_BEHIND"] = "1"
        return Outcome(exact_of(ctx.qp.H.to_dense(), ctx.qp.ubar), 1, True)


class UnderflowsHarmlessly(Solver):
    """Answers right, claimed, after an underflow NumPy ignores by default."""

    name = "test-underflows-harmlessly"
    family = "test"
    capabilities = Capabilities(needs_dense=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        np.exp(-1000.0 * np.ones(3))
        assert "CONTACTBENCH_TEST_LEFT_BEHIND" not in os.environ
        return Outcome(exact_of(ctx.qp.H.to_dense(), ctx.qp.ubar), 1, True)


def test_what_a_solver_changes_in_its_worker_is_put_back_after_it(run_harness, tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A solver's os.chdir, np.seterr and os.environ stay its own: the harness's own writes
    after it (references, field arrays, relative to the working folder) land in the run's
    folder, and the solver after it in the same worker runs as it would alone."""
    monkeypatch.chdir(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.setattr(ChangesProcessState, "elsewhere", str(elsewhere))
    table = run_harness(["paper-sweep"], solvers=[f"{HERE}:ChangesProcessState", f"{HERE}:UnderflowsHarmlessly", "pk"], out="run",
                        size=16, steps=2, profiles=("mid",), reference="nnls", warmup=False, timeout=60.0)
    assert (table["status"] == "solved").all(), table[["solver", "status", "error"]].to_string()
    assert table["p_rel_error"].astype(float).notna().all()
    assert not any(elsewhere.iterdir()), sorted(p.name for p in elsewhere.rglob("*"))
