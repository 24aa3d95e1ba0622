"""Deterministic resume: an interrupted and resumed run has the same cells, statuses and
skip reasons as an uninterrupted one.

Solve times come from a fake clock: the solvers below advance it by a cost of n, and
the worker's ``time`` is replaced by it (the isolated workers are forked from this
process, so they inherit the replacement), so every time-based decision is a function
of n alone -- no assertion depends on the wall clock.  Interruptions are simulated by
cutting the journal after k rows (what Ctrl-C or kill -9 leaves), and by a torn last
line (what a kill mid-write leaves)."""

from __future__ import annotations

import json
import os
import shutil
import types
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.run import worker
from contactbench.harness.run.plan import RunConfig, StoredCell
from contactbench.harness import run_benchmark
from contactbench.harness.run.skips import SkipPolicy
from contactbench.harness.table.store import ROWS_FILE, ResultStore, load_table
from contactbench.problems.scenes import SceneConfig
from contactbench.solvers import Outcome, SolveContext, register
from contactbench.solvers.base import ProblemTraits
from tests.helpers import ExactStub

#: paper-sweep at 32^2 with 6 steps: trial sets n = 2, 5, 7, 16, 33, 55.
CFG = SceneConfig(size=32, steps=6, seeds=(0,))
RUN = RunConfig(timeout=1.0, reference="none", warmup=False, progress=False)
SOLVERS = ["fake-steady", "fake-growing", "fake-late-timeout"]
CLOCK = [1000.0]
FAKE_TIME = types.SimpleNamespace(perf_counter=lambda: CLOCK[0])


class FakeCost(ExactStub):
    """The exact dense solver, whose solve "takes" ``cost(n)`` seconds on the fake clock."""

    def cost(self, n: int) -> float:
        raise NotImplementedError

    def iterate(self, ctx: SolveContext) -> Outcome:
        CLOCK[0] += self.cost(ctx.n)
        return super().iterate(ctx)


@register(replace=True)
class Steady(FakeCost):
    """Fast along the sequence; its static time model calls every n > 6 hopeless, so a
    resume that forgot the earlier steps would skip it."""

    name = "fake-steady"

    def cost(self, n: int) -> float:
        return 1e-3 * n

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return 1e6 if n > 6 else None


@register(replace=True)
class Growing(FakeCost):
    """Time ~ n^2: predicted under the limit at n = 33 (0.76 s: step 2 is too short to
    measure the exponent, so n^1.5), it takes 1.09 s (a timeout); the prediction from
    step 3 passes the limit at n = 55 (a skip)."""

    name = "fake-growing"

    def cost(self, n: int) -> float:
        return 1e-3 * n * n


@register(replace=True)
class LateTimeout(FakeCost):
    """Predicted fine from its small steps, then over the limit at n = 16: a timeout, and
    the larger steps skipped for it."""

    name = "fake-late-timeout"

    def cost(self, n: int) -> float:
        return 0.05 if n < 16 else 2.0


def cells(out: Path) -> pd.DataFrame:
    df = load_table(out)
    return df.set_index("cell_id")[["step", "solver", "status", "skip_reason"]].sort_index()


@pytest.fixture
def fake_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(worker, "time", FAKE_TIME)


@pytest.fixture
def uninterrupted(tmp_path: Path, fake_clock: None) -> Path:
    out = tmp_path / "whole"
    run_benchmark(["paper-sweep"], CFG, SOLVERS, RUN, out, command=["pytest"])
    return out


def test_the_uninterrupted_run_has_time_based_skips(uninterrupted: Path) -> None:
    df = cells(uninterrupted)
    assert len(df) == 6 * len(SOLVERS)
    by = {s: list(g.sort_values("step")["status"]) for s, g in df.groupby("solver")}
    assert by["fake-steady"] == ["solved"] * 6
    assert by["fake-growing"] == ["solved"] * 4 + ["timeout", "skipped"]
    assert by["fake-late-timeout"] == ["solved"] * 3 + ["timeout"] + ["skipped"] * 2
    reasons = df[df.status == "skipped"].set_index(["solver", "step"])["skip_reason"]
    assert reasons[("fake-growing", 5)].startswith("predicted solve time 1.63 s at n = 55 from 0.256 s at n = 16")
    assert "timed out at step 3" in reasons[("fake-late-timeout", 4)]
    assert "predicted solve time 1.1 s at n = 55 from 0.05 s at n = 7" in reasons[("fake-late-timeout", 5)]


