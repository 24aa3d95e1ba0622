"""MkDocs hooks of the user's guide (mkdocs.yml ``hooks``).

* The column glossary: ``docs/columns.md`` holds the marker ``GLOSSARY_MARKER``; the
  build replaces it by ``glossary_markdown()``, one row per column of
  ``contactbench.harness.table.schema.COLUMNS`` (name, dtype, meaning from the schema, the
  longer definition from the schema's module doc where it gives one) plus its unit from
  ``UNITS`` -- the one home of the units.  Meanings live only in harness/table/schema.py.
* The API sources: mkdocstrings reads the code statically from ``API_SOURCES``, where
  ``stage_api_sources`` links the installed layout (``contactbench/`` with the floors
  ``problems/``, ``solvers/``, ``harness/`` inside it, as pyproject.toml's package-dir maps
  them).
* The report figures: every ``results/<run>/figures/*.png`` of ``FIGURE_RUNS`` becomes the
  site file ``report-figures/<run>/<name>.png``, so docs/figures.md shows the committed
  figures without copying them into docs/.

Importable without MkDocs (tests/docs/test_docs_site.py calls ``glossary_markdown``).
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

from contactbench.harness.table import schema

REPO = Path(__file__).resolve().parents[2]
GLOSSARY_MARKER = "<!-- glossary: generated from harness/table/schema.py -->"
FIGURE_RUNS: tuple[str, ...] = ("default", "cmr")
FIGURE_URL = "report-figures"
API_SOURCES = REPO / "build" / "docs-api"  # mkdocs.yml: mkdocstrings' ``paths``
FLOORS: tuple[str, ...] = ("problems", "solvers", "harness")

#: The unit of every column ("-" for labels and flags, "1" for dimensionless figures).  Lengths,
#: forces and moduli are SI as the scenes build them (the counterexample: arbitrary units).
UNITS: dict[str, str] = {
    "scene": "-", "instance": "-", "step": "count", "delta": "m", "n": "count",
    "solver": "-", "profile": "-", "repeat": "count", "warm_start": "-", "status": "-",
    "skip_reason": "-", "build_time_s": "s", "solve_time_s": "s", "iterations": "count",
    "primal_residual": "1 (scaled)", "dual_residual": "1 (scaled)", "complementarity": "1 (scaled)",
    "kkt_error": "1 (scaled)", "load": "N", "load_rel_error": "1", "p_rel_error": "1",
    "contact_fraction": "1", "contact_uncertain": "1", "peak_mem_mb": "MiB", "cell_id": "-", "base_solver": "-", "params": "JSON",
    "family": "-", "solver_status": "-", "solver_converged": "-", "solver_message": "-",
    "correct_claim": "-", "check_tol": "1 (scaled)", "solve_time_min_s": "s", "solve_time_median_s": "s",
    "solver_internal_time_s": "s", "setup_time_s": "s", "matvecs": "count",
    "complementarity_sum": "1 (scaled)", "objective": "N m", "dim_load": "1",
    "E": "Pa", "nominal_area": "m^2", "N": "count", "kernel": "-",
    "periodic": "-", "operator": "-", "reference_solver": "-", "analytic_load": "N",
    "analytic_load_rel_error": "1", "time_limit_s": "s", "error": "-", "trace": "JSON", "host": "-",
    "timestamp": "ISO 8601", "history": "-", "verdict": "-", "warmup": "-",
    "surface_family": "-", "hurst": "-", "seed": "-", "control": "-", "hardness": "Pa", "load_residual": "1",
    "plastic_fraction": "1", "variant": "-",
    "N0": "count", "N1": "count", "delta0": "m", "delta1": "m", "thickness": "m", "nu": "1", "interface": "-",
    "surface_source": "-", "surface_hash": "-", "channel_index": "-", "height_unit": "-", "nan_rule": "-", "nan_filled": "count",
    "detrend": "-", "removed_mean": "m", "removed_slope0": "1", "removed_slope1": "1", "crop": "-",
    "plastic_uncertain": "1", "solved_hash": "-",
}


def schema_definitions(doc: str | None = None) -> dict[str, str]:
    """The "Definitions of the less obvious figures" of the schema's module doc, by column:
    a line that starts with a column name opens a definition, indented lines continue it."""
    text = schema.__doc__ if doc is None else doc
    head = "Definitions of the less obvious figures"
    if not text or head not in text:
        return {}
    body = text.split(head, 1)[1].split("\n", 2)[-1]  # drop the heading and its underline
    out: dict[str, str] = {}
    name = ""
    for line in body.splitlines():
        m = re.match(r"^(\S+)\s+(.*)$", line)
        if m and m.group(1) in schema.COLUMNS:
            name = m.group(1)
            out[name] = m.group(2).strip()
        elif name and line[:1].isspace() and line.strip():
            out[name] += " " + line.strip()
        else:  # a blank line, or an unindented line that names no column, ends a definition
            name = ""
    return out


def _cell(text: str) -> str:
    """``rst`` literals as Markdown code; pipes escaped for a table cell."""
    return text.replace("``", "`").replace("|", "\\|")


def glossary_rows() -> list[tuple[str, str, str, str, str]]:
    """(column, dtype, unit, meaning, required/extra) per schema column, in table order.
    A column without a unit in ``UNITS`` raises KeyError: every column gets one."""
    defs = schema_definitions()
    rows = []
    for c in schema.COLUMNS.values():
        meaning = _merge(c.doc, defs.get(c.name, ""))
        for word, values in (("STATUSES", schema.STATUSES), ("VERDICTS", schema.VERDICTS)):
            meaning = re.sub(rf"\b{word}\b", "/".join(values), meaning)
        rows.append((c.name, c.dtype, UNITS[c.name], meaning, "required" if c.required else "extra"))
    return rows


def _merge(doc: str, definition: str) -> str:
    """The column's one-line doc and its longer definition, without saying a thing twice."""
    if not definition:
        return doc
    if definition.lower().startswith(doc.lower()):
        return definition
    return f"{doc}: {definition}"


