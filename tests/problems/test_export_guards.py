"""problems.export's guards: one export at a time in a folder, nothing written through a
link or over an entry that is not an export's, a bounded count of QPs, an E whose
coefficients float64 cannot hold refused, and an unnamed folder refused; each a one-line
``ProblemInputError`` that leaves everything as it was."""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.export import export_scene, scene_steps
from contactbench.problems.scenes.base import scene_counts
from contactbench.problems.kernels import kernel_table
from contactbench.problems.qpfile import write_problem_dir
from contactbench.problems.scenes import SceneConfig, get_scene

HERTZ = SceneConfig(size=16)
HERTZ_QP = "N16-bcc-step0"


def _snapshot(folder: Path) -> dict[str, bytes | str]:
    """Every entry under ``folder``: a file's bytes, a link's target."""
    out: dict[str, bytes | str] = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        out[key] = os.readlink(p) if p.is_symlink() else (p.read_bytes() if p.is_file() else "dir")
    return out


def _one_line(exc: pytest.ExceptionInfo[ProblemInputError]) -> str:
    text = str(exc.value)
    assert "\n" not in text
    return text


# --- one export at a time ----------------------------------------------------------------


def test_an_export_into_a_folder_another_export_holds_is_refused_and_touches_nothing(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    export_scene("hertz", HERTZ, "problem-dir", out)
    before = _snapshot(out)
    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)  # another export's hold on the folder
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(ProblemInputError) as exc:
            export_scene("counterexample", SceneConfig(size=5, seeds=(0,)), "problem-dir", out)
        assert "in use by another export" in _one_line(exc) and str(out) in str(exc.value)
        assert _snapshot(out) == before
    finally:
        os.close(fd)
    export_scene("counterexample", SceneConfig(size=5, seeds=(0,)), "problem-dir", out)  # released: it runs
    assert json.loads((out / "manifest.json").read_text())["complete"] is True


# --- nothing written through a link or over what is not an export's ------------------------


def test_an_hdf5_file_that_is_a_link_is_refused_and_its_target_kept(tmp_path: Path) -> None:
    pytest.importorskip("h5py")
    out = tmp_path / "ex"
    export_scene("hertz", HERTZ, "hdf5", out)
    precious = tmp_path / "precious.txt"
    precious.write_text("user data")
    (out / "problems.h5").unlink()
    (out / "problems.h5").symlink_to(precious)
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, "hdf5", out)
    assert "symbolic link" in _one_line(exc) and "problems.h5" in str(exc.value)
    assert precious.read_text() == "user data" and (out / "problems.h5").is_symlink()


def test_a_problem_directory_that_is_a_link_is_refused_and_its_target_kept(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    export_scene("hertz", HERTZ, "problem-dir", out)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "problem.json").write_text("user's problem.json")
    (outside / "p0.f64").write_text("user p0")
    for f in (out / HERTZ_QP).iterdir():
        f.unlink()
    (out / HERTZ_QP).rmdir()
    (out / HERTZ_QP).symlink_to(outside, target_is_directory=True)
    before = _snapshot(outside)
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, "problem-dir", out)
    assert "symbolic link" in _one_line(exc) and HERTZ_QP in str(exc.value)
    assert _snapshot(outside) == before


@pytest.mark.parametrize("fmt, name", [("qpbenchmark", "hertz.parquet"), ("hdf5", "problems.h5")])
def test_a_users_file_of_the_formats_name_is_refused_and_kept(tmp_path: Path, fmt: str, name: str) -> None:
    if fmt == "hdf5":
        pytest.importorskip("h5py")
    out = tmp_path / "ex"
    export_scene("hertz", HERTZ, "problem-dir", out)
    (out / name).write_text("my own file")
    before = _snapshot(out)
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, fmt, out)
    assert "not an export's" in _one_line(exc) and name in str(exc.value)
    assert _snapshot(out) == before


def test_a_users_folder_of_a_problems_name_is_refused_and_kept(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    export_scene("counterexample", SceneConfig(size=5, seeds=(0,)), "problem-dir", out)
    mine = out / HERTZ_QP
    mine.mkdir()
    (mine / "problem.json").write_text("mine")
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, "problem-dir", out)
    assert "not an export's" in _one_line(exc) and HERTZ_QP in str(exc.value)
    assert (mine / "problem.json").read_text() == "mine" and sorted(p.name for p in mine.iterdir()) == ["problem.json"]


def test_a_manifest_that_is_a_link_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    export_scene("hertz", HERTZ, "problem-dir", out)
    other = tmp_path / "other.json"
    other.write_text((out / "manifest.json").read_text())
    (out / "manifest.json").unlink()
    (out / "manifest.json").symlink_to(other)
    before = other.read_text()
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, "problem-dir", out)
    assert "symbolic link" in _one_line(exc)
    assert other.read_text() == before


