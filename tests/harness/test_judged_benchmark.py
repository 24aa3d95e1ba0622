"""Judged pytest-benchmark timings (``harness.judged_benchmark``): a timing counts only
when the judge passes every answer timed, a user's own benchmark included, and every
solve is handed a problem no earlier solve saw, so a solver that caches answers across
solves gets no fake timing."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness.judged_benchmark import (
    PASSED_KEY,
    JudgedBenchmark,
    exclude_unpassed,
    keep_judged,
    round_factor,
    scaled_instance,
)
from contactbench.problems.instances import ContactInstance, InstanceBuilder, counterexample
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.surfaces import Surface, fourier_synthesis
from contactbench.solvers import Capabilities, Outcome, Solver
from contactbench.solvers.base import SolveContext
from tests.helpers import REPO, dense_exact_solution


@dataclass
class FakeBenchmark:
    """What ``JudgedBenchmark`` uses of pytest-benchmark's fixture: ``pedantic`` runs the
    warm-up and the rounds as pytest-benchmark does (setup, the call, teardown)."""

    has_error: bool = False
    extra_info: dict[str, Any] = field(default_factory=dict)
    disabled: bool = False
    times: list[float] = field(default_factory=list)

    def pedantic(self, target: Callable[..., Any], setup: Callable[[], Any], teardown: Callable[..., None],
                 rounds: int, iterations: int, warmup_rounds: int) -> Any:
        if self.disabled:  # (one call, no teardown: pytest-benchmark's --benchmark-disable)
            args, kwargs = setup()
            return target(*args, **kwargs)
        try:
            for k in range(warmup_rounds + rounds):
                args, kwargs = setup()
                t0 = time.perf_counter()
                result = target(*args, **kwargs)
                if k >= warmup_rounds:
                    self.times.append(time.perf_counter() - t0)
                teardown(*args, **kwargs)
            return result
        except Exception:
            self.has_error = True
            raise

    def row(self) -> dict[str, Any]:
        """The flat record ``pytest_benchmark_group_stats`` gets."""
        return {"name": "bench", "extra_info": dict(self.extra_info)}  # (no has_error, as pytest-benchmark's)


class Exact(Solver):
    """The exact answer of any problem (bounds and load equality included)."""

    name = "test-judged-exact"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True, input_format="dense", load_control=True, bounds=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        qp = ctx.qp
        if qp.constraints.plain:
            return Outcome(dense_exact_solution(qp), 1, True)
        ref = constrained_exact_solution(qp.H.to_dense(), np.asarray(qp.ubar, float), qp.constraints)
        return Outcome(ref.p, 1, True, multiplier=ref.multiplier)


class Wrong(Solver):
    """Claims p = 1e-3 everywhere converged."""

    name = "test-judged-wrong"
    family = "test"
    capabilities = Capabilities(input_format="dense")

    def iterate(self, ctx: SolveContext) -> Outcome:
        return Outcome(np.full(ctx.n, 1e-3), 1, True)


class Memo(Exact):
    """The exact answer, memoised across solves by the bytes of ubar (``seen`` counts the
    solves of each ubar); a miss sleeps ``miss`` seconds, a long solve."""

    name = "test-judged-memo"
    miss = 0.0

    def __init__(self) -> None:
        super().__init__()
        self.memo: dict[bytes, np.ndarray] = {}
        self.seen: dict[bytes, int] = {}

    def key(self, ubar: np.ndarray) -> bytes:
        return np.asarray(ubar, float).tobytes()

    def iterate(self, ctx: SolveContext) -> Outcome:
        key = self.key(ctx.qp.ubar)
        self.seen[key] = self.seen.get(key, 0) + 1
        if key not in self.memo:
            time.sleep(self.miss)
            self.memo[key] = dense_exact_solution(ctx.qp)
        return Outcome(self.memo[key] * self.scale(ctx.qp.ubar), 1, True)

    def scale(self, ubar: np.ndarray) -> float:
        return 1.0


class NormalisedMemo(Memo):
    """Memoises the answer of ubar / ||ubar|| and scales it back: a scaled problem hits."""

    name = "test-judged-normalised-memo"
    miss = 0.05

    def key(self, ubar: np.ndarray) -> bytes:
        u = np.asarray(ubar, float)
        return np.round(u / np.linalg.norm(u), 12).tobytes()

    def iterate(self, ctx: SolveContext) -> Outcome:
        key = self.key(ctx.qp.ubar)
        if key not in self.memo:
            time.sleep(self.miss)
            u = np.asarray(ctx.qp.ubar, float)
            self.memo[key] = dense_exact_solution(ctx.qp) / np.linalg.norm(u)
        return Outcome(self.memo[key] * np.linalg.norm(np.asarray(ctx.qp.ubar, float)), 1, True)


class SlowFirstCall(Exact):
    """A one-off cost in its first call ever (a compile, a device context), then exact."""

    name = "test-judged-slow-first-call"

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def iterate(self, ctx: SolveContext) -> Outcome:
        self.calls += 1
        time.sleep(0.2 if self.calls == 1 else 0.005)  # (every solve takes a while: a stable ratio)
        return super().iterate(ctx)


@pytest.fixture(scope="module")
def inst() -> ContactInstance:
    return counterexample(49, seed=1)


def load_instance() -> ContactInstance:
    """A load-controlled instance with hardness bounds (n = 144)."""
    E, side = 1e9, 12
    surface = fourier_synthesis(side, 0.8, 0.1, length=1e-4, seed=3)
    builder = InstanceBuilder(surface, E, operator="dense")
    plain = builder.build_load(4e-4 * E * (side * surface.delta) ** 2)
    p = constrained_exact_solution(plain.qp.H.to_dense(), np.asarray(plain.qp.ubar, float), plain.qp.constraints).p
    hardness = 0.8 * float(np.max(p)) / surface.delta**2
    return builder.build_load(4e-4 * E * (side * surface.delta) ** 2, hardness=hardness)


# -- a wrong answer's timing never counts ----------------------------------------------


def test_a_wrong_answers_row_is_not_kept() -> None:
    bench = FakeBenchmark()
    with pytest.raises(pytest.fail.Exception, match="kkt_error"):
        JudgedBenchmark(bench).run(Wrong(), counterexample(49, seed=1), rounds=2)
    assert bench.has_error and bench.extra_info[PASSED_KEY] is False
    assert keep_judged([("g", [bench.row()])]) == []


def test_a_benchmark_row_counts_only_once_passed(inst: ContactInstance) -> None:
    bench = FakeBenchmark()
    judged = JudgedBenchmark(bench)
    assert bench.has_error and keep_judged([("g", [bench.row()])]) == []
    verdict = judged.run(Exact(), inst, rounds=2)
    assert verdict.reading == "pass" and not bench.has_error and bench.extra_info[PASSED_KEY] is True
    assert keep_judged([("g", [bench.row()])]) == [("g", [bench.row()])]


def test_a_plain_benchmark_rows_has_error_is_set_when_its_test_does_not_pass() -> None:
    """A user's test that times with the plain ``benchmark`` fixture and settles the
    verdict after it: its failure (or xfail) sets ``has_error``; a pass leaves it."""

    @dataclass
    class Item:
        funcargs: dict[str, Any]

    def Report(when: str, passed: bool, **xfail: str) -> SimpleNamespace:  # noqa: N802
        return SimpleNamespace(when=when, passed=passed, **xfail)  # (wasxfail only on an xfail, as pytest's)

    def after(report: SimpleNamespace) -> bool:
        bench = FakeBenchmark()
        exclude_unpassed(Item({"benchmark": bench}), report)
        assert bench.has_error is (keep_judged([("g", [bench.row()])]) == [])
        return bench.has_error

    assert after(Report("call", False))
    assert after(Report("call", False, wasxfail="unconverged"))
    assert after(Report("teardown", False))
    assert not after(Report("call", True))
    assert not after(Report("setup", True))
    exclude_unpassed(Item({}), Report("call", False))  # (no benchmark: nothing to do)
    assert keep_judged([("g", [{"has_error": True, "extra_info": {}}])]) == []


PLUGIN = '''
import pytest

from contactbench.harness.judged_benchmark import JudgedBenchmark, exclude_unpassed, keep_judged


@pytest.fixture
def judged(benchmark):
    return JudgedBenchmark(benchmark)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    exclude_unpassed(item, report)
    return report


@pytest.hookimpl(wrapper=True)
def pytest_benchmark_group_stats(config, benchmarks, group_by):
    return keep_judged((yield))
'''

USER_BENCH = '''
import copy

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.harness.pytest_plugin import settle
from contactbench.problems.instances import counterexample
from contactbench.solvers import Capabilities, Outcome, Solver
from tests.helpers import dense_exact_solution


class Answer(Solver):
    family = "test"
    capabilities = Capabilities(input_format="dense")
    right = True

    def iterate(self, ctx):
        return Outcome(dense_exact_solution(ctx.qp) if self.right else np.full(ctx.n, 1e-3), 1, True)


class WrongAnswer(Answer):
    right = False


INST = counterexample(25, seed=1)


@pytest.mark.parametrize("right", [True, False], ids=["right", "wrong"])
def test_plain(benchmark, right):
    solver = Answer() if right else WrongAnswer()
    res = benchmark.pedantic(lambda: solver.solve(copy.deepcopy(INST.qp), None), rounds=2, iterations=1)
    settle(judge(INST, res.p, bool(res.converged), 1e-8), "user bench", res.message)


@pytest.mark.parametrize("right", [True, False], ids=["right", "wrong"])
def test_judged(judged, right):
    judged.run(Answer() if right else WrongAnswer(), INST, rounds=2)
'''


def test_a_users_own_benchmark_keeps_a_wrong_answers_row_out(tmp_path: Path) -> None:
    """pytest with the hooks the plugin runs: a wrong answer, timed by the plain
    ``benchmark`` fixture or by ``JudgedBenchmark.run``, is in neither the table nor the
    JSON; the right ones are in both."""
    (tmp_path / "judged_hooks.py").write_text(PLUGIN)
    (tmp_path / "test_user_bench.py").write_text(USER_BENCH)
    out = tmp_path / "b.json"
    env = {"PYTHONPATH": f"{tmp_path}:{REPO}", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "PATH": "/usr/bin:/bin"}
    cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "judged_hooks", "-q", "-rA",
           "--benchmark-only", "--benchmark-enable", f"--benchmark-json={out}", str(tmp_path / "test_user_bench.py")]
    done = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=240, check=False)
    text = done.stdout + done.stderr
    assert "2 failed, 2 passed" in text, text
    timed = sorted(b["name"] for b in json.loads(out.read_text())["benchmarks"])
    assert timed == ["test_judged[right]", "test_plain[right]"], text
    rows = sorted(line.split()[0] for line in text.splitlines() if line.startswith(("test_plain[", "test_judged[")))
    assert rows == timed, text


# -- every solve is handed a problem no earlier solve saw --------------------------------


def test_each_solve_is_handed_a_problem_no_earlier_solve_saw(inst: ContactInstance) -> None:
    solver = Memo()
    JudgedBenchmark(FakeBenchmark()).run(solver, inst, rounds=3, warmup_speedup=None)  # (no timing read here)
    assert len(solver.seen) == 4 and set(solver.seen.values()) == {1}  # the warm-up and 3 rounds
    assert inst.qp.ubar.tobytes() not in solver.seen  # nor the instance as built


def test_the_benchmark_suite_hands_each_round_its_own_problem(tmp_path: Path) -> None:
    """benchmarks/test_bench_solvers.py with a solver that records each ubar it is handed:
    the warm-up and the 2 timed rounds (and any solve the cache check adds on a loaded
    machine) each see a different one."""
    record = tmp_path / "seen.txt"
    (tmp_path / "judged_recorder.py").write_text(f'''
import hashlib

import numpy as np

from contactbench.solvers import Capabilities, Outcome, Solver, register
from tests.helpers import dense_exact_solution


@register(replace=True)
class Recorder(Solver):
    name = "test-judged-recorder"
    family = "test"
    capabilities = Capabilities(needs_dense=True, exact=True, input_format="dense")

    def iterate(self, ctx):
        with open({str(record)!r}, "a") as f:
            f.write(hashlib.sha1(np.asarray(ctx.qp.ubar, float).tobytes()).hexdigest() + "\\n")
        return Outcome(dense_exact_solution(ctx.qp), 1, True)
''')
    env = {"PYTHONPATH": f"{tmp_path}:{REPO}", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "PATH": "/usr/bin:/bin", "CONTACTBENCH_BENCH_ROUNDS": "2"}
    cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "judged_recorder", "-q",
           "--benchmark-only", "--benchmark-enable", "benchmarks/test_bench_solvers.py",
           "-k", "test-judged-recorder and counterexample"]
    done = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=240, check=False)
    text = done.stdout + done.stderr
    assert "1 passed" in text, text
    seen = record.read_text().split()
    assert len(seen) >= 3 and len(set(seen)) == len(seen), (seen, text)


@pytest.mark.parametrize("which", ["plain", "load-and-bounds"])
def test_the_scaled_problems_are_the_instance_and_each_answer_is_judged(inst: ContactInstance, which: str) -> None:
    """Scaling keeps the problem equivalent: the exact answer passes every solve (bounds
    and load scaled alike), each against the reference scaled alike, and the figures
    reported are the instance's own."""
    case = inst if which == "plain" else load_instance()
    c = case.qp.constraints
    ref = (dense_exact_solution(case.qp) if c.plain else
           constrained_exact_solution(case.qp.H.to_dense(), np.asarray(case.qp.ubar, float), c).p)
    bench = FakeBenchmark()
    verdict = JudgedBenchmark(bench).run(Exact(), case, rounds=3, reference=ref, warmup_speedup=None)
    assert verdict.reading == "pass"
    assert bench.extra_info["solves_judged"] == 4
    assert bench.extra_info["load"] == pytest.approx(float(np.sum(ref)), rel=1e-9)
    assert bench.extra_info["p_rel_error"] < 1e-9
    assert len({round_factor(k, 4) for k in range(5)} | {1.0}) == 6  # (distinct, none the instance's)