def interrupted_copy(src: Path, dst: Path, keep_rows: int, torn: bool = False) -> None:
    """``dst`` = ``src`` as an interruption after ``keep_rows`` journal rows leaves it
    (and, with ``torn``, half of the next row: a kill mid-write)."""
    shutil.copytree(src, dst)
    lines = (dst / ROWS_FILE).read_text(encoding="utf-8").splitlines(keepends=True)
    text = "".join(lines[:keep_rows]) + (lines[keep_rows][: len(lines[keep_rows]) // 2] if torn else "")
    (dst / ROWS_FILE).write_text(text, encoding="utf-8")
    for name in ("results.parquet", "results.csv"):
        (dst / name).unlink()


@pytest.mark.parametrize(("keep_rows", "torn"), [(2, False), (8, False), (13, False), (10, True)])
def test_resume_after_an_interruption_gives_the_same_cells(uninterrupted: Path, tmp_path: Path, keep_rows: int,
                                                           torn: bool) -> None:
    out = tmp_path / f"cut-{keep_rows}"
    interrupted_copy(uninterrupted, out, keep_rows, torn)
    CLOCK[0] += 12345.678  # the resumed run's clock is elsewhere: only differences may matter
    summary = run_benchmark(["paper-sweep"], CFG, SOLVERS, RUN, out, command=["pytest"])
    assert summary.new_rows == 6 * len(SOLVERS) - keep_rows
    pd.testing.assert_frame_equal(cells(out), cells(uninterrupted))


def test_stored_cells_read_nan_null_and_text_as_unknown() -> None:
    row = {"step": 3, "solver": "s", "profile": "default", "n": None, "status": "failed", "solve_time_s": float("nan")}
    cell = StoredCell.of(row)
    assert (cell.n, cell.seconds) == (None, None)
    assert StoredCell.of({**row, "n": "x", "solve_time_s": float("inf")}).n is None
    assert StoredCell.of({**row, "n": 12.0, "solve_time_s": 0.5}) == StoredCell(3, "s", "default", 12, "failed", 0.5)
    policy = SkipPolicy(1.0, 2**30)
    policy.note(("s", "default"), 0, None, "timeout", float("nan"))  # a row of a step that was never built
    assert policy.first_timeout(("s", "default"), 5) is None


def test_policy_reads_only_earlier_steps_whatever_the_order_rows_arrive() -> None:
    traits = ProblemTraits(n=55, operator="dense")
    rows = [(0, 2, "solved", 0.004), (1, 5, "solved", 0.025), (2, 7, "solved", 0.06), (3, 16, "solved", 0.256),
            (5, 55, "timeout", 9.0)]
    forward, backward = SkipPolicy(1.0, 2**30), SkipPolicy(1.0, 2**30)
    for row in rows:
        forward.note(("fake-growing", "default"), *row)
    for row in reversed(rows):
        backward.note(("fake-growing", "default"), *row)
    for policy in (forward, backward):
        d = policy.decide("fake-growing", ("fake-growing", "default"), traits, step=4)
        assert d.skip and "from 0.256 s at n = 16" in d.reason  # steps 2 and 3; the step-5 timeout is later
        small = ProblemTraits(n=16, operator="dense")
        assert not policy.decide("fake-growing", ("fake-growing", "default"), small, step=3).skip
    assert forward.observations(("fake-growing", "default"), 4) == [(7, 0.06), (16, 0.256)]
    assert forward.first_timeout(("fake-growing", "default"), 6).step == 5


@pytest.mark.parametrize("solvers", [["pk", "nnls", "bvls"], ["nnls", "gp", "admm"]],
                         ids=["exact-solvers-left", "no-exact-solver-left"])
def test_a_resumed_step_keeps_the_reference_its_first_answer_served(tmp_path: Path, solvers: list[str]) -> None:
    """The run's own exact answer serves as a step's reference, and its row comes first.  A
    run interrupted just after that row finds the stored answer on resume (it is no longer
    among the solvers to run, and the others may not be exact), so every row of the step is
    measured against the same reference as in the uninterrupted run."""
    cfg = SceneConfig(size=16, steps=2, seeds=(0,))
    run = RunConfig(reference="auto", warmup=False, progress=False)
    whole = tmp_path / "whole"
    run_benchmark(["paper-sweep"], cfg, solvers, run, whole, command=["pytest"])
    first = load_table(whole)
    order = [(r["step"], r["solver"]) for r in map(json.loads, (whole / ROWS_FILE).read_text().splitlines())]
    served = first.set_index(["step", "solver"])["reference_solver"]
    server = served[order[len(solvers)]].split("@")[0]  # the server of step 1 runs first there
    assert order[len(solvers)] == (1, server)
    out = tmp_path / "cut"
    interrupted_copy(whole, out, len(solvers) + 1)  # step 0, and the server's row of step 1
    run_benchmark(["paper-sweep"], cfg, solvers, run, out, command=["pytest"])
    again = load_table(out).set_index(["step", "solver"]).sort_index()
    before = first.set_index(["step", "solver"]).sort_index()
    assert (again["reference_solver"] == before["reference_solver"]).all(), again["reference_solver"]
    assert (again.loc[1, "reference_solver"] == f"{server}@default").all()
    pd.testing.assert_series_equal(again["p_rel_error"], before["p_rel_error"], rtol=1e-6, atol=1e-15)


@register(replace=True)
class LoggedExact(ExactStub):
    """The exact solver, warm-startable, logging each solve's start ("cold" / "warm") to the
    file ``SOLVE_LOG`` names (the run's workers are other processes)."""

    name = "fake-logged"
    capabilities = replace(ExactStub.capabilities, warm_start="primal")

    def iterate(self, ctx: SolveContext) -> Outcome:
        with open(os.environ[SOLVE_LOG], "a", encoding="utf-8") as fh:
            fh.write(f"{ctx.n} {'warm' if ctx.warm else 'cold'}\n")
        return super().iterate(ctx)


SOLVE_LOG = "CONTACTBENCH_TEST_SOLVE_LOG"


def run_cut_after(rows: int, monkeypatch: pytest.MonkeyPatch, *args: object) -> None:
    """``run_benchmark(*args)`` interrupted by Ctrl-C just after its ``rows``-th row."""
    append, written = ResultStore.append, [0]

    def interrupted_after(store: ResultStore, row: dict[str, object]) -> None:
        append(store, row)
        written[0] += 1
        if written[0] == rows:
            raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(ResultStore, "append", interrupted_after)
        with pytest.raises(KeyboardInterrupt):
            run_benchmark(*args)  # type: ignore[arg-type]


@pytest.mark.parametrize("keep_rows", [1, 3, 4])
def test_a_resumed_run_starts_from_the_kept_answer_not_a_re_solve(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, keep_rows: int) -> None:
    """The answer a next step starts from is kept in the run's cache folder until that step
    is recorded: the resumed run solves only its missing cells, each warm from the first
    run's answer (the previous step was re-solved from p = 0 before, so its start, and the
    digits after it, were another run's).  The kept answers are removed once the job is done."""
    cfg = SceneConfig(size=32, steps=5, seeds=(0,))
    run = RunConfig(reference="none", warmup=False, progress=False)
    log = tmp_path / "solves.log"
    monkeypatch.setenv(SOLVE_LOG, str(log))
    args = (["paper-sweep"], cfg, ["fake-logged"], run, tmp_path / "cut", ["pytest"])
    run_cut_after(keep_rows, monkeypatch, *args)
    kept = next((tmp_path / "cut" / "_cache").glob("warm-*.npz"))
    part = kept.with_name(f".{kept.name}.999999.0123456789ab.tmp")  # what a write cut by a kill leaves
    part.write_bytes(b"half")
    log.unlink()
    run_benchmark(*args)  # type: ignore[arg-type]
    starts = [line.split()[1] for line in log.read_text().splitlines()]
    assert starts == ["warm"] * (5 - keep_rows)  # no cold re-solve of the previous step
    assert len(load_table(tmp_path / "cut")) == 5
    assert not any((tmp_path / "cut" / "_cache").glob("warm-*.npz")) and not part.exists()


def test_a_kept_answer_that_cannot_be_written_or_removed_costs_no_row(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Where a kept answer cannot be written or removed (a folder in its place, as a full or
    read-only disk would refuse it), the solve's row stands and the run goes on: a solved
    cell was recorded failed, and the run ended with exit 2, before."""
    cfg = SceneConfig(size=32, steps=5, seeds=(0,))
    run = RunConfig(reference="none", warmup=False, progress=False)
    monkeypatch.setenv(SOLVE_LOG, str(tmp_path / "solves.log"))
    args = (["paper-sweep"], cfg, ["fake-logged"], run, tmp_path / "cut", ["pytest"])
    run_cut_after(1, monkeypatch, *args)
    (first,) = (tmp_path / "cut" / "_cache").glob("warm-*-k0.npz")
    for k in range(5):
        Path(str(first).replace("-k0.npz", f"-k{k}.npz")).unlink(missing_ok=True)
        Path(str(first).replace("-k0.npz", f"-k{k}.npz")).mkdir()
    run_benchmark(*args)  # type: ignore[arg-type]
    rows = load_table(tmp_path / "cut")
    assert len(rows) == 5 and (rows["status"] == "solved").all()


@pytest.mark.parametrize("damage", ["truncated", "another step's", "not finite"])
def test_a_kept_answer_that_cannot_be_read_is_re_solved_not_trusted(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, damage: str) -> None:
    """A kept answer that is cut short, holds another step's answer or a non-finite one is
    not a warm start: the previous step is re-solved from p = 0, and every row is solved."""
    cfg = SceneConfig(size=32, steps=4, seeds=(0,))
    run = RunConfig(reference="none", warmup=False, progress=False)
    log = tmp_path / "solves.log"
    monkeypatch.setenv(SOLVE_LOG, str(log))
    args = (["paper-sweep"], cfg, ["fake-logged"], run, tmp_path / "cut", ["pytest"])
    run_cut_after(2, monkeypatch, *args)
    (kept,) = (tmp_path / "cut" / "_cache").glob("warm-*-k1.npz")
    if damage == "truncated":
        kept.write_bytes(kept.read_bytes()[:40])
    else:
        with np.load(kept) as f:
            items = dict(f)
        if damage == "another step's":
            items["step"] = np.int64(0)
        else:
            items["values"] = np.full_like(items["values"], np.nan)
        np.savez(kept, **items)
    log.unlink()
    run_benchmark(*args)  # type: ignore[arg-type]
    assert [line.split()[1] for line in log.read_text().splitlines()] == ["cold", "warm", "warm"]
    assert (load_table(tmp_path / "cut")["status"] == "solved").all()


@pytest.mark.parametrize("keep_rows", [4, 7, 10])
def test_a_resumed_run_of_the_fast_solvers_matches_the_uninterrupted_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, keep_rows: int) -> None:
    """Interrupted after ``keep_rows`` rows and resumed, three warm-started solvers end each
    step as the uninterrupted run did: the same products, to one iteration (the operator's
    caches, which the solvers share in a worker, differ after a restart: rounding, not
    another start), and errors and loads to 1e-6."""
    cfg = SceneConfig(size=64, steps=5, seeds=(0,))
    run = RunConfig(reference="none", warmup=False, progress=False)
    solvers = ["fast-dual-pccg", "fast-ccg", "pk"]
    run_benchmark(["paper-sweep"], cfg, solvers, run, tmp_path / "whole", command=["pytest"])
    args = (["paper-sweep"], cfg, solvers, run, tmp_path / "cut", ["pytest"])
    run_cut_after(keep_rows, monkeypatch, *args)
    run_benchmark(*args)  # type: ignore[arg-type]
    whole, cut = (load_table(tmp_path / d).set_index(["solver", "step"]).sort_index() for d in ("whole", "cut"))
    assert (cut["status"] == "solved").all() and len(cut) == 15
    assert ((cut["iterations"] - whole["iterations"]).abs() <= 1).all()
    for col in ("kkt_error", "load"):
        pd.testing.assert_series_equal(cut[col], whole[col], rtol=1e-6 if col == "load" else 1e-2, atol=0.0)
