"""A surface path that is a symlink loop (``problems.io.check_surface_file``): one
``SurfaceFileError`` line naming the path and "symlink loop", and exit 2 from ``run`` and
``export``, never a traceback."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from contactbench.harness.cli import main
from contactbench.problems.io import load_surface
from contactbench.problems.map_readers import SurfaceFileError


def loops(tmp_path: Path) -> list[str]:
    """A link to itself, a two-link loop and a file under a looping folder link."""
    os.symlink("loop.npy", tmp_path / "loop.npy")
    os.symlink("b.npy", tmp_path / "a.npy")
    os.symlink("a.npy", tmp_path / "b.npy")
    os.symlink("d", tmp_path / "d")
    return ["loop.npy", "a.npy", os.path.join("d", "x.npy")]


def test_loading_a_looping_link_is_one_line_naming_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    for name in loops(tmp_path):
        with pytest.raises(SurfaceFileError) as exc:
            load_surface(name, 32e-6)
        assert f"{name!r}" in str(exc.value) and "symlink loop" in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("command", [["run", "paper-sweep", "--solvers", "pk"],
                                     ["export", "paper-sweep", "--format", "problem-dir"]])
def test_run_and_export_refuse_a_looping_surface_with_exit_2(
        command: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    name = loops(tmp_path)[0]
    try:
        rc = main([*command, "--surface", name, "--length", "32e-6", "--steps", "1", "--out", "o"])
    except SystemExit as exc:
        rc = int(exc.code or 0)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "symlink loop" in lines[0] and "'loop.npy'" in lines[0], err
    assert not (tmp_path / "o").exists()
