"""The device benchmarks' shared pieces (benchmarks/csv_rows.py, device_warmup.py) and their
exit codes: a missing device or a bad size is a one-line error with exit 2 before anything
runs, and the profile script runs a solve end to end."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from contactbench.problems.operators_gpu import gpu_unavailable_reason
from tests.helpers import REPO

BENCH = REPO / "benchmarks"


def run_script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=BENCH, capture_output=True, text=True, timeout=300, check=False)


def last_line(text: str) -> str:
    return (text.strip().splitlines() or [""])[-1]


def test_profile_solve_profiles_a_solve_and_refuses_a_bad_size() -> None:
    done = run_script("profile_solve.py", "--size", "64", "--top", "3", "--callers", "1", "--chains", r"\(matvec\)",
                      "--depth", "2")
    assert done.returncode == 0, done.stderr
    assert "converged" in done.stdout and "was called by" in done.stdout
    chain = done.stdout[done.stdout.index("(matvec): "):]  # the chains: a callee, then its callers indented
    assert "calls" in chain and "\n  <- " in chain
    bad = run_script("profile_solve.py", "--size", "100")
    line = last_line(bad.stderr)
    assert bad.returncode == 2 and "--size must be a power of two >= 16" in line and "got 100" in line


@pytest.mark.skipif(gpu_unavailable_reason() is None, reason="CuPy and a CUDA device are present")
@pytest.mark.parametrize("script", ["bench_cost_law.py", "bench_surface_population.py", "profile_solve.py"])
def test_a_missing_device_is_refused_before_anything_runs(script: str) -> None:
    where = ["--size", "64"] if script == "profile_solve.py" else ["--sizes", "64", "--out", "/nonexistent/never"]
    done = run_script(script, "--operator", "gpu", *where)
    assert done.returncode == 2 and "operator 'gpu' is not available here" in last_line(done.stderr)
    assert not done.stdout.strip()


def test_the_rows_name_the_machine_and_the_warm_up_is_device_only(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(BENCH))
    from csv_rows import host_name
    from device_warmup import warm_up_device

    monkeypatch.setenv("CONTACTBENCH_HOST", "NVIDIA H200 + 16 cores")
    assert host_name() == "NVIDIA H200 + 16 cores"
    monkeypatch.delenv("CONTACTBENCH_HOST")
    assert "cores)" in host_name() and host_name() != "vm"
    assert math.isnan(warm_up_device("fast-dual-pccg", {}, "fft"))
    assert math.isnan(warm_up_device("fast-dual-pccg", {}, "fft", lambda: pytest.fail("a twin built off the device")))
