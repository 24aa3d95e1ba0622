"""A results folder that is safe to point at, and plans bounded before anything runs.

* a foreign non-empty folder is refused (exit 2, one line) and left untouched;
* a run of another configuration into a run folder is refused, naming the differences,
  unless ``--append``; meta.json and the report header then name every command;
* a folder written before the marker (meta.json + rows.jsonl) is resumed as before;
* a plan beyond ``--max-cells`` or the memory budget is refused from sizes and counts,
  before any instance or surface is built, and no lock or folder is left behind."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import read_meta
from contactbench.harness.run.plan import PlanError, RunConfig, plan_run
from contactbench.harness.report.core import ReportContext, header_section
from contactbench.harness import run_benchmark
from contactbench.harness.table.store import LOCK_FILE, MARKER_FILE, RunFolderError, RunLock, load_table
from contactbench.problems.scenes import SceneConfig, get_scene

SOLVER = "test-exact"
RUN = RunConfig(reference="none", warmup=False, progress=False)


def small(size: int = 8) -> SceneConfig:
    return SceneConfig(size=size, steps=2, seeds=(0,))


def snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


def cli_run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = cli.main(["run", *args, "--no-progress"])
    return code, capsys.readouterr().err


def test_a_foreign_folder_is_refused_and_left_untouched(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    foreign = tmp_path / "theirs"
    foreign.mkdir()
    (foreign / "results.csv").write_text("a,b\n1,2\n")
    (foreign / "meta.json").write_text('{"tool": "someone else"}')
    before = snapshot(foreign)
    code, err = cli_run(capsys, "paper-sweep", "--size", "8", "--solvers", SOLVER, "--out", str(foreign))
    assert code == 2
    assert err.count("\n") == 1 and str(foreign) in err and "not a contactbench run folder" in err
    assert snapshot(foreign) == before  # no lock file, no marker, nothing rewritten


def test_new_and_empty_folders_and_a_lone_lock_file_are_fine(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, empty, command=["pytest"])
    marker = json.loads((empty / MARKER_FILE).read_text())
    assert marker["format"] == 1 and len(marker["runs"]) == 1 and len(marker["runs"][0]["fingerprint"]) == 16
    locked = tmp_path / "lock-only"  # a run killed right after taking its lock (an empty lock file: no holder)
    locked.mkdir()
    (locked / LOCK_FILE).touch()
    run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, locked, command=["pytest"])
    assert not (locked / LOCK_FILE).exists() and len(load_table(locked)) == 2


def test_another_configuration_is_refused_unless_appended(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    common = ["paper-sweep", "--steps", "2", "--solvers", SOLVER, "--reference", "none", "--out", str(out)]
    assert cli_run(capsys, *common, "--size", "8")[0] == 0
    before = snapshot(out)
    code, err = cli_run(capsys, *common, "--size", "16")
    assert code == 2 and err.count("\n") == 1
    assert "scene_config.size: 8 in the folder, 16 in this run" in err and "--append" in err
    assert snapshot(out) == before
    assert cli_run(capsys, *common, "--size", "8", "--timeout", "5")[0] == 2  # a run setting counts too
    assert cli_run(capsys, *common, "--size", "16", "--append")[0] == 0
    assert sorted(load_table(out)["N"].unique()) == [8, 16]
    assert cli_run(capsys, *common, "--size", "16")[0] == 0  # each recorded configuration resumes without --append
    assert cli_run(capsys, *common, "--size", "8", "--jobs", "2")[0] == 0  # how it executes is not the configuration
    meta = read_meta(out)  # every distinct command that wrote to the folder, in order
    assert [c.split("--size ")[1] for c in meta["commands"]] == ["8 --no-progress", "16 --append --no-progress",
                                                                 "16 --no-progress", "8 --jobs 2 --no-progress"]
    header = header_section(ReportContext(out, load_table(out), meta))
    assert "| Commands |" in header and all(c in header for c in meta["commands"])


def test_a_measured_map_edited_between_two_runs_is_another_configuration(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The folder pins the maps' contents: the same command after one height of the file
    changed is refused (naming the hash), and resumes while the file holds what it held."""
    import numpy as np

    heights = np.random.default_rng(1).normal(size=(16, 16)) * 1e-6
    np.save(tmp_path / "s.npy", heights)
    out = tmp_path / "run"
    common = ["paper-sweep", "--surface", str(tmp_path / "s.npy"), "--length", "1e-4", "--steps", "2",
              "--solvers", SOLVER, "--reference", "none", "--out", str(out)]
    assert cli_run(capsys, *common)[0] == 0
    assert cli_run(capsys, *common)[0] == 0  # the same map: resumed
    before = snapshot(out)
    heights[3, 3] += 1e-7
    np.save(tmp_path / "s.npy", heights)
    code, err = cli_run(capsys, *common)
    assert code == 2 and err.count("\n") == 1 and "surface_sha256" in err and "--append" in err
    assert snapshot(out) == before
    assert cli_run(capsys, *common, "--append")[0] == 0
    assert load_table(out)["instance"].nunique() == 2
    records = read_meta(out)["surface_preprocessing"]  # each map's record, the first one's too
    assert sorted(records) == sorted(f"paper-sweep/{i}" for i in load_table(out)["instance"].unique())


