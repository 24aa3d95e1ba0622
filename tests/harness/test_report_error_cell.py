"""The error cell of "Skips and failures" (harness/report/sections/generic.py): of a
multi-line error, a traceback's exception line, else the message's first line with text."""

from __future__ import annotations

import traceback
from pathlib import Path

import pytest

from contactbench.harness.report.core import ReportContext
from contactbench.harness.report.view import report_view
from contactbench.harness.report.sections.generic import skips_section
from tests.helpers import META, fabricate_table


def _traceback(exc: BaseException) -> str:
    try:
        raise exc
    except BaseException:
        return traceback.format_exc()


def _chained() -> str:
    """A traceback of an exception raised while another was handled (two tracebacks)."""
    try:
        try:
            {}["x"]
        except KeyError as exc:
            raise RuntimeError("while handling it") from exc
    except RuntimeError:
        return traceback.format_exc()
    raise AssertionError("unreachable")


@pytest.mark.parametrize(("text", "line"), [
    ("solver diverged: residual 1e3 at iteration 40\nthe last iterates: ...\n  step 39: 1e2",
     "solver diverged: residual 1e3 at iteration 40"),
    ("\n\n  LinAlgError: matrix is singular  \nsee the log", "LinAlgError: matrix is singular"),
    (_traceback(ValueError("bad value\nits second line")), "ValueError: bad value"),
    (_chained(), "RuntimeError: while handling it"),
    ("Traceback (most recent call last):\nMemoryError", "MemoryError"),
    ("one line", "one line"),
    ("  \n", ""),
])
def test_the_line_that_says_the_most(text: str, line: str) -> None:
    from contactbench.harness.report.sections.generic import error_line

    assert error_line(text) == line


def test_the_failures_table_shows_that_line(tmp_path: Path) -> None:
    df = fabricate_table()
    df = report_view(df[df["scene"] == "hertz"])
    bad = df.index[df["status"].isin(["crashed", "timeout"])]
    assert len(bad) >= 2
    df.loc[bad[0], "error"] = "the solver gave up: no descent direction\nat iteration 12\nwith step 0"
    df.loc[bad[1], "error"] = _traceback(ZeroDivisionError("division by zero"))
    body = skips_section(ReportContext(tmp_path, df, dict(META)), df).body
    assert "| the solver gave up: no descent direction |" in body and "with step 0" not in body
    assert "| ZeroDivisionError: division by zero |" in body and "Traceback" not in body
