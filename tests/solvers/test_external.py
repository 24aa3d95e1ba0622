"""External solvers over the file protocol: the problem and
solution directories, the manifest, `validate --command` on a C solver and a standalone
script, the misbehaving variants, and the conformance report (`validate --out`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.conformance.command import main as validate_main
from contactbench.harness import RunConfig
from contactbench.harness import run_benchmark
from contactbench.harness import load_table
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import counterexample
from contactbench.problems.qpfile import (
    FORMAT,
    SolutionFileError,
    read_problem_dir,
    read_solution_dir,
    write_problem_dir,
)
from contactbench.problems.scenes import SceneConfig
from contactbench.problems.scenes.stress import known_solution_instance
from contactbench.solvers import SolverSettings
from contactbench.solvers.external import (
    MANIFEST_ENV,
    ExternalSolver,
    command_solver,
    load_manifest,
    manifest_paths,
    register_manifest,
)
from contactbench.solvers.registry import all_solvers, unregister
from tests.helpers import REPO, TESTS, compile_c

HERE = TESTS / "external"
SCRIPT = HERE / "standalone_solver.py"
PY = sys.executable


def script_command(*flags: str) -> str:
    return " ".join([PY, str(SCRIPT), "{problem}", "{solution}", *flags])


@pytest.fixture(scope="module")
def pgs_binary(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The C example, compiled with the system C compiler (skipped without one)."""
    return compile_c(HERE / "pgs.c", tmp_path_factory.mktemp("pgs") / "pgs", "-lm", what="the C example")


# ---------------------------------------------------------------------------
# The problem and solution directories
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("operator", ["dense", "fft"])
def test_problem_dir_layout_and_round_trip(tmp_path: Path, operator: str) -> None:
    inst = counterexample(16, 0, operator=operator)
    d = write_problem_dir(inst, tmp_path / "p", tol=1e-8, time_limit=7.0, p0=np.arange(16.0))
    doc = json.loads((d / "problem.json").read_text())
    assert doc["format"] == FORMAT and doc["n"] == 16 and doc["grid"] == [4, 4] and doc["kernel"] == "bcc"
    assert doc["tol"] == 1e-8 and doc["time_limit"] == 7.0 and doc["periodic"] is False and doc["E"] == 0.01
    shapes = {k: v["shape"] for k, v in doc["arrays"].items()}
    assert shapes == {"ubar": [16], "index": [16, 2], "H": [16, 16], "kernel_table": [8, 8], "p0": [16]}
    assert doc["arrays"]["index"]["dtype"] == "<i8" and doc["arrays"]["H"]["dtype"] == "<f8"
    raw_H = np.fromfile(d / doc["arrays"]["H"]["file"], dtype="<f8").reshape(16, 16)  # row-major, raw
    H = inst.qp.H.to_dense()
    assert np.array_equal(raw_H, H)
    pf = read_problem_dir(d)
    assert np.array_equal(pf.ubar, inst.qp.ubar) and np.array_equal(pf.p0, np.arange(16.0))
    assert np.array_equal(pf.flat_indices, inst.qp.geometry.indices)
    # The kernel table alone rebuilds H through the FFT operator: the formula of the docs.
    K, (i, j) = pf.kernel_table, pf.index.T
    P1, P2 = K.shape
    assert np.allclose(K[(i[:, None] - i[None, :]) % P1, (j[:, None] - j[None, :]) % P2], H, rtol=0, atol=1e-14 * H.max())
    pf.H = None
    x = np.random.default_rng(1).random(16)
    assert np.allclose(pf.qp().H.matvec(x), H @ x, rtol=1e-12)


def test_problem_dir_over_the_dense_limit_has_only_the_kernel_table(tmp_path: Path) -> None:
    inst = known_solution_instance(6, 0)
    d = write_problem_dir(inst, tmp_path, tol=None, time_limit=None, dense_limit=inst.n - 1)
    doc = json.loads((d / "problem.json").read_text())
    assert "H" not in doc["arrays"] and "kernel_table" in doc["arrays"] and doc["tol"] is None
    x = np.ones(inst.n)
    assert np.allclose(read_problem_dir(d).operator().matvec(x), inst.qp.H.matvec(x), rtol=1e-12)


