"""The conformance report of ``contactbench validate ... --out DIR``.

Two files, from the verdict tables of ``harness.conformance.battery`` (nothing is re-judged):

``verdicts.csv``      every verdict row (one per solve, plus the comparison rows), with
                      the solver's outcome and the exact reference's time;
``conformance.md``    one short page: per solver its headline and exit status, the scaled
                      KKT threshold its answers were judged at (its promise), then one
                      line per case -- the verdict (the worst row status of its steps),
                      the worst scaled KKT error, the worst error in p against the exact
                      reference, and the solver's time against the reference's;
``.contactbench-conformance``
                      the marker: this folder is a conformance report folder.

Nothing that is not ours is overwritten (``check_report_folder``, before anything runs):
the report goes into a missing or empty folder, or into a conformance report folder --
one with the marker, or one that holds nothing but a ``conformance.md`` whose first
line is the page's heading and a ``verdicts.csv``; any other folder (a user's, a
``contactbench run`` results folder) or a file is refused.
"""

from __future__ import annotations

import csv
import math
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from contactbench.problems.errors import ProblemInputError
from .battery import VerdictRow, VerdictTable, held_promise, left_out_lines, promise_text

#: Row statuses from worst to best: a case's verdict is the worst of its rows.
SEVERITY = ("WRONG", "crashed", "timeout", "flagged", "unconverged", "refused", "skipped", "pass")
CSV_NAME, MD_NAME, MARKER_NAME = "verdicts.csv", "conformance.md", ".contactbench-conformance"
#: The first line of the page (``markdown_page``).
PAGE_HEADING = "# Conformance report"
MARKER_TEXT = f"a conformance report folder of `contactbench validate` ({CSV_NAME}, {MD_NAME})\n"


class ReportFolderError(ProblemInputError):
    """A report folder that ``validate`` may not write into (one line naming it)."""


def _first_line(path: Path) -> str:
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return fh.readline().rstrip("\n")
    except OSError:
        return ""


def is_report_folder(folder: Path) -> bool:
    """Whether ``folder`` (an existing folder) is empty or a conformance report folder
    (module doc)."""
    names = {p.name for p in folder.iterdir()}
    if not names or MARKER_NAME in names:
        return True
    return names <= {CSV_NAME, MD_NAME} and MD_NAME in names and _first_line(folder / MD_NAME) == PAGE_HEADING


def check_report_folder(out_dir: str | Path, option: str = "--out") -> Path:
    """``out_dir`` if the report may be written there (module doc), else a
    ``ReportFolderError`` naming it and ``option``.  Reads only; creates nothing."""
    out = Path(out_dir)
    if not out.exists():
        return out
    if not out.is_dir():
        raise ReportFolderError(f"{option} {out_dir}: exists and is not a folder")
    try:
        ours = is_report_folder(out)
    except OSError as exc:
        raise ReportFolderError(f"{option} {out_dir}: cannot read the folder ({exc.strerror or exc})") from None
    if not ours:
        raise ReportFolderError(f"{option} {out_dir}: the folder is not empty and is not a conformance report "
                                f"folder (no {MARKER_NAME}); choose an empty or new folder")
    return out


@dataclass(frozen=True)
class CaseLine:
    """One line of the page: a case of one solver, over its steps."""

    case: str
    group: str
    n: int
    verdict: str
    kkt_error: float
    p_rel_error: float
    time_s: float
    ref_time_s: float
    note: str

    @property
    def time_ratio(self) -> float:
        ok = math.isfinite(self.time_s) and math.isfinite(self.ref_time_s) and self.ref_time_s > 0
        return self.time_s / self.ref_time_s if ok else math.nan


