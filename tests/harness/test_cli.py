"""The command line a user hits: exit status and one-line messages (harness/cli.py).

Every refusal is exit 2 with one line on stderr and no traceback, before anything is
written; a run whose rows the judge could not read at all is exit 1; the shell commands
of docs/harness.md ("Exit status") run with the exit status they state.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from contactbench.solvers.registry import get_solver
from tests.helpers import REPO, run_cli

ROOT = REPO
DOC = ROOT / "docs" / "harness.md"
TINY = ["--size", "16", "--steps", "2", "--seeds", "0", "--no-progress"]

#: A user's solver module, written into the current folder of a run: ``honest=false``
#: (the default) answers NaN; ``honest=true`` answers with the PK solver's p.
PROBE_MODULE = '''
import numpy as np
from contactbench.solvers import Capabilities, Outcome, Param, Solver, SolverSettings, get_solver


class Probe(Solver):
    name = "param-probe"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), exact=False)
    params = (Param("honest", bool, False, "answer with PK's p instead of NaN"),)

    def iterate(self, ctx):
        if not ctx.params["honest"]:
            return Outcome(p=np.full(ctx.qp.n, np.nan), iterations=1, converged=True)
        p = get_solver("pk").solve(ctx.qp, SolverSettings(tol=1e-10)).p
        return Outcome(p=p, iterations=1, converged=True)


class Picky(Probe):
    name = "picky-probe"

    def skip(self, traits):
        return "takes no problem at all"
'''


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``contactbench ARGS`` run in this process."""
    return run_cli(args, capsys)