def test_a_wrong_answer_in_any_round_fails_naming_it(inst: ContactInstance) -> None:
    class WrongInRound2(Exact):
        calls = 0

        def iterate(self, ctx: SolveContext) -> Outcome:
            type(self).calls += 1
            out = super().iterate(ctx)
            return Outcome(out.p * (1.5 if type(self).calls == 3 else 1.0), 1, True)

    bench = FakeBenchmark()
    with pytest.raises(pytest.fail.Exception, match="in timed round 2"):
        JudgedBenchmark(bench).run(WrongInRound2(), inst, rounds=3, warmup_speedup=None)
    assert bench.has_error


# -- timed rounds far faster than a solve ------------------------------------------------


def test_a_cache_that_survives_the_scaling_fails_the_benchmark(inst: ContactInstance) -> None:
    """Timed rounds > 10x faster than the warm-up and than perturbed problems after them."""
    bench = FakeBenchmark()
    with pytest.raises(pytest.fail.Exception, match="carries work across solves"):
        JudgedBenchmark(bench).run(NormalisedMemo(), inst, rounds=2)
    assert bench.has_error and keep_judged([("g", [bench.row()])]) == []


def test_a_one_off_cost_of_the_first_call_is_not_flagged(inst: ContactInstance) -> None:
    bench = FakeBenchmark()
    verdict = JudgedBenchmark(bench).run(SlowFirstCall(), inst, rounds=2)
    assert verdict.reading == "pass" and not bench.has_error
    assert bench.extra_info["solves_judged"] in (4, 5)  # (the warm-up, 2 rounds and the check's solves)