def write_p(d: Path, p: np.ndarray | bytes, report: dict | None = None) -> Path:
    d.mkdir(exist_ok=True)
    (d / "p.f64").write_bytes(p if isinstance(p, bytes) else np.asarray(p, dtype="<f8").tobytes())
    if report is not None:
        (d / "solution.json").write_text(json.dumps(report))
    return d


@pytest.mark.parametrize("content, words", [
    (None, "is missing"),
    (np.ones(4), "wrong length 4, expected n = 5"),
    (np.array([1, np.nan, 0, 0, 0.0]), "1 NaN/inf"),
    (np.array([1, -1e-3, 0, 0, 0.0]), "1 negative"),
    (b"\x00" * 13, "13 bytes"),
])
def test_a_bad_solution_says_what_is_wrong(tmp_path: Path, content: object, words: str) -> None:
    d = tmp_path / "s"
    d.mkdir()
    if content is not None:
        write_p(d, content)  # type: ignore[arg-type]
    with pytest.raises(SolutionFileError, match="solution p") as err:
        read_solution_dir(d, 5)
    assert words in str(err.value)


def test_solution_report_and_the_claim_rule(tmp_path: Path) -> None:
    silent = read_solution_dir(write_p(tmp_path / "a", np.ones(3)), 3)
    assert silent.status is None and silent.claims_converged  # no status: read as a claim
    honest = read_solution_dir(write_p(tmp_path / "b", np.ones(3), {"status": "max_iter", "iterations": 9}), 3)
    assert not honest.claims_converged and honest.iterations == 9
    for k, word in enumerate(("converged", "Solved", "optimal", "not_converged", "max_iter", "time_limit",
                              "stalled", "failed")):
        sol = read_solution_dir(write_p(tmp_path / f"w{k}", np.ones(3), {"status": word}), 3)
        assert sol.claims_converged == (word.lower() in ("converged", "solved", "optimal")), word
    for word in ("done", "success", "ok", ""):
        with pytest.raises(SolutionFileError, match="not a protocol word.*converged, solved, optimal"):
            read_solution_dir(write_p(tmp_path / f"bad-{word}", np.ones(3), {"status": word}), 3)
    (tmp_path / "b" / "solution.json").write_text("{not json")
    with pytest.raises(SolutionFileError, match="solution.json is unreadable"):
        read_solution_dir(tmp_path / "b", 3)


# ---------------------------------------------------------------------------
# The manifest
# ---------------------------------------------------------------------------


def write_manifest(path: Path, entries: list[dict[str, object]]) -> Path:
    lines = []
    for e in entries:
        lines.append("[[solver]]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in e.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("entry, words", [
    ({"name": "x", "command": "prog {problem}"}, "must contain {problem} and {solution}"),
    ({"name": "x", "command": "{problem} {solution}"}, "first word names the program"),
    ({"name": "x", "command": "x{problem} --out={solution}"}, "first word names the program"),
    ({"name": "x", "command": "prog {problem} {solution}", "inputs": "sparse"}, "inputs must be"),
    ({"name": "x", "command": "prog {problem} {solution}", "colour": 1}, "unknown key(s) colour"),
    ({"command": "prog {problem} {solution}"}, "'name' is required"),
    ({"name": "x", "command": "prog {problem} {solution}", "warm_start": "yes"}, "true or false"),
    ({"name": "x", "command": "prog {problem} {solution}", "promise": "approximate"}, "a positive scaled KKT floor"),
    ({"name": "x", "command": "prog {problem} {solution}", "promise": -1e-7}, "a positive scaled KKT floor"),
    ({"name": "lab/pgs", "command": "prog {problem} {solution}"}, "must be letters, digits"),
    ({"name": "pgs[fast]", "command": "prog {problem} {solution}"}, "must be letters, digits"),
    ({"name": "pgs@1", "command": "prog {problem} {solution}"}, "must be letters, digits"),
])
def test_a_bad_manifest_entry_is_named(tmp_path: Path, entry: dict[str, object], words: str) -> None:
    with pytest.raises(ProblemInputError) as err:
        load_manifest(write_manifest(tmp_path / "m.toml", [entry]))
    assert words in str(err.value) and "m.toml" in str(err.value)


