"""The report of an interrupted run says in its header that it is partial: how many of
the plan's cells (meta.json ``config.cells``) have a row."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from contactbench.harness import run_benchmark
from contactbench.harness.report.core import ReportContext, header_section
from contactbench.harness.report.view import read_table
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.table.meta import META_FILE, read_meta
from contactbench.harness.table.store import ROWS_FILE
from contactbench.problems.scenes import SceneConfig

#: paper-sweep at 16^2 with 3 steps and 2 solvers: 6 cells.
CFG = SceneConfig(size=16, steps=3, seeds=(0,))
RUN = RunConfig(reference="none", warmup=False, progress=False)
SOLVERS = ["scipy-nnls", "bvls"]


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("partial") / "whole"
    run_benchmark(["paper-sweep"], CFG, SOLVERS, RUN, out, command=["pytest"])
    return out


def header(out: Path) -> str:
    """report.md's header (``header_section``, as ``build_report`` writes it first)."""
    return header_section(ReportContext(out, read_table(out), read_meta(out))).split("*Table 1", 1)[0]


def test_the_plan_records_its_cells_and_a_whole_run_says_complete(whole: Path) -> None:
    assert json.loads((whole / META_FILE).read_text())["config"]["cells"] == 6
    top = header(whole)
    assert "| Cells | 6 of 6 planned cells (complete) |" in top and "PARTIAL" not in top


