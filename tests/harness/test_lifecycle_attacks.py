"""A folder's life across interrupts and ``--append``: the report's header counts the cells
of each plan (a ``--cold`` run appended to a warm one is another plan, with cells of its
own), its prose names a problem's history, and an interrupt before the first row says so."""

from __future__ import annotations

import json
import shutil
from argparse import Namespace
from pathlib import Path

import pytest

from contactbench.harness import run_benchmark
from contactbench.harness.cli import interrupted_text
from contactbench.harness.report.core import ReportContext, header_section
from contactbench.harness.report.sections.generic import aggregates_section
from contactbench.harness.report.view import read_table
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.table.meta import read_meta
from contactbench.harness.table.store import ROWS_FILE, ResultStore
from contactbench.problems.scenes import SceneConfig

#: paper-sweep at 16^2, 2 steps, 2 solvers: 4 cells a plan.
CFG = SceneConfig(size=16, steps=2, seeds=(0,))
RUN = RunConfig(reference="none", warmup=False, progress=False)
SOLVERS = ["pk", "nnls"]


@pytest.fixture(scope="module")
def both(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A warm run, then the same plan ``--cold`` with ``--append``: 4 + 4 cells, all written."""
    out = tmp_path_factory.mktemp("lifecycle") / "both"
    run_benchmark(["paper-sweep"], CFG, SOLVERS, RUN, out, command=["pytest"])
    cold = RunConfig(reference="none", warmup=False, progress=False, warm=False)
    run_benchmark(["paper-sweep"], CFG, SOLVERS, cold, out, command=["pytest", "--cold"], append=True)
    return out


def cells_line(out: Path) -> str:
    top = header_section(ReportContext(out, read_table(out), read_meta(out)))
    return next(line for line in top.splitlines() if line.startswith("| Cells |"))


def keeping_cold(both: Path, tmp_path: Path, k: int) -> Path:
    """``both`` with every warm row and only ``k`` cold rows (the cold run stopped there)."""
    out = tmp_path / f"cold{k}"
    shutil.copytree(both, out)
    lines = (out / ROWS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    warm = [line for line in lines if json.loads(line)["history"] == "warm"]
    cold = [line for line in lines if json.loads(line)["history"] == "cold"]
    assert len(warm) == len(cold) == 4
    (out / ROWS_FILE).write_text("".join(warm + cold[:k]), encoding="utf-8")
    for name in ("results.parquet", "results.csv"):
        (out / name).unlink()
    return out


def test_the_prose_names_a_problems_history(both: Path) -> None:
    """A problem is keyed by its history too (``aggregates.PROBLEM_KEYS``): the prose said
    "(instance, step, profile)", so warm and cold rows read as one problem counted twice."""
    table = read_table(both)
    body = aggregates_section(ReportContext(both, table, read_meta(both)), table).body
    assert "A problem is one (instance, step, profile, history)" in body


def test_an_interrupt_before_the_first_row_does_not_say_rows_are_kept(tmp_path: Path) -> None:
    """An interrupt before the first row leaves the table of no row (its header only): the
    line said "rows so far are kept" (a table file was read as rows)."""
    out = tmp_path / "run"
    out.mkdir()
    ResultStore(out).finalize()
    assert (out / "results.csv").is_file()
    text = interrupted_text(Namespace(command="run", out=str(out), scenes=["hertz"]))
    assert text.startswith("no row was written") and "run the same command again" in text
