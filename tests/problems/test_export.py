"""problems.export / ``contactbench export``: every (instance, step) QP of a scene
written as problem directories, HDF5 and a qpbenchmark test set; reading one back and
solving it gives the original answer to round-off."""

from __future__ import annotations

import builtins
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.export import (
    export_scene,
    problem_name,
    read_hdf5_problem,
    qpbenchmark_test_set,
    read_qpbenchmark_row,
    scene_steps,
)
from contactbench.problems.lcp import exact_solution
from contactbench.problems.qpfile import read_problem_dir
from contactbench.problems.scenes import SceneConfig

SWEEP = SceneConfig(size=32, steps=2)
COUNTER = SceneConfig(size=5, seeds=(0, 1))


def originals(scene: str, cfg: SceneConfig) -> dict[str, Any]:
    """name -> the scene's own instance of every exported QP."""
    return {problem_name(i, k): inst for i, k, inst in scene_steps(scene, cfg)}


def exact_p(H: np.ndarray, ubar: np.ndarray) -> np.ndarray:
    return exact_solution(np.asarray(H, dtype=np.float64), np.asarray(ubar, dtype=np.float64)).p


def assert_same_answer(H: np.ndarray, ubar: np.ndarray, inst: Any) -> None:
    p0 = exact_p(inst.qp.H.to_dense(), inst.qp.ubar)
    p = exact_p(H, ubar)
    np.testing.assert_allclose(p, p0, rtol=1e-12, atol=1e-12 * float(np.max(p0)))


@pytest.mark.parametrize("scene,cfg", [("paper-sweep", SWEEP), ("counterexample", COUNTER)])
def test_problem_dir_round_trip_gives_the_original_answer(tmp_path: Path, scene: str, cfg: SceneConfig) -> None:
    summary = export_scene(scene, cfg, "problem-dir", tmp_path)
    orig = originals(scene, cfg)
    assert {q.name for q in summary.written} == set(orig) and len(orig) >= 2
    for name, inst in orig.items():
        pf = read_problem_dir(tmp_path / name)
        assert pf.H is not None
        np.testing.assert_array_equal(pf.ubar, inst.qp.ubar)
        assert_same_answer(pf.H, pf.ubar, inst)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert [q["name"] for q in manifest["qps"]] == [q.name for q in summary.written]


def test_over_the_dense_limit_the_kernel_table_still_gives_the_answer(tmp_path: Path) -> None:
    summary = export_scene("paper-sweep", SWEEP, "problem-dir", tmp_path, dense_limit=40)
    assert "dense H left out" in summary.line()
    for name, inst in originals("paper-sweep", SWEEP).items():
        pf = read_problem_dir(tmp_path / name)
        assert (pf.H is None) == (inst.n > 40)
        assert_same_answer(pf.qp().H.to_dense(), pf.ubar, inst)


def test_hdf5_round_trip(tmp_path: Path) -> None:
    pytest.importorskip("h5py")
    export_scene("counterexample", COUNTER, "hdf5", tmp_path)
    for name, inst in originals("counterexample", COUNTER).items():
        pf = read_hdf5_problem(tmp_path / "problems.h5", name)
        np.testing.assert_array_equal(pf.H, inst.qp.H.to_dense())
        assert_same_answer(pf.H, pf.ubar, inst)


def test_hdf5_without_h5py_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_h5py(name: str, *a: Any, **kw: Any) -> Any:
        if name == "h5py":
            raise ImportError("no h5py")
        return real_import(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_h5py)
    with pytest.raises(ProblemInputError, match="needs h5py, which is not installed"):
        export_scene("counterexample", COUNTER, "hdf5", tmp_path)


def test_qpbenchmark_test_set_is_P_H_q_minus_ubar_lb_zero(tmp_path: Path) -> None:
    summary = export_scene("paper-sweep", SWEEP, "qpbenchmark", tmp_path, dense_limit=100)
    orig = originals("paper-sweep", SWEEP)
    big = {n for n, inst in orig.items() if inst.n > 100}
    assert big and {s["name"] for s in summary.skipped} == big and "skipped 1" in summary.line()
    for name in set(orig) - big:
        inst = orig[name]
        P, q, lb = read_qpbenchmark_row(tmp_path / "paper-sweep.parquet", name)
        np.testing.assert_array_equal(P, inst.qp.H.to_dense())
        np.testing.assert_array_equal(q, -inst.qp.ubar)
        assert not lb.any()
        assert_same_answer(P, -q, inst)


def test_qpbenchmark_reads_the_exported_set(tmp_path: Path) -> None:
    pytest.importorskip("qpbenchmark")
    export_scene("counterexample", COUNTER, "qpbenchmark", tmp_path)
    problems = {pb.name: pb for pb in qpbenchmark_test_set(tmp_path / "counterexample.parquet")}
    orig = originals("counterexample", COUNTER)
    assert set(problems) == set(orig)
    for name, inst in orig.items():
        pb = problems[name]
        np.testing.assert_array_equal(pb.P, inst.qp.H.to_dense())
        assert pb.G is None and pb.A is None and pb.ub is None and not pb.lb.any()


