"""External programs and their manifests under hostile input: every bad manifest is refused
in one line naming its file before anything runs (a version command that is no command, a
name too long, a file that is a folder, a dangling link, not UTF-8, or that declares
nothing under a misspelt key), an unknown placeholder in a command template is refused
naming it, the version command runs before a solve and outside its time, and what a
program leaves running ends before its answer is read."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness.conformance.command import main as validate_main
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, counterexample
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import SolveResult, SolverSettings, external
from contactbench.solvers._external_manifest import NAME_MAX_CHARS
from contactbench.solvers.external import (
    LOCAL_MANIFEST,
    ExternalSolver,
    ExternalSpec,
    command_solver,
    command_words,
    load_manifest,
    manifest_paths,
    register_manifests,
)
from tests.helpers import TESTS, process_gone

PY = sys.executable
SCRIPT = TESTS / "external" / "standalone_solver.py"
GOOD = f"{PY} {SCRIPT} {{problem}} {{solution}}"
#: How long a process a test starts lives at most (it must be ended long before).
LIFETIME_S = 20


def manifest(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def entry(**keys: object) -> str:
    """One ``[[solver]]`` table of a manifest (values written as JSON, which TOML reads)."""
    return "[[solver]]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in keys.items())


def end(pid: int) -> None:
    """Kill ``pid`` if it still runs (a failing test leaves nothing behind)."""
    if not process_gone(pid):
        os.kill(pid, 9)


def solved_exactly(res: SolveResult, qp: QP) -> bool:
    """Whether ``res`` is the exact solution of ``qp`` (to 1e-8 of its largest entry)."""
    p_ref = exact_solution(qp.H.to_dense(), np.asarray(qp.ubar, dtype=np.float64)).p
    return bool(np.allclose(res.p, p_ref, rtol=0, atol=1e-8 * np.max(np.abs(p_ref))))


# ---------------------------------------------------------------------------
# The version command
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("version, words", [
    ("prog 'unterminated", "cannot parse version command"),
    (5, "'version' must be a string"),
    (["prog", "--version"], "'version' must be a string"),
    ("", "version must be a command to run"),
    ("   ", "version must be a command to run"),
])
def test_a_version_that_is_no_command_refuses_the_manifest(tmp_path: Path, version: object, words: str) -> None:
    path = manifest(tmp_path / "m.toml", entry(name="x1", command=GOOD, version=version))
    with pytest.raises(ProblemInputError) as err:
        load_manifest(path)
    assert words in str(err.value) and "m.toml" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("command, text", [
    ("sh -c 'echo ran >> {marker}; sleep {life} & echo v1.0'", "v1.0"),
    ("sh -c 'echo ran >> {marker}; echo no-licence >&2; exit 3'", "(version command exited 3: no-licence)"),
    ("sh -c 'echo ran >> {marker}; exec sleep {life}'", "(version command gave no answer within 0.3 s)"),
])
def test_the_version_command_runs_once_before_the_solve_and_never_fails_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str, text: str) -> None:
    """``availability()`` asks the version command once, under its own limit, what it left
    running ended; the solve does not run it and records its text."""
    monkeypatch.setattr(external, "VERSION_LIMIT_S", 0.3)
    marker = tmp_path / "ran"
    spec = ExternalSpec(name="x1", command=GOOD, version=command.format(marker=marker, life=LIFETIME_S))
    solver = ExternalSolver(spec)
    assert solver.availability() == (True, "available")
    assert marker.read_text().count("ran") == 1
    qp = counterexample(16, 0).qp
    res = solver.solve(qp, SolverSettings(tol=1e-9, time_limit=30.0))
    assert marker.read_text().count("ran") == 1  # not run again, nor inside the solve
    assert res.converged and solved_exactly(res, qp)
    assert res.info["external_version"] == text and f"version {text}" in res.message


# ---------------------------------------------------------------------------
# The name
# ---------------------------------------------------------------------------


def test_a_name_over_the_limit_refuses_the_manifest_and_one_at_it_loads(tmp_path: Path) -> None:
    limit = NAME_MAX_CHARS
    too_long = manifest(tmp_path / "long.toml", entry(name="x" * (limit + 1), command=GOOD))
    with pytest.raises(ProblemInputError) as err:
        load_manifest(too_long)
    assert f"at most {limit}" in str(err.value) and "long.toml" in str(err.value)
    assert [s.name for s in load_manifest(manifest(tmp_path / "ok.toml", entry(name="y" * limit, command=GOOD)))] \
        == ["y" * limit]


def test_the_temporary_folder_of_a_solve_has_a_bounded_name_whatever_the_solver_s_name() -> None:
    solver = command_solver(GOOD)
    solver.name = "x" * 300  # type: ignore[misc]  # (past any file-name limit)
    qp = counterexample(16, 0).qp
    res = solver.solve(qp, SolverSettings(tol=1e-9, time_limit=30.0))
    assert res.converged and solved_exactly(res, qp)


# ---------------------------------------------------------------------------
# Manifests that declare nothing, or cannot be read
# ---------------------------------------------------------------------------


def _dangling(path: Path) -> None:
    path.symlink_to(path.parent / "no-such-manifest.toml")


def _folder(path: Path) -> None:
    path.mkdir()


def _typo(path: Path) -> None:
    path.write_text(entry(name="x1", command=GOOD).replace("[[solver]]", "[[solvers]]"))


def _other_key(path: Path) -> None:
    path.write_text('title = "my solvers"\n' + entry(name="x1", command=GOOD))


def _latin1(path: Path) -> None:
    path.write_bytes((entry(name="x1", command=GOOD) + 'description = "caf\xe9"\n').encode("latin-1"))


@pytest.mark.parametrize("make, words", [
    (_dangling, "does not exist"),
    (_folder, "is a folder"),
    (_typo, "unknown top-level key(s) solvers"),
    (_other_key, "unknown top-level key(s) title"),
    (_latin1, "is not UTF-8 text"),
])
def test_a_local_manifest_that_declares_nothing_or_cannot_be_read_is_an_error_naming_it(
        tmp_path: Path, make: Callable[[Path], None], words: str) -> None:
    local = tmp_path / LOCAL_MANIFEST
    make(local)
    paths = manifest_paths({}, cwd=str(tmp_path))
    assert paths == [local]
    with pytest.raises(ProblemInputError) as err:
        register_manifests(paths)
    assert words in str(err.value) and str(local) in str(err.value) and "\n" not in str(err.value)


# ---------------------------------------------------------------------------
# Placeholders
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("command, named", [
    ("prog {problem} {solution} --warm {p0}", "{p0}"),
    ("prog {problem} {soluton}", "{soluton}"),
    ("prog {problem} {solution} {}", "{}"),
    ("prog {problem!r} {solution}", "{problem!r}"),
    ("prog {problem:>9} {solution}", "{problem:>9}"),
    ("prog {problem} {solution} }", "lone brace"),
    ("prog {problem} {solution} {", "lone brace"),
])
def test_an_unknown_placeholder_is_refused_naming_it_and_the_known_ones(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, named: str) -> None:
    with pytest.raises(ProblemInputError) as err:
        command_solver(command)
    assert named in str(err.value) and "{problem}, {solution}" in str(err.value) and "{{" in str(err.value)
    with pytest.raises(ProblemInputError, match="m.toml"):
        load_manifest(manifest(tmp_path / "m.toml", entry(name="x1", command=command)))
    assert validate_main(["--command", command]) == 2
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert len(err_lines) == 1 and named in err_lines[0]


def test_a_doubled_brace_is_a_literal_brace() -> None:
    words = command_words("awk '{{print}}' {problem}/x {solution} {{}}", Path("/p"), Path("/s"))
    assert words == ["awk", "{print}", "/p/x", "/s", "{}"]
    with pytest.raises(ProblemInputError, match="must contain"):
        command_solver("prog {{problem}} {solution}")  # a literal, not the placeholder


# ---------------------------------------------------------------------------
# What a program leaves running
# ---------------------------------------------------------------------------

#: A program that answers (the standalone solver), then leaves a process that left its
#: group (``setsid``) and whose parent exited, writing into the solution folder without
#: end; it exits 0 once that process runs, its pid in argv[3].
LEAVES_A_WRITER = f"""
import os, runpy, sys, time
problem, solution, pid_file = sys.argv[1:4]
sys.argv = [{str(SCRIPT)!r}, problem, solution]
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
except SystemExit:
    pass
