"""An export checks, before each QP, that the disk holding its folder has room for it
(``export.check_room``, ``qpfile.payload_nbytes``): a scene too large for the disk is
refused in one line naming the QP, not written until the disk is full."""

from __future__ import annotations

import errno
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contactbench.problems import export as ex
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.qpfile import payload_nbytes, problem_payload
from contactbench.problems.surfaces import rmd_surface_n
from tests.helpers import run_cli


def test_the_payload_is_counted_as_written() -> None:
    b = InstanceBuilder(rmd_surface_n(17, 0.7, seed=1, length=1e-5), 1e9, "bcc")
    inst = b.build(0.5 * float(np.ptp(b.surface.heights)))
    for limit in (10, 10_000):
        _, arrays = problem_payload(inst, tol=None, time_limit=None, dense_limit=limit)
        assert payload_nbytes(inst, limit) == sum(a.nbytes for a in arrays.values())


@pytest.mark.parametrize("fmt", ["problem-dir", "hdf5", "qpbenchmark"])
def test_an_export_the_disk_cannot_hold_is_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch, fmt: str) -> None:
    if fmt == "hdf5":
        pytest.importorskip("h5py")
    real = shutil.disk_usage

    def nearly_full(path: Any) -> Any:
        u = real(path)
        return type(u)(u.total, u.total - ex.DISK_RESERVE_BYTES, ex.DISK_RESERVE_BYTES)

    monkeypatch.setattr(ex.shutil, "disk_usage", nearly_full)
    rc, _, err = run_cli(["export", "hertz", "--size", "16", "--format", fmt, "--out", str(tmp_path / "e")], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "GB free" in lines[0], err
    left = [p for p in (tmp_path / "e").rglob("*") if p.is_file() and p.name.endswith(".tmp")]
    assert left == []


def test_a_write_that_fails_once_the_export_writes_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk met while writing is no bad input: one line, exit 1, the manifest left
    incomplete so that the same command finishes the export."""
    def full(*args: Any, **kwargs: Any) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ex, "write_problem_dir", full)
    rc, _, err = run_cli(["export", "hertz", "--size", "16", "--format", "problem-dir", "--out", str(tmp_path / "e")],
                         capsys)
    lines = err.strip().splitlines()
    assert rc == 1 and len(lines) == 1 and "No space left on device" in lines[0], err
    assert '"complete": false' in (tmp_path / "e" / "manifest.json").read_text()
