"""A journal edited by hand in a way that keeps its size and its last row (one status word
for another of the same length) is not the journal the table was made from: ``report``
reads the journal, as ``run`` does, and refuses the row that contradicts its figures."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness.table.reading import journal_stamp
from tests.helpers import run_cli

RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--seeds", "0", "--solvers", "nnls",
       "--reference", "none", "--no-progress", "--out", "o"]


def test_report_and_run_agree_on_a_journal_edited_in_place(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli(RUN, capsys)[0] == 0
    journal = in_tmp / "o" / "rows.jsonl"
    before, text = journal_stamp(journal), journal.read_text()
    edited = text.replace('"status": "solved"', '"status": "failed"', 1)
    assert edited != text and len(edited) == len(text) and edited.splitlines()[-1] == text.splitlines()[-1]
    journal.write_text(edited)
    assert journal_stamp(journal) != before
    rc_report, _, err_report = run_cli(["report", "o"], capsys)
    rc_run, _, err_run = run_cli(RUN, capsys)
    assert rc_report == rc_run == 2, (err_report, err_run)
    assert "rows.jsonl" in err_report and "rows.jsonl" in err_run