def glossary_markdown() -> str:
    """The glossary table of docs/columns.md."""
    lines = ["| column | dtype | unit | meaning and rule | set |", "| :--- | :--- | :--- | :--- | :--- |"]
    for name, dtype, unit, meaning, kind in glossary_rows():
        lines.append(f"| `{name}` | {dtype} | {unit} | {_cell(meaning)} | {kind} |")
    return "\n".join(lines) + "\n"


def figure_sources() -> dict[str, Path]:
    """Site path -> committed figure, for every PNG of the runs in ``FIGURE_RUNS``."""
    out: dict[str, Path] = {}
    for run in FIGURE_RUNS:
        for png in sorted((REPO / "results" / run / "figures").glob("*.png")):
            out[f"{FIGURE_URL}/{run}/{png.name}"] = png
    return out


def stage_api_sources(root: Path = API_SOURCES) -> Path:
    """``root/contactbench``: links to contactbench/*.py and to the three floors, the
    package layout of the install; rebuilt from scratch each time."""
    pkg = root / "contactbench"
    if pkg.exists():
        shutil.rmtree(pkg)
    pkg.mkdir(parents=True)
    for f in sorted((REPO / "contactbench").glob("*.py")):
        (pkg / f.name).symlink_to(f)
    for floor in FLOORS:
        (pkg / floor).symlink_to(REPO / floor, target_is_directory=True)
    return pkg


# ---------------------------------------------------------------------------
# MkDocs event hooks
# ---------------------------------------------------------------------------


def on_startup(command: str, dirty: bool) -> None:
    # Before any plugin's on_config: mkdocstrings fixes its search paths there.
    stage_api_sources()


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    for uri, path in figure_sources().items():
        files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if page.file.src_uri == "columns.md":
        if GLOSSARY_MARKER not in markdown:
            raise ValueError(f"docs/columns.md lost its marker {GLOSSARY_MARKER!r}")
        return markdown.replace(GLOSSARY_MARKER, glossary_markdown())
    return markdown
