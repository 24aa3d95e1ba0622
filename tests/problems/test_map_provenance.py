"""Every change to a measured map is recorded: ``problems.io.load_surface``'s
``MapPreprocessing`` record (the removed plane, the filled points, the crop, the unit and
the spacing per axis, the warnings), carried by the instance into meta.json
(``surface_preprocessing``), the table's columns and the report's header; the instance is
named from the file's base name and a hash of its heights and options, never from the
path as typed."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.helpers import run_cli
from contactbench.harness.report.build import build_report
from contactbench.harness.report.core import fmt_num, problem_changes
from contactbench.harness.run.plan import RunConfig, job_cell_ids, plan_run
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.io import load_surface, read_height_map
from contactbench.problems.scenes import SceneConfig

N0, N1 = 24, 16
D = 2e-6  # metres per point, both axes
SLOPE = (0.08, -0.05)  # the imposed tilt, rise per length along axes 0 and 1
HOLES = ((3, 4), (10, 7), (11, 7))
LENGTH = f"{N0 * D:g},{N1 * D:g}"


def tilted_map_with_holes() -> np.ndarray:
    """A rough 24 x 16 map (rms slope ~0.01) on a plane much steeper than it, 3 points missing."""
    rng = np.random.default_rng(3)
    i, j = np.mgrid[0:N0, 0:N1]
    z = rng.normal(0.0, 1e-8, (N0, N1)) + 5e-7 + SLOPE[0] * D * i + SLOPE[1] * D * j
    for h in HOLES:
        z[h] = np.nan
    return z


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    rc, _, err = run_cli(args, capsys)
    return rc, err


def run_args(path: str, out: str, *extra: str) -> list[str]:
    return ["run", "paper-sweep", "--surface", path, "--length", LENGTH, "--steps", "2", "--solvers", "pk",
            "--no-progress", "--out", out, *extra]


def stored(out: str) -> tuple[pd.DataFrame, dict]:
    return pd.read_parquet(Path(out) / "results.parquet"), json.loads((Path(out) / "meta.json").read_text())


def run(path: str, out: str, capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[pd.DataFrame, dict, str]:
    """The CLI in this process (its warnings go to pytest, not to stderr)."""
    rc, err = cli(run_args(path, out, *extra), capsys)
    assert rc == 0, err
    return (*stored(out), err)


def run_fresh(cwd: Path, path: str, out: str, *extra: str) -> tuple[pd.DataFrame, dict, str]:
    """``contactbench`` in a fresh interpreter: what a user sees on stderr."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONWARNINGS")}
    res = subprocess.run([sys.executable, "-m", "contactbench.harness.cli", *run_args(path, out, *extra)], cwd=cwd,
                         env=env, capture_output=True, text=True, timeout=300, check=False)
    assert res.returncode == 0, res.stderr
    return (*stored(str(cwd / out)), res.stderr)