@pytest.mark.parametrize("keep", [1, 4])
def test_an_interrupted_run_says_it_is_partial(whole: Path, tmp_path: Path, keep: int) -> None:
    out = tmp_path / f"cut-{keep}"
    shutil.copytree(whole, out)  # what Ctrl-C after ``keep`` journal rows leaves
    lines = (out / ROWS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    (out / ROWS_FILE).write_text("".join(lines[:keep]), encoding="utf-8")
    for name in ("results.parquet", "results.csv"):
        (out / name).unlink()
    assert f"| Cells | PARTIAL RUN: {keep} of 6 planned cells have a row ({6 - keep} missing" in header(out)


def test_a_folder_without_a_recorded_plan_says_nothing_of_cells(whole: Path, tmp_path: Path) -> None:
    out = tmp_path / "old"
    shutil.copytree(whole, out)
    meta = json.loads((out / META_FILE).read_text())
    del meta["config"]["cells"]
    for inv in meta["invocations"]:
        del inv["config"]["cells"]
    (out / META_FILE).write_text(json.dumps(meta))
    assert "| Cells |" not in header(out)


def test_a_run_appended_to_an_interrupted_one_leaves_the_folder_partial(whole: Path, tmp_path: Path) -> None:
    """--append adds a plan of its own: the folder is complete only when the first plan is too
    (the count is not compared with the last plan alone), and the missing cells are bounded,
    not counted (2 of the first plan's 6 have a row, and 1 of the second's: never "3 of 6")."""
    out = tmp_path / "appended"
    shutil.copytree(whole, out)
    lines = (out / ROWS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    (out / ROWS_FILE).write_text("".join(lines[:2]), encoding="utf-8")
    for name in ("results.parquet", "results.csv"):
        (out / name).unlink()
    small = SceneConfig(size=16, steps=1, seeds=(0,))
    run_benchmark(["hertz"], SceneConfig(size=16), ["scipy-nnls"], RUN, out, command=["pytest", "hertz"], append=True)
    top = header(out)
    assert ("PARTIAL RUN: 3 cells have a row over 2 runs added with --append, which planned 6 + 1 cells: at least 3 "
            "of the largest run's are missing") in top and "(complete)" not in top and "3 of 6" not in top
    whole2 = tmp_path / "two-whole"
    shutil.copytree(whole, whole2)
    run_benchmark(["paper-sweep"], small, ["pk"], RUN, whole2, command=["pytest", "pk"], append=True)
    assert "| Cells | 7 of 7 planned cells over 2 runs added with --append (complete) |" in header(whole2)


def test_a_cold_run_appended_to_a_warm_one_is_a_plan_of_its_own(whole: Path, tmp_path: Path) -> None:
    """The same scenes, options, solvers and cells solved cold (``--cold --append``) are other
    cells: a folder whose cold run wrote no row is not complete (it read "6 of 6 planned
    cells (complete)": the two plans were counted as one)."""
    out = tmp_path / "warm-then-cold"
    shutil.copytree(whole, out)
    warm_rows = (out / ROWS_FILE).read_text(encoding="utf-8")
    run_benchmark(["paper-sweep"], CFG, SOLVERS, replace(RUN, warm=False), out, command=["pytest", "cold"], append=True)
    assert "| Cells | 12 of 12 planned cells over 2 runs added with --append (complete) |" in header(out)
    (out / ROWS_FILE).write_text(warm_rows, encoding="utf-8")  # what a cold run stopped before its first row leaves
    for name in ("results.parquet", "results.csv"):
        (out / name).unlink()
    top = header(out)
    assert "(complete)" not in top and "planned 6 + 6 cells" in top, top


@pytest.mark.parametrize("text", ["[1, 2]", "not json", '{"config": {"cells": -5}}'])
def test_a_broken_meta_json_is_named_or_read_as_no_plan(whole: Path, tmp_path: Path, text: str) -> None:
    """A meta.json that is not a run's record: the report and a resumed run refuse it in one
    line naming the file, and it is left as it was; a plan of -5 cells is no plan."""
    from contactbench.harness.cli import main

    out = tmp_path / "broken"
    shutil.copytree(whole, out)
    (out / META_FILE).write_text(text)
    if text.startswith("{"):
        assert "| Cells |" not in header(out)
        return
    assert main(["report", str(out)]) == 2
    argv = ["run", "paper-sweep", "--size", "16", "--steps", "3", "--seeds", "0", "--solvers", ",".join(SOLVERS),
            "--reference", "none", "--no-warmup", "--no-progress", "--out", str(out)]
    assert main(argv) == 2
    assert (out / META_FILE).read_text() == text


def test_cells_are_counted_without_cell_ids_and_foreign_rows_are_not_called_complete(whole: Path,
                                                                                      tmp_path: Path) -> None:
    """A table without ``cell_id`` counts its cells by ``CELL_COLUMNS`` (it read "PARTIAL
    RUN: 1 of 6": the empty ids counted as one cell); a row not of the plan is not read as
    the plan complete (it read "7 of 6 planned cells (complete)")."""
    import pandas as pd

    no_ids = tmp_path / "no-ids"
    shutil.copytree(whole, no_ids)
    (no_ids / ROWS_FILE).unlink()
    table = pd.read_parquet(whole / "results.parquet")
    table.drop(columns=["cell_id"]).to_parquet(no_ids / "results.parquet", index=False)
    (no_ids / "results.csv").unlink()
    assert "| Cells | 6 of 6 planned cells (complete) |" in header(no_ids)
    extra = tmp_path / "extra"
    shutil.copytree(no_ids, extra)
    foreign = table.iloc[[0]].assign(solver="elsewhere", base_solver="elsewhere", cell_id="foreign-1")
    pd.concat([table, foreign]).to_parquet(extra / "results.parquet", index=False)
    top = header(extra)
    assert "7 cells with a row, 6 planned: 1 more than the plan has" in top and "(complete)" not in top


@pytest.mark.parametrize("key", ["invocations", "warnings"])
def test_a_meta_record_whose_list_is_a_number_reads_as_no_entry(whole: Path, tmp_path: Path, key: str) -> None:
    """A hand-edited meta.json with ``invocations`` or ``warnings`` a number: the report and a
    resumed run's record read it as no entry (both ended in a TypeError traceback)."""
    from contactbench.harness.table.meta import write_meta

    out = tmp_path / "meta"
    shutil.copytree(whole, out)
    meta = json.loads((out / META_FILE).read_text())
    meta[key] = 5
    (out / META_FILE).write_text(json.dumps(meta))
    assert "| Cells |" in header(out)
    write_meta(out, {"command": ["again"], "warnings": ["w"]})
    again = read_meta(out)
    assert isinstance(again["invocations"], list) and "w" in again["warnings"]
