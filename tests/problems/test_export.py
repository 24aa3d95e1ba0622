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
