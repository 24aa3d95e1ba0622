"""A results folder whose meta.json is another folder's (copied over it) is refused by a run
in one line, exit 2, before anything is written: the marker does not record that run, and
merging the record would make the report read the folder as another run's, for good."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.helpers import run_cli

RUN = ["run", "paper-sweep", "--seeds", "0", "--solvers", "nnls", "--reference", "none", "--no-progress"]


def test_a_meta_json_of_another_folder_is_refused(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli([*RUN, "--size", "8", "--steps", "2", "--out", "mine"], capsys)[0] == 0
    assert run_cli([*RUN, "--size", "16", "--steps", "3", "--out", "other"], capsys)[0] == 0
    shutil.copy(in_tmp / "other" / "meta.json", in_tmp / "mine" / "meta.json")
    before = {p.name: p.read_bytes() for p in (in_tmp / "mine").iterdir() if p.is_file()}
    rc, _, err = run_cli([*RUN, "--size", "8", "--steps", "2", "--out", "mine"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "meta.json records a run its marker" in lines[0], (rc, err)
    assert {p.name: p.read_bytes() for p in (in_tmp / "mine").iterdir() if p.is_file()} == before
    (in_tmp / "mine" / "meta.json").unlink()  # the way out the line gives: the next run writes it anew
    assert run_cli([*RUN, "--size", "8", "--steps", "2", "--out", "mine"], capsys)[0] == 0


def test_a_folder_s_own_meta_json_after_an_append_is_taken(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert run_cli([*RUN, "--size", "8", "--steps", "2", "--out", "o"], capsys)[0] == 0
    assert run_cli([*RUN, "--size", "16", "--steps", "2", "--out", "o", "--append"], capsys)[0] == 0
    assert run_cli([*RUN, "--size", "8", "--steps", "2", "--out", "o"], capsys)[0] == 0
    assert run_cli([*RUN, "--size", "16", "--steps", "2", "--out", "o", "--append"], capsys)[0] == 0