def test_one_map_file_spelled_another_way_resumes_the_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A relative path, the absolute one and a link to the file name one map (docs/problems.md):
    each resumes the folder the first wrote, adding nothing."""
    import numpy as np

    np.save(tmp_path / "s.npy", np.random.default_rng(2).normal(size=(16, 16)) * 1e-6)
    (tmp_path / "link.npy").symlink_to(tmp_path / "s.npy")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "run"
    common = ["paper-sweep", "--length", "1e-4", "--steps", "2", "--solvers", SOLVER, "--reference", "none",
              "--out", str(out)]
    assert cli_run(capsys, *common, "--surface", "s.npy")[0] == 0
    rows = len(load_table(out))
    for spelling in (str(tmp_path / "s.npy"), "./link.npy"):
        code, err = cli_run(capsys, *common, "--surface", spelling)
        assert code == 0 and len(load_table(out)) == rows, (spelling, err)


def test_a_default_written_out_resumes_the_folder_written_without_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An option that only spells out the scene's default (--kernel bcc, --operator fft,
    --length 1e-4, --E 1e9, the study's own --profile) is the same configuration: it resumes
    the folder a run without it wrote, and the other way round; another value is still
    another configuration."""
    plain, spelled = tmp_path / "plain", tmp_path / "spelled"
    common = ["paper-sweep", "--size", "8", "--steps", "2", "--solvers", SOLVER, "--reference", "none"]
    defaults = ["--kernel", "bcc", "--operator", "fft", "--length", "1e-4", "--E", "1e9", "--seeds", "5"]
    assert cli_run(capsys, *common, "--out", str(plain))[0] == 0
    profiles = sorted(set(load_table(plain)["profile"]))
    spell = [*defaults, "--profile", ",".join(profiles)]
    code, err = cli_run(capsys, *common, *spell, "--out", str(plain))
    assert code == 0, err
    assert len(load_table(plain)) == 2 * len(profiles)  # nothing new was solved
    assert cli_run(capsys, *common, *spell, "--out", str(spelled))[0] == 0
    assert cli_run(capsys, *common, "--out", str(spelled))[0] == 0
    before = snapshot(plain)
    code, err = cli_run(capsys, *common, "--kernel", "love", "--out", str(plain))
    assert code == 2 and "scene_config.kernel" in err
    assert snapshot(plain) == before


def test_a_folder_written_before_the_marker_is_resumed(tmp_path: Path) -> None:
    out = tmp_path / "old"
    run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    (out / MARKER_FILE).unlink()
    rows = (out / "rows.jsonl").read_text().splitlines(keepends=True)
    (out / "rows.jsonl").write_text(rows[0])  # interrupted after one row
    with pytest.raises(RunFolderError, match="scene_config.size"):
        run_benchmark(["paper-sweep"], small(16), [SOLVER], RUN, out, command=["pytest"])
    assert not (out / MARKER_FILE).exists()
    summary = run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    assert summary.new_rows == 1 and (out / MARKER_FILE).exists()


def test_a_folder_with_only_some_rows_and_no_meta_is_foreign(tmp_path: Path) -> None:
    out = tmp_path / "half"
    out.mkdir()
    (out / "rows.jsonl").write_text('{"cell_id": "x"}\n')
    with pytest.raises(RunFolderError, match="not a contactbench run folder"):
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    (out / "meta.json").write_text('{"command": "not a list", "config": {}}')
    with pytest.raises(RunFolderError, match="not a contactbench run folder"):
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "rows.jsonl"]


def test_an_unreadable_marker_and_a_file_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "bad"
    out.mkdir()
    (out / MARKER_FILE).write_text("{not json")
    with pytest.raises(RunFolderError, match="cannot be read"):
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    for bad in ({"format": 1, "runs": "all"}, {"format": 1, "runs": [1]}, {"runs": []}, [1]):
        (out / MARKER_FILE).write_text(json.dumps(bad))
        with pytest.raises(RunFolderError, match="cannot be read"):
            run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    (out / MARKER_FILE).write_text(json.dumps({"format": 99, "runs": []}))
    with pytest.raises(RunFolderError, match="newer contactbench"):
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(RunFolderError, match="is not a folder"):
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, afile, command=["pytest"])


def test_a_caller_holding_the_lock_can_run(tmp_path: Path) -> None:
    out = tmp_path / "held"
    with RunLock(out):  # (scripts and the pytest plugin wrap the run in the folder's lock)
        run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, out, command=["pytest"])
    assert not (out / LOCK_FILE).exists() and len(load_table(out)) == 2


# ---------------------------------------------------------------------------
# Bounded plans
# ---------------------------------------------------------------------------