def _worst(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return max(finite) if finite else math.nan


def _total(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return sum(finite) if finite and len(finite) == len(values) else math.nan


def case_lines(table: VerdictTable) -> list[CaseLine]:
    """The rows of ``table`` folded per case (module doc)."""
    by_case: dict[str, list[VerdictRow]] = {}
    for r in table.rows:
        by_case.setdefault(r.case, []).append(r)
    out = []
    for case, rows in by_case.items():
        verdict = min((r.status for r in rows), key=lambda s: SEVERITY.index(s) if s in SEVERITY else 0)
        solves = [r for r in rows if r.step >= 0]
        worst = next((r for r in rows if r.status == verdict), rows[0])
        out.append(CaseLine(case, rows[0].group, max(r.n for r in rows), verdict,
                            _worst([r.kkt_error for r in solves]), _worst([r.p_rel_error for r in solves]),
                            _total([r.time_s for r in solves]), _total([r.ref_time_s for r in solves]),
                            worst.message if verdict != "pass" else ""))
    return out


def write_csv(tables: Sequence[VerdictTable], path: Path, strict: bool = False) -> None:
    records: list[dict[str, Any]] = [rec for t in tables for rec in t.records(strict)]
    fields = list(records[0]) if records else ["solver", "case", "status"]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(records)


def _fmt(x: float, spec: str = ".2e") -> str:
    return "" if not math.isfinite(x) else format(x, spec)


def _cell(text: str, width: int = 160) -> str:
    one = " ".join(str(text).split()).replace("|", "\\|")
    return one if len(one) <= width else one[: width - 1] + "…"


def threshold_line(table: VerdictTable) -> str:
    """The scaled KKT threshold the answers of ``table`` were judged at: the case's profile
    threshold for the promise "exact", else the solver's floor (held to ``PROMISE_BOUND``)
    where it is above that."""
    used = sorted({r.check_tol for r in table.solves if math.isfinite(r.check_tol)})
    at = ", ".join(f"{x:.3g}" for x in used) or "none (no solve judged)"
    if table.promise == "exact":
        return f"Promise: exact -- judged at the case's profile threshold (here {at})."
    return (f"Promise: {promise_text(table.promise)} -- judged at max(the case's profile threshold, "
            f"{float(held_promise(table.promise)):.3g}) (here {at}).")


def markdown_page(tables: Sequence[VerdictTable], strict: bool = False, command: Sequence[str] = ()) -> str:
    lines = [PAGE_HEADING, ""]
    if command:
        lines += ["`contactbench validate " + shlex.join(command) + "`", ""]
    lines += ["Every answer is judged by the harness's scaled KKT check (problems/kkt.py) at the threshold "
              "its solver promises (stated under each solver); `p error` is max ||p - p_ref||_inf / "
              "||p_ref||_inf against the exact reference; `time / ref` compares the solver's seconds (all "
              "steps) with the exact reference's.", ""]
    for t in tables:
        lines += [f"## {t.solver} ({t.mode} battery)", "",
                  f"**{t.headline(strict)}** -- exit status {t.exit_code(strict)}", "", threshold_line(t), ""]
        if t.note:
            lines += [t.note, ""]
        lines += ["| case | n | verdict | worst KKT | p error | time (s) | ref (s) | time / ref | note |",
                  "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | --- |"]
        for c in case_lines(t):
            lines.append(f"| {c.case} | {c.n} | {c.verdict} | {_fmt(c.kkt_error)} | {_fmt(c.p_rel_error)} | "
                         f"{_fmt(c.time_s, '.3g')} | {_fmt(c.ref_time_s, '.3g')} | {_fmt(c.time_ratio, '.3g')} | "
                         f"{_cell(c.note)} |")
        left = left_out_lines(t)
        if left:
            lines += ["", *[f"- {ln.strip()}" for ln in left[1:]]]
        lines.append("")
    return "\n".join(lines)


def write_conformance_report(tables: Sequence[VerdictTable], out_dir: str | Path, *, strict: bool = False,
                             command: Sequence[str] = ()) -> Path:
    """Write the marker, DIR/verdicts.csv and DIR/conformance.md and return the page's
    path; a folder that is not ours is a ``ReportFolderError`` (``check_report_folder``)."""
    out = check_report_folder(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER_NAME).write_text(MARKER_TEXT)
    write_csv(tables, out / CSV_NAME, strict)
    page = out / MD_NAME
    page.write_text(markdown_page(tables, strict, command))
    return page
