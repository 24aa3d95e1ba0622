"""Assembly of a report: ``build_report(OUT)`` writes OUT/report.md with its figures
under OUT/figures/ and (``html``) the interactive OUT/report.html, from the stored
table and OUT/meta.json.  It never solves anything, and it writes over no file of those
names that a report did not write (harness/report/owned_files.py): it refuses instead.

The sections are the registered ones (harness/report/core.py ``registered_sections``):
a scene section is rendered when its scene has rows, in the order of its group.
"""

from __future__ import annotations

from pathlib import Path

from contactbench.problems.atomic_files import FolderLockedError, folder_lock

from ..arguments import os_error_line
from ..table import aggregates as agg
from ..table.files import write_text_atomic
from ..table.meta import read_meta
from .view import read_table
from .core import (
    REPORT_NAME,
    PageChart,
    ReportContext,
    ReportInputError,
    Section,
    SectionSpec,
    header_section,
    registered_sections,
)
from .figure_files import discard, figure_dir, publish
from .html import write_html_report
from .owned_files import page_names, refuse_foreign
from .panels import EMPTY_NOTE, no_figure


# ---------------------------------------------------------------------------
# Assembly
# ---------------------------------------------------------------------------


def build_report(out_dir: str | Path, shift: float = agg.DEFAULT_SHIFT_S, html: bool = True) -> Path:
    """Write OUT/report.md and OUT/figures/*.png from the stored table, and (``html``)
    the interactive OUT/report.html (harness/report/html.py); return report.md's path."""
    write_report(out_dir, shift, html)
    return Path(out_dir) / REPORT_NAME


def check_pages(out_dir: str | Path, html: bool = True) -> None:
    """``ReportInputError`` (one line) when a report in ``out_dir`` would be refused for a
    page there that no report wrote (``owned_files.refuse_foreign``): a run that builds its
    report asks before it solves."""
    refuse_foreign(Path(out_dir), page_names(html))


def write_report(out_dir: str | Path, shift: float = agg.DEFAULT_SHIFT_S, html: bool = True) -> ReportContext:
    """``build_report``, returning the context it filled: its figures, tables, charts and
    ``blank_panels`` (the panels saved with nothing on them and no note: none is right).
    One report writes in a folder at a time: it holds a lock on OUT/figures/ while it
    stages and publishes, and a second one is refused at once (``ReportInputError``).
    A page or a figure of this report's names that no report wrote is refused too
    (``ReportInputError``, owned_files.py), before anything is written."""
    out = Path(out_dir)
    table = read_table(out)
    if table.empty:
        raise ReportInputError(f"the results table in {out} has no rows")
    ctx = ReportContext(out, table, read_meta(out), shift=shift)
    check_pages(out, html)  # (before the figures folder is made; again under the lock)
    figure_dir(out).mkdir(parents=True, exist_ok=True)
    try:
        with folder_lock(figure_dir(out)):
            _write_locked(ctx, html)
    except FolderLockedError:  # (raised by folder_lock alone)
        raise ReportInputError(f"report {out}: another report is writing in this folder; run this one again "
                               "when it has finished") from None
    return ctx


class ReportWriteError(RuntimeError):
    """A report whose figures or pages could not be written (a full disk): one line naming
    the file (the folder where the system names none); the results are untouched and what
    the report staged is discarded (``cli``: exit 1, not bad input)."""


def _write_locked(ctx: ReportContext, html: bool) -> None:
    """``write_report``'s writing, with the folder's report lock held: whatever a report
    killed part-way staged is discarded first, and this one's staging on failure.  Once the
    figures are rendered, a page or a figure of this report's names that no report wrote
    is refused (``refuse_foreign``) before report.md is written."""
    out = ctx.out_dir
    discard(out)
    pages = page_names(html)
    try:
        text = _render(ctx)
        refuse_foreign(out, pages + ctx.figures)
        write_text_atomic(out / REPORT_NAME, text)
        if html:
            write_html_report(ctx)
    except BaseException as exc:
        discard(out)
        if isinstance(exc, OSError):  # (the table was read before: a write that failed)
            exc.filename = exc.filename or str(out)
            raise ReportWriteError(f"{os_error_line(exc)}; the report was not written, the results are untouched: "
                                   "`contactbench report` writes it again") from None
        raise
    publish(out, [Path(rel).name for rel in ctx.figures])


def _render(ctx: ReportContext) -> str:
    """report.md's text, the figures rendered into the staging folder."""
    sections = registered_sections()
    doc = [header_section(ctx)]
    for sp in _in_order(sections, "lead"):  # whole-table sections that lead the report
        if (sec := sp.fn(ctx, ctx.table)) is not None:
            doc.append(f"## {sec.title}\n\n{sec.body}{charts_md(ctx, '', sec)}")
    scenes = set(ctx.scenes())
    for group, heading in (("paper", "Paper reproductions (Bemporad & Paggi 2015)"), ("scenes", "Scene studies")):
        rendered = [(sp, sec) for sp in _in_order(sections, group) if sp.scene in scenes
                    if (sec := sp.fn(ctx, ctx.rows(sp.scene))) is not None]
        if rendered:
            doc.append(f"## {heading}\n")
            doc += [f"### {sec.title}\n\n{sec.body}{charts_md(ctx, sp.scene, sec)}" for sp, sec in rendered]
    for sp in _in_order(sections, "summary"):
        sec = sp.fn(ctx, ctx.table)
        if sec is not None:
            doc.append(f"## {sec.title}\n\n{sec.body}{charts_md(ctx, '', sec)}")
    return "\n".join(d.rstrip() + "\n" for d in doc)


def charts_md(ctx: ReportContext, scene: str, sec: Section) -> str:
    """Each of the section's charts as a PNG under its body, kept on the context for
    report.html (under ``scene``) with the section's page charts; a chart with no finite
    point that says why (``Chart.notes[EMPTY_NOTE]``) is no PNG but that paragraph
    (``no_figure``; the page writes the note on the chart)."""
    parts = []
    ctx.charts.extend(PageChart(scene, rc) for rc in sec.page_charts)
    for chart in sec.charts:
        ctx.charts.append(PageChart(scene, chart))
        if not chart.has_data and chart.notes.get(EMPTY_NOTE):
            parts.append(no_figure(f"{chart.title}: {str(chart.notes[EMPTY_NOTE]).rstrip('.')}."))
            continue
        parts.append(ctx.figure_md(ctx.save_figure(chart.to_figure(), f"chart-{chart.name}"), chart.title))
    return "\n" + "\n".join(parts) if parts else ""


def _in_order(sections: dict[str, SectionSpec], group: str) -> list[SectionSpec]:
    return sorted((sp for sp in sections.values() if sp.group == group), key=lambda sp: (sp.order, sp.scene))
