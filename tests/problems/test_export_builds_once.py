"""An export builds each QP its plan's check built once: the check's instances are kept for
the writing within ``export_plan.KEEP_SHARE`` of the memory budget, and past it dropped and
built again -- either way the files are the same."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from contactbench.problems import export_plan
from contactbench.problems.export import export_scene
from contactbench.problems.scenes import SceneConfig, get_scene


def count_builds(monkeypatch: pytest.MonkeyPatch, scene_name: str) -> list[str]:
    """The instance names the scene builds (``Scene.build``), in order, from now on."""
    scene = get_scene(scene_name)
    built: list[str] = []
    real = type(scene).build

    def counted(self: Any, spec: Any) -> Any:
        built.append(spec.instance)
        return real(self, spec)

    monkeypatch.setattr(type(scene), "build", counted)
    return built


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "manifest.json"}


def test_a_synthetic_scene_is_built_once(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    built = count_builds(monkeypatch, "counterexample")
    summary = export_scene("counterexample", SceneConfig(), "problem-dir", tmp_path / "once")
    assert summary.written and len(built) == len(set(built)), built


def test_past_the_allowance_the_qps_are_built_again_and_written_alike(monkeypatch: pytest.MonkeyPatch,
                                                                     tmp_path: Path) -> None:
    kept = export_scene("counterexample", SceneConfig(), "problem-dir", tmp_path / "kept")
    built = count_builds(monkeypatch, "counterexample")
    monkeypatch.setattr(export_plan, "KEEP_SHARE", 0.0)  # nothing is kept
    again = export_scene("counterexample", SceneConfig(), "problem-dir", tmp_path / "again")
    assert len(built) == 2 * len(set(built)) > 0, built
    assert kept.written == again.written
    assert files(tmp_path / "kept") == files(tmp_path / "again")


def test_the_allowance_is_a_share_of_the_budget() -> None:
    keeper = export_plan.Keeper(100.0)

    class Op:
        memory_nbytes = 60

    class QP:
        H = Op()

    class Inst:
        qp = QP()

    for step in range(3):
        keeper(0, step, Inst())  # type: ignore[arg-type]
    assert list(keeper.kept) == [(0, 0)] and keeper.held == 60 and keeper.full
