"""The claims ledger as a document: ``claims.md`` written from ``claims.csv`` alone, and
the section that leads ``report.md`` of a folder holding a ledger.

``write_claims_report(DIR)`` is what ``contactbench report DIR`` does first: in a folder
of a ``paper-claims`` run (its meta names the study) it (re)computes ``claims.csv`` from
the results table (``harness/report/claims.py``); wherever ``claims.csv`` is, it writes
``claims.md`` from that file and nothing else.  Outside a claims run, a ``claims.csv``
whose header shares fewer than ``LEDGER_MIN_SHARED`` columns with ``LEDGER_COLUMNS`` is
not a ledger: it is someone else's file, left as it is and not read (``ledger_in``; a
warning says so).  A ledger that lacks a column or holds a verdict or a condition outside
its lists is refused with one line.
"""

from __future__ import annotations

import math
import logging
from pathlib import Path

import pandas as pd
from contactbench.problems.atomic_files import literal_path

from ..claims import CLAIMS, CONDITIONS, LEDGER_COLUMNS, LEDGER_NAME, VERDICTS, write_ledger
from ...table.files import write_text_atomic
from ...table.meta import commands_of, read_meta
from ..owned_files import refuse_foreign_page, title_line
from ..view import read_table
from ..core import (
    ReportContext,
    ReportInputError,
    Section,
    fmt_num,
    markdown_table,
    md_escape,
    register_section,
)

log = logging.getLogger(__name__)

#: The document written beside ``claims.csv``.
CLAIMS_MD = "claims.md"
#: claims.md's title (its first line: how a report knows the page as its own).
CLAIMS_TITLE = "The paper's claims ledger (Bemporad & Paggi 2015)"
#: A claims.csv outside a claims run is read as a ledger (and refused when it is a broken
#: one) when its header names at least this many of ``LEDGER_COLUMNS``; with fewer it is
#: another file of that name (module doc).
LEDGER_MIN_SHARED = len(LEDGER_COLUMNS) // 2
#: The study whose run folders get their ledger (re)computed by ``contactbench report``.
CLAIMS_STUDY = "paper-claims"
#: What each condition is, for the reader.
CONDITION_TEXT = {
    "dense": "the paper's: dense H, eps = 1e-8 (profile `paper`), P&K cold (P&K1999) and warm, NNLS warm, "
             "NNLS+GP K = 100, ADMM alpha 1.5 rho 1, greedy CG / Cholesky / Gauss-Seidel",
    "fft": "ours: FFT operators, each solver's own tolerance (profile `default`), the fast solvers beside the paper's",
}
#: The paper's own size, against which the dense rows' sizes are read.
PAPER_SIZE_TEXT = ("The paper's Figs. 4-6 are one 512^2 surface with n = 35,555 at the top step: its dense H is "
                   "about 10 GB. The dense rows here run at the sizes in `n_or_size`; where a claim has rows at "
                   "several sizes, the table *with n* shows which way its value moves towards the paper's n.")


