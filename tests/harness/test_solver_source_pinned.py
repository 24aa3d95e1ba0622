"""A results folder pins the source of each solver it ran from outside this package
(``registry.source_digest``): a rerun after the user edited the solver's file is refused in
one line, ``--append`` too, before anything runs -- the folder's rows were written by the
old code and would be kept as the edited solver's (a resume runs only missing cells)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from contactbench.solvers.registry import get_solver, source_digest, unregister
from tests.helpers import run_cli

SOLVER = """
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, Solver
BUG = {bug}
class Mine(Solver):
    name = "test-pinned-mine"
    family = "test"
    capabilities = Capabilities(needs_dense=True)
    def iterate(self, ctx):
        p = exact_solution(ctx.qp.H.to_dense(), ctx.qp.ubar).p
        return Outcome(p * (1.0 + BUG), 1, True)
"""


@pytest.fixture(autouse=True)
def no_module_left(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Each test imports its own ``pinned_mine`` and leaves neither it nor its solver."""
    monkeypatch.delitem(sys.modules, "pinned_mine", raising=False)
    yield
    sys.modules.pop("pinned_mine", None)
    unregister("test-pinned-mine", missing_ok=True)


def write_solver(folder: Path, bug: float) -> None:
    (folder / "pinned_mine.py").write_text(SOLVER.format(bug=bug), encoding="utf-8")


def run(out: Path, capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[int, str]:
    rc, _, err = run_cli(["run", "counterexample", "--size", "6", "--seeds", "0", "--reference", "none",
                          "--no-progress", "--no-warmup", "--out", str(out), "--solvers", "pinned_mine:Mine", *extra],
                         capsys)
    return rc, err


def test_an_edited_solver_is_not_resumed_as_the_code_that_wrote_the_rows(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "out"
    write_solver(tmp_path, 1e-3)
    rc, err = run(out, capsys)
    assert rc == 0, err
    rows = (out / "rows.jsonl").read_bytes()
    write_solver(tmp_path, 0.0)
    del sys.modules["pinned_mine"]  # (a new process would read the edited file)
    for extra in ((), ("--append",)):
        rc, err = run(out, capsys, *extra)
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and "'test-pinned-mine'" in lines[0] and "edited" in lines[0], err
        assert (out / "rows.jsonl").read_bytes() == rows
    rc, err = run(tmp_path / "elsewhere", capsys)
    assert rc == 0, err


def test_the_project_s_own_solvers_have_no_digest_and_an_outside_one_has_one(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    assert source_digest(get_solver("pk")) is None
    monkeypatch.syspath_prepend(str(tmp_path))
    write_solver(tmp_path, 0.0)
    import pinned_mine  # type: ignore[import-not-found]

    first = source_digest(pinned_mine.Mine())
    write_solver(tmp_path, 1.0)
    assert first is not None and source_digest(pinned_mine.Mine()) not in (None, first)