@pytest.mark.slow
def test_a_tilted_map_with_holes_states_its_plane_and_filled_points_everywhere(in_tmp: Path) -> None:
    np.save(in_tmp / "tilted.npy", tilted_map_with_holes())
    t, meta, err = run_fresh(in_tmp, "tilted.npy", "o", "--kernel", "love", "--thickness", "1e-5", "--nu", "0.45")
    (name,) = set(t["instance"])
    # meta.json: one record per instance, the plane in lengths, the filled points, the warnings
    rec = meta["surface_preprocessing"][f"paper-sweep/{name}"]
    assert rec["source"] == "tilted.npy" and rec["path"] == str((in_tmp / "tilted.npy").resolve())
    assert rec["detrend"] == "plane" and rec["removed_slope"] == pytest.approx(SLOPE, abs=2e-3)
    assert rec["nan_rule"] == "fill-mean" and rec["filled"] == len(HOLES)
    assert rec["filled_fraction"] == pytest.approx(len(HOLES) / (N0 * N1))
    assert rec["shape"] == [N0, N1] and rec["spacing"] == pytest.approx([D, D]) and rec["crop"] == "none"
    assert rec["height_unit"] == "m" and rec["unit_from"] == "default (metres)"
    assert any("3 missing points" in w for w in rec["warnings"]) and any("tilted" in w for w in rec["warnings"])
    assert all(any(w in m for m in meta["warnings"]) for w in rec["warnings"])
    # the table: the grid per axis, the layer, the map's preparation
    row = t.iloc[0]
    assert (row["N0"], row["N1"], row["N"]) == (N0, N1, N0)
    assert row["delta0"] == pytest.approx(D) and row["delta1"] == pytest.approx(D)
    assert row["thickness"] == pytest.approx(1e-5) and row["nu"] == pytest.approx(0.45)
    assert row["interface"] == "bonded"
    assert (row["surface_source"], row["detrend"], row["nan_rule"], row["crop"]) == ("tilted.npy", "plane",
                                                                                    "fill-mean", "none")
    assert row["nan_filled"] == len(HOLES) and row["surface_hash"] == rec["raw_sha256"][:16]
    assert (row["removed_slope0"], row["removed_slope1"]) == pytest.approx(SLOPE, abs=2e-3)
    # each warning printed once, on one line of its own
    assert err.count("3 missing points") == 1 and err.count("mean plane is tilted") == 1, err
    warned = [ln for ln in err.splitlines() if "missing points" in ln or "mean plane is tilted" in ln]
    assert all(ln.startswith("contactbench: warning: ") for ln in warned) and "UserWarning" not in err, err
    # the report's header names the removed plane and the filled points
    report = build_report(in_tmp / "o", html=False).read_text()
    (line,) = [ln for ln in report.splitlines() if ln.startswith("| Problem changes |")]
    assert name in line and "plane removed" in line
    assert "3 missing points filled (fill-mean, relative to the measured points' plane)" in line
    assert f"slopes {fmt_num(row['removed_slope0'])} and {fmt_num(row['removed_slope1'])}" in line


def test_the_header_states_the_heights_unit_and_the_crop_done(in_tmp: Path) -> None:
    """A map of micrometres padded to a square: the header's "Problem changes" says the
    heights were scaled to metres and how the map was padded, with the factor by which the
    padding grows the nominal area, not only "crop pad-square"."""
    z = tilted_map_with_holes()[:, :N1 - 2]
    z[np.isnan(z)] = 0.0
    np.save(in_tmp / "um.npy", z / 1e-6)
    run_fresh(in_tmp, "um.npy", "o", "--height-unit", "um", "--crop", "pad-square", "--kernel", "love")
    report = build_report(in_tmp / "o", html=False).read_text()
    (line,) = [ln for ln in report.splitlines() if ln.startswith("| Problem changes |")]
    assert "heights in um (height_unit argument), scaled by 1.00e-06 to metres" in line, line
    assert f"padded {N0}x{N1 - 2} to" in line, line
    assert f"the nominal area A0 grows by a factor {N0 * N0 / (N0 * (N1 - 2)):.4g}" in line, line


