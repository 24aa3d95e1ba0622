"""The heights as solved are pinned by the map's record: ``MapPreprocessing.solved_sha256``
(``raw_heights_sha256`` of the heights in metres after unit, fill, detrend and crop), in
meta.json's record (``as_dict``) and the table's ``solved_hash`` column; a record written
before it was kept reads as ""."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from contactbench.problems.io import load_surface
from contactbench.problems.preprocessing import TABLE_HASH_DIGITS, MapPreprocessing, raw_heights_sha256


def tilted_map(path: Path) -> Path:
    rng = np.random.default_rng(7)
    i, j = np.mgrid[0:16, 0:16]
    np.save(path, rng.normal(0.0, 1e-8, (16, 16)) + 2e-9 * i - 1e-9 * j)
    return path


def test_detrend_options_give_other_solved_hashes_of_the_same_raw_map(tmp_path: Path) -> None:
    path = tilted_map(tmp_path / "tilted.npy")
    loads = {rule: load_surface(path, 16e-6, detrend=rule) for rule in ("plane", "mean", "none")}
    records = {rule: s.preprocessing for rule, s in loads.items()}
    assert all(r is not None for r in records.values())
    assert len({r.raw_sha256 for r in records.values()}) == 1  # one file as read
    assert len({r.solved_sha256 for r in records.values()}) == 3  # three problems as solved
    for s in loads.values():
        rec = s.preprocessing
        assert rec.solved_sha256 == raw_heights_sha256(s.heights)  # the Surface's heights as solved
        assert rec.as_dict()["solved_sha256"] == rec.solved_sha256
        assert rec.columns()["solved_hash"] == rec.solved_sha256[:TABLE_HASH_DIGITS]
    cropped = load_surface(path, 16e-6, crop="square", height_unit="mm").preprocessing
    assert cropped.raw_sha256 == records["plane"].raw_sha256 and cropped.solved_sha256 != records["plane"].solved_sha256


def test_a_record_without_the_solved_hash_still_reads(tmp_path: Path) -> None:
    rec = load_surface(tilted_map(tmp_path / "m.npy"), 16e-6).preprocessing
    names = {f.name for f in dataclasses.fields(MapPreprocessing)}
    old = {k: v for k, v in rec.as_dict().items() if k in names and k != "solved_sha256"}
    again = MapPreprocessing(**old)
    assert again.solved_sha256 == "" and again.columns()["solved_hash"] == ""