def read_ledger(path: str | Path) -> pd.DataFrame:
    """``claims.csv`` checked: every column of ``LEDGER_COLUMNS``, verdicts and conditions
    from their lists; ``measured`` as floats (blank: NaN)."""
    p = Path(path)
    try:
        df = pd.read_csv(literal_path(p), dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ReportInputError(f"{p}: not a readable CSV ledger ({exc})") from None
    missing = [c for c in LEDGER_COLUMNS if c not in df.columns]
    if missing:
        raise ReportInputError(f"{p}: the ledger lacks column(s) {', '.join(missing)}")
    bad = sorted(set(df["verdict"]) - set(VERDICTS))
    if bad:
        raise ReportInputError(f"{p}: verdict(s) {', '.join(map(repr, bad))} not in {', '.join(VERDICTS)}")
    badc = sorted(set(df["condition"]) - set(CONDITIONS))
    if badc:
        raise ReportInputError(f"{p}: condition(s) {', '.join(map(repr, badc))} not in {', '.join(CONDITIONS)}")
    df["measured"] = pd.to_numeric(df["measured"].replace("", "nan"), errors="coerce")
    return df


def fmt_measured(v: float) -> str:
    return "-" if not math.isfinite(v) else fmt_num(v, 3)


def verdict_counts(df: pd.DataFrame) -> str:
    """"dense: 5 holds, 3 partly, ...; fft: ..."."""
    parts = []
    for cond in CONDITIONS:
        d = df[df["condition"] == cond]
        if len(d):
            parts.append(f"{cond}: " + ", ".join(f"{int((d['verdict'] == v).sum())} {v}" for v in VERDICTS
                                                 if (d["verdict"] == v).any()))
    return "; ".join(parts)


def ledger_table(df: pd.DataFrame, evidence: bool = True) -> str:
    heads = ["claim", "figure", "tex", "paper", "condition", "measured", "n / size", "seeds", "repeats", "verdict"]
    rows = [[md_escape(r.claim), md_escape(r.figure), md_escape(r.tex_lines), md_escape(r.paper_value), r.condition,
             fmt_measured(r.measured), md_escape(r.n_or_size), md_escape(r.seeds), md_escape(r.repeats),
             f"**{r.verdict}**"] for r in df.itertuples()]
    if evidence:
        heads.append("evidence")
        for row, r in zip(rows, df.itertuples()):
            row.append(md_escape(r.evidence) or "-")
    return markdown_table(heads, rows, "llllllrlrl" + ("l" if evidence else ""))


def fails_under_paper(df: pd.DataFrame) -> str:
    """The claims that fail under the paper's own condition, one line each."""
    f = df[(df["condition"] == "dense") & (df["verdict"] == "fails")]
    if f.empty:
        return "No claim fails under the paper's own condition (dense) in this ledger.\n"
    lines = [f"- `{r.claim}` ({md_escape(r.figure)}, {md_escape(r.n_or_size)}): measured {fmt_measured(r.measured)} "
             f"against the paper's {md_escape(r.paper_value)}; {md_escape(r.evidence)}" for r in f.itertuples()]
    return "\n".join(lines) + "\n"


def with_n(df: pd.DataFrame) -> str:
    """Claims measured at several sizes under one condition: the value per size, in order."""
    lines = []
    for (claim, cond), g in df.groupby(["claim", "condition"], sort=False):
        if len(g) > 1:
            lines.append([claim, cond, "; ".join(f"{md_escape(r.n_or_size)}: {fmt_measured(r.measured)} "
                                                 f"({r.verdict})" for r in g.itertuples())])
    if not lines:
        return "No claim is measured at more than one size.\n"
    return markdown_table(["claim", "condition", "measured per size"], lines, "lll") + "\n"


def rules_table() -> str:
    rows = [[c.id, md_escape(c.tex_lines), md_escape(c.paper_value), md_escape(c.measures or "-"),
             md_escape(c.rule.text())] for c in CLAIMS.values()]
    return markdown_table(["claim", "tex", "paper", "measured", "verdict rule on measured"], rows, "lllll") + "\n"


def claims_markdown(df: pd.DataFrame) -> str:
    """The whole ``claims.md`` of a ledger (a pure function of ``df``)."""
    doc = [title_line(CLAIMS_TITLE),
           (f"Written by `contactbench report` from `{LEDGER_NAME}` alone: {len(df)} rows, "
           f"{df['claim'].nunique()} claims. Verdicts: {verdict_counts(df)}."), "",
           "Conditions:", *[f"- `{c}` -- {t}." for c, t in CONDITION_TEXT.items()], "", PAPER_SIZE_TEXT, "",
           "## Ledger: the paper's condition", "", ledger_table(df[df["condition"] == "dense"]), "",
           "## Beyond the paper: our condition", "",
           ("The same claims on FFT operators beside our fast solvers: what the paper's findings become under "
            "today's methods. A paper claim's verdict above uses the paper's methods only."), "",
           ledger_table(df[df["condition"] != "dense"]), "",
           "## Fails under the paper's own condition", "", fails_under_paper(df),
           "## With n", "", with_n(df),
           "## Verdict rules", "",
           ("`unmeasured`: the measurement is missing or not finite, or rests on no evidence, or the table cannot "
           "test the claim (never `holds`). `unresolved`: the value's interval over its timed repeats, "
           "[m / (1 + spread), m (1 + spread)], reaches across a band edge (never `holds`). Otherwise the claim's "
           "rule on `measured` (docs/claims.md):"), "", rules_table()]
    return "\n".join(doc)


def write_claims_md(out_dir: str | Path) -> Path:
    """Write OUT/claims.md from OUT/claims.csv; return its path.  A claims.md that is not
    such a page is left as it is: ``ReportInputError`` (``owned_files.refuse_foreign_page``)."""
    out = Path(out_dir)
    path = out / CLAIMS_MD
    refuse_foreign_page(path, CLAIMS_TITLE)
    write_text_atomic(path, claims_markdown(read_ledger(out / LEDGER_NAME)))
    return path


def is_claims_run(out_dir: str | Path) -> bool:
    """Whether a command that wrote to the folder ran the ``paper-claims`` study."""
    return any(CLAIMS_STUDY in cmd.split() for cmd in commands_of(read_meta(out_dir)))


def has_ledger_header(path: Path) -> bool:
    """Whether the first line of the file ``path`` names at least ``LEDGER_MIN_SHARED`` of
    the columns of ``LEDGER_COLUMNS``."""
    try:
        with path.open(encoding="utf-8", errors="replace") as fh:
            header = fh.readline()
    except OSError:
        return False
    named = {c.strip().strip('"') for c in header.rstrip("\r\n").split(",")}
    return len(named & set(LEDGER_COLUMNS)) >= LEDGER_MIN_SHARED


def ledger_in(out: Path, warn: bool = True) -> Path | None:
    """OUT/claims.csv when it is a ledger -- the folder is a claims run, or the file's header
    has most of the ledger's columns -- else None (module doc: another file of that name is not read;
    with ``warn``, a warning names it)."""
    path = out / LEDGER_NAME
    if not path.is_file():
        return None
    if is_claims_run(out) or has_ledger_header(path):
        return path
    if warn:
        log.warning("%s: not a claims ledger (its header has few of the ledger's columns); left as it is", path)
    return None


def write_claims_report(out_dir: str | Path) -> Path | None:
    """For a ``paper-claims`` run folder: claims.csv from its results table; then, wherever
    claims.csv is a ledger (``ledger_in``), claims.md from it.  None for a folder with neither."""
    out = Path(out_dir)
    if is_claims_run(out):
        write_ledger(read_table(out), out)
    if ledger_in(out) is None:
        return None
    return write_claims_md(out)


@register_section("claims-ledger", title="The paper's claims ledger", group="lead", order=0)
def claims_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    """The ledger at the head of report.md, when the folder holds one (else no section)."""
    path = ledger_in(ctx.out_dir, warn=False)  # (write_claims_report warned)
    if path is None:
        return None
    df = read_ledger(path)
    body = [(f"Each quantitative claim of the paper under the paper's condition (`dense`) and ours (`fft`); "
            f"verdicts: {verdict_counts(df)}. Rules, the claims that fail under the paper's own condition and how "
            f"each value moves with n: [{CLAIMS_MD}]({CLAIMS_MD})."), "", ledger_table(df, evidence=False), ""]
    return Section("The paper's claims ledger", "\n".join(body))