def test_a_manifest_declares_its_promise(tmp_path: Path) -> None:
    base = {"command": "prog {problem} {solution}"}
    specs = load_manifest(write_manifest(tmp_path / "m.toml", [{"name": "a", **base}, {"name": "b", "promise": 1e-7,
                                                                                         **base}]))
    assert [s.promise for s in specs] == ["exact", 1e-7]


def test_manifest_paths_from_the_environment_and_the_current_folder(tmp_path: Path) -> None:
    a, b = write_manifest(tmp_path / "a.toml", []), tmp_path / "contactbench-solvers.toml"
    assert manifest_paths({MANIFEST_ENV: str(a)}, cwd=str(tmp_path)) == [a]
    write_manifest(b, [])
    assert manifest_paths({MANIFEST_ENV: os.pathsep.join([str(a), ""])}, cwd=str(tmp_path)) == [a, b]


def test_a_manifest_entry_is_a_registered_solver_listed_by_the_cli(tmp_path: Path) -> None:
    m = write_manifest(tmp_path / "m.toml", [{"name": "ext-listed", "command": script_command(), "inputs": "kernel",
                                              "warm_start": True, "version": f"{PY} --version"}])
    env = {**os.environ, MANIFEST_ENV: str(m)}
    out = subprocess.run([PY, "-m", "contactbench.harness.cli", "list", "solvers"], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    line = next(ln for ln in out.stdout.splitlines() if ln.startswith("ext-listed"))
    assert "external" in line and "yes" in line
    with pytest.raises(ProblemInputError, match="already registered"):  # a built-in name is refused
        register_manifest(write_manifest(tmp_path / "clash.toml", [{"name": "test-exact", "command": "x {problem} {solution}"}]))


# ---------------------------------------------------------------------------
# validate --command
# ---------------------------------------------------------------------------


QUICK = ["--group", "edge", "--group", "random", "--group", "counterexample"]


def test_the_c_example_passes_validate_command_and_writes_its_report(
        pgs_binary: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    rc = validate_main(["--command", f"{pgs_binary} {{problem}} {{solution}}", *QUICK, "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "CONFORMS: every solve correct" in text
    rows = pd.read_csv(out / "verdicts.csv")
    assert set(rows["status"]) == {"pass"} and len(rows) >= 15 and (rows["ref_time_s"].notna()).any()
    page = (out / "conformance.md").read_text()
    assert "exit status 0" in page and "| counterexample/example1-n400-s0 | 400 | pass |" in page


def test_the_standalone_script_passes_with_kernel_inputs_and_says_what_it_left_out(
        capsys: pytest.CaptureFixture[str]) -> None:
    rc = validate_main(["--command", script_command("--kernel"), "--inputs", "kernel", "--group", "random",
                  "--group", "packing", "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "left out 8 solve(s)" in text and "random/spd-n30-s0@0" in text  # dense-only cases: with a reason
    assert "builds a dense H" in text


#: One periodic whole grid: ubar there holds the whole relief below zero, so the judge's
#: displacement scale is the approach max ubar, far below ||ubar||_inf (problems/kkt.py).
PERIODIC = ["--group", "periodic", "--cases", "periodic/whole-grid-bcc-*"]


@pytest.mark.parametrize("inputs", ["dense", "kernel"], ids=["c-example-dense", "standalone-script-kernel"])
def test_the_examples_stop_on_the_judges_scale_on_a_periodic_grid(
        request: pytest.FixtureRequest, inputs: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Both examples stop on the judge's u_s = max(max ubar, 1e-6 ||ubar||_inf): an example
    stopping on ||ubar||_inf claims convergence early on a periodic grid and is judged WRONG."""
    pgs = request.getfixturevalue("pgs_binary") if inputs == "dense" else None
    command = f"{pgs} {{problem}} {{solution}}" if pgs is not None else script_command("--kernel")
    rc = validate_main(["--command", command, "--inputs", inputs, *PERIODIC])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "CONFORMS: every solve correct" in text and "periodic/whole-grid-bcc-N32@0" in text


def test_the_c_example_prints_its_version(pgs_binary: Path) -> None:
    """`pgs --version` (the manifest example's version command) prints one line and exits 0."""
    out = subprocess.run([str(pgs_binary), "--version"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("pgs ") and len(out.stdout.splitlines()) == 1


def test_the_clipping_variant_is_caught_with_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    rc = validate_main(["--command", script_command("--variant", "clip"), "--group", "counterexample", "--quiet",
                  "--out", str(out)])
    assert rc == 1
    assert "WRONG" in capsys.readouterr().out
    assert "exit status 1" in (out / "conformance.md").read_text()
    assert set(pd.read_csv(out / "verdicts.csv")["status"]) == {"WRONG"}


def test_validate_command_bad_input_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["--command", "prog {problem}"]) == 2
    assert "must contain {problem} and {solution}" in capsys.readouterr().err
    assert validate_main(["--command", "/no/such/prog {problem} {solution}"]) == 2
    assert "not an executable file" in capsys.readouterr().err
    assert validate_main(["test-exact", "--inputs", "kernel"]) == 2


def test_validate_records_a_timeout_a_crash_and_a_claimed_non_answer(capsys: pytest.CaptureFixture[str]) -> None:
    for variant, status in (("sleep", "timeout"), ("segv", "crashed"), ("fail", "crashed"), ("short", "WRONG"),
                            ("nan", "WRONG")):
        table = cf.validate(command_solver(script_command("--variant", variant)),
                            cf.conformance_cases("fast", ["edge"], "edge/plateau*"),
                            timeout=1.0 if variant == "sleep" else 300.0)  # (room for a loaded machine)
        assert [r.status for r in table.rows] == [status], (variant, table.format())
        if status == "WRONG":  # a short or NaN p written with "converged": no answer, claimed as one
            assert table.outcome() == "wrong" and table.exit_code() == 1
        else:
            assert table.outcome() == "incomplete" and table.exit_code() == 3  # unsolved, not wrong


# ---------------------------------------------------------------------------
# The solver inside a run
# ---------------------------------------------------------------------------


def test_a_direct_solve_keeps_the_output_tail_and_the_claim(pgs_binary: Path) -> None:
    inst = counterexample(100, 0)
    res = command_solver(f"{pgs_binary} {{problem}} {{solution}}").solve(inst.qp, SolverSettings(tol=1e-9))
    assert res.converged and res.status == "converged" and res.iterations > 0
    assert "pgs: n = 100" in res.info["external_output_tail"] and "pgs: n = 100" in res.message
    assert res.setup_time > 0 and res.info["external_time_s"] > 0


def test_a_program_that_exits_0_without_an_answer_keeps_its_output_tail() -> None:
    """What the program said on stderr travels with the error that p.f64 is missing, as it
    does with a failed exit."""
    solver = command_solver("sh -c 'echo cannot-open-the-licence-file >&2' {problem} {solution}")
    with pytest.raises(Exception) as err:
        solver.solve(counterexample(16, 0).qp, SolverSettings(time_limit=10.0))
    assert "p.f64" in str(err.value) and "cannot-open-the-licence-file" in str(err.value)


def test_the_process_group_is_killed_at_the_time_limit(tmp_path: Path) -> None:
    pidfile = tmp_path / "child.pid"
    solver = command_solver(f"sh -c 'sleep 30 & echo $! > {pidfile}; wait' {{problem}} {{solution}}")
    t0 = time.perf_counter()
    with pytest.raises(Exception) as err:
        solver.solve(counterexample(16, 0).qp, SolverSettings(time_limit=0.5))
    assert getattr(err.value, "status", "") == "timeout" and time.perf_counter() - t0 < 10
    pid = int(pidfile.read_text())
    time.sleep(0.2)
    stat = Path(f"/proc/{pid}/stat")
    assert not stat.exists() or stat.read_text().split()[2] == "Z"  # the grandchild is gone too


@pytest.mark.slow
def test_misbehaving_programs_cost_only_their_own_rows(tmp_path: Path) -> None:
    variants = ("sleep", "segv", "fail", "short", "nan", "clip")
    entries = [{"name": f"ext-{v}", "command": script_command("--variant", v)} for v in variants]
    entries.append({"name": "ext-good", "command": script_command(), "inputs": "kernel"})
    registered = register_manifest(write_manifest(tmp_path / "m.toml", entries), replace=True)
    try:
        assert all(isinstance(all_solvers()[s.name], ExternalSolver) for s in registered)
        names = ["test-exact", *[s.name for s in registered]]
        # Two cells (seeds) of one step each: no time extrapolation along a load history,
        # so every status below is the program's own doing, whatever the machine's load.
        run_benchmark(["paper-sweep"], SceneConfig(size=8, steps=1, seeds=(0, 1)), names,
                      RunConfig(reference="test-exact", timeout=3.0, warmup=False, progress=False), tmp_path / "run",
                      command=["pytest"])
        df = load_table(tmp_path / "run")
    finally:
        for s in registered:
            unregister(s.name)
    assert len(df) == 2 * len(names)  # every row kept
    status = {s: set(g["status"]) for s, g in df.groupby("solver")}
    assert status["test-exact"] == {"solved"} and status["ext-good"] == {"solved"}
    assert status["ext-sleep"] == {"timeout"}
    assert status["ext-segv"] == {"crashed"} and status["ext-fail"] == {"failed"}
    assert status["ext-short"] == {"failed"} and status["ext-nan"] == {"failed"}
    verdict = {s: set(g["verdict"]) for s, g in df.groupby("solver")}
    assert verdict["ext-short"] == {"wrong"} and verdict["ext-nan"] == {"wrong"}  # claimed "converged"
    errors = {s: " ".join(g["error"].astype(str)) for s, g in df.groupby("solver")}
    assert "giving up on purpose" in errors["ext-fail"] and "exited with code 3" in errors["ext-fail"]
    assert "wrong length" in errors["ext-short"] and "NaN" in errors["ext-nan"]
    assert "SIGSEGV" in errors["ext-segv"]
    clipped = df[(df.solver == "ext-clip") & (df.status == "inaccurate")]  # judged, not trusted
    assert len(clipped) and clipped["solver_converged"].all() and not clipped["correct_claim"].any()
    good = df[df.solver == "ext-good"]
    assert (good["kkt_error"] <= good["check_tol"]).all() and good["solver_message"].str.contains("exit 0").all()


def test_the_python_reading_snippet_of_the_docs_works(tmp_path: Path) -> None:
    import re

    doc = (REPO / "docs" / "external-solvers.md").read_text()
    snippet = re.search(r"### Python.*?```python\n(.*?)```", doc, flags=re.S).group(1)
    space: dict[str, object] = {}
    exec(compile(snippet, "docs/external-solvers.md", "exec"), space)
    inst = counterexample(16, 0)
    head, arrays = space["read_problem"](write_problem_dir(inst, tmp_path / "p", tol=1e-8, time_limit=1.0))
    assert head["n"] == 16 and np.array_equal(arrays["H"], inst.qp.H.to_dense())
    (tmp_path / "s").mkdir()
    space["write_solution"](str(tmp_path / "s"), np.ones(16), 3, "max_iter")
    sol = read_solution_dir(tmp_path / "s", 16)
    assert sol.iterations == 3 and not sol.claims_converged


def test_an_answer_that_is_not_a_regular_file_or_is_oversized_is_refused_without_reading_it(tmp_path: Path) -> None:
    """A FIFO at p.f64 would block the reader until the hard limit; a huge solution.json
    would be read whole: both are refused by what the file is."""
    fifo = tmp_path / "fifo"
    fifo.mkdir()
    os.mkfifo(fifo / "p.f64")
    with pytest.raises(SolutionFileError, match="not a regular file"):
        read_solution_dir(fifo, 4)
    big = tmp_path / "big"
    big.mkdir()
    np.zeros(4).tofile(big / "p.f64")
    (big / "solution.json").write_text('{"status": "converged", "pad": "' + "x" * (2 << 20) + '"}')
    with pytest.raises(SolutionFileError, match="more than the"):
        read_solution_dir(big, 4)
    np.zeros(10**6).tofile(big / "p.f64")
    with pytest.raises(SolutionFileError, match="more than the"):
        read_solution_dir(big, 4, as_written=True)


def test_a_child_left_running_by_a_program_that_exited_is_killed(tmp_path: Path) -> None:
    pidfile = tmp_path / "child.pid"
    solver = command_solver(f"sh -c 'sleep 30 & echo $! > {pidfile}; exit 0' {{problem}} {{solution}}")
    with pytest.raises(Exception):
        solver.solve(counterexample(16, 0).qp, SolverSettings(time_limit=10.0))
    pid = int(pidfile.read_text())
    time.sleep(0.2)
    stat = Path(f"/proc/{pid}/stat")
    assert not stat.exists() or stat.read_text().split()[2] == "Z"
