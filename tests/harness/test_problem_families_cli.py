"""The problem families on the command line: load control (``--control load --loads``),
hardness (``--hardness``), layers (``--thickness``, ``--nu``), a measured map's cleaning and
rectangular size (``--length L0,L1``, ``--detrend``, ``--nan``, ``--crop``), and the scenes
that pose them.  Bad input is one line, exit 2, before anything runs; a run records what the
judge read (control, delta as the equality's multiplier, load_residual, plastic_fraction,
variant) in the table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.helpers import run_cli
from contactbench.harness.report.build import build_report

pytestmark = pytest.mark.usefixtures("in_tmp")
TINY = ["--size", "16", "--seeds", "0", "--no-progress"]


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    rc, _, err = run_cli(args, capsys)
    return rc, err


@pytest.mark.parametrize("args, needle", [
    (["--control", "load"], "--loads"),
    (["--loads", "0.001"], "--control load"),
    (["--control", "load", "--loads", "0.002,0.001"], "increasing"),
    (["--control", "load", "--loads", "nan"], "loads"),
    (["--control", "load", "--loads", "0.001,inf"], "loads"),
    (["--control", "load", "--loads", "0.001", "--steps", "3"], "--steps"),
    (["--hardness", "-1"], "--hardness"),
    (["--hardness", "nan"], "--hardness"),
    (["--hardness", "inf"], "--hardness"),
    (["--nu", "0.7", "--thickness", "1e-5"], "--nu"),
    (["--nu", "0.3"], "--thickness"),
    (["--detrend", "none"], "--surface"),
    (["--crop", "square"], "--surface"),
    (["--length", "1e-4,2e-4,3e-4"], "--length"),
    (["--length", "1e-4,-2e-4"], "--length"),
])
def test_bad_family_options_are_one_line_before_anything_runs(args: list[str], needle: str,
                                                             capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    rc, err = cli(["run", "paper-sweep", *TINY, *args, "--out", "o"], capsys)
    assert rc == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert needle in err
    assert not (in_tmp / "o").exists()


@pytest.mark.parametrize("scene, args", [("cmr", ["--thickness", "1e-5"]), ("cmr", ["--hardness", "1e8"]),
                                         ("counterexample", ["--control", "displacement"]),
                                         ("hertz", ["--hardness", "1e8"])])
def test_a_scene_that_poses_only_the_plain_problem_refuses_the_families(scene: str, args: list[str],
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    rc, err = cli(["run", scene, *args, "--out", "o"], capsys)
    assert rc == 2 and "does not take" in err, err


def test_load_control_records_the_approach_and_the_equality(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    rc, err = cli(["run", "paper-sweep", *TINY, "--control", "load", "--loads", "0.0005,0.001",
                   "--solvers", "pk,nnls", "--out", "o"], capsys)
    assert rc == 0, err
    t = pd.read_parquet(in_tmp / "o" / "results.parquet")
    assert set(t["control"]) == {"load"}
    nnls = t[t["solver"] == "nnls"]
    assert (nnls["status"] == "skipped").all() and nnls["skip_reason"].str.contains("load control").all()
    pk = t[t["solver"] == "pk"].sort_values("step")
    assert (pk["status"] == "solved").all(), pk[["status", "error"]]
    assert np.allclose(pk["dim_load"], [0.0005, 0.001], rtol=1e-6)
    assert (pk["load_residual"] < 1e-6).all()
    assert pk["delta"].notna().all() and (pk["delta"].diff().dropna() > 0).all()  # more load, deeper approach


def test_a_hardness_bounds_the_pressures_and_records_the_plastic_share(capsys: pytest.CaptureFixture[str],
                                                                       in_tmp: Path) -> None:
    rc, err = cli(["run", "paper-sweep", *TINY, "--steps", "2", "--hardness", "2e7",
                   "--solvers", "pk,fast-dual-pccg,nnls", "--out", "o"], capsys)
    assert rc == 0, err
    t = pd.read_parquet(in_tmp / "o" / "results.parquet")
    assert (t["hardness"] == 2e7).all()
    nnls = t[t["solver"] == "nnls"]
    assert (nnls["status"] == "skipped").all() and nnls["skip_reason"].str.contains("bound|hardness").all()
    fast = t[t["solver"] == "fast-dual-pccg"]
    assert (fast["status"] == "solved").all(), fast[["status", "error"]]
    pk = t[t["solver"] == "pk"]
    assert (pk["status"] == "solved").all(), pk[["status", "error"]]
    assert pk["plastic_fraction"].between(0, 1).all() and pk["plastic_fraction"].max() > 0


def test_a_rectangular_map_runs_uncropped_with_its_two_lengths(capsys: pytest.CaptureFixture[str],
                                                               in_tmp: Path) -> None:
    rng = np.random.default_rng(0)
    np.save(in_tmp / "map.npy", rng.standard_normal((24, 16)).cumsum(0).cumsum(1) * 1e-8)
    rc, err = cli(["run", "paper-sweep", "--surface", "map.npy", "--length", "48e-6,32e-6", "--steps", "2",
                   "--solvers", "pk", "--no-progress", "--out", "o"], capsys)
    assert rc == 0, err
    t = pd.read_parquet(in_tmp / "o" / "results.parquet")
    assert (t["status"] == "solved").all()
    assert np.allclose(t["nominal_area"], 48e-6 * 32e-6)


def test_greedy_kernels_reports_its_variants_from_the_table(capsys: pytest.CaptureFixture[str],
                                                            in_tmp: Path) -> None:
    rc, err = cli(["run", "greedy-kernels", "--size", "3", "--seeds", "0-1", "--solvers", "greedy-cg",
                   "--reference", "none", "--no-progress", "--out", "o"], capsys)
    assert rc == 0, err
    t = pd.read_parquet(in_tmp / "o" / "results.parquet")
    assert set(t["variant"]) == {"bcc", "love", "thin-layer", "hardness"}
    report = build_report(in_tmp / "o", html=False).read_text()
    assert "Greedy on other forms of H" in report
    for variant in ("love", "thin-layer", "hardness"):
        assert f"| greedy-cg | {variant} |" in report