read, write = os.pipe()
if os.fork() == 0:
    os.setsid()
    if os.fork() == 0:
        os.write(write, str(os.getpid()).encode())
        deadline, k = time.time() + {LIFETIME_S}, 0
        while time.time() < deadline:
            with open(os.path.join(solution, f"junk{{k % 64}}"), "w") as fh:
                fh.write("x")
            k += 1
        os._exit(0)
    os._exit(0)
os.close(write)
with open(pid_file, "wb") as fh:
    fh.write(os.read(read, 32))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, and orphans adopted (PR_SET_CHILD_SUBREAPER)")
def test_what_a_program_left_running_ends_before_its_answer_is_read(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The answer is read once the left process has ended, and the row is the program's
    answer, not an error of the folder's removal."""
    program = tmp_path / "leaves_a_writer.py"
    program.write_text(LEAVES_A_WRITER)
    pid_file = tmp_path / "writer.pid"
    seen: list[bool] = []
    read = external.read_solution_dir

    def read_after_checking(*args: Any, **kwargs: Any) -> Any:
        seen.append(process_gone(int(pid_file.read_text())))
        return read(*args, **kwargs)

    monkeypatch.setattr(external, "read_solution_dir", read_after_checking)
    qp = counterexample(16, 0).qp
    try:
        res = command_solver(f"{PY} {program} {{problem}} {{solution}} {pid_file}").solve(
            qp, SolverSettings(tol=1e-9, time_limit=30.0))
        assert seen == [True], "the left process was still running when the answer was read"
        assert res.converged and solved_exactly(res, qp)
    finally:
        if pid_file.exists():
            end(int(pid_file.read_text()))
    deadline = time.monotonic() + 5.0
    while not process_gone(int(pid_file.read_text())) and time.monotonic() < deadline:  # (the kernel's time)
        time.sleep(0.02)
    assert process_gone(int(pid_file.read_text()))


# ---------------------------------------------------------------------------
# The iteration limit a program is told (problem.json's "max_iter")
# ---------------------------------------------------------------------------

#: A program that answers exactly and reports ``max_iter`` plus its first argument as its
#: iteration count (0: honours the limit; 1: one past it), or 123 when it is told none.
TOLD_LIMIT = '''
import json, os, sys
import numpy as np
extra, prob, soln = int(sys.argv[1]), sys.argv[2], sys.argv[3]
doc = json.load(open(os.path.join(prob, "problem.json")))
a = doc["arrays"]["H"]
H = np.fromfile(os.path.join(prob, a["file"]), dtype="<f8").reshape(a["shape"])
ubar = np.fromfile(os.path.join(prob, "ubar.f64"), dtype="<f8")
F = np.zeros(ubar.size, dtype=bool)
for _ in range(4 * ubar.size + 4):  # block principal pivoting: exact on these small SPD cases
    p = np.zeros(ubar.size)
    if F.any():
        p[F] = np.linalg.solve(H[np.ix_(F, F)], ubar[F])
    bad = (F & (p < 0)) | (~F & (H @ p - ubar < -1e-13 * np.abs(ubar).max()))
    if not bad.any():
        break
    F ^= bad
np.maximum(p, 0.0).astype("<f8").tofile(os.path.join(soln, "p.f64"))
told = doc.get("max_iter")
json.dump({"iterations": 123 if told is None else told + extra}, open(os.path.join(soln, "solution.json"), "w"))
'''


def told_limit_command(tmp_path: Path, extra: int) -> str:
    script = tmp_path / "told_limit.py"
    script.write_text(TOLD_LIMIT)
    return f"{PY} {script} {extra} {{problem}} {{solution}}"


def test_problem_json_carries_the_iteration_limit_the_solve_runs_under(tmp_path: Path) -> None:
    from contactbench.problems.qpfile import problem_payload

    inst = counterexample(16, 0)
    assert problem_payload(inst, tol=1e-8, time_limit=None, max_iter=7)[0]["max_iter"] == 7
    assert problem_payload(inst, tol=1e-8, time_limit=None)[0]["max_iter"] is None
    with pytest.raises(ProblemInputError, match="max_iter"):
        problem_payload(inst, tol=1e-8, time_limit=None, max_iter=-1)
    solver = command_solver(told_limit_command(tmp_path, 0))
    assert solver.solve(inst.qp, SolverSettings(max_iter=5, time_limit=30.0)).iterations == 5
    assert solver.solve(inst.qp, SolverSettings(time_limit=30.0)).iterations == 123  # told none: null


def test_the_limit_group_passes_a_program_that_honours_its_limit_and_flags_one_past_it(tmp_path: Path) -> None:
    from contactbench.harness.conformance import battery as cf
    from contactbench.harness.conformance.cases import ITERATION_LIMIT, limit_cases

    honest = cf.validate(command_solver(told_limit_command(tmp_path, 0)), limit_cases(), isolate=False)
    assert [r.status for r in honest.rows] == ["pass"] * len(honest.rows), honest.format()
    assert [r.iterations for r in honest.rows] == [ITERATION_LIMIT] * len(honest.rows)
    assert honest.exit_code(strict=True) == 0
    past = cf.validate(command_solver(told_limit_command(tmp_path, 1)), limit_cases(), isolate=False)
    assert [r.status for r in past.rows] == ["flagged"] * len(past.rows), past.format()
    assert all(f"{ITERATION_LIMIT + 1} iterations under max_iter {ITERATION_LIMIT}" in r.message for r in past.rows)
    assert past.exit_code(strict=True) == 1


def test_the_example_program_stops_at_the_limit_it_is_told() -> None:
    from contactbench.harness.conformance import battery as cf
    from contactbench.harness.conformance.cases import ITERATION_LIMIT, limit_cases

    table = cf.validate(command_solver(GOOD), limit_cases(), isolate=False)
    assert all(r.status in ("pass", "unconverged") for r in table.rows), table.format()
    assert all(r.iterations is not None and r.iterations <= ITERATION_LIMIT for r in table.rows), table.format()


def test_problem_json_says_whether_h_is_singular() -> None:
    from contactbench.problems.instances import InstanceBuilder
    from contactbench.problems.qpfile import problem_payload
    from contactbench.problems.surfaces import fourier_synthesis

    inst = InstanceBuilder(fourier_synthesis(8, 0.8, 0.1, length=1e-4, seed=3), 1e9, "bcc", periodic=True).build(1e-6)
    assert inst.n == 64  # a periodic step is posed on the whole grid: H 1 = 0
    assert np.allclose(inst.qp.H.to_dense().sum(axis=1), 0.0, atol=1e-12 * float(inst.qp.H.diagonal().max()))
    assert problem_payload(inst, tol=None, time_limit=None)[0]["singular"] is True
    subset = inst.qp.restrict(np.arange(40))
    assert problem_payload(subset, tol=None, time_limit=None)[0]["singular"] is False
    assert problem_payload(counterexample(16, 0), tol=None, time_limit=None)[0]["singular"] is False
