"""Markdown report with PNG figures from a stored tidy table -- it never solves anything.

``build_report(OUT)`` reads the table of ``OUT`` (``schema.load_table``: the columns and
dtypes are harness/table/schema.py's contract) and ``OUT/meta.json`` if present, and writes
``OUT/report.md`` with its figures under ``OUT/figures/``.

This module is the report's core: the context a section gets, the section registry,
the formatting and plotting helpers every section shares and the header; the assembly
is harness/report/build.py.  The sections live in the modules of
harness/report/sections/, found by the registry on first use:

* ``paper.py``            -- Figs. 4, 5, 6 (Bemporad & Paggi 2015, sec. 4), the closed-form checks;
* ``counterexample.py``, ``greedy_kernels.py`` -- Example 1, and its draw on other forms of H;
* ``cmr.py``              -- cascade multi-resolution (sec. 5, Figs. 8-11; its figures in ``cmr_figures.py``);
* ``constrained.py``, ``population.py``, ``stress.py`` -- the load-controlled and hardness-bounded
  sweeps, Monte Carlo population statistics (kappa), the stress battery's survival tables;
* ``claims.py``, ``fields.py`` -- the claims ledger, leading the report; the contact fields,
  the load-area curve and the traces;
* ``generic.py``          -- what every table gets: run time against error,
  aggregates (harness/table/aggregates.py), skips and failures, one table per scene.

Extending: a section is a function ``(ctx, rows) -> Section | None`` registered with
``@register_section("scene-name", title=..., group="paper"|"scenes", order=...)`` in
a module of harness/report/sections/ or in a module named by an entry point of
group ``contactbench.report_sections``.  A scene section is rendered only when its
scene has rows in the table; a ``group="summary"`` section gets the whole table and is
always rendered.  See docs/report.md.

Output is deterministic for a given table and meta.json (sorted rows, fixed number
formats, no clock reads), so two reports diff cleanly.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from contactbench.plugins import PluginRegistry
from contactbench.problems.scenes import all_scenes

from ..table import aggregates as agg
from ..table.meta import cells_text, commands_of, listed
from .charts import Chart, RowChart
from .figure_files import FIGURE_DIR, staging_dir
from .panels import blank_panels, label_short_log_axes
from .markdown_text import md_escape
from .style import DEFAULT_FAMILY, SolverStyles, scene_colors
from ..table.schema import CELL_COLUMNS, STATUSES, TableError, as_finite, as_text

REPORT_NAME = "report.md"
#: The title report.md and report.html begin with ("<title>: <suite>").
REPORT_TITLE = "contactbench report"
#: Values below this are drawn at this floor on log axes (exact zeros, round-off).
LOG_FLOOR = 1e-16
#: Profiles from tightest to loosest (harness/profiles.py): ``pick_profile`` takes the first
#: one present; ``paper`` (tol 1e-8, the paper's epsilon, judged at 1e-6) before ``mid``.
PROFILE_PREFERENCE = ("high", "paper", "mid", "default", "low")
#: The label suffix of a solver's warm-started runs where its cold runs are also shown.
WARM_SUFFIX = " (warm)"

#: The table cannot be reported on (missing file or columns, values outside the contract).
ReportInputError = TableError


# ---------------------------------------------------------------------------
# Context, sections and the registry
# ---------------------------------------------------------------------------


@dataclass
class Section:
    """A report section: a title (## heading), its Markdown body, its charts
    (harness/report/charts.py: drawn under the body in report.md and on report.html) and
    its page charts (drawn by report.html from the scene's rows)."""

    title: str
    body: str
    charts: Sequence[Chart] = ()
    page_charts: Sequence[RowChart] = ()  # drawn on report.html only, from the scene's rows


@dataclass(frozen=True)
class PageChart:
    """A section's chart as report.html shows it: under its scene (or, for a summary
    section, under no scene)."""

    scene: str
    chart: Chart | RowChart


@dataclass(frozen=True)
class TableRecord:
    """A numbered table as ``table_md`` rendered it (kept on the context so that the HTML
    page can show the same cells without computing them again)."""

    number: int
    caption: str
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    align: str
    on_page: bool = False  # also shown on the HTML page (html.py ``tables_html``)


@dataclass
class ReportContext:
    """What a section function gets: the whole table, meta.json, and helpers to save
    figures (``save_figure``), colour solvers consistently (``color``), count tables
    (``next_table``) and format numbers (module functions ``fmt_*``)."""

    out_dir: Path
    table: pd.DataFrame
    meta: dict[str, Any]
    shift: float = agg.DEFAULT_SHIFT_S
    figures: list[str] = field(default_factory=list)
    page_figures: list[str] = field(default_factory=list)
    tables: list[TableRecord] = field(default_factory=list)
    charts: list[PageChart] = field(default_factory=list)
    #: "<figure file>: <panel title>" for every panel saved with nothing finite on it and
    #: no note saying why (harness/report/panels.py); the tests require none.
    blank_panels: list[str] = field(default_factory=list)
    _styles: SolverStyles | None = None
    _own_colors: dict[str, dict[str, str]] = field(default_factory=dict)  # scene -> its ``scene_colors``
    _table_no: int = 0
    _fig_no: int = 0

    @property
    def fig_dir(self) -> Path:  # where this report renders its figures (figure_files.py)
        return staging_dir(self.out_dir)

    def rows(self, scene: str) -> pd.DataFrame:
        return self.table[self.table["scene"] == scene]

    def scenes(self) -> list[str]:
        return sort_scenes(self.table["scene"].unique())

    @property
    def styles(self) -> SolverStyles:
        """Each solver's colour and marker for the whole report (a family shares a hue;
        harness/report/style.py)."""
        if self._styles is None:
            self._styles = SolverStyles(solver_families(self.table), natural_key)
        return self._styles

    def color(self, solver: str, scene: str = "") -> Any:
        """``solver``'s colour; in the figures of ``scene``, the scene's own where its section
        gives one (``style.scene_colors``, read once a report: Fig. 6's K variants)."""
        if scene not in self._own_colors:
            self._own_colors[scene] = scene_colors(self.table, scene)
        name = solver.removesuffix(WARM_SUFFIX)
        return self._own_colors[scene].get(name) or self.styles.color(name)

    def marker(self, solver: str) -> str:
        return self.styles.marker(solver.removesuffix(WARM_SUFFIX))

    def dash(self, solver: str) -> str:
        return self.styles.dash(solver.removesuffix(WARM_SUFFIX))

    def family(self, solver: str) -> str:
        return self.styles.family(solver.removesuffix(WARM_SUFFIX))

    def save_figure(self, fig: Figure, name: str, on_page: bool = False) -> str:
        """Write ``figures/<name>.png`` and return the Markdown-relative path;
        ``on_page``: report.html shows it too, as an image (a figure with no interactive
        twin on the page)."""
        self.fig_dir.mkdir(parents=True, exist_ok=True)
        fname = f"{slug(name)}.png"
        self.blank_panels += [f"{fname}: {title}" for title in blank_panels(fig)]
        label_short_log_axes(fig)
        fig.savefig(self.fig_dir / fname, dpi=110, bbox_inches="tight", metadata={"Software": None})
        rel = f"{FIGURE_DIR}/{fname}"
        self.figures.append(rel)
        if on_page:
            self.page_figures.append(rel)
        return rel

    def figure_md(self, rel: str, caption: str) -> str:
        self._fig_no += 1
        return f"![Figure {self._fig_no}]({rel})\n\n*Figure {self._fig_no}: {caption}*\n"

    def next_table(self) -> int:
        self._table_no += 1
        return self._table_no


SectionFn = Callable[[ReportContext, pd.DataFrame], "Section | None"]
SECTION_GROUPS = ("lead", "paper", "scenes", "summary")


@dataclass(frozen=True)
class SectionSpec:
    """A registered section.  ``group`` "lead" (whole-table sections rendered first, e.g.
    the claims ledger), "paper" (the paper reproductions) or "scenes"
    (other scene studies): rendered when ``scene`` has rows, given those rows; group
    "summary": ``scene`` is just the section's name, and it is given the whole table
    (it may return None to be left out).  ``order`` sorts within the group."""

    scene: str
    title: str
    fn: SectionFn
    group: str = "scenes"
    order: int = 100


def _same_section(old: SectionSpec, new: SectionSpec) -> bool:
    return old.fn is new.fn


_SECTIONS: PluginRegistry[SectionSpec] = PluginRegistry(
    "report section", package="contactbench.harness.report.sections", entry_point_group="contactbench.report_sections",
    same=_same_section)


def register_section(scene: str, *, title: str, group: str = "scenes", order: int = 100,
                     replace: bool = False) -> Callable[[SectionFn], SectionFn]:
    """Decorator: render ``fn(ctx, rows)`` as a section (see SectionSpec)."""
    if group not in SECTION_GROUPS:
        raise ValueError(f"section group must be one of {', '.join(SECTION_GROUPS)}, got {group!r}")

    def deco(fn: SectionFn) -> SectionFn:
        _SECTIONS.add(scene, SectionSpec(scene, title, fn, group, order), replace=replace)
        return fn

    return deco


def unregister_section(scene: str) -> None:
    _SECTIONS.remove(scene)


def registered_sections() -> dict[str, SectionSpec]:
    """All sections, after importing harness/report/sections/ and the entry points of
    group ``contactbench.report_sections`` -- and after the scene registry's discovery
    (problems/scenes, entry points of group ``contactbench.scenes``): a scene module
    that registers its section is read before the sections are."""
    all_scenes()
    return _SECTIONS.all()


def section_import_errors() -> dict[str, str]:
    """Module -> traceback of each section module that failed to import."""
    return _SECTIONS.import_errors()


# ---------------------------------------------------------------------------
# Formatting helpers (shared by every section; deterministic)
# ---------------------------------------------------------------------------


def distinct_colors(k: int) -> list[Any]:
    """``k`` colours of distinct hue: tab10, then Dark2 and Set1 (no light/dark pairs
    as in tab20), cycling beyond 25."""
    import matplotlib

    base = [*matplotlib.colormaps["tab10"].colors, *matplotlib.colormaps["Dark2"].colors,
            *matplotlib.colormaps["Set1"].colors[:7]]
    return [base[i % len(base)] for i in range(k)]


def solver_families(table: pd.DataFrame) -> dict[str, str]:
    """Solver label -> its family (the first non-empty ``family`` of its rows, else
    DEFAULT_FAMILY)."""
    out: dict[str, str] = {}
    for s, f in zip(table["solver"].astype(str), table["family"].astype(str)):
        if f and not out.get(s):
            out[s] = f
        else:
            out.setdefault(s, "")
    return {s: (f or DEFAULT_FAMILY) for s, f in out.items()}


def slug(text: str) -> str:
    """A figure's file name from its name: lower case, each run of characters other than
    letters, digits and ``._+-`` as one "-".  A number keeps its digits, point and the
    sign of its exponent ("HA3e+08" -> "ha3e+08"): the name round-trips its numbers."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "-", text).strip("-").lower() or "x"


def natural_key(text: str) -> tuple:
    """Sort "nnls-gp[K=50]" before "nnls-gp[K=100]"."""
    return tuple((0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", str(text)) if t)


def natural_sorted(items: Iterable[Any]) -> list[Any]:
    return sorted(items, key=lambda s: natural_key(str(s)))


def sort_scenes(scenes: Iterable[str]) -> list[str]:
    return sorted({str(s) for s in scenes}, key=scene_rank)


def scene_rank(scene: str) -> tuple:
    """Sort key of a scene: scenes with a registered section first, in the report's
    order of sections (group, then ``order``); then the others in natural order."""
    spec = registered_sections().get(scene)
    if spec is None or spec.group not in ("paper", "scenes"):
        return (1, 0, 0, natural_key(scene))
    return (0, SECTION_GROUPS.index(spec.group), spec.order, natural_key(scene))


def fmt_num(v: Any, digits: int = 3) -> str:
    """Significant-figure format, a number of 10^digits to 1e5 whole ("3450"); '-' for missing."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "-" if v is None else str(v)
    if not math.isfinite(x):
        return "-" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e5:
        return f"{x:.0f}" if abs(x) >= 10 ** digits else f"{x:.{digits}g}"
    return f"{x:.{max(digits - 1, 0)}e}"


def fmt_err(v: Any) -> str:
    """Errors and residuals: one decimal, exponent form."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "-"
    if not math.isfinite(x):
        return "-" if math.isnan(x) else "inf"
    return "0" if x == 0 else f"{x:.1e}"


def fmt_pct(v: float) -> str:
    return "-" if not (isinstance(v, (int, float)) and math.isfinite(v)) else f"{100 * v:.0f} %"


def fmt_ratio(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.3g}x"


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]], align: str | None = None) -> str:
    """A GitHub Markdown table; ``align`` is one char per column ('l' or 'r')."""
    align = align or ("l" + "r" * (len(headers) - 1))
    sep = ["---:" if a == "r" else ":---" for a in align]
    lines = ["| " + " | ".join(md_escape(h) for h in headers) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(md_escape(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def table_md(ctx: ReportContext, caption: str, headers: Sequence[str], rows: Sequence[Sequence[Any]],
             align: str | None = None, on_page: bool = False) -> str:
    """A numbered, captioned table (also recorded in ``ctx.tables``; ``on_page``: the HTML
    page shows it too)."""
    number = ctx.next_table()
    rows = [tuple(r) for r in rows]
    align = align or ("l" + "r" * (len(headers) - 1))
    ctx.tables.append(TableRecord(number, caption, tuple(str(h) for h in headers),
                                  tuple(tuple(str(c) for c in r) for r in rows), align, on_page))
    return f"*Table {number}: {caption}*\n\n" + markdown_table(headers, rows, align)


# ---------------------------------------------------------------------------
# Reading the table
# ---------------------------------------------------------------------------


def parse_json(text: Any, default: Any) -> Any:
    if not isinstance(text, str) or not text.strip():
        return default
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return default


def parse_trace(text: Any) -> np.ndarray:
    """The ``trace`` column as an (m, 3) array of [iteration, elapsed_s, residual]."""
    t = parse_json(text, [])
    try:
        a = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        return np.empty((0, 3))
    return a if a.ndim == 2 and a.shape[1] >= 3 and len(a) else np.empty((0, 3))


def profile_rank(profile: str) -> tuple:
    """A profile's sort key, tightest first: ``PROFILE_PREFERENCE``, then the others in
    natural order."""
    known = PROFILE_PREFERENCE.index(profile) if profile in PROFILE_PREFERENCE else len(PROFILE_PREFERENCE)
    return known, natural_key(profile)


def pick_profile(rows: pd.DataFrame) -> str:
    """The tightest profile of ``rows`` (``PROFILE_PREFERENCE``, then the others in natural
    order; "" for none); the paper sections pick one per condition (paper_conditions.py)."""
    present = set(rows["profile"])
    for p in PROFILE_PREFERENCE:
        if p in present:
            return p
    return natural_sorted(present)[0] if present else ""


def attempted(rows: pd.DataFrame) -> pd.DataFrame:
    return rows[rows["status"] != "skipped"]


def representative_traces(rows: pd.DataFrame) -> dict[str, pd.Series]:
    """Solver -> its representative traced row: the largest n at the tightest profile
    (then the first instance, step and repeat); solvers without a trace are left out."""
    t = rows[rows["trace"].str.len() > 2]
    rank = {p: i for i, p in enumerate(PROFILE_PREFERENCE)}
    t = t.assign(_pr=t["profile"].map(lambda p: rank.get(p, len(rank))))
    t = t.sort_values(["n", "_pr", "instance", "step", "repeat"], ascending=[False, True, True, True, True],
                      kind="stable")
    return {s: g.iloc[0] for s, g in t.groupby("solver", sort=False)}


def per_cell(rows: pd.DataFrame) -> pd.DataFrame:
    """Fold repeats: min solve time, worst (any unsolved) status, first of the rest."""
    keys = [c for c in CELL_COLUMNS if c in rows.columns]  # (schema: what identifies a cell)
    if rows.empty:
        return rows.assign(solved=pd.Series(dtype=bool))
    r = rows.assign(solved=rows["status"] == "solved", _t=rows["solve_time_s"])
    r = r.sort_values(keys + ["repeat"], kind="stable")
    g = r.groupby(keys, sort=True, dropna=False)
    first = g.first()
    first["solve_time_s"] = g["_t"].min()
    first["solved"] = g["solved"].all()
    first["repeats"] = g.size()
    first["status"] = np.where(first["solved"], "solved", g["status"].agg(lambda s: next(
        (x for x in s if x != "solved"), "solved")))
    return first.reset_index().drop(columns=["_t"])


# ---------------------------------------------------------------------------
# Plotting helpers
# ---------------------------------------------------------------------------


def log_if_wide(ax: Any, axis: str, values: Iterable[float], decades: float = 1.0) -> bool:
    """Log scale on ``axis`` when the positive finite values span more than ``decades``
    (then tidy its tick labels); returns whether it did."""
    v = np.asarray([x for x in values if np.isfinite(x) and x > 0], dtype=float)
    if len(v) and np.log10(v.max() / v.min()) > decades:
        (ax.set_xscale if axis == "x" else ax.set_yscale)("log")
        tidy_log_ticks(ax, axis, float(np.log10(v.max() / v.min())))
        return True
    return False


def tidy_log_ticks(ax: Any, axis: str, span_decades: float) -> None:
    """On a log axis spanning under two decades, label 1-2-5 steps in plain numbers and
    leave minor ticks unlabelled (matplotlib's minor labels collide on narrow panels)."""
    from matplotlib.ticker import LogLocator, NullFormatter

    a = ax.xaxis if axis == "x" else ax.yaxis
    a.set_minor_formatter(NullFormatter())
    if span_decades < 2:
        a.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        a.set_major_formatter(lambda x, _pos: f"{x:g}")


def legend_outside(ax: Any, title: str | None = None) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, title=title,
                  title_fontsize=8, frameon=False)


def new_figure(ncols: int = 1, width: float = 6.4, height: float = 4.0) -> tuple[Figure, list[Any]]:
    fig = Figure(figsize=(width * ncols if ncols > 1 else width, height))
    axes = [fig.add_subplot(1, ncols, i + 1) for i in range(ncols)]
    fig.subplots_adjust(wspace=0.32)  # bbox_inches="tight" trims the outer margins
    return fig, axes


def grid_figure(nrows: int, ncols: int, width: float = 4.6, height: float = 3.4,
                wspace: float = 0.30) -> tuple[Figure, list[list[Any]]]:
    """A figure of ``nrows`` x ``ncols`` panels of ``width`` x ``height`` inches each
    (small multiples); ``axes[i][j]``."""
    fig = Figure(figsize=(width * ncols, height * nrows))
    axes = [[fig.add_subplot(nrows, ncols, i * ncols + j + 1) for j in range(ncols)] for i in range(nrows)]
    fig.subplots_adjust(wspace=wspace, hspace=0.42)
    return fig, axes


def integer_ticks(ax: Any, values: Iterable[float], max_ticks: int = 8) -> None:
    """Label a log x axis at the data's own integer values (e.g. N = 16, 32, 64)."""
    from matplotlib.ticker import FixedLocator, NullFormatter, NullLocator

    v = sorted({float(x) for x in values if np.isfinite(x) and x > 0})
    if 1 < len(v) <= max_ticks:
        ax.xaxis.set_major_locator(FixedLocator(v))
        ax.xaxis.set_major_formatter(lambda x, _pos: f"{x:g}")
        ax.xaxis.set_minor_locator(NullLocator())
        ax.xaxis.set_minor_formatter(NullFormatter())


def floor_log(v: Iterable[float]) -> np.ndarray:
    a = np.asarray(list(v), dtype=float)
    return np.where(np.isfinite(a), np.maximum(a, LOG_FLOOR), np.nan)


# ---------------------------------------------------------------------------
# Header
# ---------------------------------------------------------------------------


def _meta_get(meta: dict[str, Any], *keys: str) -> Any:
    for k in keys:
        cur: Any = meta
        for part in k.split("."):
            cur = cur.get(part) if isinstance(cur, dict) else None
        if cur not in (None, "", {}):
            return cur
    return None


def _fmt_value(v: Any) -> str:
    if isinstance(v, dict):
        return ", ".join(f"{k}={_fmt_value(x)}" for k, x in sorted(v.items()))
    if isinstance(v, (list, tuple)):
        return " ".join(str(x) for x in v)
    return str(v)


def _git_text(m: dict[str, Any]) -> str | None:
    """The commit of each command that wrote to the folder (meta.json's ``invocations``,
    then its own record), distinct, first first: a resume at another commit is named too."""
    commits = [_one_git_text(inv) for inv in listed(m.get("invocations")) if isinstance(inv, dict)]
    return "; ".join(dict.fromkeys(c for c in [*commits, _one_git_text(m)] if c)) or None


def _one_git_text(m: dict[str, Any]) -> str | None:
    commit = _meta_get(m, "git_commit", "git.commit", "commit")
    if commit is None and isinstance(m.get("git"), str):
        commit = m["git"]
    if commit is None:
        return None
    dirty = _meta_get(m, "git.dirty")
    return f"{commit}{' (with uncommitted changes)' if dirty is True else ''}"


def _cores_text(m: dict[str, Any]) -> str | None:
    direct = _meta_get(m, "cores", "cpu_count", "n_cores", "machine.cores")
    if direct is not None:
        return str(direct)
    phys, logi = _meta_get(m, "machine.physical_cores"), _meta_get(m, "machine.logical_cores")
    if phys is None and logi is None:
        return None
    return f"{phys if phys is not None else '?'} physical, {logi if logi is not None else '?'} logical"


def _threads_text(v: Any) -> str | None:
    """meta.json's thread record ({"env": {...}, "threadpools": [...], "fft_workers": k}
    from harness/table/meta.py, or any dict / string) in one line."""
    if v is None:
        return None
    if not isinstance(v, dict) or not ({"env", "threadpools", "fft_workers"} & set(v)):
        return _fmt_value(v)
    parts = [f"{k}={x}" for k, x in sorted((v.get("env") or {}).items()) if x not in (None, "")]
    if v.get("fft_workers") is not None:
        backend = f" ({v['fft_backend']})" if v.get("fft_backend") else ""
        parts.append(f"FFT workers={v['fft_workers']}{backend}")
    for pool in v.get("threadpools") or []:
        if isinstance(pool, dict):
            text = f"{pool.get('internal_api') or pool.get('user_api')}: {pool.get('num_threads')} threads"
            if text not in parts:
                parts.append(text)
    return ", ".join(parts) or None


def _worker_threads_text(meta: dict[str, Any]) -> str | None:
    """The BLAS/FFT threads each solve worker was held to (meta ``config.worker_threads``),
    where the run held them (--threads, or --jobs above 1); else None: the line above holds."""
    k = _meta_get(meta, "config.worker_threads")
    return None if k is None else f"{k} (BLAS and FFT threads of each solve worker; the line above is the parent's)"


def status_counts(t: pd.DataFrame) -> str:
    """"solved 12, skipped 3, ..." in STATUSES order."""
    counts = t["status"].value_counts()
    return ", ".join(f"{s} {int(counts[s])}" for s in STATUSES if s in counts.index)


def grid_sizes(r: pd.DataFrame) -> list[str]:
    """The distinct grids of a scene's rows, smallest first: "N" for a square grid, "N0 x N1"
    for a rectangular one (tables without N0 / N1: N)."""
    if "N0" not in r.columns or r["N0"].isna().all():
        return [str(int(x)) for x in sorted(r["N"].dropna().unique())]
    pairs = sorted({(int(a), int(b)) for a, b in zip(r["N0"], r["N1"]) if not (pd.isna(a) or pd.isna(b))})
    return [str(a) if a == b else f"{a} x {b}" for a, b in pairs]


def map_changes(r: pd.Series, record: dict[str, Any] | None = None) -> str:
    """What was done to one instance's measured map, from its table columns
    (``schema.MAP_COLUMNS``) and its meta.json record (``record``: the unit's scale, the
    shape read, the crop done and the channel read, where the run recorded them): the
    heights' unit, the removed plane or mean, the filled points (of the map as read, and how
    many of them the map as solved keeps), the crop."""
    rec, shape = record or {}, f"{fmt_num(r['N0'])} x {fmt_num(r['N1'])}"
    scale, unit = as_finite(rec.get("metres_per_unit")), as_text(r["height_unit"]) or as_text(rec.get("height_unit"))
    units = (f"heights in {unit} ({rec.get('unit_from', 'as given')}), scaled by {fmt_num(scale)} to metres; "
             if unit and unit != "m" and scale is not None else "")
    detrend = as_text(r["detrend"])
    if detrend == "plane":
        removed = (f"plane removed ({fmt_num(r['removed_mean'])} m at the centre, slopes "
                   f"{fmt_num(r['removed_slope0'])} and {fmt_num(r['removed_slope1'])} rise per length along axes 0 "
                   "and 1)")
    elif detrend == "mean":
        removed = f"mean {fmt_num(r['removed_mean'])} m removed"
    else:
        removed = "nothing removed (detrend none)"
    filled, read = int(as_finite(r["nan_filled"]) or 0), int(as_finite(rec.get("filled")) or 0)
    fill = f"{max(filled, read)} missing points filled ({as_text(r['nan_rule'])})" if filled or read else \
        "no missing point"
    if (filled or read) and rec.get("fill_relative_to") not in (None, "zero"):
        fill = fill[:-1] + f", relative to {rec['fill_relative_to']})"
    if read > filled:  # (the table's nan_filled counts the map as solved: a crop left the others out)
        fill += f", {filled or 'none'} of them in the map as solved (the crop left {read - filled} out)"
    crop = as_text(r["crop"])
    cropped = "" if crop in ("", "none") else f"; {as_text(rec.get('crop_done')) or f'crop {crop}'}"
    channel = f", channel {as_text(rec.get('channel'))!r}" if as_text(rec.get("channel")) else ""
    return (f"`{r['scene']}/{r['instance']}` ({as_text(r['surface_source'])}{channel}, {shape}): {units}{removed}; "
            f"{fill}{cropped}")


def problem_changes(t: pd.DataFrame, meta: dict[str, Any] | None = None) -> str:
    """One clause per instance on a measured map (``map_changes``, with its meta.json
    ``surface_preprocessing`` record); "" when every surface was generated."""
    if "surface_source" not in t.columns:
        return ""
    records = (meta or {}).get("surface_preprocessing") or {}
    maps = t[t["surface_source"].map(as_text) != ""].drop_duplicates(["scene", "instance"])
    return "; ".join(map_changes(r, records.get(f"{r['scene']}/{r['instance']}"))
                     for _, r in maps.sort_values(["scene", "instance"]).iterrows())


def header_section(ctx: ReportContext) -> str:
    m, t = ctx.meta, ctx.table
    scenes = ctx.scenes()
    suite = _meta_get(m, "suite", "name") or ", ".join(scenes)
    lines = [f"# {REPORT_TITLE}: {suite}", ""]
    git = _git_text(m)
    info = [
        ("Scenes", ", ".join(scenes)),
        ("Solvers", ", ".join(natural_sorted(t["solver"].unique()))),
        ("Profiles", ", ".join(p for p in PROFILE_PREFERENCE[::-1] if p in set(t["profile"])) or
         ", ".join(natural_sorted(t["profile"].unique()))),
        ("Rows", f"{len(t)} ({status_counts(t)})"),
        ("Cells", cells_text(m, t)),
        ("Commands" if len(commands_of(m)) > 1 else "Command",
         "; ".join(commands_of(m)) or _meta_get(m, "command", "command_line", "argv")),
        ("Date", _meta_get(m, "date", "started", "timestamp") or "unknown (no meta.json)"),
        ("Git commits" if "; " in (git or "") else "Git commit", git),
        ("Host", _meta_get(m, "host", "hostname", "machine.host")),
        ("CPU", _meta_get(m, "cpu", "machine.cpu", "processor", "cpu_model")),
        ("Cores", _cores_text(m)),
        ("Threads (BLAS/FFT)", _threads_text(_meta_get(m, "threads", "thread_settings", "machine.threads"))),
        ("Threads of each solve", _worker_threads_text(m)),
        ("Platform", _meta_get(m, "platform", "os", "machine.platform")),
        ("Python", _meta_get(m, "python", "python_version", "machine.python")),
        ("Package versions", _meta_get(m, "versions", "packages", "package_versions")),
        ("Problem changes", problem_changes(t, m)),
        ("Run warnings", "; ".join(str(w) for w in listed(m.get("warnings")))),
        ("Report sections that failed to load", ", ".join(section_import_errors())),
    ]
    lines.append(markdown_table(["", ""], [(k, _fmt_value(v)) for k, v in info if v not in (None, "")], "ll"))
    sizes = []
    for sc in scenes:
        r = ctx.rows(sc)
        n = r["n"].dropna()
        grids = grid_sizes(r)
        steps = r["step"].dropna().nunique()
        sizes.append((sc, r["instance"].nunique(), steps, ", ".join(grids) or "-",
                      "-" if n.empty else f"{int(n.min())} - {int(n.max())}",
                      r["solver"].nunique(), len(r)))
    lines.append(f"*Table {ctx.next_table()}: instance sizes per scene (N: grid points per side, N0 x N1 on a "
                 "rectangular grid; n: trial-set "
                 f"size, smallest to largest over instances and steps).*\n")
    lines.append(markdown_table(["scene", "instances", "steps", "N", "n", "solvers", "rows"], sizes, "lrrlrrr"))
    return "\n".join(lines)
