"""A results folder pins each measured map as prepared (``runner.surface_keys``): the
raw heights and everything else that makes the problem, the lateral size a file states
included.  A map file rewritten with the same heights and another spacing is another
configuration: refused in one line naming the map and ``--append``; with ``--append`` it
is a new instance."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import read_meta
from contactbench.harness.table.store import load_table


def write_xyz(path: Path, spacing: float) -> None:
    """A 16 x 16 map as x,y,z columns (metres), whose coordinates state its lateral size;
    the same heights (rms 10 nm: plausible slopes at 1 or 2 um) whatever the spacing."""
    z = np.random.default_rng(4).normal(0.0, 1e-8, (16, 16))
    yy, xx = np.mgrid[0:16, 0:16] * spacing
    np.savetxt(path, np.column_stack([xx.ravel(), yy.ravel(), z.ravel()]), delimiter=",", fmt="%.17g")


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


def cli_run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = cli.main(["run", *args, "--no-progress"])
    return code, capsys.readouterr().err


def test_a_map_file_stating_another_lateral_size_is_another_configuration(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, out = tmp_path / "m.csv", tmp_path / "run"
    write_xyz(path, 1e-6)
    common = ["paper-sweep", "--surface", str(path), "--steps", "2", "--solvers", "test-exact", "--reference", "none",
              "--out", str(out)]
    assert cli_run(capsys, *common)[0] == 0
    before = snapshot(out)
    write_xyz(path, 2e-6)  # the same heights, twice the spacing
    code, err = cli_run(capsys, *common)
    assert code == 2 and err.count("\n") == 1, err
    assert "surface_key" in err and "m.csv (key " in err and "--append" in err
    assert "surface_sha256" not in err  # the heights did not change
    assert snapshot(out) == before
    assert cli_run(capsys, *common, "--append")[0] == 0
    table = load_table(out)
    assert table["instance"].nunique() == 2
    assert sorted(table.groupby("instance")["delta0"].first()) == pytest.approx([1e-6, 2e-6])
    assert len(read_meta(out)["surface_preprocessing"]) == 2