def test_with_pytest_benchmark_disabled_its_one_solve_is_judged(inst: ContactInstance) -> None:
    bench = FakeBenchmark(disabled=True)
    assert JudgedBenchmark(bench).run(Exact(), inst, rounds=3).reading == "pass"
    assert bench.extra_info["solves_judged"] == 1 and not bench.has_error
    with pytest.raises(pytest.fail.Exception, match="in its one solve"):
        JudgedBenchmark(FakeBenchmark(disabled=True)).run(Wrong(), inst)


def test_the_check_s_problems_are_no_harder_than_the_timed_ones() -> None:
    """A problem at zero gap on a plateau (ubar <= 0, exact zeros: p = 0 at once) with a
    one-off first-call cost: the check's perturbed problems keep every sign and zero, so
    they stay trivial and the solver is not failed as a cache (with additive noise half
    the zeros turned positive: a real solve, 27x the timed rounds)."""
    h = np.minimum(np.random.default_rng(0).standard_normal((32, 32)), 0.0) * 1e-7
    plateau = InstanceBuilder(Surface(h, 1e-6), 1e9, kernel="bcc").build(0.0)
    assert np.max(plateau.qp.ubar) == 0.0
    zero = scaled_instance(plateau, 1.5, 1e-6 * np.random.default_rng(1).standard_normal(plateau.n))
    assert np.array_equal(zero.qp.ubar == 0.0, plateau.qp.ubar == 0.0) and np.max(zero.qp.ubar) == 0.0
    bench = FakeBenchmark()
    assert JudgedBenchmark(bench).run(SlowFirstSolve(), plateau, rounds=2).reading == "pass" and not bench.has_error


class SlowFirstSolve(Exact):
    """A one-off cost in its first ``solve`` ever, before the lifecycle (which answers a
    problem with ubar <= 0 by p = 0 at once)."""

    name = "test-judged-slow-first-solve"

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def solve(self, qp: Any, settings: Any = None, warm: Any = None) -> Any:
        self.calls += 1
        if self.calls == 1:
            time.sleep(0.5)
        return super().solve(qp, settings, warm)
