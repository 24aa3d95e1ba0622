"""``contactbench export`` refuses a QP it cannot write before it writes any: a user's
entry named like a later QP's problem directory, a later QP's dense H over the memory
budget, a later QP its scene cannot build within the budget, a later QP over the dense
limit with no kernel table, two QPs of one name.  Each refusal is one line with exit 2; a new folder is not
made, and an export's folder keeps every file byte for byte and its complete manifest."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.export import export_scene
from contactbench.problems.operators import memory_budget_scope
from contactbench.problems.scenes import SceneConfig, get_scene
from tests.helpers import run_cli

SWEEP = ["paper-sweep", "--size", "8"]
#: paper-sweep at 32^2 over 3 steps: n = 31, 82, 143; only the last dense H (160 KiB) is
#: over this budget.
BUDGET_SWEEP = ["paper-sweep", "--size", "32", "--steps", "3"]
BUDGET = 0.0001 * 2**30
OVER_BUDGET_QP = "saupe-H0.7-N32-bcc-np-s5-K3-step2"


def hashes(folder: Path) -> dict[str, str]:
    """Every entry under ``folder``: a file's SHA-256, a link's target, "dir" for a folder."""
    out: dict[str, str] = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        if p.is_symlink():
            out[key] = os.readlink(p)
        else:
            out[key] = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
    return out


def export_argv(scene: list[str], fmt: str, out: Path, *more: str) -> list[str]:
    return ["export", *scene, *more, "--format", fmt, "--out", str(out)]


def refusal(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one stderr line of ``contactbench ARGV`` refusing its input (exit 2, no traceback)."""
    rc, _, err = run_cli(argv, capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("contactbench: error: "), (rc, err)
    return lines[0]


def complete(out: Path) -> bool:
    return json.loads((out / "manifest.json").read_text())["complete"] is True


def exported(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = run_cli(argv, capsys)
    assert rc == 0, err


def test_a_users_folder_named_like_a_later_step_is_refused_before_any_step_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ex"
    exported(export_argv([*SWEEP, "--steps", "1"], "problem-dir", out), capsys)
    mine = out / "saupe-H0.7-N8-bcc-np-s5-K2-step1"  # where the --steps 2 export below writes its second step
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    before = hashes(out)
    line = refusal(export_argv([*SWEEP, "--steps", "2"], "problem-dir", out), capsys)
    assert mine.name in line and "not an export's" in line
    assert hashes(out) == before and complete(out)


@pytest.mark.parametrize("fmt", ["problem-dir", "hdf5", "qpbenchmark"])
def test_a_later_dense_H_over_the_budget_is_refused_before_a_new_folder_is_made(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str) -> None:
    if fmt == "hdf5":
        pytest.importorskip("h5py")
    out = tmp_path / "ex"
    with memory_budget_scope(BUDGET):
        line = refusal(export_argv(BUDGET_SWEEP, fmt, out), capsys)
    assert line.startswith(f"contactbench: error: the dense H of {OVER_BUDGET_QP}") and "memory budget" in line
    assert not out.exists()


@pytest.mark.parametrize("fmt", ["problem-dir", "hdf5", "qpbenchmark"])
def test_a_later_dense_H_over_the_budget_leaves_an_export_as_it_was(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str) -> None:
    if fmt == "hdf5":
        pytest.importorskip("h5py")
    out = tmp_path / "ex"
    exported(export_argv(BUDGET_SWEEP, fmt, out), capsys)
    before = hashes(out)
    with memory_budget_scope(BUDGET):
        line = refusal(export_argv(BUDGET_SWEEP, fmt, out), capsys)
    assert OVER_BUDGET_QP in line
    assert hashes(out) == before and complete(out)


def test_a_later_dense_operator_over_the_budget_is_refused_in_one_line_before_anything_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ex"
    with memory_budget_scope(BUDGET):
        line = refusal(export_argv(BUDGET_SWEEP, "problem-dir", out, "--operator", "dense", "--dense-limit", "8"),
                       capsys)
    assert OVER_BUDGET_QP in line and "memory budget" in line
    assert not out.exists()


def test_a_later_qp_over_the_dense_limit_with_no_kernel_table_is_refused_before_anything_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """greedy-kernels at seed 0: n = 25, 100, 400 for each operator; the thin-layer
    operator's n = 100 is the first QP over a dense limit of 50 that has no kernel table."""
    out = tmp_path / "ex"
    line = refusal(export_argv(["greedy-kernels", "--seeds", "0"], "problem-dir", out, "--dense-limit", "50"), capsys)
    assert "thin-layer-n100-s0-step0" in line and "no kernel table" in line
    assert not out.exists()


def test_two_qps_of_one_name_are_refused_before_anything_is_written(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A scene whose recipes repeat an instance name (here hertz's, listed twice) would
    write two QPs into one problem directory."""
    hertz = type(get_scene("hertz"))
    recipes = hertz.instances
    monkeypatch.setattr(hertz, "instances", lambda self, cfg: recipes(self, cfg) * 2)
    out = tmp_path / "ex"
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", SceneConfig(size=16), "problem-dir", out)
    assert "\n" not in str(exc.value) and "'N16-bcc-step0'" in str(exc.value)
    assert not out.exists()
