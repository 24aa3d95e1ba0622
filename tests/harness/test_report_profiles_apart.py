"""The report compares solvers within one profile everywhere: the "All scenes" summary of
Aggregates across instances is one table per profile, and Fig. 4 draws the profile where
the most of its solvers ran, saying which and that others exist.

The table (scene "paper-sweep", one instance, 2 load steps, every solve solved):

    profile   solvers
    low       pk, nnls-gp, fast-ccg
    mid       pk, nnls-gp, fast-ccg
    high      pk

(a run of three solvers at low and mid, then P&K alone appended at high).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from contactbench.harness.report import core as rp
from contactbench.harness.report.sections import generic
from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.report.view import read_table, report_view
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row, write_out

SCENE = "paper-sweep"
THREE = ("pk", "nnls-gp", "fast-ccg")


def _rows(runs: dict[str, tuple[str, ...]], steps: int = 2) -> pd.DataFrame:
    """Profile -> the solvers that ran the sweep's ``steps`` steps there, all solved."""
    rows = [report_row(scene=SCENE, instance="i0", step=k, n=10 * (k + 1), N=32, solver=s, profile=p,
                       solve_time_s=0.01 * (i + 1) * (k + 1), dim_load=1e-4 * (k + 1),
                       family="fast" if s.startswith("fast") else "paper")
            for p, solvers in runs.items() for i, s in enumerate(solvers) for k in range(steps)]
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def _appended() -> pd.DataFrame:
    return _rows({"low": THREE, "mid": THREE, "high": ("pk",)})


def _all_scenes(tmp_path: Path, df: pd.DataFrame) -> tuple[str, list[rp.TableRecord]]:
    ctx = rp.ReportContext(tmp_path, report_view(df), {})
    section = generic.aggregates_section(ctx, ctx.table)
    return section.body, [t for t in ctx.tables if "over every scene" in t.caption]


def _cells(t: rp.TableRecord, column: str) -> dict[str, str]:
    return {r[0]: r[t.headers.index(column)] for r in t.rows}


# --- All scenes: one summary per profile ------------------------------------------------------


def test_the_all_scenes_summary_is_one_table_per_profile(tmp_path: Path) -> None:
    """fast-ccg solved both problems of each profile it ran: 100 %, never 4 of 6 for the
    profile `high` it never ran; pk's high problems are a table of their own."""
    body, tables = _all_scenes(tmp_path, _appended())
    assert [t.caption.split(" (")[0] for t in tables] == [
        f"solved shares and correct rates over every scene, profile `{p}`" for p in ("high", "low", "mid")]
    high, low, mid = tables
    assert [r[0] for r in high.rows] == ["pk"]
    for t in (low, mid):
        assert _cells(t, "problems") == {s: "2" for s in THREE}
        assert _cells(t, "solved / problems") == {s: "100 %" for s in THREE}
    assert _cells(high, "problems") == {"pk": "2"}
    assert "67 %" not in body


def test_a_solver_s_share_counts_only_the_profiles_it_ran(tmp_path: Path) -> None:
    """nnls-gp solved one of its two mid problems: 50 % at mid, 100 % at low, whatever pk
    ran at high."""
    df = _appended()
    df.loc[(df["solver"] == "nnls-gp") & (df["profile"] == "mid") & (df["step"] == 1), "status"] = "inaccurate"
    _, tables = _all_scenes(tmp_path, df)
    by = {t.caption.split("profile `")[1].split("`")[0]: t for t in tables}
    assert _cells(by["mid"], "solved / problems")["nnls-gp"] == "50 %"
    assert _cells(by["low"], "solved / problems")["nnls-gp"] == "100 %"
    assert "nnls-gp" not in _cells(by["high"], "problems")


def test_a_table_at_one_profile_keeps_its_one_summary(tmp_path: Path) -> None:
    _, tables = _all_scenes(tmp_path, _rows({"mid": THREE}))
    (t,) = tables
    assert "profile `" not in t.caption and _cells(t, "problems") == {s: "2" for s in THREE}


# --- Fig. 4: the profile where the most of its solvers ran -------------------------------------


def _fig4(tmp_path: Path, df: pd.DataFrame) -> str:
    out = write_out(tmp_path, df)
    ctx = rp.ReportContext(out, read_table(out), META)
    ctx.save_figure = lambda fig, name, on_page=False: f"figures/{name}.png"  # type: ignore[method-assign]
    sec = rpp.fig4_section(ctx, ctx.rows(SCENE))
    assert sec is not None
    return sec.body


def _totals_solvers(body: str) -> set[str]:
    table = body.split("total solve time over")[1].split("**Reading.**")[0]
    return {ln.strip("|").split("|")[0].strip().removesuffix(" (warm)") for ln in table.splitlines()
            if ln.startswith("|") and not ln.startswith("| :") and not ln.startswith("| solver")}


def test_fig4_draws_the_profile_where_the_most_of_its_solvers_ran(tmp_path: Path) -> None:
    """mid holds all three solvers, high pk alone: Fig. 4 shows mid (the tightest of the
    two with three) and says the sweep also ran at high and low."""
    body = _fig4(tmp_path, _appended())
    assert "did not run under this condition" not in body
    assert _totals_solvers(body) == set(THREE)
    assert "total solve time over the sweep's 2 steps (instances x load steps), profile `mid`" in body
    caption = body.split("*Figure")[1].split("*")[0]
    assert "profile `mid`" in caption
    assert "the sweep also ran at `high`, `low`, not drawn here" in caption
    assert "NNLS+GP (K = 100) fastest" in body and "NNLS+GP is not in this table" not in body


def test_fig4_takes_the_tightest_of_profiles_with_as_many_solvers(tmp_path: Path) -> None:
    body = _fig4(tmp_path, _rows({"low": THREE, "mid": THREE}))
    assert "profile `mid`" in body.split("*Figure")[1] and "the sweep also ran at `low`" in body


def test_fig4_of_one_profile_names_no_other(tmp_path: Path) -> None:
    body = _fig4(tmp_path, _rows({"mid": THREE}))
    assert "also ran at" not in body and _totals_solvers(body) == set(THREE)


def test_fig4_keeps_the_tightest_profile_that_lacks_only_one_of_many_solvers(tmp_path: Path) -> None:
    """high holds three of the four solvers low holds (one declines that accuracy): high is
    still the condition to draw, not the looser low."""
    body = _fig4(tmp_path, _rows({"high": THREE, "low": (*THREE, "nnls")}))
    assert "profile `high`" in body.split("*Figure")[1] and "the sweep also ran at `low`" in body
