"""The report's figure files: which PNGs under OUT/figures/ a report owns, and how a new
report replaces the last one's without touching anything else.

* A report renders its figures into a staging folder, OUT/figures/.staging/ (``staging_dir``),
  so that a report that fails part-way leaves the last report's figures as they were
  (``discard``).
* Once report.md (and report.html) are written, ``publish`` moves the staged PNGs into
  OUT/figures/, removes those the last report wrote that this one did not, and records the
  names it wrote in OUT/figures/.report-figures.json (``MANIFEST``).
* A PNG that no report of ours recorded -- the user's own, or one in a folder written before
  the manifest existed -- is never removed; a report that would write one of its name is
  refused before it writes anything (harness/report/owned_files.py), except in a folder
  with no manifest, where the PNGs the last report.md links are the report's own.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from ..table.files import write_text_atomic

#: The folder of a report's figures, relative to OUT (the Markdown links read it).
FIGURE_DIR = "figures"
#: Where a report renders its figures until it is written, inside ``FIGURE_DIR``.
STAGING = ".staging"
#: The names of the PNGs the last report wrote, inside ``FIGURE_DIR``.
MANIFEST = ".report-figures.json"


def figure_dir(out: Path) -> Path:
    return out / FIGURE_DIR


def staging_dir(out: Path) -> Path:
    return figure_dir(out) / STAGING


def recorded(out: Path) -> set[str]:
    """The PNG names the last published report recorded (none when it recorded nothing, or
    the record cannot be read: then nothing is removed as stale)."""
    try:
        names = json.loads((figure_dir(out) / MANIFEST).read_text())
    except (OSError, ValueError):
        return set()
    if not isinstance(names, list):
        return set()
    return {n for n in names if isinstance(n, str) and n.endswith(".png") and Path(n).name == n}


def publish(out: Path, written: list[str]) -> None:
    """Move the staged PNGs ``written`` (file names) into OUT/figures/, remove the PNGs the
    last report recorded that are not among them, and record ``written``."""
    final, stage = figure_dir(out), staging_dir(out)
    names = sorted(set(written))
    final.mkdir(parents=True, exist_ok=True)
    for name in names:
        os.replace(stage / name, final / name)
    for old in sorted(recorded(out) - set(names)):
        (final / old).unlink(missing_ok=True)
    write_text_atomic(final / MANIFEST, json.dumps(names, indent=0) + "\n")
    discard(out)


def discard(out: Path) -> None:
    """Remove the staging folder and whatever a report left in it."""
    shutil.rmtree(staging_dir(out), ignore_errors=True)
