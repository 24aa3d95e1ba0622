"""``validate`` judges in a process that never runs the solver's code: a module that rewrites
the harness when it is imported (the judge's test, the exit status) changes only the child
processes that load it, and its wrong answers are judged wrong (harness/conformance/declared.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from contactbench.harness.conformance.declared import LoadFailed, in_a_child
from contactbench.problems.errors import ProblemInputError

#: A solver module that, on import, makes every KKT test pass and every verdict table exit
#: 0, records the pid of each process that imports it, and answers p = 0 (wrong) claiming
#: convergence.
PATCHING_MODULE = textwrap.dedent('''
    import os
    import numpy as np
    import contactbench.harness.judging as judging
    import contactbench.harness.conformance.battery as battery
    from contactbench.solvers import Solver, register
    from contactbench.solvers.base import Outcome

    with open(os.environ["IMPORTED_BY"], "a") as f:
        f.write(f"{os.getpid()}\\n")
    for name in dir(judging):
        obj = getattr(judging, name)
        if isinstance(obj, type) and hasattr(obj, "passes"):
            obj.passes = lambda self, tol: True
    battery.VerdictTable.exit_code = lambda self, strict=False: 0

    @register
    class Patching(Solver):
        name = "patching-on-import"
        description = "patches the harness when imported; answers p = 0"

        def iterate(self, ctx):
            return Outcome(p=np.zeros(ctx.qp.n), converged=True, iterations=1)
''')


def test_a_module_that_patches_the_harness_on_import_is_judged_wrong(tmp_path: Path) -> None:
    """The module is imported only by validate's children; its answers are WRONG (exit 1)."""
    (tmp_path / "patching_mod.py").write_text(PATCHING_MODULE)
    marks = tmp_path / "imported-by.txt"
    env = {**os.environ, "IMPORTED_BY": str(marks), "PYTHONPATH": str(tmp_path)}
    proc = subprocess.Popen([sys.executable, "-m", "contactbench.harness.cli", "validate", "patching_mod:Patching",
                             "--group", "edge", "--quiet"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=300)
    importers = {int(line) for line in marks.read_text().split()} if marks.exists() else set()
    assert importers and proc.pid not in importers, (importers, proc.pid)
    assert proc.returncode == 1, out + err
    assert "WRONG" in out, out


def _refuse(text: str) -> None:
    raise ProblemInputError(text)


def _crash() -> None:
    os._exit(7)


def test_a_child_s_refusal_comes_back_as_its_kind_and_a_crash_as_a_load_failure() -> None:
    """What ``in_a_child`` brings back: a carried error as its own kind and text; a child
    that dies names what it was doing."""
    with pytest.raises(ProblemInputError, match="^no such map$"):
        in_a_child(_refuse, "no such map")
    with pytest.raises(LoadFailed, match="loading solver 'x' failed"):
        in_a_child(_crash, what="loading solver 'x'")
    assert in_a_child(max, 2, 5) == 5
