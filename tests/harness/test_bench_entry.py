"""The pytest-benchmark entry (``pytest --benchmark-only --benchmark-enable benchmarks/``,
benchmarks/test_bench_solvers.py) run in a subprocess on the counterexample (n = 100)
with throw-away ``test-bench-*`` solvers registered through a plugin (``-p``) and a
solver entry point that fails to import: a timing counts only when the judge passes
every solve, the untimed warm-up included; each solve gets its own problem, sealed,
watched for threads and under a hard limit; a solver source that fails to load is a
failing item; a bad setting stops pytest in one line before anything runs."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from tests.helpers import REPO

PLUGIN = '''
import threading
import time

import numpy as np

from contactbench.solvers import Capabilities, Outcome, Solver, register
from tests.helpers import dense_exact_solution


class Counted(Solver):
    """Answers exactly, but for the calls ``wrong_on`` (1: its first solve), where it claims p = 0."""
    family = "test"
    capabilities = Capabilities()
    wrong_on = ()
    calls = 0

    def iterate(self, ctx):
        type(self).calls += 1
        if type(self).calls in self.wrong_on:
            return Outcome(np.zeros(ctx.n), 1, True, "converged")
        return Outcome(self.answer(ctx), 1, True, "converged")

    def answer(self, ctx):
        return dense_exact_solution(ctx.qp)


@register(replace=True)
class Exact(Counted):
    name = "test-bench-exact"


@register(replace=True)
class Zero(Counted):
    name = "test-bench-zero"
    wrong_on = range(1, 100)


@register(replace=True)
class WarmUpWrong(Counted):
    name = "test-bench-warm-up-wrong"
    wrong_on = (1,)


@register(replace=True)
class RoundWrong(Counted):
    name = "test-bench-round-wrong"
    wrong_on = (2,)


@register(replace=True)
class ATamper(Counted):
    """Zeroes the off-diagonal of H in place in its first solve; answers the diagonal problem."""
    name = "test-bench-a-tamper"

    def answer(self, ctx):
        H = ctx.qp.H.to_dense()
        if type(self).calls == 1:
            d = np.diag(H).copy()
            H[...] = 0.0
            H[np.diag_indices_from(H)] = d
        return np.maximum(ctx.qp.ubar / np.diag(H), 0.0)


@register(replace=True)
class BDiagonal(Counted):
    """Answers the diagonal problem (wrong unless H is diagonal), after test-bench-a-tamper."""
    name = "test-bench-b-diagonal"

    def answer(self, ctx):
        return np.maximum(ctx.qp.ubar / ctx.qp.H.diagonal(), 0.0)


@register(replace=True)
class Leaver(Counted):
    name = "test-bench-leaver"

    def answer(self, ctx):
        threading.Thread(target=time.sleep, args=(3.0,), name="test-bench-left-thread", daemon=True).start()
        return dense_exact_solution(ctx.qp)


@register(replace=True)
class Hang(Counted):
    name = "test-bench-hang"

    def answer(self, ctx):
        while True:
            time.sleep(0.05)
'''

BROKEN = 'raise ImportError("test_bench_broken needs the package notinstalled")\n'


#: The words that start pytest's short test summary lines (-rA).
OUTCOMES = ("PASSED", "FAILED", "ERROR", "SKIPPED", "XFAIL", "XPASS")


@dataclass(frozen=True)
class BenchRun:
    """One pytest-benchmark run: exit status, output and the JSON's benchmark names."""

    returncode: int
    text: str
    timed: list[str]

    def outcome(self, solver: str) -> str:
        """The short-summary word (PASSED, FAILED, XFAIL, ...) of ``solver``'s item."""
        item = f"::test_solver[{solver}-counterexample-100-s1]"
        words = [line.split()[0] for line in self.text.splitlines()
                 if line.split(" ", 1)[0] in OUTCOMES and (line.rstrip().endswith(item) or f"{item} " in line)]
        return words[0] if words else "(not run)"

    def failure(self, solver: str) -> str:
        """The failure message of ``solver``'s item (the line naming it)."""
        lines = [line for line in self.text.splitlines() if line.startswith(f"{solver} on counterexample")]
        return lines[0] if lines else ""

    def table_rows(self) -> list[str]:
        return [line.split()[0] for line in self.text.splitlines() if line.startswith("test_solver[")]


