"""Fig. 4 (harness/report/sections/paper.py, sweep_totals.py): its totals table, its
reading, its markers and its caption, on small fabricated load sweeps.

Each sweep is a dict solver -> one (status, solve time, kkt_error) per load step;
"skipped" steps carry no figures.  The section is called directly on a report context
over the written table, so that its figure can be looked at before it is saved.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.report import core as rp
from contactbench.harness.report.view import read_table
from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.table.aggregates import served_name
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row, write_out

Step = tuple[str, float, float]  # (status, solve time [s], kkt_error)
OK = ("solved", 1.0, 1e-10)
SKIP = ("skipped", np.nan, np.nan)


def sweep_rows(sweep: dict[str, list[Step]], family: dict[str, str] | None = None) -> pd.DataFrame:
    """The rows of a one-instance paper-sweep at profile "high": step k has n = 100 (k + 1)
    and load 1e-4 (k + 1)."""
    rows = []
    for s, steps in sweep.items():
        for k, (status, t, kkt) in enumerate(steps):
            rows.append(report_row(scene="paper-sweep", instance="i0", step=k, n=100 * (k + 1), N=64, solver=s,
                                   family=(family or {}).get(s, "paper"), profile="high", status=status,
                                   solve_time_s=t, kkt_error=kkt, dim_load=1e-4 * (k + 1), warm_start=False,
                                   skip_reason="predicted over the time limit" if status == "skipped" else ""))
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def fig4(tmp_path: Path, df: pd.DataFrame) -> tuple[str, dict[str, Any], rp.ReportContext]:
    """(the section's Markdown, its figures by name, the context) for the table ``df``."""
    out = write_out(tmp_path, df)
    ctx = rp.ReportContext(out, read_table(out), META)
    figures: dict[str, Any] = {}

    def keep(fig: Any, name: str, on_page: bool = False) -> str:
        figures[name] = fig
        return f"figures/{name}.png"

    ctx.save_figure = keep  # type: ignore[method-assign]
    sec = rpp.fig4_section(ctx, ctx.rows("paper-sweep"))
    assert sec is not None
    return sec.body, figures, ctx


def totals_table(body: str) -> list[list[str]]:
    """The cells of the section's totals table, header first."""
    lines = [ln for ln in body.split("total solve time over")[1].split("**Reading.**")[0].splitlines()
             if ln.startswith("|") and not ln.startswith("| :")]
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in lines]


def legend_labels(fig: Any) -> set[str]:
    return {lab for ax in fig.axes for lab in ax.get_legend_handles_labels()[1]}


def test_totals_table_gives_a_total_only_over_the_whole_sweep_and_lists_those_rows_first(tmp_path: Path) -> None:
    """A solver that solved 3 of 10 steps (skipped the rest) has no total beside one that
    solved all 10: its sum is marked as over 3 of 10 steps and its row comes after."""
    df = sweep_rows({"nnls-gp": [("solved", 5.0, 1e-10)] * 10,
                     "gp": [("solved", 4.0, 1e-10)] * 3 + [SKIP] * 7})
    body, _, _ = fig4(tmp_path, df)
    table = totals_table(body)
    assert table[0] == ["solver", "family", "steps solved", "total [s]", "worst kkt", "worst p err"]
    rows = {r[0]: r for r in table[1:]}
    assert [r[0] for r in table[1:]] == ["nnls-gp", "gp"]
    assert rows["nnls-gp"][2:4] == ["10 of 10", "50"]
    assert rows["gp"][2] == "3 of 10"
    assert rows["gp"][3].startswith("-") and "12 over 3 of 10 steps" in rows["gp"][3]
    assert "over the sweep's 10 steps" in body


def test_reading_names_no_fastest_when_no_solver_solved_the_whole_sweep(tmp_path: Path) -> None:
    """Every solver skipped the last step: none covers the sweep, so none is named fastest."""
    df = sweep_rows({"pk": [OK] * 3 + [SKIP], "nnls-gp": [("solved", 3.0, 1e-10)] * 3 + [SKIP]})
    body, _, _ = fig4(tmp_path, df)
    reading = body.split("**Reading.**")[1]
    assert "fastest solver over the whole sweep" not in reading
    assert "No solver solved all 4 steps of the sweep" in reading
    assert "1 of 4" not in reading and "did not solve every step" in reading  # P&K / NNLS+GP not compared


def test_worst_kkt_counts_the_answers_the_inaccurate_table_counts(tmp_path: Path) -> None:
    """A timed-out solve's kkt_error is not an answer's: the totals' worst kkt is the
    worst over solved and inaccurate answers, the figure the inaccurate-answers table shows."""
    df = sweep_rows({"greedy-gs": [OK, ("inaccurate", 1.0, 2.4e-2), ("timeout", 120.0, 1.8)]})
    body, _, _ = fig4(tmp_path, df)
    header, row = totals_table(body)
    assert row[0] == "greedy-gs" and row[header.index("worst kkt")] == rp.fmt_err(2.4e-2)
    assert "solved and inaccurate" in body  # the caption says which answers count