def one_line(err: str) -> str:
    """The single line of ``err`` (asserting there is one and no traceback)."""
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def refused(args: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> str:
    """Assert ``args`` exit 2 with one line holding every needle; return the line."""
    rc, _, err = cli(args, capsys)
    line = one_line(err)
    assert rc == 2, (rc, err)
    for needle in needles:
        assert needle in line, (needle, line)
    return line


#: Every test runs in an empty folder of its own (tests/conftest.py's ``in_tmp``):
#: relative --out paths land there.
pytestmark = pytest.mark.usefixtures("in_tmp")


def written(folder: Path) -> list[str]:
    """Every file under ``folder`` (relative paths; empty folders are not counted)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


# ---------------------------------------------------------------------------
# --version, --help, did you mean
# ---------------------------------------------------------------------------


def test_version_is_the_installed_one(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = cli(["--version"], capsys)
    assert rc == 0
    assert out.strip() == f"contactbench {metadata.version('contactbench')}"


def test_help_shows_the_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = cli(["run", "--help"], capsys)
    assert rc == 0
    text = " ".join(out.split())
    for shown in ("hard limit per solve, seconds (default: 60.0)", "(default: 1)", "(default: auto)",
                  "grid points per side N (default: the scene's"):
        assert shown in text, shown
    assert "(default: None)" not in text and "(default: False)" not in text


@pytest.mark.parametrize(("args", "needles"), [
    (["rnu", "hertz"], ("invalid choice 'rnu'", "did you mean 'run'?")),
    (["list", "scens"], ("did you mean 'scenes'?",)),
    (["run", "hertzz"], ("unknown scene 'hertzz'", "did you mean 'hertz'")),
    (["run", "hertz", "--solvers", "scipy-nnsl"], ("unknown solver 'scipy-nnsl'", "did you mean 'scipy-nnls'")),
    (["run", "hertz", "--profile", "hihg"], ("unknown profile 'hihg'", "did you mean 'high'?")),
    (["run", "hertz", "--kernel", "bbc"], ("invalid choice 'bbc'", "did you mean 'bcc'?")),
], ids=["command", "list", "scene", "solver", "profile", "kernel"])
def test_a_misspelt_name_gets_the_closest_known_ones(args: list[str], needles: tuple[str, ...],
                                                     capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    refused(args, capsys, *needles)
    assert written(in_tmp) == []


def test_a_name_far_from_every_known_one_gets_no_suggestion(capsys: pytest.CaptureFixture[str]) -> None:
    line = refused(["run", "hertz", "--solvers", "zzzzzz"], capsys, "unknown solver 'zzzzzz'")
    assert "did you mean" not in line


# ---------------------------------------------------------------------------
# Options refused up front
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("solvers", ["", ",", " , "])
def test_an_empty_solver_list_is_refused_not_read_as_every_solver(solvers: str,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    refused(["run", "hertz", "--size", "16", "--solvers", solvers], capsys, "--solvers", "names no solver")


@pytest.mark.parametrize(("args", "needles"), [
    (["run", "counterexample", "--surface", "x.npy"], ("scene 'counterexample' does not take --surface",)),
    (["run", "counterexample", "--E", "1e9"], ("does not take --E",)),
    (["run", "hertz", "--periodic"], ("scene 'hertz' does not take --periodic",)),
    (["run", "hertz", "--seeds", "0-3"], ("does not take --seeds",)),
    (["run", "population", "--surface-family", "saupe"], ("does not take --surface-family",)),
    (["run", "stress-edge", "--size", "16"], ("scene 'stress-edge' does not take --size", "no scene option")),
    (["export", "counterexample", "--kernel", "love", "--format", "problem-dir", "--out", "e"],
     ("does not take --kernel",)),
], ids=["surface", "E", "periodic", "seeds", "family", "stress-size", "export-kernel"])
def test_an_option_the_scene_would_ignore_is_refused(args: list[str], needles: tuple[str, ...],
                                                     capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    refused(args, capsys, *needles)
    assert written(in_tmp) == []


def test_an_option_that_some_part_of_a_composite_takes_is_not_refused() -> None:
    from contactbench.harness.run.plan import option_problems
    from contactbench.problems.scenes import SceneConfig

    assert option_problems(["default"], SceneConfig(kernel="love")) == []  # counterexample ignores it, paper-sweep takes it
    assert any("does not take --surface-family" in p
               for p in option_problems(["stress"], SceneConfig(extra={"family": "saupe"})))


@pytest.fixture
def npy_surface(in_tmp: Path) -> Path:
    from contactbench.problems.surfaces import rmd_surface_n

    z = rmd_surface_n(33, 0.7, length=1e-4, rms_height=1e-6, seed=0).heights[:32, :32]
    np.save(in_tmp / "s.npy", z)
    return in_tmp / "s.npy"


@pytest.mark.parametrize("option", [["--size", "16"], ["--seeds", "0-3"]], ids=["size", "seeds"])
def test_generated_surface_options_are_refused_with_a_surface_file(option: list[str], npy_surface: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    refused(["run", "paper-sweep", "--surface", str(npy_surface), "--length", "1e-4", *option], capsys,
            f"{option[0]} does not apply with --surface")


def test_height_unit_is_refused_for_a_file_that_states_its_unit(in_tmp: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("SurfaceTopography")
    from contactbench.problems.io import write_topography

    z = np.random.default_rng(0).normal(scale=1e-7, size=(32, 32))
    path = write_topography(in_tmp / "s.x3p", z, 1e-4 / 32, fmt="x3p")
    for unit in ("um", "m"):  # even the default unit: the option would be ignored
        refused(["run", "paper-sweep", "--surface", str(path), "--height-unit", unit, "--out", "o"], capsys,
                "states its own unit", "--height-unit")
    assert written(in_tmp) == ["s.x3p"]


def test_height_unit_is_taken_for_a_file_that_states_none(npy_surface: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    # metres read as micrometres: plausible either way at this rms height, so it runs
    rc, out, err = cli(["run", "paper-sweep", "--surface", str(npy_surface), "--length", "1e-4", "--height-unit",
                        "m", "--steps", "1", "--solvers", "pk", "--out", "o", "--no-progress"], capsys)
    assert rc == 0, err
    assert "solved 1" in out


def test_a_scene_that_applies_no_height_unit_refuses_it(npy_surface: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    refused(["run", "cmr-cutoff", "--surface", str(npy_surface), "--length", "1e-4", "--height-unit", "um"], capsys,
            "scene 'cmr-cutoff' does not take --height-unit")


@pytest.mark.parametrize("scene", ["paper-sweep", "hertz", "population"])
def test_the_spectral_kernel_needs_a_periodic_domain(scene: str, capsys: pytest.CaptureFixture[str],
                                                     in_tmp: Path) -> None:
    # population is periodic by default; paper-sweep and hertz are not
    args = ["run", scene, "--kernel", "spectral", "--size", "16", "--out", "o"]
    if scene == "population":
        args = ["run", scene, "--kernel", "spectral", "--size", "16", "--seeds", "0", "--solvers", "nnls",
                "--out", "o", "--no-progress"]
        rc, _, err = cli(args, capsys)
        assert rc == 0, err
        return
    refused(args, capsys, "'spectral' kernel is defined for periodic domains only")
    assert written(in_tmp) == []


def test_spectral_with_periodic_runs(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = cli(["run", "paper-sweep", *TINY, "--kernel", "spectral", "--periodic", "--solvers", "nnls",
                        "--out", "o"], capsys)
    assert rc == 0, err
    assert "solved 2" in out


@pytest.mark.parametrize("E", ["1e-300", "999", "1.1e13", "inf"])
def test_an_implausible_modulus_is_refused(E: str, capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    line = refused(["run", "paper-sweep", *TINY, "--E", E, "--out", "o"], capsys, "--E")
    assert ("plausible range" in line and "--allow-any-E" in line) or "must be finite" in line
    assert written(in_tmp) == []


def test_the_plausible_range_is_inclusive_and_lives_in_units() -> None:
    from contactbench.problems.scenes.options import BY_NAME, value_problem
    from contactbench.problems.units import PLAUSIBLE_MODULUS

    lo, hi = PLAUSIBLE_MODULUS
    record = BY_NAME["E"]  # the option's record reads its range from units
    assert (record.plausible.lo, record.plausible.hi) == PLAUSIBLE_MODULUS
    assert value_problem(record, lo, set()) is None and value_problem(record, hi, set()) is None
    for bad in (np.nextafter(lo, 0), np.nextafter(hi, np.inf), float("nan")):
        assert value_problem(record, bad, set()) is not None
    assert value_problem(record, np.nextafter(lo, 0), {"allow_any_E"}) is None


@pytest.mark.parametrize("args", [["--length", "-1e-6"], ["--length=-1e-6"], ["--E", "-5"], ["--steps", "-2"],
                                  ["--length", "-.5"]])
def test_a_negative_number_is_a_value_that_must_be_positive(args: list[str],
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    flag = args[0].split("=")[0]
    refused(["run", "paper-sweep", *args], capsys, f"{flag} must be >", "got -")


# ---------------------------------------------------------------------------
# Paths
# ---------------------------------------------------------------------------


def test_out_naming_a_file_is_refused(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (in_tmp / "somefile").write_text("x")
    refused(["run", "hertz", "--size", "16", "--out", "somefile"], capsys, "--out somefile", "not a folder")
    refused(["run", "hertz", "--size", "16", "--out", "somefile/sub"], capsys, "--out somefile/sub",
            "somefile is a file")
    refused(["export", "hertz", "--size", "16", "--format", "problem-dir", "--out", "somefile"], capsys,
            "--out somefile", "not a folder")
    refused(["export", "hertz", "--size", "16", "--format", "problem-dir", "--out", "somefile/sub"], capsys,
            "--out somefile/sub")
    assert written(in_tmp) == ["somefile"]


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
def test_out_where_nothing_may_be_made_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    # /proc takes no new folder, even for root (chmod does not stop root)
    refused(["run", "hertz", "--size", "16", "--solvers", "pk", "--out", "/proc/contactbench-x/y"], capsys,
            "/proc/contactbench-x")


def test_report_of_a_missing_or_empty_folder_is_one_line(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    refused(["report", "nosuch"], capsys, "report nosuch: no such folder")
    (in_tmp / "empty").mkdir()
    refused(["report", "empty"], capsys, "no results table in empty")


# ---------------------------------------------------------------------------
# Solver parameters on run, a solver module in the current folder
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(("spec", "needles"), [
    ("fast-dual-pccg[precision=quad]", ("solver 'fast-dual-pccg[precision=quad]'", "one of 'double', 'mixed'")),
    ("fast-dual-pccg[precison=double]", ("has no parameter 'precison'", "allowed: ")),
    ("nnls-gp[K=1.5]", ("parameter 'K' takes a whole number, got '1.5'",)),
    ("fast-dual-pccg[precision=double", ("unclosed '['",)),
    ("fast-dual-pccg[precision]", ("write key=value",)),
    ("fast-dual-pccg[]", ("empty parameter list",)),
    ("fast-dual-pccg[precision=double,precision=mixed]", ("given twice",)),
    ("admm[rho=0]", ("parameter 'rho' must lie in (0, inf), got 0",)),
    ("admm[alpha=2.0]", ("parameter 'alpha' must lie in (0, 2), got 2.0",)),
    ("nnls-gp[K=-1]", ("parameter 'K' must lie in [0, inf), got -1",)),
    ("pk[grid]", ("solver 'pk[grid]': 'pk' declares no grid to expand",)),
    ("nnls-gp[grid,K=0.5]", ("parameter 'K' takes a whole number, got '0.5'",)),
    ("nnls-gp[grid],nnls-gp[K=50]", ("--solvers names the variant 'nnls-gp[K=50]' twice",)),
], ids=["bad-choice", "unknown-key", "bad-int", "unclosed", "no-value", "empty", "twice", "open-low", "open-high",
        "closed-low", "no-grid", "grid-bad-fixed", "grid-variant-twice"])
def test_bad_solver_parameters_are_refused_in_one_line(spec: str, needles: tuple[str, ...], in_tmp: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    refused(["run", "paper-sweep", *TINY, "--solvers", spec, "--out", "o"], capsys, *needles)
    assert written(in_tmp) == []


def test_solver_parameters_make_labelled_variants(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    rc, _, err = cli(["run", "paper-sweep", *TINY, "--solvers",
                        "fast-dual-pccg[precision=double],nnls-gp[K=5],pk", "--out", "o"], capsys)
    assert rc == 0, err
    df = pd.read_parquet(in_tmp / "o" / "results.parquet")
    got = {(r.solver, r.base_solver, r.params) for r in df.itertuples()}
    assert got == {("fast-dual-pccg[precision=double]", "fast-dual-pccg", '{"precision": "double"}'),
                   ("nnls-gp[K=5]", "nnls-gp", '{"K": 5}'), ("pk", "pk", "{}")}


def test_a_solvers_grid_runs_one_labelled_variant_per_point(capsys: pytest.CaptureFixture[str],
                                                            in_tmp: Path) -> None:
    rc, _, err = cli(["run", "paper-sweep", *TINY, "--solvers", "nnls-gp[grid,restart=on],pk", "--out", "o"], capsys)
    assert rc == 0, err
    df = pd.read_parquet(in_tmp / "o" / "results.parquet")
    got = {(r.solver, r.base_solver, r.params) for r in df.itertuples()}
    grid = get_solver("nnls-gp").grid["K"]
    assert got == {("pk", "pk", "{}")} | {(f"nnls-gp[K={k},restart=True]", "nnls-gp", f'{{"K": {k}, "restart": true}}')
                                          for k in grid}
    assert len(df) == 2 * (len(grid) + 1)  # every variant at each of the two steps


#: A user's solver module whose declarations break the rules (solvers/registry.py
#: ``check_declaration``), and one whose grid is over ``MAX_GRID_VARIANTS``.
BAD_DECLARATIONS = '''
from contactbench.solvers import Capabilities, Outcome, Param, Solver


class Base(Solver):
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}))

    def iterate(self, ctx):
        return Outcome(p=ctx.qp.ubar * 0.0, iterations=1, converged=False)


class BadGrid(Base):
    name = "bad-grid"
    params = (Param("step", float, 1.0, low=0.1, high=1.0),)
    grid = {"step": ("fast", 7.0), "nonexistent": (1, 2)}


class BadParamKind(Base):
    name = "bad-param-kind"
    params = (Param("opts", list, [1, 2]), Param("choice", str, "a", choices=("a", 3)))


class BigGrid(Base):
    name = "big-grid"
    params = (Param("a", int, 0), Param("b", int, 0))
    grid = {"a": tuple(range(20)), "b": tuple(range(20))}
'''


@pytest.mark.parametrize(("cls", "needles"), [
    ("BadGrid", ("solver 'bad-grid': ", "parameter 'step' takes a number, got 'fast'", "got 7.0",
                 "its grid names 'nonexistent', which is not a declared parameter")),
    ("BadParamKind", ("solver 'bad-param-kind': ", "parameter 'opts' is of kind list",
                      "parameter 'choice' takes text, got 3")),
    ("BigGrid[grid]", ("its grid has 400 points, over the limit of 100",)),
], ids=["grid", "kind", "grid-limit"])
def test_a_solver_module_whose_declaration_breaks_the_rules_is_refused_in_one_line(
        cls: str, needles: tuple[str, ...], in_tmp: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (in_tmp / "cb_bad_declarations.py").write_text(BAD_DECLARATIONS)
    monkeypatch.delitem(sys.modules, "cb_bad_declarations", raising=False)
    refused(["run", "counterexample", "--size", "10", "--seeds", "0", "--no-progress",
             "--solvers", f"cb_bad_declarations:{cls}", "--out", "o"], capsys, *needles)
    assert written(in_tmp) == ["cb_bad_declarations.py"]


def contactbench(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``contactbench ARGS`` in a fresh interpreter in ``cwd``, with no PYTHONPATH."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, "-m", "contactbench.harness.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout, check=False)


def test_a_solver_module_in_the_current_folder_runs_with_its_parameters(in_tmp: Path) -> None:
    (in_tmp / "probe_solver.py").write_text(PROBE_MODULE)
    res = contactbench(["run", "paper-sweep", *TINY, "--solvers",
                        "probe_solver:Probe[honest=true],probe_solver:Probe", "--out", "o"], in_tmp)
    assert res.returncode == 0, res.stderr
    df = pd.read_parquet(in_tmp / "o" / "results.parquet")
    status = {solver: set(rows) for solver, rows in df.groupby("solver")["status"]}
    # the parameter reached the solve: the honest variant is solved, the default one fails on NaN
    assert status == {"param-probe[honest=True]": {"solved"}, "param-probe": {"failed"}}


# ---------------------------------------------------------------------------
# Exit 1: nothing could be judged
# ---------------------------------------------------------------------------


def test_a_run_whose_every_row_failed_exits_1(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (in_tmp / "probe_solver.py").write_text(PROBE_MODULE)
    rc, out, err = cli(["run", "paper-sweep", *TINY, "--solvers", "probe_solver:Probe", "--out", "o"], capsys)
    assert rc == 1
    assert re.search(r"2 rows \(2 new\) in .* s: failed 2 -> o", out), out
    line = one_line(err)
    assert "no row could be judged" in line and "o/results.csv" in line
    assert re.search(r"most common reason \([12] of 2\): p has \d+ NaN/inf entries", line), line
    assert (in_tmp / "o" / "results.parquet").is_file()  # the table is written all the same


def test_a_run_whose_every_row_was_skipped_exits_1(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    (in_tmp / "probe_solver.py").write_text(PROBE_MODULE)
    rc, out, err = cli(["run", "paper-sweep", *TINY, "--solvers", "probe_solver:Picky", "--out", "o"], capsys)
    assert rc == 1, (out, err)
    assert "skipped 2" in out
    line = one_line(err)
    assert "no row could be judged" in line and "takes no problem at all" in line


@pytest.mark.slow
def test_allow_any_modulus_takes_an_implausible_one(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    # the scaled KKT error is unit-free: PK solves the problem at E = 1e-200 Pa all the same
    # (at 1e-300 the forces of this grid would be subnormal floats)
    rc, _, err = cli(["run", "paper-sweep", *TINY, "--E", "1e-200", "--allow-any-E", "--solvers", "pk",
                        "--out", "o"], capsys)
    assert rc == 0, err
    assert pd.read_parquet(in_tmp / "o" / "results.parquet")["E"].eq(1e-200).all()


def test_a_run_with_one_judged_row_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = cli(["run", "paper-sweep", *TINY, "--solvers", "pk", "--out", "o"], capsys)
    assert rc == 0, err
    assert err.strip() == ""


def test_the_summary_counts_judged_rows() -> None:
    from contactbench.harness import RunSummary

    def summary(statuses: dict[str, int]) -> RunSummary:
        return RunSummary("o", sum(statuses.values()), 0, statuses, 0.0, [])

    assert summary({"failed": 3, "skipped": 2, "crashed": 1, "timeout": 1}).judged == 0
    assert summary({"failed": 3, "inaccurate": 1}).judged == 1
    assert summary({"solved": 2, "inaccurate": 1}).judged == 3
    assert summary({}).judged == 0


# ---------------------------------------------------------------------------
# docs/harness.md
# ---------------------------------------------------------------------------


def doc_commands() -> list[tuple[str, int]]:
    """(command, exit status) of every line of the ```sh blocks of docs/harness.md; each
    line ends in ``# exit N``."""
    out = []
    for block in re.findall(r"```sh\n(.*?)```", DOC.read_text(), flags=re.DOTALL):
        for line in block.splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                m = re.fullmatch(r"\s*(contactbench .*?)\s+# exit (\d+)\b.*", line)
                assert m, f"docs/harness.md: a shell line without '# exit N': {line!r}"
                out.append((m.group(1), int(m.group(2))))
    return out


def test_the_docs_show_runnable_commands() -> None:
    assert len(doc_commands()) >= 5


@pytest.mark.parametrize(("command", "status"), doc_commands(), ids=[c[len("contactbench "):][:50]
                                                                      for c, _ in doc_commands()])
def test_each_docs_command_exits_as_stated(command: str, status: int, capsys: pytest.CaptureFixture[str],
                                           in_tmp: Path) -> None:
    (in_tmp / "notafolder").write_text("x")
    rc, _, err = cli(shlex.split(command)[1:], capsys)
    assert rc == status, (command, err)
    if status:
        one_line(err)


def test_a_reader_that_goes_away_ends_the_listing_quietly() -> None:
    """`contactbench list solvers --params | head -1`: no error line when head stops reading
    (here the reader is gone before the listing starts, so the first write meets it)."""
    proc = subprocess.Popen([sys.executable, "-m", "contactbench.harness.cli", "list", "solvers", "--params"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    proc.stdout.close()
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 141 and err.decode() == ""


def test_params_of_a_listing_without_parameters_is_refused(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    refused(["list", "scenes", "--params"], capsys, "--params lists the solvers' parameters")


def test_an_interrupted_command_says_what_it_left(tmp_path: Path) -> None:
    """Ctrl-C: a report says no report was written (it said "rows so far are kept", the
    run's line); an export that made no folder says nothing was exported (it pointed to a
    manifest.json that does not exist); a run stopped before it wrote a row says so (it
    said its rows were kept, with no folder made)."""
    from argparse import Namespace

    from contactbench.harness.cli import interrupted_text

    assert interrupted_text(Namespace(command="report")).startswith("no report was written")
    assert interrupted_text(Namespace(command="export", out=str(tmp_path / "none"))).startswith("nothing was exported")
    (tmp_path / "manifest.json").write_text("{}")
    assert "incomplete" in interrupted_text(Namespace(command="export", out=str(tmp_path)))
    run = tmp_path / "run"
    assert interrupted_text(Namespace(command="run", out=str(run), scenes=["hertz"])).startswith("no row was written")
    run.mkdir()
    (run / "rows.jsonl").write_text("{}\n")
    assert interrupted_text(Namespace(command="run", out=str(run), scenes=["hertz"])).startswith("rows so far are kept")


def test_an_export_that_skips_a_qp_exits_1_not_0(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Exit 0 says every QP is written: a qpbenchmark export whose dense limit leaves QPs out
    exits 1 with one line counting them (it exited 0 having written none)."""
    args = ["export", "paper-sweep", "--size", "16", "--steps", "2", "--format", "qpbenchmark", "--dense-limit", "1",
            "--out", str(tmp_path / "ex")]
    code, out, err = run_cli(args, capsys)
    assert code == 1 and "exported 0 QPs" in out and "skipped 2" in out, (out, err)
    assert err.strip() == "contactbench export: 2 of 2 QPs not written (the line above says why)"


def test_exporting_a_composite_names_its_scenes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``list scenes`` lists the composite ``default``; ``export default`` says what it is and
    which scenes to export (it said "unknown scene 'default'"), exit 2, nothing written."""
    code, _out, err = run_cli(["export", "default", "--format", "hdf5", "--out", str(tmp_path / "ex")], capsys)
    assert code == 2 and "a composite of the scenes paper-sweep, counterexample" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "ex").exists()
