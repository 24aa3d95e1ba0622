"""A run whose every cell ran but whose table cannot be written (a full disk) stopped after
running: exit 1, one line, the rows kept -- not exit 2, which says bad input refused before
anything ran."""

from __future__ import annotations

import errno
from pathlib import Path

import pytest

from contactbench.harness.table.store import ResultStore
from tests.helpers import run_cli


def test_a_table_that_cannot_be_written_after_the_cells_ran_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    def full(self: ResultStore) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "out" / "results.parquet"))

    monkeypatch.setattr(ResultStore, "finalize", full)
    args = ["run", "counterexample", "--size", "6", "--seeds", "0", "--reference", "none", "--no-progress",
            "--no-warmup", "--solvers", "nnls", "--out", str(tmp_path / "out")]
    rc, _, err = run_cli(args, capsys)
    lines = err.strip().splitlines()
    assert rc == 1 and len(lines) == 1 and "No space left on device" in lines[0], err
    assert "rows stored are kept" in lines[0]
    assert (tmp_path / "out" / "rows.jsonl").stat().st_size > 0
    monkeypatch.undo()
    rc, _, err = run_cli(args, capsys)
    assert rc == 0 and (tmp_path / "out" / "results.csv").is_file(), err
