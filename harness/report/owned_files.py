"""What a report may write over in its folder.  A report writes report.md, report.html
(when asked for) and its figures under figures/ (figure_files.py); a file of one of those
names that is already there is written over only when a report wrote it.  Any other stops
the report before it writes anything (``refuse_foreign``: one line naming the file, which
is left as it is).

* report.md and report.html are a report's when they begin as a report's page begins
  (``page_starts``: the header ``core.header_section`` writes, the head
  ``html.render_html`` writes).
* A figure is a report's when the record of the last report's figures lists it
  (figure_files.py ``recorded``); in a folder with no such record (one reported before the
  record was kept), when the report's report.md there links it.

The other pages the report's writers make (claims.md, population.md, the stress
battery's README.md) follow the same rule: ``write_own_page`` writes one only where no
file of its name is there, or where the one there begins with the page's own title line
(``title_line``: the page that writer makes); it refuses any other.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Iterable

from ..table.files import begins_with, write_text_atomic
from .core import REPORT_NAME, REPORT_TITLE, ReportInputError
from .figure_files import FIGURE_DIR, MANIFEST, figure_dir, recorded
from .html import HTML_HEAD, HTML_NAME

#: A Markdown image link to a figure, as ``ReportContext.figure_md`` writes it: the file name.
_FIGURE_LINK = re.compile(rf"!\[[^\]]*\]\({re.escape(FIGURE_DIR)}/([^)/]+\.png)\)")


def page_starts() -> dict[str, bytes]:
    """Page name -> the bytes every page of that name a report writes begins with."""
    return {REPORT_NAME: f"# {REPORT_TITLE}: ".encode(), HTML_NAME: f"{HTML_HEAD}{REPORT_TITLE}: ".encode()}


def page_names(html: bool) -> list[str]:
    """The pages a report writes: report.md, and report.html with ``html``."""
    return [REPORT_NAME, HTML_NAME] if html else [REPORT_NAME]


def linked_figures(out: Path) -> set[str]:
    """The figure file names OUT/report.md links, when a report wrote it (else none)."""
    path = out / REPORT_NAME
    if not begins_with(path, page_starts()[REPORT_NAME]):
        return set()
    return set(_FIGURE_LINK.findall(path.read_text(encoding="utf-8", errors="replace")))


def foreign_files(out: Path, names: Iterable[str]) -> list[Path]:
    """The files among ``names`` (paths relative to OUT: a page name, or
    ``figures/<name>.png``) that are there and that no report wrote (module doc), in the
    order given."""
    starts = page_starts()
    ours_figures: set[str] | None = None
    foreign = []
    for rel in names:
        path = out / rel
        if not os.path.lexists(path):
            continue
        if rel in starts:
            ours = begins_with(path, starts[rel])
        elif Path(rel).parent == Path(FIGURE_DIR):
            if ours_figures is None:
                has_record = os.path.lexists(figure_dir(out) / MANIFEST)
                ours_figures = recorded(out) if has_record else linked_figures(out)
            ours = path.is_file() and not path.is_symlink() and path.name in ours_figures
        else:
            ours = False
        if not ours:
            foreign.append(path)
    return foreign


def refuse_foreign(out: Path, names: Iterable[str]) -> None:
    """``ReportInputError`` (one line, naming the first) when a file among ``names`` is
    there and no report wrote it (``foreign_files``); nothing is written or removed."""
    foreign = foreign_files(out, names)
    if foreign:
        more = f" (and {len(foreign) - 1} more such file{'s' if len(foreign) > 2 else ''})" if len(foreign) > 1 else ""
        raise ReportInputError(f"report {out}: {foreign[0]} was not written by a report and would be written over"
                               f"{more}; move it away to report in this folder (nothing was written)")


def title_line(title: str) -> str:
    """The first line of a page titled ``title``: its Markdown heading."""
    return f"# {title}\n"


def refuse_foreign_page(path: Path, title: str) -> None:
    """``ReportInputError`` (one line naming ``path``) when a file is there that is not a
    page titled ``title`` (it does not begin with ``title_line``, or it is a link or a
    folder): nothing is written or removed."""
    if not os.path.lexists(path):
        return
    if not begins_with(path, title_line(title).encode()):
        raise ReportInputError(f"report {path.parent}: {path} was not written by a report and would be written over; "
                               "move it away to report in this folder (nothing was written)")


def write_own_page(path: Path, title: str, body: str) -> Path:
    """Write the page ``title_line(title) + body`` at ``path`` (whole or not at all),
    unless a file there is not such a page (``refuse_foreign_page``).  Returns ``path``."""
    refuse_foreign_page(path, title)
    write_text_atomic(path, title_line(title) + body)
    return path
