"""A stored row whose reading its own figures contradict is refused on reading, in one
line naming the table and the row: the report never counts a forged "solved"."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.table.schema import TableError
from contactbench.harness.table.store import load_table
from tests.helpers import fabricate_table, run_cli, write_out


def first(df: pd.DataFrame, status: str) -> int:
    return int(np.flatnonzero(df["status"] == status)[0])


def forged(df: pd.DataFrame, case: str) -> pd.DataFrame:
    """``df`` with one row (solved, inaccurate or crashed) edited as a user, or a broken
    tool, might."""
    bad = df.copy()
    solved, inaccurate, failed = first(bad, "solved"), first(bad, "inaccurate"), first(bad, "crashed")
    edits = {
        "solved-above-tol": (solved, {"kkt_error": 1e3, "solve_time_s": 1e-9}),
        "solved-inf-kkt": (solved, {"kkt_error": np.inf}),
        "solved-nan-kkt": (solved, {"kkt_error": np.nan}),
        "negative-kkt": (inaccurate, {"kkt_error": -5.0}),
        "solved-nan-time": (solved, {"solve_time_s": np.nan}),
        "inf-time": (solved, {"solve_time_s": np.inf}),
        "inf-build-time": (failed, {"build_time_s": np.inf}),
        "inaccurate-within-tol": (inaccurate, {"kkt_error": 1e-12}),
        "pass-on-crashed": (failed, {"verdict": "pass"}),
        "bool-junk": (solved, {"warm_start": "maybe"}),
        "tol-infinite": (solved, {"kkt_error": 0.5, "check_tol": np.inf}),
        "tol-negative": (inaccurate, {"kkt_error": 0.0, "check_tol": -1.0}),
        "timeout-pass-above-tol": (first(bad, "timeout"), {"verdict": "pass", "kkt_error": 1.0}),
        "count-fraction": (solved, {"n": 2.4}),
        "count-past-int64": (solved, {"iterations": 1e300}),
        "solved-no-tol": (solved, {"kkt_error": 5.0, "check_tol": np.nan}),
        "tol-huge": (solved, {"kkt_error": 1e300, "check_tol": 1e308}),
        "negative-count": (solved, {"n": -3}),
        "negative-step": (solved, {"step": -1}),
        "negative-iterations": (solved, {"iterations": -1}),
        "fraction-above-one": (solved, {"contact_fraction": 5.0}),
        "negative-E": (solved, {"E": -1e9}),
        "huge-time": (solved, {"solve_time_s": 1e308}),
        "negative-residual": (inaccurate, {"dual_residual": -1e-3}),
    }
    row, values = edits[case]
    bad = bad.astype({col: "object" for col in values})
    for col, value in values.items():
        bad.loc[row, col] = value
    return bad


CASES = {
    "solved-above-tol": "status solved with kkt_error 1000.0 above its check_tol",
    "solved-inf-kkt": "status solved with kkt_error inf",
    "solved-nan-kkt": "status solved with kkt_error nan",
    "negative-kkt": "a negative kkt_error -5.0",
    "solved-nan-time": "status solved with solve_time_s nan",
    "inf-time": "column solve_time_s of .* holds an infinite duration",
    "inf-build-time": "column build_time_s of .* holds an infinite duration",
    "inaccurate-within-tol": "status inaccurate with kkt_error 1e-12 within its check_tol",
    "pass-on-crashed": "the reading pass on a row whose status is neither solved nor timeout",
    "bool-junk": "column warm_start of .* holds 'maybe', not true or false",
    "tol-infinite": "a check_tol inf, not a number > 0 and at most 1",
    "tol-negative": "a check_tol -1.0, not a number > 0 and at most 1",
    "timeout-pass-above-tol": "the reading pass with kkt_error 1.0 above its check_tol",
    "count-fraction": "column n of .* holds 2.4, not a whole number",
    "count-past-int64": "column iterations of .* holds 1e\\+300, beyond a count's range",
    "solved-no-tol": "status solved with kkt_error 5.0 above its check_tol nan",
    "tol-huge": "a check_tol 1e\\+308, not a number > 0 and at most 1",
    "negative-count": "column n of .* holds -3, outside its range \\(>= 0",
    "negative-step": "column step of .* holds -1, outside its range",
    "negative-iterations": "column iterations of .* holds -1, outside its range",
    "fraction-above-one": "column contact_fraction of .* holds 5, outside its range \\(\\[0, 1\\]",
    "negative-E": "column E of .* holds -1e\\+09, outside its range \\(> 0",
    "huge-time": "column solve_time_s of .* holds a longer than 1e\\+09 s duration",
    "negative-residual": "column dual_residual of .* holds -0.001, outside its range",
}


def test_the_fabricated_table_is_consistent() -> None:
    """The table the forgeries start from reads (so each refusal below is the edit's)."""
    df = fabricate_table()
    assert {"solved", "inaccurate", "crashed", "timeout"} <= set(df["status"])
    load_table_of(df)


def load_table_of(df: pd.DataFrame, tmp: Path | None = None) -> pd.DataFrame:
    import tempfile

    folder = Path(tempfile.mkdtemp(dir=tmp))
    return load_table(write_out(folder, df, fmt="csv"))  # (CSV: a hand-edited table keeps any text)


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_row_its_own_figures_contradict_is_refused_on_reading(case: str, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A forged "solved" (kkt 1e3, inf, NaN; no time), a negative KKT error, an infinite
    duration, "inaccurate" within its tolerance, the reading "pass" on a crashed row, text in
    a true/false column or a fraction in a count: the report counted the forged solve as the
    fastest correct one, 100 % success, and read the others as missing or rounded."""
    df = forged(fabricate_table(), case)
    with pytest.raises(TableError, match=CASES[case]):
        load_table_of(df, tmp_path)
    out = write_out(tmp_path / "forged", df, fmt="csv")
    code, stdout, err = run_cli(["report", str(out)], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "forged" in err and not (out / "report.md").exists()


def test_a_run_cannot_record_an_infinite_time_limit() -> None:
    """``RunConfig(timeout=inf)`` is refused: its rows would record ``time_limit_s`` = inf,
    an infinite duration, and the run could not read its own journal back."""
    import math

    from contactbench.harness.run.plan import RunConfig

    with pytest.raises(ValueError, match="timeout must be a finite number of seconds"):
        RunConfig(timeout=math.inf)


def test_a_csv_cut_inside_a_quoted_field_ends_in_the_middle_of_its_row(tmp_path: Path) -> None:
    """A results.csv cut off inside a quoted text field (a trace, a message) is a truncated
    table, named as one, as a cut between fields is."""
    df = fabricate_table()
    write_out(tmp_path, df, fmt="csv")
    path = tmp_path / "results.csv"
    text = path.read_text()
    row = 3
    row_start = sum(len(ln) for ln in text.splitlines(keepends=True)[:row])  # (the header, then rows 1 .. row - 1)
    path.write_text(text[:text.index('"', row_start) + 2])  # into the row's first quoted field
    with pytest.raises(TableError, match=f"ends in the middle of its row {row} "):
        load_table(path)