def test_cli_export_and_its_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness import cli

    out = tmp_path / "pd"
    assert cli.main(["export", "counterexample", "--size", "5", "--seeds", "0", "--format", "problem-dir",
                     "--out", str(out)]) == 0
    assert "exported 1 QPs of counterexample" in capsys.readouterr().out
    assert (out / "n25-s0-step0" / "problem.json").is_file()
    assert cli.main(["export", "paper-sweep", "--size", "1", "--format", "problem-dir", "--out", str(out)]) == 2
    assert "error" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["export", "paper-sweep", "--format", "mps", "--out", str(out)])


# ---------------------------------------------------------------------------
# Writing into a folder written before; an interrupted export; rectangular pixels
# ---------------------------------------------------------------------------


def _files(d: Path) -> set[str]:
    return {p.name for p in d.iterdir()}


def test_a_problem_dir_written_again_holds_only_the_new_problems_files(tmp_path: Path) -> None:
    from contactbench.problems.scenes.battery_families import constrained_instance
    from contactbench.problems.qpfile import write_problem_dir

    bounded = constrained_instance("hardness", 0)
    d = write_problem_dir(bounded, tmp_path / "qp", tol=1e-8, time_limit=None, p0=np.ones(bounded.n))
    assert {"H.f64", "p0.f64", "upper.f64"} <= _files(d)
    (d / "notes.txt").write_text("not the harness's")
    inst = next(iter(originals("counterexample", COUNTER).values()))
    write_problem_dir(inst, d, tol=None, time_limit=None, dense_limit=inst.n - 1)
    listed = {e["file"] for e in json.loads((d / "problem.json").read_text())["arrays"].values()}
    assert _files(d) == listed | {"problem.json", "notes.txt"} and "H.f64" not in listed
    pf = read_problem_dir(d)
    assert pf.H is None and pf.p0 is None and pf.upper is None and pf.n == inst.n


def test_exporting_again_removes_what_the_earlier_export_wrote_and_this_one_does_not(tmp_path: Path) -> None:
    hertz = tmp_path / "N16-bcc-step0"
    export_scene("hertz", SceneConfig(size=16), "problem-dir", tmp_path)
    assert "H.f64" in _files(hertz)
    export_scene("hertz", SceneConfig(size=16), "problem-dir", tmp_path, dense_limit=10)
    assert "H.f64" not in _files(hertz) and read_problem_dir(hertz).E == 1e9
    export_scene("hertz", SceneConfig(size=16, E=2e9), "problem-dir", tmp_path)  # (another instance: its own folder)
    assert _files(tmp_path) == {"manifest.json", "N16-bcc-E2e9-step0"}
    assert read_problem_dir(tmp_path / "N16-bcc-E2e9-step0").E == 2e9
    (tmp_path / "mine.txt").write_text("kept")
    export_scene("counterexample", COUNTER, "problem-dir", tmp_path)  # this export does not write the hertz folder
    assert _files(tmp_path) == {"manifest.json", "mine.txt", "n25-s0-step0", "n25-s1-step0"}
    (tmp_path / "n25-s1-step0" / "notes.txt").write_text("not ours: it and its folder are kept")
    export_scene("counterexample", COUNTER, "qpbenchmark", tmp_path)
    assert _files(tmp_path) == {"manifest.json", "mine.txt", "n25-s1-step0", "counterexample.parquet"}
    assert _files(tmp_path / "n25-s1-step0") == {"notes.txt"}  # the earlier export's files are gone
    export_scene("paper-sweep", SWEEP, "qpbenchmark", tmp_path)
    assert "counterexample.parquet" not in _files(tmp_path) and "paper-sweep.parquet" in _files(tmp_path)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["complete"] is True and manifest["scene"] == "paper-sweep"


def test_a_shorter_export_removes_an_earlier_qp_s_files_and_keeps_a_user_s_file_beside_them(tmp_path: Path) -> None:
    out = tmp_path / "ex1"
    first = export_scene("paper-sweep", SceneConfig(size=16, steps=2, seeds=(0,)), "problem-dir", out)
    assert [q.step for q in first.written] == [0, 1]
    gone = out / first.written[1].name
    (gone / "notes.txt").write_text("the user's")
    second = export_scene("paper-sweep", SceneConfig(size=16, steps=1, seeds=(0,)), "problem-dir", out)
    assert gone.name not in {q.name for q in second.written}
    assert _files(gone) == {"notes.txt"} and (gone / "notes.txt").read_text() == "the user's"
    assert _files(out) == {"manifest.json", gone.name, second.written[0].name}
    with pytest.raises(ProblemInputError, match="is not an export's"):  # (no longer listed: never written into)
        export_scene("paper-sweep", SceneConfig(size=16, steps=2, seeds=(0,)), "problem-dir", out)
    assert _files(gone) == {"notes.txt"}


