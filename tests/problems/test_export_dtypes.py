"""problems.export keeps the dtype of the data an instance holds: the float32 stress case
(``stress-precision``: ubar handed over as float32) is written as float32 where the
format allows it (hdf5's ``ubar`` dataset, qpbenchmark's q and lb) and reads back with
that dtype and the same values; every format's metadata records the dtype (the
manifest, hdf5's ``problem_json``, the Parquet file's key-value metadata)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from contactbench.problems import export
from contactbench.problems.export import append_qpbenchmark_row, export_scene, problem_name, scene_steps, write_parquet
from contactbench.problems.qpfile import read_problem_dir
from contactbench.problems.scenes import SceneConfig

#: The float32 stress scene: one QP whose ubar is float32.
FLOAT32_SCENE = "stress-precision"


def float32_qp() -> tuple[str, Any]:
    """(exported name, instance) of the one QP of the float32 stress scene."""
    (instance, k, inst), = scene_steps(FLOAT32_SCENE, SceneConfig())
    assert inst.qp.ubar.dtype == np.float32
    return problem_name(instance, k), inst


def manifest_dtypes(out: Path) -> dict[str, str]:
    return {q["name"]: q["dtype"] for q in json.loads((out / export.MANIFEST_FILE).read_text())["qps"]}


def test_hdf5_keeps_a_float32_ubar_and_says_so(tmp_path: Path) -> None:
    h5py = pytest.importorskip("h5py")
    name, inst = float32_qp()
    export_scene(FLOAT32_SCENE, SceneConfig(), "hdf5", tmp_path)
    with h5py.File(tmp_path / export.HDF5_FILE, "r") as h5:
        ubar = h5[name]["ubar"][...]
        doc = json.loads(h5[name].attrs["problem_json"])
    assert ubar.dtype == np.float32 and np.array_equal(ubar, inst.qp.ubar)
    assert doc["arrays"]["ubar"]["dtype"] == "<f4"
    assert manifest_dtypes(tmp_path) == {name: "float32"}
    back = export.read_hdf5_problem(tmp_path / export.HDF5_FILE, name).ubar  # as a problem directory: float64
    assert back.dtype == np.float64 and np.array_equal(back, inst.qp.ubar)


def test_qpbenchmark_keeps_a_float32_q_and_lb_and_says_so(tmp_path: Path) -> None:
    name, inst = float32_qp()
    export_scene(FLOAT32_SCENE, SceneConfig(), "qpbenchmark", tmp_path)
    path = tmp_path / f"{FLOAT32_SCENE}.parquet"
    row = pd.read_parquet(path, engine="pyarrow").set_index("name").loc[name]  # as qpbenchmark reads it
    assert row["q"].dtype == np.float32 and np.array_equal(row["q"], -inst.qp.ubar)
    assert row["lb"].dtype == np.float32 and not row["lb"].any()
    assert row["P"].dtype == np.float64 and np.array_equal(row["P"], inst.qp.H.to_dense().ravel())
    assert export.read_qpbenchmark_dtypes(path) == {name: "float32"}
    assert manifest_dtypes(tmp_path) == {name: "float32"}


def test_problem_dir_is_float64_only_and_its_manifest_records_float32(tmp_path: Path) -> None:
    name, inst = float32_qp()
    export_scene(FLOAT32_SCENE, SceneConfig(), "problem-dir", tmp_path)
    assert np.array_equal(read_problem_dir(tmp_path / name).ubar, inst.qp.ubar)  # widened exactly
    assert manifest_dtypes(tmp_path) == {name: "float32"}


@pytest.mark.parametrize("float32_first", [True, False])
def test_a_file_mixing_float32_and_float64_qps_holds_both_exactly(tmp_path: Path, float32_first: bool) -> None:
    """A column holds one dtype: a float64 QP after a float32 one widens the rows written
    so far (exactly); the metadata still names each QP's own dtype."""
    _, f32 = float32_qp()
    (_, _, f64), = scene_steps("counterexample", SceneConfig(size=4, seeds=(0,)))
    order = [("f32", f32), ("f64", f64)] if float32_first else [("f64", f64), ("f32", f32)]
    rows: dict[str, list[Any]] = {k: [] for k in export.QPBENCHMARK_KEYS}
    for name, inst in order:
        append_qpbenchmark_row(rows, name, inst)
    path = write_parquet(rows, tmp_path / "mixed.parquet")
    assert pq.read_schema(path).field("q").type == pa.list_(pa.float64())
    df = pd.read_parquet(path, engine="pyarrow").set_index("name")
    for name, inst in order:
        assert np.array_equal(df.loc[name, "q"], -np.asarray(inst.qp.ubar, dtype=np.float64))
        assert np.array_equal(df.loc[name, "P"], inst.qp.H.to_dense().ravel())
    assert export.read_qpbenchmark_dtypes(path) == {"f32": "float32", "f64": "float64"}
    assert not list(tmp_path.glob(".*"))  # no temporary file left
