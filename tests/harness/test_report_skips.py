"""The Skips table of "Skips and failures" (harness/report/sections/generic.py
``skips_section``): a solver's skips are grouped by the kind of their reason (the text with
its numbers masked), with the steps as ranges and the first step's reason in full, so that
a prediction made afresh at each step is one row, not one row per step."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from contactbench.harness.report import core as rp
from contactbench.harness.report.sections import generic
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row


def predicted(n: int, t: float) -> str:
    return (f"predicted solve time {t:.3g} s at n = {n} from 40.3 s at n = 1881 on the previous step "
            f"(time ~ n^3), over the time limit of 120 s")


def skips_table() -> pd.DataFrame:
    """Solver gp: solved at steps 0-2, a prediction skip at steps 3-6 (each its own n and
    time) and 8, a memory skip at step 7; solver nnls: one reason at steps 0-1."""
    rows = [report_row(scene="paper-sweep", instance="i0", step=k, n=1000 * (k + 1), solver="gp") for k in range(3)]
    rows += [report_row(scene="paper-sweep", instance="i0", step=k, n=1000 * (k + 1), solver="gp", status="skipped",
                        skip_reason=predicted(1000 * (k + 1), 100.0 * k)) for k in (3, 4, 5, 6, 8)]
    rows.append(report_row(scene="paper-sweep", instance="i0", step=7, n=8000, solver="gp", status="skipped",
                           skip_reason="memory estimate 9.24 GiB at n = 8000 exceeds the memory budget of 8 GiB"))
    rows += [report_row(scene="paper-sweep", instance="i0", step=k, n=1000, solver="nnls", status="skipped",
                        skip_reason="nnls declares an accuracy floor of 1e-06") for k in (0, 1)]
    return pd.DataFrame(rows, columns=list(ALL_COLUMNS))


def skip_lines(tmp: Path) -> list[list[str]]:
    t = skips_table()
    body = generic.skips_section(rp.ReportContext(tmp, t, dict(META)), t).body
    table = body[body.index("| scene |"):].split("\n\n")[0].splitlines()[2:]
    return [[c.strip() for c in line.strip("|").split("|")] for line in table]


def test_a_reason_kind_masks_only_the_numbers() -> None:
    assert generic.reason_kind(predicted(3785, 328.0)) == generic.reason_kind(predicted(35218, 1.68e3))
    assert generic.reason_kind("accuracy floor of 1e-06; checks 1e-08") == "accuracy floor of #; checks #"
    assert generic.reason_kind(predicted(10, 1.0)) != generic.reason_kind("memory estimate 1 GiB at n = 10")


def test_skips_of_one_kind_are_one_row_with_step_ranges_and_an_example(tmp_path: Path) -> None:
    lines = skip_lines(tmp_path)
    assert [(x[1], x[2], x[4]) for x in lines] == [("gp", "5", "3-6, 8"), ("gp", "1", "7"), ("nnls", "2", "0-1")]
    assert lines[0][5] == "e.g. " + predicted(4000, 300.0)  # the first step's reason, in full
    assert lines[1][5].startswith("memory estimate 9.24 GiB")
    assert lines[2][5] == "nnls declares an accuracy floor of 1e-06"  # one text: no "e.g."