def test_an_interrupted_export_leaves_a_folder_that_the_same_export_writes_again(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness import cli
    from contactbench.problems import export

    real_write = export.write_problem_dir
    calls: list[Path] = []

    def interrupted_write(inst: Any, directory: Path, **kw: Any) -> Path:
        if len(calls) == 1:
            raise KeyboardInterrupt
        calls.append(Path(directory))
        return real_write(inst, directory, **kw)

    monkeypatch.setattr(export, "write_problem_dir", interrupted_write)
    out = tmp_path / "pd"
    argv = ["export", "counterexample", "--size", "5", "--seeds", "0,1", "--format", "problem-dir", "--out", str(out)]
    assert cli.main(argv) == 130
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] is False and manifest["owned_folders"] == ["n25-s0-step0", "n25-s1-step0"]
    assert export.check_export_folder(out) == out
    monkeypatch.setattr(export, "write_problem_dir", real_write)
    capsys.readouterr()
    assert cli.main(argv) == 0, capsys.readouterr().err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["complete"] is True and [q["name"] for q in manifest["qps"]] == ["n25-s0-step0", "n25-s1-step0"]
    # an interrupted export's folders go when another export is written there
    monkeypatch.setattr(export, "write_problem_dir", interrupted_write)
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        export_scene("paper-sweep", SWEEP, "problem-dir", out)
    assert len(calls) == 1 and calls[0].is_dir()
    monkeypatch.setattr(export, "write_problem_dir", real_write)
    export_scene("hertz", SceneConfig(size=16), "problem-dir", out)
    assert _files(out) == {"manifest.json", "N16-bcc-step0"}


def test_rectangular_pixels_are_described_by_both_spacings(tmp_path: Path) -> None:
    from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
    from contactbench.problems.surfaces import Surface, rmd_surface_n
    from contactbench.problems.qpfile import write_problem_dir

    scene = SceneConfig()
    export_scene("stress-rectangular", scene, "problem-dir", tmp_path, dense_limit=10)
    for name, inst in originals("stress-rectangular", scene).items():
        d0, d1 = inst.qp.geometry.spacing
        doc = json.loads((tmp_path / name / "problem.json").read_text())
        assert doc["grid"] == [48, 32] and (doc["spacing"], doc["spacing1"]) == (d0, d1)
        pf = read_problem_dir(tmp_path / name)
        assert pf.geometry().spacing == (d0, d1)
        np.testing.assert_allclose(pf.geometry().positions, inst.qp.geometry.positions)
        assert_same_answer(pf.qp().H.to_dense(), pf.ubar, inst)
    assert {json.loads((tmp_path / n / "problem.json").read_text())["spacing1"] / i.qp.geometry.delta
            for n, i in originals("stress-rectangular", scene).items()} == {1.0, 1.5}
    # a dense operator on rectangular pixels gets its kernel table too
    square = rmd_surface_n(16, 0.7, length=100e-6, rms_height=1e-6, seed=0)
    surf = Surface(np.array(square.heights[:12, :8]), square.delta, delta1=1.5 * square.delta)
    dense = InstanceBuilder(surf, 1e9, "love", operator="dense").build(paper_max_displacement(surf))
    pf = read_problem_dir(write_problem_dir(dense, tmp_path / "dense", tol=None, time_limit=None))
    assert pf.kernel_table is not None and pf.spacing1 == 1.5 * square.delta
    # a file without spacing1 (square pixels) reads as square
    doc = json.loads((tmp_path / "dense" / "problem.json").read_text())
    del doc["spacing1"]
    (tmp_path / "dense" / "problem.json").write_text(json.dumps(doc))
    assert read_problem_dir(tmp_path / "dense").geometry().spacing == (square.delta, square.delta)


def test_the_manifest_records_the_options_the_version_and_a_measured_map_s_hash(tmp_path: Path) -> None:
    import warnings

    from contactbench.problems.preprocessing import raw_heights_sha256
    from contactbench.problems.scenes.options import CONFIG_FIELDS
    from contactbench.problems.surfaces import rmd_surface_n

    heights = rmd_surface_n(17, 0.7, length=1e-4, rms_height=1e-6, seed=2).heights
    np.save(tmp_path / "m.npy", heights)
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        export_scene("paper-sweep", SceneConfig(surface_path=str(tmp_path / "m.npy"), length=1e-4, steps=2),
                     "problem-dir", out)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["contactbench_version"] and isinstance(manifest["contactbench_version"], str)
    options = manifest["scene_options"]
    assert set(CONFIG_FIELDS) <= set(options) and options["steps"] == 2 and options["length"] == 1e-4
    assert options["surface_path"] == str(tmp_path / "m.npy") and options["size"] is not None  # (defaults filled)
    assert [q["surface_sha256"] for q in manifest["qps"]] == [raw_heights_sha256(heights)] * 2
    export_scene("paper-sweep", SceneConfig(size=16, steps=1, seeds=range(0, 1)), "problem-dir", tmp_path / "gen")
    generated = json.loads((tmp_path / "gen" / "manifest.json").read_text())
    assert [q["surface_sha256"] for q in generated["qps"]] == [None]
    assert generated["scene_options"]["size"] == 16 and generated["scene_options"]["seeds"] == "range(0, 1)"
