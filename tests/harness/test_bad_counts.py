"""A solve's own account -- its product count, its set-up and solve times -- is one a
results table can hold, or the row fails naming it: the lifecycle refuses a count or a time
no table holds (``add_matvecs``, ``add_setup_time``, ``finish``), the worker and validate
the same in a result of a solver that takes over ``solve``, and the journal stores a row
that would not read back as a failed row saying why -- never as given, so a folder is never
left that no command reads."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.run.worker import SolverFacts
from contactbench.harness.table.journal import encode_row
from contactbench.harness.table.store import ResultStore
from contactbench.problems.instances import counterexample
from contactbench.problems.lcp import exact_solution
from contactbench.solvers import Capabilities, Outcome, SolveContext, SolveResult, Solver
from contactbench.solvers.base import SolverReturnError

HERE = __name__  # the import path of the solvers below


def _exact(ctx: SolveContext) -> np.ndarray:
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


def _restricted_set_back(ctx: SolveContext) -> None:
    sub = ctx.restricted(np.arange(ctx.n), None)
    sub.qp.H.matvec(np.ones(ctx.n))
    sub.qp.H.matvec_count = -50


class TwoFaced(int):
    """An int that says 5 but converts to -7: the count a table would store is not the one checked."""

    def __int__(self) -> int:
        return -7

    def __index__(self) -> int:
        return -7


def _clock_moved(ctx: SolveContext) -> None:
    ctx.trace.t0 = math.nan


#: What a solve does to its own account, and the field the refusal names.
LIES: dict[str, tuple[Callable[[SolveContext], None], str]] = {
    "negative-matvecs": (lambda ctx: ctx.add_matvecs(-999), "add_matvecs(-999)"),
    "huge-matvecs": (lambda ctx: ctx.add_matvecs(2**70), "add_matvecs(1180591620717411303424)"),
    "float-matvecs": (lambda ctx: ctx.add_matvecs(2.7), "add_matvecs(2.7)"),
    "nan-matvecs": (lambda ctx: ctx.add_matvecs(math.nan), "add_matvecs(nan)"),
    "bool-matvecs": (lambda ctx: ctx.add_matvecs(True), "add_matvecs(True)"),
    "summed-matvecs": (lambda ctx: [ctx.add_matvecs(2**62) for _ in range(2)], "add up to"),
    "set-back-matvecs": (_restricted_set_back, "add up to"),
    "negative-setup": (lambda ctx: ctx.add_setup_time(-100.0), "add_setup_time(-100.0)"),
    "nan-setup": (lambda ctx: ctx.add_setup_time(math.nan), "add_setup_time(nan)"),
    "inf-setup": (lambda ctx: ctx.add_setup_time(math.inf), "add_setup_time(inf)"),
    "text-setup": (lambda ctx: ctx.add_setup_time("1"), "add_setup_time('1')"),
    "setup-beyond-solve": (lambda ctx: ctx.add_setup_time(1e9), "setup_time is"),
    "setup-set-nan": (lambda ctx: setattr(ctx, "setup_time", math.nan), "setup_time is nan"),
    "clock-moved": (_clock_moved, "solve_time is nan"),
    "int-that-converts-to-another": (lambda ctx: ctx.add_matvecs(TwoFaced(5)), "add_matvecs(5)"),
}


class Liar(Solver):
    """Answers right, claimed, after doing ``lie`` to its own account."""

    name = "test-account-liar"
    family = "test"
    capabilities = Capabilities(needs_dense=False)
    lie: Callable[[SolveContext], None] = staticmethod(lambda ctx: None)

    def iterate(self, ctx: SolveContext) -> Outcome:
        type(self).lie(ctx)
        return Outcome(_exact(ctx), 1, True)


class NegativeMatvecs(Liar):
    name = "test-account-negative-matvecs"
    lie = staticmethod(LIES["negative-matvecs"][0])


class NanSetup(Liar):
    name = "test-account-nan-setup"
    lie = staticmethod(LIES["nan-setup"][0])


class TakesOverSolve(Liar):
    """Bypasses the lifecycle's check: its ``solve`` hands back counts no table holds."""

    name = "test-account-takes-over-solve"

    def solve(self, qp: Any, settings: Any = None, warm: Any = None) -> SolveResult:
        res = super().solve(qp, settings, warm)
        res.matvecs, res.iterations, res.setup_time = -7, -3, math.inf
        return res


@pytest.mark.parametrize("kind", sorted(LIES))
def test_the_lifecycle_refuses_an_account_no_table_holds(kind: str) -> None:
    lie, named = LIES[kind]
    cls = type(f"Lie_{kind}", (Liar,), {"lie": staticmethod(lie)})
    with pytest.raises(SolverReturnError, match="^.*" + named.replace("(", r"\(").replace(")", r"\)")):
        cls().solve(counterexample(9, 0).qp)