def test_timeouts_and_failures_have_their_own_markers_and_labels(tmp_path: Path) -> None:
    """A timeout and a crash with a time are drawn at their time, each with its own marker
    and legend label, never as a KKT failure; the caption says what each marker is."""
    df = sweep_rows({"pk": [OK, OK, OK], "qp-qpalm": [OK, ("timeout", 130.0, 4.9e-7), ("crashed", 2.0, np.nan)]})
    body, figures, _ = fig4(tmp_path, df)
    fig = figures["fig4-paper-sweep"]
    labels = legend_labels(fig)
    assert "not solved (KKT check)" not in labels
    assert {"timed out", "failed or crashed"} <= labels
    ax = fig.axes[0]
    marks = {ln.get_marker(): list(ln.get_ydata()) for ln in ax.get_lines() if ln.get_linestyle() == "None"
             and len(ln.get_ydata())}
    assert marks.get("s") == [pytest.approx(130.0)] and marks.get("D") == [pytest.approx(2.0)]
    assert "x" not in marks
    assert "solves stopped at the time limit" in body and "failed or crashed" in body
    assert "red crosses" not in body


def test_caption_counts_skipped_steps_names_undrawn_solvers_and_gives_the_sweeps_largest_n(tmp_path: Path) -> None:
    """Skipped steps leave no mark, so the caption counts them per solver; a solver skipped
    at every step is named as not drawn; "n" is the sweep's largest, skipped steps included."""
    df = sweep_rows({"pk": [OK] * 4 + [SKIP], "gp": [OK, OK] + [SKIP] * 3, "admm": [SKIP] * 5})
    body, _, _ = fig4(tmp_path, df)
    caption = body.split("*Figure")[1].split("*\n")[0]
    assert "largest trial set has n = 500" in caption
    assert "Every solver of the scene is drawn" not in caption
    assert re.search(r"not drawn, 1 solvers? .*`admm`", caption)
    assert "`gp` 3" in caption and "`pk` 1" in caption


def test_best_of_a_family_is_never_a_solver_that_solved_no_step(tmp_path: Path) -> None:
    """With more solvers than one panel holds, the first panel shows each family's best:
    a family whose solvers solved nothing has none there, however fast they failed, and
    the caption states the rule."""
    fam = {**{f"paper-{i}": "paper" for i in range(6)}, "wrap-fast": "wrapper", "wrap-slow": "wrapper",
           **{f"fast-{i}": "fast" for i in range(4)}}
    sweep: dict[str, list[Step]] = {s: [("solved", 1.0 + i, 1e-10)] * 3 for i, s in enumerate(fam)}
    sweep["wrap-fast"] = [("inaccurate", 0.01, 0.5)] * 3
    sweep["wrap-slow"] = [("inaccurate", 0.02, 0.5)] * 3
    body, figures, _ = fig4(tmp_path, sweep_rows(sweep, fam))
    first = figures["fig4-paper-sweep"].axes[0]
    assert "best of each family" in first.get_title()
    drawn = set(first.get_legend_handles_labels()[1])
    assert not drawn & {"wrap-fast", "wrap-slow"}
    assert {"paper-0", "fast-0"} <= drawn
    assert "solver that solved the most steps" in body


def test_nothing_solved_says_so_instead_of_an_empty_figure(tmp_path: Path) -> None:
    """No step solved (two timeouts, the rest skipped): no load places a time, so the
    section says that in text and saves no figure."""
    df = sweep_rows({"cm-dual-ccg": [("timeout", 1.0, np.nan)] + [SKIP] * 3,
                     "pk": [SKIP] * 4, "fast-dual-pccg": [("timeout", 0.02, 1.0)] + [SKIP] * 3})
    body, figures, _ = fig4(tmp_path, df)
    assert "fig4-paper-sweep" not in figures
    assert "**No figure.**" in body and "no step was solved" in body
    assert "timeout 2, skipped 10" in body


def test_worst_p_err_leaves_out_the_answers_that_served_as_the_reference(tmp_path: Path) -> None:
    """pk's answers served as the reference of steps 0-1 (p error 0 by construction): its
    worst p err is that of step 2 against another reference, and a solver whose every
    measured answer was the reference reads "ref", not 0."""
    df = sweep_rows({"pk": [OK] * 3, "nnls": [OK] * 3, "gp": [OK] * 3})
    served = served_name("pk", "high")
    df["reference_solver"] = [served if k < 2 else "nnls@high" for k in df["step"]]
    df["p_rel_error"] = [0.0 if (s == "pk" and k < 2) or (s == "nnls" and k == 2) else 3e-7 if s == "pk" else 1e-9
                         for s, k in zip(df["solver"], df["step"])]
    df.loc[(df["solver"] == "nnls") & (df["step"] < 2), "p_rel_error"] = 2e-8
    only = sweep_rows({"pk": [OK] * 3, "gp": [OK] * 3})
    only["reference_solver"] = served
    only["p_rel_error"] = [0.0 if s == "pk" else 1e-9 for s in only["solver"]]
    rows = {r[0]: r for r in totals_table(fig4(tmp_path / "a", df)[0])[1:]}
    assert rows["pk"][5] == "3.0e-07" and rows["gp"][5] == "1.0e-09"
    rows = {r[0]: r for r in totals_table(fig4(tmp_path / "b", only)[0])[1:]}
    assert rows["pk"][5] == "ref" and rows["gp"][5] == "1.0e-09"
