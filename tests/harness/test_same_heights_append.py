"""A map appended to a results folder that already holds the same heights, prepared the
same way, under another base name (``runner.same_heights``): a warning -- one that names
both maps, recorded in meta.json's warnings and the run's summary -- not a refusal."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import read_meta


def cli_run(capsys: pytest.CaptureFixture[str], surface: Path, out: Path, *more: str) -> tuple[int, str]:
    code = cli.main(["run", "paper-sweep", "--surface", str(surface), "--length", "16e-6", "--steps", "1",
                     "--solvers", "test-exact", "--reference", "none", "--out", str(out), "--no-progress", *more])
    return code, capsys.readouterr().err


def test_the_same_heights_under_another_name_are_appended_with_a_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture) -> None:
    good, copy, other, out = tmp_path / "good.npy", tmp_path / "good_copy.npy", tmp_path / "other.npy", tmp_path / "D"
    rng = np.random.default_rng(4)
    np.save(good, rng.normal(0.0, 1e-8, (16, 16)))  # (rms 10 nm at 1 um spacing: plausible slopes)
    np.save(other, rng.normal(0.0, 1e-8, (16, 16)))
    shutil.copyfile(good, copy)
    code, err = cli_run(capsys, good, out)
    assert code == 0 and "same heights" not in err
    caplog.clear()
    code, err = cli_run(capsys, copy, out, "--append")
    assert code == 0, err
    said = [r.getMessage() for r in caplog.records if "same heights" in r.getMessage()]
    assert len(said) == 1 and "same heights" not in err, (said, err)  # (the run says it once; the CLI not again)
    assert "'good_copy.npy' has the same heights" in said[0] and "as 'good.npy' already in" in said[0]
    warnings = read_meta(out)["warnings"]
    assert len(warnings) == 1 and "'good_copy.npy' has the same heights" in warnings[0]
    code, err = cli_run(capsys, other, out, "--append")  # other heights: nothing to say
    assert code == 0 and "same heights" not in err and read_meta(out)["warnings"] == warnings
