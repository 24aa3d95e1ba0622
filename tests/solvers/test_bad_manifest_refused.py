"""A bad external manifest (``CONTACTBENCH_EXTERNAL_SOLVERS``) is refused in one line, exit
2, before anything runs, whichever solvers ``run`` or ``validate`` names -- never left out
in silence while the run goes on without the user's solver.  Each call is its own process:
the registry reads the manifests once a process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import REPO

CALLS = {
    "run": ["run", "paper-sweep", "--size", "8", "--steps", "1", "--seeds", "0", "--solvers", "fast-ccg",
            "--no-progress", "--out"],
    "validate": ["validate", "pk", "--cases", "random/spd-n30-s0", "--out"],
}


@pytest.mark.parametrize("call", sorted(CALLS))
@pytest.mark.parametrize("manifest", ['[[solver]]\nname = "ext-bad"\ncommand = "prog {problem}"\n', "not toml ["])
def test_a_bad_manifest_stops_the_run_before_anything_is_written(tmp_path: Path, call: str, manifest: str) -> None:
    (tmp_path / "m.toml").write_text(manifest)
    out = tmp_path / "out"
    env = {**os.environ, "CONTACTBENCH_EXTERNAL_SOLVERS": str(tmp_path / "m.toml")}
    done = subprocess.run([sys.executable, "-m", "contactbench.harness.cli", *CALLS[call], str(out)], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=300)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "m.toml" in lines[0], done.stderr
    assert "external solvers could not be read" in lines[0]
    assert not out.exists()
