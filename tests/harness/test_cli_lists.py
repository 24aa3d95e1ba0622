"""Comma lists and time limits on the command line (harness/cli.py, harness/arguments.py).

* an empty item or an item given twice in a comma list (``--solvers``, ``--profile``,
  ``--seeds``, ``--loads``, ``--length``) is one line, exit 2, naming the option and the
  list, before anything runs; a value may repeat where its position means something
  (``--length L0,L1``);
* a time limit above a week (``--timeout``, ``--reference-timeout``) is one line, exit 2,
  before anything runs.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from tests.helpers import run_cli

from contactbench.harness import arguments
from contactbench.harness.run import plan

#: A run that takes well under a second where it is not refused.
SMALL = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--reference", "none", "--no-progress", "--out", "o"]

pytestmark = pytest.mark.usefixtures("in_tmp")


def refused_in_one_line(args: list[str], capsys: pytest.CaptureFixture[str], folder: Path) -> str:
    """The one line of a refusal of ``args`` (exit 2, no traceback, nothing written)."""
    rc, _, err = run_cli(args, capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, (rc, err)
    assert not any(folder.iterdir()), sorted(p.name for p in folder.iterdir())
    return lines[0]


@pytest.mark.parametrize(("option", "value", "needle"), [
    ("--solvers", "test-exact,,test-dummy", "empty item in 'test-exact,,test-dummy'"),
    ("--solvers", "test-exact,", "empty item in 'test-exact,'"),
    ("--solvers", "test-exact, test-exact", "'test-exact' twice"),
    ("--profile", "default,,low", "empty item in 'default,,low'"),
    ("--profile", "default,default", "'default' twice"),
    ("--seeds", "0,,1", "empty item in '0,,1'"),
    ("--seeds", "1,1", "'1' twice"),
    ("--seeds", "0-1,0-1", "'0-1' twice"),
    ("--length", "1e-4,,1e-4", "empty item in '1e-4,,1e-4'"),
], ids=["solvers-empty", "solvers-trailing", "solvers-twice", "profile-empty", "profile-twice", "seeds-empty",
        "seeds-twice", "seed-range-twice", "length-empty"])
def test_an_empty_or_repeated_item_is_refused(option: str, value: str, needle: str, in_tmp: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    solvers = [] if option == "--solvers" else ["--solvers", "test-exact"]
    line = refused_in_one_line([*SMALL, *solvers, option, value], capsys, in_tmp)
    assert option in line and needle in line, line


def test_a_solver_with_parameters_keeps_its_commas_and_counts_as_one_item() -> None:
    from contactbench.solvers.registry import split_solver_list

    items = getattr(arguments, "comma_items", None)
    assert items is not None, "harness.arguments.comma_items: the one splitter of a comma list"
    assert items("pk[tol=1e-8,maxit=3], nnls", split=split_solver_list) == ["pk[tol=1e-8,maxit=3]", "nnls"]
    assert items("pk[tol=1e-8],pk", split=split_solver_list) == ["pk[tol=1e-8]", "pk"]
    assert items(" , ") == []  # names nothing: each option says what that means
    assert items("1e-4,1e-4", repeats=True) == ["1e-4", "1e-4"]


@pytest.mark.parametrize("option", ["--timeout", "--reference-timeout"])
def test_a_time_limit_above_a_week_is_refused(option: str, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused_in_one_line([*SMALL, "--solvers", "test-exact", option, "1e300"], capsys, in_tmp)
    assert option in line and "at most 604800" in line, line
    week = 7 * 24 * 3600.0
    assert getattr(arguments, "MAX_TIMEOUT_S", None) == week
    assert plan.RunConfig(timeout=week, reference_timeout=week).timeout == week


@pytest.mark.parametrize(("env", "value"), [("CONTACTBENCH_FFT_WORKERS", "two"),
                                            ("CONTACTBENCH_FFT_BACKEND", "fftw3")])
def test_a_bad_fft_setting_is_refused_before_the_run(env: str, value: str, in_tmp: Path, monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv(env, value)
    line = refused_in_one_line([*SMALL, "--solvers", "test-exact"], capsys, in_tmp)
    assert env in line, line


def test_export_takes_its_cap_of_qps_from_the_command_line(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["export", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0,1", "--format", "problem-dir",
            "--out", "o"]
    line = refused_in_one_line([*args, "--max-qps", "3"], capsys, in_tmp)
    assert "over the limit of 3" in line and "--max-qps" in line, line
    rc, _, err = run_cli([*args, "--max-qps", "4"], capsys)
    assert rc == 0, err


def test_a_solver_loaded_by_path_with_a_registered_solver_s_name_is_refused(
        in_tmp: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """MODULE:NAME whose class calls itself "pk" would run in pk's place, its rows read as
    pk's (and a resume would keep them): one line, exit 2, nothing run or written."""
    from contactbench.solvers.registry import get_solver, register

    real = get_solver("pk")
    (in_tmp / "impostor.py").write_text(
        "from contactbench.solvers.base import Outcome, Solver\n"
        "class FakePK(Solver):\n"
        "    name = 'pk'\n"
        "    family = 'audit'\n"
        "    def iterate(self, ctx):\n"
        "        return Outcome(ctx.qp.ubar * 0.0, 1, True)\n")
    monkeypatch.syspath_prepend(str(in_tmp))
    try:
        rc, _, err = run_cli(["run", "counterexample", "--size", "10", "--seeds", "0", "--reference", "none",
                              "--no-progress", "--out", "o", "--solvers", "pk,impostor:FakePK"], capsys)
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and "'pk'" in lines[0] and "name of its own" in lines[0], err
        assert not (in_tmp / "o").exists()
        assert type(get_solver("pk")) is type(real)
    finally:
        register(real, replace=True)



def test_an_empty_surface_path_is_refused_not_read_as_no_surface(in_tmp: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """``--surface "$MAP"`` with MAP unset must not read as no ``--surface`` (the generated
    surface, its cleaning options ignored): refused in one line."""
    line = refused_in_one_line([*SMALL, "--solvers", "test-exact", "--surface", "", "--detrend", "none"], capsys,
                               in_tmp)
    assert "--surface is empty" in line, line


@pytest.mark.parametrize(("option", "value"), [("--length", "1_0e-4"), ("--size", "1_6"), ("--E", "1_0e9"),
                                               ("--loads", "0.001,0_002"), ("--length", "\u0661e-4"),
                                               ("--timeout", "6_0"), ("--repeats", "1_0"), ("--seeds", "0_0"),
                                               ("--memory-budget-gb", "1_0")])
def test_a_number_not_written_plainly_is_refused(option: str, value: str, capsys: pytest.CaptureFixture[str],
                                                 in_tmp: Path) -> None:
    """Numbers on the command line are written plainly, as in a map's text: Python's
    ``float`` would take "1_0e-4" (underscores) and digits of other scripts."""
    line = refused_in_one_line([*without(SMALL, option), option, value], capsys, in_tmp)
    assert option in line and repr(value) in line


def without(argv: list[str], option: str) -> list[str]:
    """``argv`` less ``option`` and its value (an option is given once)."""
    k = argv.index(option) if option in argv else len(argv)
    return argv[:k] + argv[k + 2:]
