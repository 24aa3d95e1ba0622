"""docs/adding-a-solver.md works as written: its example is tests/example_solver.py, and
every shell command it shows runs, from a folder outside the repository."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from contactbench.solvers import unregister
from tests.helpers import REPO, TESTS

ROOT = REPO
DOC = ROOT / "docs" / "adding-a-solver.md"
EXAMPLE = TESTS / "example_solver.py"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), flags=re.S)


def shell_commands() -> list[str]:
    lines = [ln.strip() for b in blocks("sh") for ln in b.splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("#")]


def command_param(cmd: str) -> Any:
    return pytest.param(cmd, id=cmd[len("contactbench "):][:60])


@pytest.fixture(scope="module")
def outside(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder outside the repository holding only the example solver."""
    folder = tmp_path_factory.mktemp("user-project")
    shutil.copy(EXAMPLE, folder / "example_solver.py")
    return folder


def contactbench(args: list[str], cwd: Path, timeout: float = 180) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run([sys.executable, "-m", "contactbench.harness.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_the_docs_example_is_the_tested_file_and_short() -> None:
    text = EXAMPLE.read_text()
    assert text in blocks("python"), "docs/adding-a-solver.md must show tests/example_solver.py verbatim"
    assert len(text.splitlines()) <= 60


def test_the_example_imports_only_the_public_namespace() -> None:
    imports = re.findall(r"^(?:from (\S+) import|import (\S+))", EXAMPLE.read_text(), flags=re.M)
    modules = {a or b for a, b in imports}
    assert modules == {"__future__", "math", "numpy", "contactbench.solvers"}


def test_the_doc_shows_every_documented_command() -> None:
    cmds = shell_commands()
    assert cmds and all(c.startswith("contactbench ") for c in cmds), cmds
    for must in ("validate --list", "validate --all --quiet", "validate --help", "validate example_solver:"):
        assert any(must in c for c in cmds), must


@pytest.mark.slow
@pytest.mark.parametrize("cmd", [command_param(c) for c in shell_commands()])
def test_every_shell_command_of_the_doc_runs(cmd: str, outside: Path) -> None:
    res = contactbench(shlex.split(cmd)[1:], outside)
    assert res.returncode == 0, f"{cmd}\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    if "validate example_solver:" in cmd:
        assert "example-apg [fast]: CONFORMS" in res.stdout
    if "--csv verdicts.csv" in cmd:
        assert (outside / "verdicts.csv").read_text().count("\n") > 1
    if "validate --list" in cmd:
        assert "counterexample/example1-n400-s0" in res.stdout
    if "validate --help" in cmd:
        assert "--quiet" in res.stdout and "exit status" in res.stdout
    if "list solvers --params" in cmd:
        assert "pk" in res.stdout


def test_a_mistyped_import_path_exits_2_with_one_clear_line(outside: Path) -> None:
    res = contactbench(["validate", "example_solver:NoSuchSolver"], outside)
    assert res.returncode == 2
    assert res.stderr.strip() == ("contactbench validate: error: module 'example_solver' has no attribute "
                                  "'NoSuchSolver' (solver 'example_solver:NoSuchSolver')")


def test_the_docs_pytest_snippet_passes(outside: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    snippet = next(b for b in blocks("python") if "assert_conforms" in b)
    monkeypatch.syspath_prepend(str(outside))
    namespace: dict[str, Any] = {}
    try:
        exec(compile(snippet, str(DOC), "exec"), namespace)
        tests = [f for name, f in namespace.items() if name.startswith("test_")]
        assert tests
        for test in tests:
            test()
    finally:  # importing the example registered it: leave the registry as it was
        unregister("example-apg")
        sys.modules.pop("example_solver", None)


def test_the_docs_case_by_case_snippet_passes_and_skips_what_is_not_handed(outside: Path) -> None:
    snippet = next(b for b in blocks("python") if "case_conforms" in b)
    (outside / "test_cases_snippet.py").write_text(snippet)
    env = {**os.environ, "PYTHONPATH": str(outside)}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                           "-rs", "test_cases_snippet.py", "-k", "delta0 or single-point or load-bcc"],
                          cwd=outside, env=env, capture_output=True, text=True, timeout=300)
    out = done.stdout + done.stderr
    assert done.returncode == 0 and "passed" in out and "skipped" in out, out
    assert "[edge/delta0-N16]" in out or "edge/delta0-N16" in out, out  # (each test named by its case)