def test_an_honest_account_passes() -> None:
    def honest(ctx: SolveContext) -> None:
        ctx.add_matvecs(np.int64(3))
        ctx.add_setup_time(0.0)
        ctx.add_setup_time(np.float64(1e-9))
        ctx.restricted(np.arange(2), None).add_matvecs(1)

    cls = type("Honest", (Liar,), {"lie": staticmethod(honest)})
    res = cls().solve(counterexample(9, 0).qp)
    assert res.matvecs >= 4 and 0.0 <= res.setup_time <= res.solve_time


def test_the_worker_reads_a_result_no_table_holds_as_a_failure() -> None:
    from contactbench.harness.run.worker import solver_facts

    good = SolveResult(p=np.zeros(3), iterations=2, matvecs=0)  # times not reported: NaN, missing in the row
    facts = solver_facts(good, 5)
    assert isinstance(facts, SolverFacts) and facts.matvecs == 5 and math.isnan(facts.setup_time_s)
    for field, value in (("matvecs", -7), ("iterations", 2.5), ("setup_time", -1.0), ("solve_time", math.inf),
                         ("matvecs", 2**70), ("iterations", TwoFaced(5))):
        why = solver_facts(SolveResult(p=np.zeros(3), **{field: value}), 5)
        assert isinstance(why, str) and f"{field} is" in why, why
    assert "cannot be read" in str(solver_facts(None, 0))


def _row() -> dict[str, Any]:
    return {"cell_id": "c1", "scene": "s", "instance": "i", "solver": "x", "status": "solved", "verdict": "pass",
            "check_tol": 1e-6, "kkt_error": 1e-9, "solve_time_s": 0.1, "matvecs": 3, "setup_time_s": 0.0,
            "iterations": 2, "error": ""}


@pytest.mark.parametrize("column, value", [("matvecs", -999), ("matvecs", 2**70), ("setup_time_s", -100.0),
                                           ("setup_time_s", math.inf), ("iterations", 2.5),
                                           ("solver_internal_time_s", 1e12), ("check_tol", 5.0)])
def test_the_journal_stores_a_row_that_would_not_read_back_as_failed(tmp_path: Path, column: str,
                                                                     value: Any) -> None:
    from contactbench.harness.table.journal import row_problem

    good = _row()
    assert row_problem(good) == "" and encode_row(good) and good == _row()
    store = ResultStore(tmp_path)
    row = dict(_row(), **{column: value})
    store.append(row)
    stored = store.rows()  # (reads back: no JournalError)
    assert len(stored) == 1 and stored[0]["status"] == "failed" and stored[0]["verdict"] == ""
    assert stored[0][column] is None and "would not read back" in stored[0]["error"]
    assert row == stored[0] and store.status_of("c1") == "failed"
    assert json.loads((tmp_path / "rows.jsonl").read_text())["status"] == "failed"


def test_run_fails_each_liar_naming_it_and_reads_its_folder_again(run_harness, tmp_path: Path) -> None:
    """Each liar's row fails naming the field; pk's rows stand; the folder reads back, and
    a second run over it resumes (the liars' failed cells run again, as failed cells do)."""
    out = tmp_path / "run"
    solvers = [f"{HERE}:{cls.__name__}" for cls in (NegativeMatvecs, NanSetup, TakesOverSolve)] + ["pk"]
    options: dict[str, Any] = dict(size=5, seeds=(0,), profiles=("mid",), warmup=False, timeout=60.0, reference="none")
    table = run_harness(["counterexample"], solvers=solvers, out=out, **options)
    for cls, named in ((NegativeMatvecs, "add_matvecs(-999)"), (NanSetup, "add_setup_time(nan)"),
                       (TakesOverSolve, "matvecs is -7")):
        rows = table[table["solver"] == cls.name]
        assert len(rows) == 1 and rows["status"].tolist() == ["failed"], cls.name
        assert named in rows["error"].iloc[0], rows["error"].iloc[0]
    assert table[table["solver"] == "pk"]["status"].tolist() == ["solved"]
    again = run_harness(["counterexample"], solvers=solvers, out=out, **options)
    assert sorted(again["solver"]) == sorted(table["solver"])


def test_validate_fails_a_liar() -> None:
    cases = cf.conformance_cases("fast", pattern="counterexample/example1-n400-s0")
    for solver, named in ((NegativeMatvecs(), "add_matvecs(-999)"), (TakesOverSolve(), "matvecs is -7")):
        table = cf.validate(solver, cases, isolate=False)
        assert [r.status for r in table.rows] == ["crashed"] and named in table.rows[0].message, table.format()
        assert table.outcome() != "conforms"
