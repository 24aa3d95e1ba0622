"""The contact-fields section (harness/report/sections/fields.py) with no field file: it
says that no answer at a top step was solved when none was (the runner keeps only a
solved one), and gives the backfill command only when top steps were solved but the
folder keeps no field for them."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from contactbench.harness.report import core as rp
from contactbench.harness.report.sections import fields
from contactbench.harness.table.schema import ALL_COLUMNS
from tests.helpers import META, report_row

BACKFILL = "contactbench.harness.run.backfill"


def fields_body(tmp: Path, top_status: str) -> str:
    """The section's text for a sweep of two instances, steps 0-2, solved below the top step
    and ``top_status`` at step 2, in a folder with no arrays."""
    rows = [report_row(scene="paper-sweep", instance=i, step=k, solver=s,
                       status=top_status if k == 2 else "solved", kkt_error=1e-3 if top_status == "inaccurate"
                       and k == 2 else 1e-10, solve_time_s=0.1)
            for i in ("i0", "i1") for k in range(3) for s in ("a", "b")]
    t = pd.DataFrame(rows, columns=list(ALL_COLUMNS))
    section = fields.fields_section(rp.ReportContext(tmp, t, dict(META)), t)
    assert section is not None
    return section.body


def test_no_solved_top_step_is_said_without_the_backfill_hint(tmp_path: Path) -> None:
    body = fields_body(tmp_path, "timeout")
    assert "no answer at a top step was solved (the top steps' rows: timeout 4)" in body
    assert BACKFILL not in body and "before" not in body


def test_solved_top_steps_without_fields_get_the_backfill_hint(tmp_path: Path) -> None:
    body = fields_body(tmp_path, "solved")
    assert "2 instance(s) have a solved answer at their top step" in body and BACKFILL in body
    assert "before fields were kept" not in body