@pytest.mark.slow
def test_detrend_none_and_plane_are_different_problems_with_different_names(
        capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    np.save(in_tmp / "tilted.npy", tilted_map_with_holes())
    plane, meta_plane, _ = run("tilted.npy", "plane", capsys, "--detrend", "plane")
    kept, meta_kept, _ = run("tilted.npy", "kept", capsys, "--detrend", "none")
    assert set(plane["instance"]).isdisjoint(set(kept["instance"]))
    assert set(plane["cell_id"]).isdisjoint(set(kept["cell_id"]))
    assert set(kept["detrend"]) == {"none"} and kept["removed_slope0"].isna().all()
    (rec,) = meta_kept["surface_preprocessing"].values()
    assert rec["detrend"] == "none" and rec["removed_slope"] is None and rec["tilt"] == pytest.approx(
        float(np.hypot(*SLOPE)), rel=0.05)
    top = {k: float(t.loc[t["step"] == 1, "load"].iloc[0]) for k, t in (("plane", plane), ("kept", kept))}
    assert top["plane"] != pytest.approx(top["kept"], rel=0.05)  # not the same problem
    assert "nothing removed (detrend none)" in problem_changes(kept)  # the report header's line


@pytest.mark.usefixtures("in_tmp")
def test_the_default_cleaning_is_the_explicit_one() -> None:
    cfg = dict(length=(N0 * D, N1 * D), steps=2)
    np.save("m.npy", tilted_map_with_holes())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        default = plan_run(["paper-sweep"], SceneConfig(surface_path="m.npy", **cfg), ["pk"])
        explicit = plan_run(["paper-sweep"], SceneConfig(surface_path="m.npy", extra={"detrend": "plane",
                                                                                     "nan": "fill-mean"}, **cfg), ["pk"])
    assert [j.spec.instance for j in default.jobs] == [j.spec.instance for j in explicit.jobs]


@pytest.mark.usefixtures("in_tmp")
def test_two_paths_to_one_map_give_one_name_and_the_same_cell_ids(tmp_path: Path) -> None:
    np.save(tmp_path / "m.npy", tilted_map_with_holes())
    (tmp_path / "sub").mkdir()
    os.symlink(tmp_path / "m.npy", tmp_path / "sub" / "link.npy")
    shutil.copy(tmp_path / "m.npy", tmp_path / "sub" / "m.npy")
    cfg = dict(length=(N0 * D, N1 * D), steps=2)

    def planned(path: str) -> tuple[str, list[str]]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            (job,) = plan_run(["paper-sweep"], SceneConfig(surface_path=path, **cfg), ["pk"]).jobs
        assert "/" not in job.spec.instance and "_tmp" not in job.spec.instance
        return job.spec.instance, job_cell_ids(job, RunConfig())

    name, ids = planned("m.npy")
    assert name.startswith("file-m.npy-")
    assert planned(str(tmp_path / "m.npy")) == (name, ids)
    assert planned(str(tmp_path / "sub" / ".." / "m.npy")) == (name, ids)
    assert planned(str(tmp_path / "sub" / "link.npy")) == (name, ids)  # a link: the file it names
    assert planned(str(tmp_path / "sub" / "m.npy")) == (name, ids)  # a copy: the same map, the same cells
    np.save(tmp_path / "other.npy", tilted_map_with_holes() * 1.5)
    assert planned(str(tmp_path / "other.npy"))[1] != ids  # another map: other cells


def test_a_map_changed_after_the_plan_is_refused_when_its_steps_are_built(tmp_path: Path) -> None:
    """The plan names the instance by the map's content; a file replaced before its steps
    are built (during a run, between planning and a worker, or before a resume) does not
    give that instance, and building it says so instead of solving another map under the
    planned name."""
    from contactbench.problems.errors import ProblemInputError

    np.save(tmp_path / "m.npy", tilted_map_with_holes())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (job,) = plan_run(["paper-sweep"], SceneConfig(surface_path=str(tmp_path / "m.npy"),
                                                      length=(N0 * D, N1 * D), steps=2), ["pk"]).jobs
        job.spec.build()  # the file as planned
        np.save(tmp_path / "m.npy", tilted_map_with_holes() * 1.5)
        with pytest.raises(ProblemInputError, match="has changed since the run was planned"):
            job.spec.build()


def test_the_record_follows_the_options_and_the_heights(tmp_path: Path) -> None:
    z = tilted_map_with_holes()
    np.save(tmp_path / "a.npy", z)
    np.save(tmp_path / "b.npy", z + 1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = load_surface(tmp_path / "a.npy", (N0 * D, N1 * D)).preprocessing
        keys = {load_surface(tmp_path / "a.npy", (N0 * D, N1 * D), **kw).preprocessing.key for kw in (
            {}, {"detrend": "none"}, {"detrend": "mean"}, {"nan": "fill-min"}, {"crop": "square"},
            {"height_unit": "um"})}
        keys.add(load_surface(tmp_path / "a.npy", (N0 * D, 2 * N1 * D)).preprocessing.key)
        b = load_surface(tmp_path / "b.npy", (N0 * D, N1 * D)).preprocessing
    assert a is not None and b is not None and len(keys) == 7  # every option changes the key
    assert a.raw_sha256 != b.raw_sha256 and a.key != b.key
    assert a.instance_name == f"file-a.npy-{a.key[:8]}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = load_surface(tmp_path / "a.npy", (N0 * D, N1 * D), detrend="mean").preprocessing
        sq = load_surface(tmp_path / "a.npy", (N0 * D, N1 * D), crop="square").preprocessing
    assert m is not None and m.removed_slope is None and m.removed_mean is not None
    assert sq is not None and sq.shape == (N1, N1) and sq.shape_read == (N0, N1) and "cropped" in sq.crop_done
    assert any("non-square" in w for w in sq.warnings)


def test_a_second_read_of_a_map_warns_no_more_but_records_the_same(tmp_path: Path) -> None:
    np.save(tmp_path / "w.npy", tilted_map_with_holes())
    with warnings.catch_warnings(record=True) as first:
        warnings.simplefilter("always")
        r1 = load_surface(tmp_path / "w.npy", (N0 * D, N1 * D)).preprocessing
    with warnings.catch_warnings(record=True) as second:
        warnings.simplefilter("always")
        r2 = load_surface(tmp_path / "w.npy", (N0 * D, N1 * D)).preprocessing
    assert r1 is not None and r2 is not None
    assert len(first) == 2 and not second  # filled points, tilt: announced once per process
    assert r1.warnings == r2.warnings and len(r2.warnings) == 2


def test_a_row_rebuilds_its_problem_from_the_file(capsys: pytest.CaptureFixture[str], in_tmp: Path) -> None:
    """docs/columns.md, "Rebuilding a problem from the table": the columns and the file."""
    np.save(in_tmp / "r.npy", tilted_map_with_holes())
    t, _, _ = run("r.npy", "o", capsys, "--detrend", "mean", "--nan", "fill-min", "--crop", "square")
    row = t[t["step"] == 1].iloc[0]
    assert pd.isna(row["channel_index"])  # a .npy has no channels
    raw = read_height_map(in_tmp / row["surface_source"])
    n0, n1 = raw.z.shape
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = load_surface(in_tmp / row["surface_source"], (n0 * row["delta0"], n1 * row["delta1"]),
                         nan=row["nan_rule"], detrend=row["detrend"], crop=row["crop"],
                         height_unit=None if raw.unit_known else row["height_unit"])
    assert s.preprocessing is not None and s.preprocessing.raw_sha256.startswith(row["surface_hash"])
    assert row["solved_hash"] and s.preprocessing.solved_sha256.startswith(row["solved_hash"])  # (as solved)
    assert s.preprocessing.filled_solved == row["nan_filled"]  # (the filled points the cropped map keeps)
    inst = InstanceBuilder(s, float(row["E"]), kernel=row["kernel"], periodic=bool(row["periodic"])).build(
        float(row["delta"]))
    assert inst.n == row["n"] and inst.problem_columns()["removed_mean"] == pytest.approx(row["removed_mean"])
    assert (row["N0"], row["N1"], row["crop"]) == (N1, N1, "square")  # the central square, the spacing kept
    assert inst.problem_columns()["N0"] == row["N0"] and inst.problem_columns()["N1"] == row["N1"]


def test_the_header_names_the_channel_read_from_a_file_of_several(capsys: pytest.CaptureFixture[str],
                                                                   in_tmp: Path) -> None:
    """Two channels in one file: which one was solved is part of the problem, so the
    header's "Problem changes" names it (meta.json records it too)."""
    import scipy.io

    z = tilted_map_with_holes()
    z[np.isnan(z)] = 0.0
    scipy.io.savemat(in_tmp / "two.mat", {"height": z, "intensity": np.abs(z) + 1e-6})
    _, meta, _ = run("two.mat", "o", capsys, "--channel", "height", "--kernel", "love")
    (rec,) = meta["surface_preprocessing"].values()
    assert rec["channel"] == "height"
    report = build_report(in_tmp / "o", html=False).read_text()
    (line,) = [ln for ln in report.splitlines() if ln.startswith("| Problem changes |")]
    assert "channel 'height'" in line, line


def test_a_row_of_a_file_of_channels_names_its_channel_and_no_hurst_or_seed(capsys: pytest.CaptureFixture[str],
                                                                           in_tmp: Path) -> None:
    """The channel solved is a column (its index: a name two channels may share), from which
    with the other columns the problem rebuilds (docs/columns.md); a measured map has no
    Hurst exponent and no seed, whatever the scene's defaults."""
    import scipy.io

    z = tilted_map_with_holes()
    z[np.isnan(z)] = 0.0
    scipy.io.savemat(in_tmp / "two.mat", {"height": z, "intensity": np.abs(z[::-1]) + 1e-6})
    t, meta, _ = run("two.mat", "o", capsys, "--channel", "intensity", "--kernel", "love")
    index = read_height_map(in_tmp / "two.mat", channel="intensity").info["channel_index"]
    assert set(t["channel_index"]) == {index}
    (rec,) = meta["surface_preprocessing"].values()
    assert (rec["channel"], rec["channel_index"]) == ("intensity", index)
    assert t["hurst"].isna().all() and t["seed"].isna().all()
    row = t.iloc[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = load_surface(in_tmp / row["surface_source"], (N0 * row["delta0"], N1 * row["delta1"]),
                         nan=row["nan_rule"], detrend=row["detrend"], crop=row["crop"],
                         height_unit=row["height_unit"], channel=int(row["channel_index"]))
    assert s.preprocessing is not None and s.preprocessing.raw_sha256.startswith(row["surface_hash"])


def test_a_base_name_in_other_letters_gives_a_plain_and_distinct_instance_name(tmp_path: Path) -> None:
    """Accented letters are written plainly; a name in another script, which has no plain
    letters, keeps a hash of itself, so that two such files name two instances."""
    z = tilted_map_with_holes()
    names = {}
    for base in ("Höhe-5µm.npy", "表面.npy", "粗さ.npy"):
        np.save(tmp_path / base, z)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            record = load_surface(tmp_path / base, (N0 * D, N1 * D)).preprocessing
        assert record is not None
        names[base] = record.instance_name
    key = names["Höhe-5µm.npy"].rsplit("-", 1)[1]
    assert names["Höhe-5µm.npy"] == f"file-Hohe-5um.npy-{key}"
    assert names["表面.npy"] != names["粗さ.npy"]
    assert all(n.isascii() and n.startswith("file-") and n.endswith(f"-{key}") for n in names.values()), names


def test_the_samples_provenance_states_the_shapes_and_spacings_they_load_with() -> None:
    """Each ``load_surface`` line of problems/data/PROVENANCE.md whose comment states a
    shape ("N0 x N1") and a spacing ("spacing L / N") loads with that shape and spacing."""
    import ast
    import re

    from tests.helpers import REPO

    text = (REPO / "problems" / "data" / "PROVENANCE.md").read_text(encoding="utf-8")
    lines = [ln for ln in text.splitlines() if ln.startswith("load_surface(") and "#" in ln]
    assert len(lines) >= 3
    for ln in lines:
        call, comment = ln.split("#", 1)
        node = ast.parse(call.strip(), mode="eval").body
        assert isinstance(node, ast.Call)
        path, *args = (ast.literal_eval(a) for a in node.args)
        kwargs = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = load_surface(REPO / path, *args, **kwargs)
        n0, n1 = (int(v) for v in re.search(r"(\d+) x (\d+)", comment).groups())
        assert s.shape == (n0, n1), ln
        spacing = re.search(r"spacing ([\d.e-]+) / (\d+)", comment)
        if spacing:
            assert s.spacing[0] == pytest.approx(float(spacing.group(1)) / int(spacing.group(2)), rel=1e-12), ln