def bench_env(paths: list[Path], **extra: str) -> dict[str, str]:
    """This environment with ``paths`` and the repository on PYTHONPATH, one thread, and
    the suite's settings as ``extra`` gives them (the others unset)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("CONTACTBENCH_BENCH_")}
    env["PYTHONPATH"] = os.pathsep.join([*map(str, paths), str(REPO), env.get("PYTHONPATH", "")])
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", CONTACTBENCH_FFT_WORKERS="1", **extra)
    return env


def run_bench(args: list[str], env: dict[str, str], timeout: float = 60.0) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--benchmark-only", "--benchmark-enable",
           "benchmarks/test_bench_solvers.py", *args]
    return subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout, check=False)


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory: pytest.TempPathFactory) -> BenchRun:
    """The throw-away solvers, greedy-chol (refuted on the counterexample) and the solver
    sources that fail to load, with 2 timed rounds and a time limit of 0.2 s."""
    where = tmp_path_factory.mktemp("bench")
    (where / "test_bench_plugin.py").write_text(PLUGIN)
    (where / "test_bench_broken.py").write_text(BROKEN)
    dist = where / "test_bench_broken-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: test-bench-broken\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[contactbench.solvers]\ntest_bench_broken = test_bench_broken\n")
    out = where / "bench.json"
    env = bench_env([where], CONTACTBENCH_BENCH_ROUNDS="2", CONTACTBENCH_BENCH_TIMEOUT="0.2",
                    CONTACTBENCH_EXTERNAL_SOLVERS=str(where / "missing.toml"))
    done = run_bench(["-p", "test_bench_plugin", "-rA", "-k",
                      "(test-bench and counterexample) or greedy-chol-counterexample or imports",
                      f"--benchmark-json={out}"], env)
    timed = [b["name"] for b in json.loads(out.read_text())["benchmarks"]] if out.exists() else []
    return BenchRun(done.returncode, done.stdout + done.stderr, timed)


def test_only_a_benchmark_whose_every_solve_passes_is_timed(bench_run: BenchRun) -> None:
    """Wrong answers (failed) and greedy-chol on its counterexample (xfailed) are neither
    in the JSON nor in the timing table; the exact solver is, and the run fails."""
    assert bench_run.returncode == 1, bench_run.text
    assert bench_run.outcome("test-bench-exact") == "PASSED", bench_run.text
    assert bench_run.outcome("test-bench-zero") == "FAILED", bench_run.text
    assert bench_run.outcome("greedy-chol") == "XFAIL", bench_run.text
    assert bench_run.timed == ["test_solver[test-bench-exact-counterexample-100-s1]"], bench_run.text
    assert bench_run.table_rows() == bench_run.timed, bench_run.text


def test_every_solve_is_judged_the_untimed_warm_up_included(bench_run: BenchRun) -> None:
    """A solver wrong only in its warm-up, or only in its first timed round, fails there."""
    assert bench_run.outcome("test-bench-warm-up-wrong") == "FAILED", bench_run.text
    assert "in its untimed warm-up solve" in bench_run.failure("test-bench-warm-up-wrong"), bench_run.text
    assert bench_run.outcome("test-bench-round-wrong") == "FAILED", bench_run.text
    assert "in timed round 1" in bench_run.failure("test-bench-round-wrong"), bench_run.text
    assert "claims convergence but the judge reads the answer as wrong" in bench_run.failure("test-bench-round-wrong")


def test_each_solve_gets_its_own_sealed_problem_and_the_judge_a_pristine_one(bench_run: BenchRun) -> None:
    """A write into H in the warm-up fails that solver, and reaches no later solve nor the
    judge: the diagonal answer after it is judged wrong on the instance as built."""
    assert bench_run.outcome("test-bench-a-tamper") == "FAILED", bench_run.text
    assert "wrote into the problem it was handed" in bench_run.failure("test-bench-a-tamper"), bench_run.text
    assert bench_run.outcome("test-bench-b-diagonal") == "FAILED", bench_run.text
    assert "kkt_error" in bench_run.failure("test-bench-b-diagonal"), bench_run.text


def test_threads_a_solve_leaves_running_fail_it_naming_them(bench_run: BenchRun) -> None:
    assert bench_run.outcome("test-bench-leaver") == "FAILED", bench_run.text
    assert "left 1 thread running" in bench_run.failure("test-bench-leaver"), bench_run.text
    assert "test-bench-left-thread" in bench_run.failure("test-bench-leaver"), bench_run.text


def test_a_solve_past_the_hard_limit_is_stopped_as_a_timeout(bench_run: BenchRun) -> None:
    """A solver ignoring its deadline (0.2 s) is stopped at the validate grace and fails."""
    assert bench_run.outcome("test-bench-hang") == "FAILED", bench_run.text
    line = bench_run.failure("test-bench-hang")
    assert "timeout" in line and "hard limit of 2.25 s" in line and "the solve was stopped" in line, bench_run.text


def test_a_solver_source_that_fails_to_load_is_a_failing_item(bench_run: BenchRun) -> None:
    """An entry point whose module raises and an external manifest that does not exist."""
    failed = [line for line in bench_run.text.splitlines() if line.startswith("FAILED")
              and "test_solver_module_imports" in line]
    assert len(failed) == 2, bench_run.text
    for source, error in (("entry point test_bench_broken", "needs the package notinstalled"),
                          ("contactbench.solvers.external_manifests", "missing.toml does not exist")):
        line = next((x for x in bench_run.text.splitlines() if x.startswith(f"solver source {source} failed")), "")
        assert error in line, bench_run.text


@pytest.mark.parametrize(("name", "value"), [("CONTACTBENCH_BENCH_TIMEOUT", "-1"), ("CONTACTBENCH_BENCH_ROUNDS", "0")])
def test_a_bad_setting_stops_pytest_in_one_line(name: str, value: str) -> None:
    done = run_bench(["-q", "-k", "scipy-nnls-counterexample"], bench_env([], **{name: value}))
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 4 and len(lines) == 1, done.stdout + done.stderr
    assert lines[0].startswith(f"ERROR: {name}={value!r}: "), lines


@pytest.fixture
def bench_conftest(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """benchmarks/conftest.py, imported as a module of this test's own."""
    spec = importlib.util.spec_from_file_location("bench_conftest", REPO / "benchmarks" / "conftest.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("name", "value", "takes"), [
    ("CONTACTBENCH_BENCH_PROFILE", "bogus", "choose one of default"),
    ("CONTACTBENCH_BENCH_TIMEOUT", "nan", "a finite number of seconds > 0"),
    ("CONTACTBENCH_BENCH_TIMEOUT", "abc", "a finite number of seconds > 0"),
    ("CONTACTBENCH_BENCH_TIMEOUT", "0", "a finite number of seconds > 0"),
    ("CONTACTBENCH_BENCH_ROUNDS", "abc", "a whole number >= 1"),
    ("CONTACTBENCH_BENCH_ROUNDS", "2.5", "a whole number >= 1"),
    ("CONTACTBENCH_BENCH_ROUNDS", "-1", "a whole number >= 1"),
])
def test_each_setting_is_refused_naming_the_variable_its_value_and_what_it_takes(
        bench_conftest: ModuleType, name: str, value: str, takes: str) -> None:
    conftest = bench_conftest
    with pytest.raises(ValueError) as refused:
        conftest.read_settings({name: value})
    text = str(refused.value)
    assert text.startswith(f"{name}={value!r}: ") and takes in text and "\n" not in text


def test_the_settings_default_when_unset_and_are_read_as_given(bench_conftest: ModuleType) -> None:
    conftest = bench_conftest
    assert conftest.read_settings({}) == conftest.BenchSettings("default", 30.0, 3)
    given: dict[str, Any] = {"CONTACTBENCH_BENCH_PROFILE": "low", "CONTACTBENCH_BENCH_TIMEOUT": "2.5",
                             "CONTACTBENCH_BENCH_ROUNDS": "1"}
    assert conftest.read_settings(given) == conftest.BenchSettings("low", 2.5, 1)
