"""A stored reference answer the run cannot read as its step's -- cut short, another
step's, not finite, a link -- is no reference (``worker.read_reference``): the solves of
that step are judged, never failed by a harness error put on their rows, and the
reference is computed again where it is asked."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.judging import judge
from contactbench.harness.run.worker import read_reference
from contactbench.problems.scenes import SceneConfig, get_scene
from tests.helpers import run_cli


def test_read_reference_reads_only_a_step_s_own_finite_answer(tmp_path: Path) -> None:
    good = tmp_path / "good.npz"
    np.savez(good, p=np.arange(5.0))
    assert np.array_equal(read_reference(str(good), 5), np.arange(5.0))
    assert read_reference(str(good), 4) is None  # another step's length
    nan = tmp_path / "nan.npz"
    np.savez(nan, p=np.array([1.0, np.nan]))
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:40])
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, p=np.array([{"a": 1}], dtype=object))
    nokey = tmp_path / "nokey.npz"
    np.savez(nokey, q=np.arange(5.0))
    link = tmp_path / "link.npz"
    os.symlink(good, link)
    for path, n in ((nan, 2), (empty, 5), (cut, 5), (pickled, 1), (nokey, 5), (link, 5), (tmp_path / "none.npz", 5)):
        assert read_reference(str(path), n) is None, path
    folder = tmp_path / "folder.npz"
    folder.mkdir()
    assert read_reference(str(folder), 5) is None


#: A small run of two exact solvers whose references the tests below spoil.
RUN = ["run", "paper-sweep", "--size", "16", "--steps", "3", "--solvers", "pk,nnls", "--no-progress", "--no-warmup"]


def rerun_with_spoiled_references(tmp_path: Path, capsys: pytest.CaptureFixture[str], step: int,
                                  spoil: Callable[[Path, Path], None]) -> pd.DataFrame:
    """Run ``RUN``, ``spoil(reference file, out)`` every stored reference of ``step``, drop
    that step's rows from the journal, run again (a resume), and return the step's rows."""
    out = tmp_path / "out"
    args = [*RUN, "--out", str(out)]
    rc, _, err = run_cli(args, capsys)
    assert rc == 0, err
    refs = sorted((out / "_cache").glob(f"ref-*-k{step}-*.npz"))
    assert refs
    for ref in refs:
        spoil(ref, out)
    journal = out / "rows.jsonl"
    kept = [line for line in journal.read_text().splitlines() if json.loads(line).get("step") != step]
    journal.write_text("".join(line + "\n" for line in kept))
    for name in ("results.parquet", "results.csv"):
        (out / name).unlink(missing_ok=True)
    rc, _, err = run_cli(args, capsys)
    assert rc == 0, err
    top = pd.read_csv(out / "results.csv").query(f"step == {step}")
    assert len(top) == 2 and set(top["status"]) == {"solved"}, top[["solver", "status", "error"]]
    return top


def test_a_wrong_stored_reference_is_computed_again_not_charged_to_the_solvers(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    def another_steps(ref: Path, out: Path) -> None:  # step 0's answer, of another length
        ref.write_bytes(sorted((out / "_cache").glob("ref-*-k0-*.npz"))[0].read_bytes())

    top = rerun_with_spoiled_references(tmp_path, capsys, 2, another_steps)
    assert top["error"].isna().all()


def test_a_stored_reference_of_wrong_values_is_not_trusted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file of the step's own length whose answer is wrong (its stored kkt_error says 0)
    is judged on the step, found not solved, and computed again: the rows' error in p is
    measured against the true answer, not the file's."""
    def doubled(ref: Path, out: Path) -> None:  # the right length, twice the answer
        with np.load(ref) as data:
            p = np.asarray(data["p"])
        np.savez(ref, p=2.0 * p, solver="pk", kkt_error=0.0, time=0.0)

    top = rerun_with_spoiled_references(tmp_path, capsys, 2, doubled)
    assert (top["p_rel_error"] < 1e-3).all(), top[["solver", "p_rel_error"]]


def test_a_resumed_run_takes_no_looser_served_reference_than_a_fresh_one(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A run's own answer stored as the reference at profile default (check 1e-6) does not
    serve the rows of profile high (check 1e-8) that ``--append`` adds: a fresh run at both
    profiles would have asked 1e-8 of it (``JobDriver.served_max_kkt``)."""
    scene = get_scene("paper-sweep")
    (spec,) = scene.instances(scene.config(SceneConfig(size=16, steps=2)))
    inst = spec.build().at(1)
    scale = {}

    def loosened(ref: Path, out: Path) -> None:  # scaled until the judge reads its kkt in (1e-8, 1e-6]
        with np.load(ref) as data:
            p = np.asarray(data["p"])
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if judge(inst, p * (1 + mid), True, 5e-7).status == "solved" else (lo, mid)
        scale[ref.name] = lo
        np.savez(ref, p=p * (1 + lo), solver="pk", kkt_error=0.0, time=0.0)

    out = tmp_path / "out"
    run = [*RUN[:5], "2", *RUN[6:], "--profile", "default", "--out", str(out)]
    rc, _, err = run_cli(run, capsys)
    assert rc == 0, err
    for ref in sorted((out / "_cache").glob("ref-*-k1-*.npz")):
        loosened(ref, out)
    assert scale and all(x > 0 for x in scale.values())
    rc, _, err = run_cli([*run[:-4], "--profile", "default,high", "--append", "--out", str(out)], capsys)
    assert rc == 0, err
    high = pd.read_csv(out / "results.csv").query("step == 1 and profile == 'high'")
    assert len(high) == 2 and (high["p_rel_error"] < 0.1 * min(scale.values())).all(), \
        high[["solver", "reference_solver", "p_rel_error"]]