def test_a_problem_directory_replaces_a_linked_array_file_and_keeps_its_target(tmp_path: Path) -> None:
    _, _, inst = next(scene_steps("hertz", HERTZ))
    d = tmp_path / "qp"
    write_problem_dir(inst, d, tol=None, time_limit=None)
    outside = tmp_path / "outside.f64"
    outside.write_text("user data")
    hard = tmp_path / "hard.f64"
    (d / "H.f64").unlink()
    (d / "H.f64").symlink_to(outside)
    os.link(d / "ubar.f64", hard)
    hard_before = hard.read_bytes()
    write_problem_dir(inst, d, tol=None, time_limit=None)
    assert outside.read_text() == "user data" and hard.read_bytes() == hard_before
    assert not (d / "H.f64").is_symlink()
    assert np.array_equal(np.fromfile(d / "H.f64").reshape(inst.n, inst.n), inst.qp.H.to_dense())


# --- a bounded count of QPs ---------------------------------------------------------------


def test_an_export_over_the_most_qps_is_refused_before_anything_is_made(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    with pytest.raises(ProblemInputError) as exc:
        export_scene("paper-sweep", SceneConfig(size=16, steps=2, seeds=(0, 1)), "problem-dir", out, max_qps=3)
    assert "4 QPs" in _one_line(exc) and "limit of 3" in str(exc.value)
    assert not out.exists()


def test_a_huge_seed_range_is_refused_at_once(tmp_path: Path) -> None:
    out = tmp_path / "ex"
    with pytest.raises(ProblemInputError) as exc:
        export_scene("paper-sweep", SceneConfig(size=16, steps=2, seeds=range(10**8)), "problem-dir", out)
    assert "200,000,000 QPs" in _one_line(exc)
    assert not out.exists()


def test_a_seed_range_of_2_63_seeds_is_counted_and_refused_in_one_line(tmp_path: Path) -> None:
    seeds = range(2**63)  # --seeds 0-9223372036854775807: more seeds than len() can count
    scene = get_scene("paper-sweep")
    assert scene_counts(scene, scene.config(SceneConfig(size=16, steps=2, seeds=seeds))).instances == 2**63
    out = tmp_path / "ex"
    with pytest.raises(ProblemInputError) as exc:
        export_scene("paper-sweep", SceneConfig(size=16, steps=2, seeds=seeds), "problem-dir", out)
    assert f"{2**64:,} QPs" in _one_line(exc)
    assert not out.exists()


@pytest.mark.parametrize("scene_name, cfg", [
    ("paper-sweep", SceneConfig(size=16, steps=5, seeds=(0, 1, 2, 3))),
    ("counterexample", SceneConfig(size=5, seeds=(0, 1, 2))),
    ("hertz", SceneConfig(size=16, steps=4)),
])
def test_the_count_of_a_big_range_equals_the_count_of_its_recipes(scene_name: str, cfg: SceneConfig) -> None:
    scene = get_scene(scene_name)
    merged = scene.config(cfg)
    specs = list(scene.instances(merged))
    counted = scene_counts(scene, merged)
    assert (counted.instances, counted.steps) == (len(specs), sum(int(s.params.get("steps") or 1) for s in specs))


# --- an E whose coefficients float64 cannot hold ------------------------------------------


@pytest.mark.parametrize("E", [1e308, 1e-310, 5e-324])
@pytest.mark.parametrize("kernel, periodic", [("bcc", False), ("love", False), ("bcc", True), ("spectral", True)])
def test_an_E_whose_coefficients_overflow_or_vanish_is_refused_naming_E(E: float, kernel: str, periodic: bool) -> None:
    with pytest.raises(ProblemInputError) as exc:
        kernel_table(kernel, (4, 4), 1e-4, E, periodic)
    assert _one_line(exc).startswith("E (composite modulus)")


@pytest.mark.parametrize("E", [1e308, 1e-310, 5e-324])
def test_an_export_with_such_an_E_writes_nothing(tmp_path: Path, E: float) -> None:
    out = tmp_path / "ex"
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", SceneConfig(size=16, E=E, extra={"allow_any_E": True}), "problem-dir", out)
    assert "E (composite modulus)" in _one_line(exc)
    assert not out.exists()


# --- an unnamed folder --------------------------------------------------------------------


def test_an_empty_out_is_refused_and_the_current_folder_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ProblemInputError) as exc:
        export_scene("hertz", HERTZ, "problem-dir", "")
    assert "--out" in _one_line(exc)
    assert list(tmp_path.iterdir()) == []
