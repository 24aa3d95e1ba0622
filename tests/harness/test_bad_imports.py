"""A solver named by import path whose module cannot be imported, or whose NAME cannot be
resolved, is one line naming the solver and what was raised, exit 2, before anything
runs -- whatever the module raised at import (any ``Exception``, ``SystemExit``, its own
``KeyboardInterrupt``, a ``BaseException`` subclass) -- for ``run`` and ``validate``
alike; a Ctrl-C that arrives during the import is still the user's and interrupts
(solvers/_loading.py, ``solvers.registry.load_named_solver``)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from contactbench.harness.conformance.declared import declaration_of, in_a_child
from contactbench.solvers.registry import SolverLoadError, load_named_solver, load_solver
from tests.helpers import run_cli

#: Module text -> the words the one line must hold (besides the solver's name).
AT_IMPORT: dict[str, tuple[str, ...]] = {
    "raise RuntimeError('boom at import')\n": ("RuntimeError: boom at import",),
    "def (\n": ("SyntaxError",),
    "import sys\nsys.exit(3)\n": ("SystemExit: 3",),
    "raise KeyboardInterrupt\n": ("KeyboardInterrupt",),
    "class Custom(BaseException):\n    pass\nraise Custom('its own')\n": ("Custom: its own",),
    "def f():\n    f()\nf()\n": ("RecursionError",),
    "raise ValueError('first\\nsecond')\n": ("ValueError: first / second",),
}
IDS = ["runtime", "syntax", "sysexit", "kbint", "baseexc", "recursion", "multiline"]


@pytest.fixture
def user_module(in_tmp: Path, monkeypatch: pytest.MonkeyPatch):
    """Write a module into the current folder and name its solver ``module:S``."""
    def write(text: str, name: str = "cb_bad_import") -> str:
        (in_tmp / f"{name}.py").write_text(text)
        monkeypatch.delitem(sys.modules, name, raising=False)
        return f"{name}:S"
    return write


@pytest.mark.parametrize("text", list(AT_IMPORT), ids=IDS)
def test_whatever_a_module_raises_at_import_is_one_line_naming_module_and_exception(text: str, user_module) -> None:
    spec = user_module(text)
    with pytest.raises(SolverLoadError) as caught:
        load_named_solver(spec)
    line = str(caught.value)
    assert len(line.splitlines()) == 1 and f"'{spec}'" in line, line
    assert all(word in line for word in AT_IMPORT[text]), line


@pytest.mark.parametrize("text", ["raise KeyboardInterrupt\n", "import sys\nsys.exit(3)\n",
                                  "class Custom(BaseException):\n    pass\nraise Custom()\n"],
                         ids=["kbint", "sysexit", "baseexc"])
def test_a_module_cannot_end_or_interrupt_the_process_that_loads_it(text: str, user_module) -> None:
    with pytest.raises(Exception) as caught:  # an Exception, not a BaseException that ends the command
        load_solver(user_module(text))
    assert "importing module 'cb_bad_import'" in str(caught.value)


def test_a_ctrl_c_during_the_import_is_the_users_and_interrupts(user_module) -> None:
    spec = user_module("import os, signal, time\nos.kill(os.getpid(), signal.SIGINT)\ntime.sleep(5)\n")
    with pytest.raises(KeyboardInterrupt):
        load_named_solver(spec)


@pytest.mark.parametrize("text", ["raise RuntimeError('boom at import')\n", "raise KeyboardInterrupt\n",
                                  "import sys\nsys.exit(3)\n"], ids=["runtime", "kbint", "sysexit"])
def test_run_refuses_a_module_that_fails_at_import_in_one_line_exit_2_and_writes_nothing(
        text: str, user_module, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = user_module(text)
    rc, _, err = run_cli(["run", "paper-sweep", "--size", "8", "--steps", "2", "--reference", "none",
                          "--no-progress", "--solvers", spec, "--out", "o"], capsys)
    assert rc == 2, (rc, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("contactbench: error: ") and f"'{spec}'" in err, err
    assert not (in_tmp / "o").exists()


@pytest.mark.parametrize("text", ["raise KeyboardInterrupt\n",
                                  "class Custom(BaseException):\n    pass\nraise Custom('its own')\n"],
                         ids=["kbint", "baseexc"])
def test_validates_loading_child_brings_back_the_one_line_not_a_crash(text: str, user_module) -> None:
    spec = user_module(text)
    with pytest.raises(SolverLoadError, match="importing module 'cb_bad_import' raised"):
        in_a_child(declaration_of, spec, None)