@pytest.fixture
def no_building(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any surface generation or validation of the huge plans fails the test."""
    for name in ("paper-sweep", "hertz", "population"):
        scene = type(get_scene(name))

        def refuse(self: object, *a: object, **k: object) -> None:
            raise AssertionError("the plan built or validated instances before bounding itself")

        monkeypatch.setattr(scene, "validate", refuse)
        monkeypatch.setattr(scene, "build", refuse)


@pytest.mark.parametrize(("scene", "cfg", "expect"), [
    ("paper-sweep", SceneConfig(seeds=range(0, 100_000_001)), "the plan has 1,000,000,010 cells"),
    ("paper-sweep", SceneConfig(steps=1_000_000_000), "the plan has 1,000,000,000 cells"),
    ("population", SceneConfig(steps=1_000_000_000, seeds=range(0, 1000)), "cells"),
    ("hertz", SceneConfig(size=100_000), "(N = 100000) needs at least 894 GiB, over the memory budget of 8 GiB"),
])
def test_huge_plans_are_refused_from_counts_alone(no_building: None, scene: str, cfg: SceneConfig,
                                                   expect: str) -> None:
    run = RunConfig(memory_budget=8 * 2**30)
    with pytest.raises(PlanError) as info:
        plan_run([scene], cfg, ["pk"], run)
    assert expect in str(info.value) and str(info.value).count("\n") == 0


def test_the_cell_estimate_is_exact_and_the_limit_can_be_raised() -> None:
    cfg = SceneConfig(size=8, steps=5, seeds=range(3, 7))  # estimated from 2-3 steps x 1-2 seeds
    plan = plan_run(["paper-sweep"], cfg, ["pk", SOLVER], RunConfig(profiles=("default", "low")))
    assert plan.n_cells(1) == 4 * 5 * 2 * 2
    with pytest.raises(PlanError, match="the plan has 80 cells .*over the limit of 79"):
        plan_run(["paper-sweep"], cfg, ["pk", SOLVER], RunConfig(profiles=("default", "low"), max_cells=79))
    assert plan_run(["paper-sweep"], cfg, ["pk", SOLVER], RunConfig(profiles=("default", "low"), max_cells=80)).jobs
    pop = SceneConfig(steps=7, seeds=range(0, 5))  # 3 Hurst exponents x 5 seeds, 7 separations each
    assert plan_run(["population"], pop, ["pk"], RunConfig()).n_cells(1) == 3 * 5 * 7


def test_cli_refusals_leave_no_folder_and_no_lock(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for args in (["paper-sweep", "--seeds", "0-100000000"], ["paper-sweep", "--steps", "1000000000"],
                 ["hertz", "--size", "100000"], ["paper-sweep", "--size", "64", "--max-cells", "5"]):
        out = tmp_path / "out"
        code, err = cli_run(capsys, *args, "--solvers", "pk", "--out", str(out))
        assert code == 2 and err.startswith("contactbench: error:") and err.count("\n") == 1, err
        assert not out.exists()
    existing = tmp_path / "existing"
    run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, existing, command=["pytest"])
    before = snapshot(existing)
    code, _ = cli_run(capsys, "hertz", "--size", "100000", "--out", str(existing))
    assert code == 2 and snapshot(existing) == before and not (existing / LOCK_FILE).exists()


def test_parse_seeds_is_lazy_for_one_range() -> None:
    seeds = cli.parse_seeds("0-100000000")
    assert isinstance(seeds, range) and len(seeds) == 100_000_001
    assert cli.parse_seeds("0-2,7,1") == (0, 1, 2, 7)
    assert tuple(cli.parse_seeds("3")) == (3,)
    for bad in ("5-2", "-1", "a", "", "0-5,7-100000000"):
        with pytest.raises(Exception):
            cli.parse_seeds(bad)


def test_a_lazy_seed_range_runs_like_a_tuple(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    run_benchmark(["paper-sweep"], SceneConfig(size=8, steps=1, seeds=range(0, 2)), [SOLVER], RUN, a, command=["t"])
    shutil.copytree(a, b)
    summary = run_benchmark(["paper-sweep"], SceneConfig(size=8, steps=1, seeds=(0, 1)), [SOLVER], RUN, b,
                            command=["t"])
    assert summary.new_rows == 0  # the same configuration: a resume with nothing left to do


def test_the_header_says_the_threads_each_solve_was_held_to(tmp_path: Path) -> None:
    """--threads 1 holds every solve worker's BLAS and FFT threads to 1: the header says so
    beside the parent's thread record; a run that held nothing adds no such line."""
    from dataclasses import replace

    held, free = tmp_path / "held", tmp_path / "free"
    run_benchmark(["paper-sweep"], small(), [SOLVER], replace(RUN, threads_per_worker=1), held, command=["pytest"])
    run_benchmark(["paper-sweep"], small(), [SOLVER], RUN, free, command=["pytest"])
    text = header_section(ReportContext(held, load_table(held), read_meta(held)))
    assert "| Threads of each solve | 1 (" in text
    assert "Threads of each solve" not in header_section(ReportContext(free, load_table(free), read_meta(free)))
