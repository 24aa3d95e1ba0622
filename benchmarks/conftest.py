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
warm-up included (the plugin's ``contactbench_benchmark``:
``harness.judged_benchmark.JudgedBenchmark``): any other benchmark -- a wrong answer, an
honest non-convergence, an expected failure, a timeout, a crash, a solver caching across
solves -- is left out of the timing table (the plugin's ``pytest_benchmark_group_stats``:
``keep_judged``) and of the JSON and saved runs (pytest-benchmark leaves out a benchmark
whose ``has_error`` is set).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Mapping

import pytest

from contactbench.harness.arguments import check_time_limit
from contactbench.harness.profiles import UnknownProfileError, get_profile

PROFILE_VAR = "CONTACTBENCH_BENCH_PROFILE"
TIMEOUT_VAR = "CONTACTBENCH_BENCH_TIMEOUT"
ROUNDS_VAR = "CONTACTBENCH_BENCH_ROUNDS"
DEFAULTS = {PROFILE_VAR: "default", TIMEOUT_VAR: "30", ROUNDS_VAR: "3"}


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
