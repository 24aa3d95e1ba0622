"""problems.export's memory: a dense H over the process's memory budget is refused in
one line (a ``ProblemInputError``, exit 2 from the CLI) before it is made, and a
qpbenchmark export holds one QP's P at a time, not every QP's."""

from __future__ import annotations

import tempfile
import tracemalloc
from pathlib import Path

import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.export import export_scene, problem_name, scene_steps
from contactbench.problems.export_plan import KEEP_SHARE
from contactbench.problems.operators import memory_budget_scope
from contactbench.problems.scenes import SceneConfig

#: Four QPs of n = 26, 106, 281, 557: the last one's H (2.4 MiB) is over a 1 MiB budget.
SWEEP = SceneConfig(size=64, steps=4)
BUDGET = 2**20
#: Eight QPs of n = 400 (a 1.2 MiB P each).
COUNTER = SceneConfig(size=20, seeds=tuple(range(8)))


def over_budget() -> tuple[str, int]:
    """(name, n) of the first QP of SWEEP whose dense H is over BUDGET."""
    return next((problem_name(i, k), inst.n) for i, k, inst in scene_steps("paper-sweep", SWEEP)
                if 8 * inst.n * inst.n > BUDGET)


@pytest.mark.parametrize("fmt", ["problem-dir", "hdf5", "qpbenchmark"])
def test_a_dense_H_over_the_memory_budget_is_refused_in_one_line(tmp_path: Path, fmt: str) -> None:
    if fmt == "hdf5":
        pytest.importorskip("h5py")
    name, n = over_budget()
    with memory_budget_scope(BUDGET), pytest.raises(ProblemInputError) as exc:
        export_scene("paper-sweep", SWEEP, fmt, tmp_path)
    text = str(exc.value)
    assert "\n" not in text and name in text and "memory budget" in text and f"--dense-limit below {n}" in text
    assert not list(tmp_path.glob("*.h5")) + list(tmp_path.glob("*.parquet"))  # whole or not at all
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_the_cli_refuses_it_with_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from contactbench.harness import cli

    name, _ = over_budget()
    argv = ["export", "paper-sweep", "--size", "64", "--steps", "4", "--format", "qpbenchmark", "--out",
            str(tmp_path / "ex")]
    with memory_budget_scope(BUDGET):
        code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("contactbench: error: the dense H of " + name), err


def test_a_qpbenchmark_export_holds_one_P_at_a_time(tmp_path: Path) -> None:
    """Peak traced memory of the export is that of building the QPs plus about one P and
    the instances its check keeps (``export_plan.KEEP_SHARE`` of the budget, here three
    QPs' H): 8 QPs of 1.2 MiB each, where holding every P would add 9.8 MiB."""
    with tempfile.TemporaryDirectory() as warm:  # imports (pandas, pyarrow) outside the measure
        export_scene("counterexample", SceneConfig(size=4, seeds=(0,)), "qpbenchmark", warm)
    tracemalloc.start()
    try:
        sizes = [inst.n for _, _, inst in scene_steps("counterexample", COUNTER)]
        build_peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.reset_peak()
        one_P = 8 * max(sizes) ** 2
        kept = 3 * one_P
        with memory_budget_scope(kept / KEEP_SHARE + 1):
            summary = export_scene("counterexample", COUNTER, "qpbenchmark", tmp_path)
        export_peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(summary.written) == len(sizes) == 8
    assert export_peak <= build_peak + kept + 2 * one_P, (export_peak / one_P, build_peak / one_P)


def test_a_grid_over_the_memory_budget_is_refused_before_any_surface_is_made(tmp_path: Path) -> None:
    """The largest recipe's instance (``scenes.base.instance_nbytes``: its grid arrays and
    spectra) over the budget is refused in one line naming it, nothing written: a 65537^2
    export had made a 32 GiB surface and died with a traceback."""
    out = tmp_path / "export"
    with memory_budget_scope(BUDGET), pytest.raises(ProblemInputError) as exc:
        export_scene("paper-sweep", SceneConfig(size=257, steps=2), "problem-dir", out)
    text = str(exc.value)
    assert "\n" not in text and "the export of paper-sweep" in text and "N = 257" in text and "memory budget" in text
    assert not out.exists()
