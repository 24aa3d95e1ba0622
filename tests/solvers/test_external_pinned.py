"""An outside program is pinned by its manifest entry and the files its command names
(``ExternalSolver.pinned_source``): a results folder refuses to resume, or append to, rows of
a program edited since -- or of a manifest entry pointed at another program."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from contactbench.harness.run.plan import RunConfig
from contactbench.harness.run.runner import run_benchmark
from contactbench.harness.table.store import RunFolderError
from contactbench.problems.scenes import SceneConfig
from contactbench.solvers.external import register_manifest
from contactbench.solvers.registry import get_solver, source_digest, unregister
from tests.helpers import TESTS
from tests.solvers.test_external import write_manifest

SCRIPT = TESTS / "external" / "standalone_solver.py"


def registered(tmp_path: Path, script: Path) -> str:
    entry = {"name": "ext-pinned", "command": f"{sys.executable} {script} {{problem}} {{solution}}",
             "inputs": "kernel"}
    (spec,) = register_manifest(write_manifest(tmp_path / "m.toml", [entry]), replace=True)
    return spec.name


def run(out: Path, name: str, append: bool = False) -> None:
    run_benchmark(["paper-sweep"], SceneConfig(size=8, steps=1, seeds=(0,)), [name],
                  RunConfig(reference="none", timeout=10.0, warmup=False, progress=False), out, command=["pytest"],
                  append=append)


def test_an_edited_program_is_not_resumed_as_the_one_that_wrote_the_rows(tmp_path: Path) -> None:
    script = tmp_path / "solver.py"
    shutil.copy(SCRIPT, script)
    name = registered(tmp_path, script)
    try:
        out = tmp_path / "run"
        run(out, name)
        rows = (out / "rows.jsonl").read_bytes()
        run(out, name)  # the same program: resumed, nothing new
        script.write_text(script.read_text() + "\n# edited\n")
        for append in (False, True):
            with pytest.raises(RunFolderError, match="'ext-pinned' from another source"):
                run(out, name, append)
        assert (out / "rows.jsonl").read_bytes() == rows
    finally:
        unregister(name)


def test_the_digest_follows_the_program_and_the_entry(tmp_path: Path) -> None:
    script = tmp_path / "solver.py"
    shutil.copy(SCRIPT, script)
    name = registered(tmp_path, script)
    try:
        first = source_digest(get_solver(name))
        script.write_text(script.read_text() + "\n# edited\n")
        edited = source_digest(get_solver(name))
        other = tmp_path / "other.py"
        shutil.copy(SCRIPT, other)
        registered(tmp_path, other)
        moved = source_digest(get_solver(name))
    finally:
        unregister(name)
    assert None not in (first, edited, moved) and len({first, edited, moved}) == 3
