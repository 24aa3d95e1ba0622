"""Set-up of the pytest-benchmark suite (``benchmarks/test_bench_solvers.py``).

The settings, read from the environment once, when pytest configures (``read_settings``);
a value they cannot use stops pytest before anything runs with one line naming the
variable, its value and what it takes (``pytest.UsageError``, exit status 4):

``CONTACTBENCH_BENCH_PROFILE``  the accuracy profile (``harness.profiles.PROFILES``;
                                default "default");
``CONTACTBENCH_BENCH_TIMEOUT``  each solve's time limit in seconds: a finite number > 0,
                                at most a week (default 30); a solve still running
                                ``kill_limit`` of it is stopped as a timeout;
``CONTACTBENCH_BENCH_ROUNDS``   the timed rounds per benchmark: a whole number >= 1
                                (default 3).

A timing counts only when the judge passes every solve of its benchmark, the untimed
warm-up included (``judged_benchmark``): any other benchmark -- a wrong answer, an honest
non-convergence, an expected failure, a timeout, a crash -- is left out of the timing
table (``pytest_benchmark_group_stats``) and of the JSON and saved runs (pytest-benchmark
leaves out a benchmark whose ``has_error`` is set).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Generator, Mapping

import pytest

from contactbench.harness.arguments import check_time_limit
from contactbench.harness.profiles import UnknownProfileError, get_profile

PROFILE_VAR = "CONTACTBENCH_BENCH_PROFILE"
TIMEOUT_VAR = "CONTACTBENCH_BENCH_TIMEOUT"
ROUNDS_VAR = "CONTACTBENCH_BENCH_ROUNDS"
DEFAULTS = {PROFILE_VAR: "default", TIMEOUT_VAR: "30", ROUNDS_VAR: "3"}

#: ``extra_info`` key of this suite's benchmarks: True once every solve passed the judge.
PASSED_KEY = "every_solve_passed"


@dataclass(frozen=True)
class BenchSettings:
    """The suite's settings (module doc)."""

    profile: str
    time_limit: float
    rounds: int


def read_settings(environ: Mapping[str, str]) -> BenchSettings:
    """The settings in ``environ`` (unset: the defaults), else ``ValueError`` of one line
    naming the variable, its value and what it takes."""
    text = {var: environ.get(var, default) for var, default in DEFAULTS.items()}
    try:
        profile = get_profile(text[PROFILE_VAR]).name
    except UnknownProfileError as exc:  # (its text lists the profiles)
        raise ValueError(f"{PROFILE_VAR}={text[PROFILE_VAR]!r}: {exc}") from None
    try:
        time_limit = check_time_limit(number(text[TIMEOUT_VAR]), "each solve's time limit")
    except ValueError as exc:
        raise ValueError(f"{TIMEOUT_VAR}={text[TIMEOUT_VAR]!r}: {exc}") from None
    rounds = whole_number(text[ROUNDS_VAR])
    if rounds is None or rounds < 1:
        raise ValueError(f"{ROUNDS_VAR}={text[ROUNDS_VAR]!r}: the timed rounds per benchmark must be a whole "
                         "number >= 1")
    return BenchSettings(profile, time_limit, rounds)


def number(text: str) -> float | str:
    """``text`` as a float, or ``text`` itself when it does not read as one (which
    ``check_time_limit`` then refuses, naming it)."""
    try:
        return float(text)
    except ValueError:
        return text


def whole_number(text: str) -> int | None:
    """``text`` as an int ("3", " 3 "), None when it is not one ("3.5", "abc", "nan")."""
    try:
        return int(text)
    except ValueError:
        return None


SETTINGS = pytest.StashKey[BenchSettings]()


def pytest_configure(config: pytest.Config) -> None:
    """Read the settings once, before anything is collected (module doc)."""
    try:
        config.stash[SETTINGS] = read_settings(os.environ)
    except ValueError as exc:
        raise pytest.UsageError(str(exc)) from None


@pytest.fixture
def bench_settings(pytestconfig: pytest.Config) -> BenchSettings:
    """The settings read when pytest configured (``read_settings``)."""
    return pytestconfig.stash[SETTINGS]


@dataclass
class JudgedBenchmark:
    """pytest-benchmark's ``benchmark`` fixture, whose timing counts only once ``passed``
    is called (module doc)."""

    benchmark: Any

    def passed(self) -> None:
        """Every solve passed the judge: the timing goes into the table and the JSON."""
        self.benchmark.has_error = False
        self.benchmark.extra_info[PASSED_KEY] = True


@pytest.fixture
def judged_benchmark(benchmark: Any) -> JudgedBenchmark:
    """``benchmark``, left out of the table and the JSON until ``passed``."""
    benchmark.has_error = True
    benchmark.extra_info[PASSED_KEY] = False
    return JudgedBenchmark(benchmark)


def counts(bench: Mapping[str, Any]) -> bool:
    """Whether a benchmark (pytest-benchmark's flat record) goes into the table: any but
    one of this suite's that has not passed (``PASSED_KEY``)."""
    return (bench.get("extra_info") or {}).get(PASSED_KEY) is not False


@pytest.hookimpl(wrapper=True)
def pytest_benchmark_group_stats(config: pytest.Config, benchmarks: list[dict[str, Any]],
                                 group_by: str) -> Generator[None, Any, list[tuple[Any, list[dict[str, Any]]]]]:
    """pytest-benchmark's groups, less the benchmarks that do not count (``counts``)."""
    groups = yield
    kept = [(name, [b for b in group if counts(b)]) for name, group in groups]
    return [(name, group) for name, group in kept if group]
