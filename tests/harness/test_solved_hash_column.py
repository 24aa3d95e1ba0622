"""A run on a measured map writes the hash of its heights as solved: the table's
``solved_hash`` (the first digits of meta.json's ``solved_sha256``); a folder whose
meta.json records were written without it is still appended to and read."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import read_meta
from contactbench.harness import load_table
from contactbench.problems.io import load_surface
from contactbench.problems.preprocessing import TABLE_HASH_DIGITS


def cli_run(capsys: pytest.CaptureFixture[str], surface: Path, out: Path, *more: str) -> tuple[int, str]:
    code = cli.main(["run", "paper-sweep", "--surface", str(surface), "--length", "16e-6", "--steps", "1",
                     "--solvers", "test-exact", "--reference", "none", "--out", str(out), "--no-progress", *more])
    return code, capsys.readouterr().err


def test_a_run_writes_the_solved_hash(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    surface, out = tmp_path / "map.npy", tmp_path / "D"
    np.save(surface, np.random.default_rng(5).normal(0.0, 1e-8, (16, 16)))
    code, err = cli_run(capsys, surface, out)
    assert code == 0, err
    want = load_surface(surface, 16e-6).preprocessing.solved_sha256
    records = read_meta(out)["surface_preprocessing"]
    assert [r["solved_sha256"] for r in records.values()] == [want]
    table = load_table(out)
    assert set(table["solved_hash"]) == {want[:TABLE_HASH_DIGITS]}
    meta_path = out / "meta.json"  # a folder written before the hash was kept
    meta = json.loads(meta_path.read_text())
    for rec in meta["surface_preprocessing"].values():
        del rec["solved_sha256"]
    meta_path.write_text(json.dumps(meta))
    code, err = cli_run(capsys, surface, out, "--append", "--detrend", "mean")
    assert code == 0, err
    hashes = set(load_table(out)["solved_hash"])
    assert want[:TABLE_HASH_DIGITS] in hashes and len(hashes) == 2
