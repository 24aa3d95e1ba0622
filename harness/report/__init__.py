"""The report: read a stored table, write report.md, its figures and report.html.

``view`` reads the stored table as the report does; ``core`` holds the context, the
section registry and the shared helpers; ``sections/``
the sections; ``html`` the interactive page; ``build`` the assembly.  The report reads
the table (harness/table/) and never imports the runner (harness/run/)."""

from __future__ import annotations

from .build import build_report

__all__ = ["build_report"]
