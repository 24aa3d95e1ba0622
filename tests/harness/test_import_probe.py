"""``contactbench run`` imports a solver named by import path (``module:NAME``) in a forked
child before its own process does: a module whose import ends the process that imports it
(``os._exit``, a signal, a segfault) is one line naming the module and how that process
ended, exit 2, before anything runs or is written, and ``run``'s own process never imports
it; a module whose import ends nothing is imported by one child and by ``run``, and its
solver runs (harness/run/plan.py ``probe_import``, harness/run/child_call.py).  ``validate``
probes the same way, and its line names the solver as ``run``'s does."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from tests.helpers import run_cli

#: Module text -> how the process that imports it ends, in the line's words.
ENDS_ITS_PROCESS: dict[str, str] = {
    "import os\nos._exit(3)\n": "exited with code 3",
    "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n": "killed by signal SIGKILL",
    "import ctypes\nctypes.string_at(0)\n": "killed by signal SIGSEGV",
}

#: A module that records the pid of each process that imports it (in ``imported-by.txt``
#: of the current folder) and holds two solvers: PK's answer under names of their own.
FINE_MODULE = '''
import os
from contactbench.solvers import Capabilities, Outcome, Solver, SolverSettings, get_solver

with open("imported-by.txt", "a") as f:
    f.write(f"{os.getpid()}\\n")


class S(Solver):
    name = "probe-fine"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}), exact=False)

    def iterate(self, ctx):
        p = get_solver("pk").solve(ctx.qp, SolverSettings(tol=1e-10)).p
        return Outcome(p=p, iterations=1, converged=True)


class T(S):
    name = "probe-fine-too"
'''

RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--reference", "none", "--no-progress"]


@pytest.fixture
def user_module(in_tmp: Path, monkeypatch: pytest.MonkeyPatch):
    """Write a module into the current folder (unimported here) and return its name."""
    def write(text: str, name: str) -> str:
        (in_tmp / f"{name}.py").write_text(text)
        monkeypatch.delitem(sys.modules, name, raising=False)
        return name
    return write


@pytest.mark.parametrize("text", list(ENDS_ITS_PROCESS), ids=["os-exit", "sigkill", "segfault"])
def test_run_refuses_a_module_whose_import_ends_its_process_in_one_line_exit_2_and_writes_nothing(
        text: str, user_module, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    module = user_module(text, "cb_ends_its_process")
    rc, _, err = run_cli([*RUN, "--solvers", f"{module}:S", "--out", "o"], capsys)
    assert rc == 2, (rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("contactbench: error: "), err
    assert f"cannot load solver '{module}:S': importing module '{module}' ended its process" in lines[0], err
    assert f"({ENDS_ITS_PROCESS[text]})" in lines[0], err
    assert module not in sys.modules
    assert not (in_tmp / "o").exists()


def test_a_module_whose_import_ends_nothing_is_imported_once_in_a_child_and_its_solvers_run(
        user_module, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two solvers of one module: one child imports it, then ``run``'s own process."""
    module = user_module(FINE_MODULE, "cb_imports_fine")
    rc, out, err = run_cli([*RUN, "--solvers", f"{module}:S,{module}:T", "--out", "o"], capsys)
    assert rc == 0, (out, err)
    importers = [int(pid) for pid in (in_tmp / "imported-by.txt").read_text().split()]
    assert len(importers) == 2 and importers[-1] == os.getpid(), importers
    assert (in_tmp / "o" / "results.parquet").is_file()
    assert "solved 4" in out, out


@pytest.mark.parametrize("text", list(ENDS_ITS_PROCESS), ids=["os-exit", "sigkill", "segfault"])
def test_validate_names_the_solver_whose_import_ends_its_process(
        text: str, user_module, capsys: pytest.CaptureFixture[str]) -> None:
    """The same line as ``run``'s, with another solver beside it: which one, and how."""
    module = user_module(text, "cb_ends_its_process")
    rc, _, err = run_cli(["validate", "nnls", f"{module}:S", "--quiet"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("contactbench validate: error: "), (rc, err)
    assert f"cannot load solver '{module}:S': importing module '{module}' ended its process" in lines[0], err
    assert f"({ENDS_ITS_PROCESS[text]})" in lines[0], err
    assert module not in sys.modules
