"""``report.html``: the interactive page beside report.md -- one self-contained file that
opens offline (plotly.js and the page's own script inlined).

Why Plotly: every cross-figure filter (solver picker, family toggles, scene and profile
filters acting on every chart at once) is one data table redrawn with ``Plotly.react``
from a few lines of plain JavaScript; hover templates and log axes are built in.  The
Python ``plotly`` package is used only for ``get_plotlyjs()`` (the inlined script; the
size and render-time comparison with Bokeh and Vega-Lite is in docs/report.md).

The page holds the table's attempted rows (instance, step, n, kkt_error, p error,
load error, time, iterations, status for the hover) and draws from them, for every
scene present: Fig. 4 / 6 and the CMR figures (time against load, a row at its step's
load as the static figures place it), Fig. 5 (time against n), each step not solved
marked by its status as the static figures mark it (``UNSOLVED_MARKS``), the
counterexample's violation shares, work-precision (kkt_error and p
error against time), the performance profiles and the sortable shifted-geometric-mean
table; then the load-area curve and the convergence traces per family; and, as images,
the static figures that have no interactive twin (the fields, the counterexample case,
the closed-form checks).  Colours are the report's (``ctx.styles``).
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.colors import to_hex

from ..table import aggregates as agg
from ..table.fields import find_fields
from .charts import PLOTLY_DASHES, Chart, RowChart
from .core import (REPORT_TITLE, WARM_SUFFIX, ReportContext, attempted, fmt_num, natural_key, natural_sorted,
                   parse_trace, pick_profile)
from .sections.fields import (BGT_KAPPA, MAX_LOAD_AREA_SERIES, PERSSON_KAPPA, fit_kappa, load_area_series,
                              short_traces, trace_scene, traces_empty_note)
from .sections.generic import (SGM_CAPTION, SOLVED_COLUMNS, best_of_family, family_rank, page_marker_sizes,
                               profile_empty_note, profile_taus, reached_accuracy)
from .sections.paper import UNSOLVED_MARKS, k_of, load_abscissa, unsolved_kind
from .page_script import PAGE_SCRIPT
from .panels import AT_ZERO, MARK_EVERY, curve_notes, iteration_axis
from .style import MAX_SERIES, sort_families
from ..table.files import write_text_atomic
from ..table.schema import as_finite

HTML_NAME = "report.html"
#: What report.html begins with, up to its title (``REPORT_TITLE``: the suite).
HTML_HEAD = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>"


def page_rows(ctx: ReportContext) -> list[dict[str, Any]]:
    """The attempted rows, one dict each, with short keys (the page's data table); ``ref``:
    the row's answer served as its step's reference (``agg.own_reference``: its ``perr`` is
    0 by construction, and the error-in-p chart leaves it out); ``dl``: where the load axis
    places the row, its step's load (``step_loads``: None where no answer at the step was
    solved, and the load charts leave the row out); ``uk``: the ``UNSOLVED_MARKS`` key of a
    row not solved (``unsolved_kind``), None for a solved one."""
    t = attempted(ctx.table)
    warm = t.groupby(["scene", "solver", "profile", "history"])["warm_start"].transform("any").astype(bool)
    loads = step_loads(t)
    out = []
    for (_, r), w, own, dl in zip(t.iterrows(), warm, agg.own_reference(t), loads):
        out.append(dict(sc=r["scene"], inst=r["instance"], st=as_finite(r["step"]), n=as_finite(r["n"]), so=r["solver"],
                        lab=f"{r['solver']}{WARM_SUFFIX}" if w else r["solver"], fa=ctx.family(r["solver"]),
                        pr=r["profile"], stt=r["status"], kkt=as_finite(r["kkt_error"]),
                        uk=None if r["status"] == "solved" else unsolved_kind(r["status"]),
                        perr=as_finite(r["p_rel_error"]), ref=bool(own), lerr=as_finite(r["load_rel_error"]),
                        t=as_finite(r["solve_time_s"]), it=as_finite(r["iterations"]),
                        dl=as_finite(dl), cf=as_finite(r["contact_fraction"]), K=as_finite(k_of(r)),
                        base=r["base_solver"]))
    out.sort(key=lambda d: (d["sc"], natural_key(d["so"]), d["pr"], natural_key(d["inst"]), d["st"] or 0))
    return out


def step_loads(rows: pd.DataFrame) -> pd.Series:
    """Each of ``rows``' place on a load axis, as the static figures place it
    (sections/paper.py ``load_abscissa``): the median P/(E A) of the solved answers at its
    (instance, step) among the rows of its scene and profile; NaN where none there was
    solved (a wrong or late answer's own load would put its point elsewhere)."""
    r = rows.assign(solved=rows["status"] == "solved")
    parts = [load_abscissa(g, g) for _, g in r.groupby(["scene", "profile"], sort=False, dropna=False)]
    return (pd.concat(parts) if parts else pd.Series(dtype=float)).reindex(rows.index)


#: The Plotly symbol of each matplotlib marker of ``UNSOLVED_MARKS`` (the static figure
#: fills the cross and leaves the others open).
PLOTLY_SYMBOLS: dict[str, str] = {"x": "x", "s": "square-open", "D": "diamond-open"}
#: The Plotly symbol of each solver marker (``style.MARKERS``): a solved point on the page's
#: line charts wears its solver's, as in the static figures, so that two shades of one family
#: differ in shape too.  Filled, unlike the open unsolved marks; "X" is an hourglass, so that
#: no solved point wears the KKT failure's cross.
SOLVER_SYMBOLS: dict[str, str] = {"o": "circle", "s": "square", "^": "triangle-up", "D": "diamond",
                                  "v": "triangle-down", "P": "cross", "X": "hourglass", "<": "triangle-left",
                                  ">": "triangle-right", "p": "pentagon", "h": "hexagon", "*": "star"}


def unsolved_marks() -> dict[str, dict[str, str]]:
    """``UNSOLVED_MARKS`` for the page: per kind its Plotly ``symbol``, ``color`` (hex) and
    legend ``label``, in the static figure's order."""
    return {kind: {"symbol": PLOTLY_SYMBOLS[marker], "color": to_hex(color), "label": label}
            for kind, (marker, color, label) in UNSOLVED_MARKS.items()}


def scene_summaries(ctx: ReportContext) -> dict[str, list[tuple[str, list[agg.SolverSummary]]]]:
    """Per scene, per profile (``table.aggregates.profile_parts``: solvers are compared within
    one profile), the aggregate of each solver (``summarize``: its SGM over the cells it was
    planned to run), as report.md's aggregate tables."""
    out = {}
    for scene in ctx.scenes():
        out[scene] = [(p, agg.summarize(r, ctx.shift, natural_sorted(r["solver"].unique())))
                      for p, r in agg.profile_parts(ctx.rows(scene))]
    return out


def scene_leads(ctx: ReportContext, summaries: dict[str, list[tuple[str, list[agg.SolverSummary]]]]
                ) -> dict[str, dict[str, Any]]:
    """Per scene, what its charts draw first when they would hold more than ``MAX_SERIES``
    series (the page's ``thin`` draws the first ``MAX_SERIES`` solvers of ``order``; the other
    series stay in the legend, a click away): ``order``, the scene's solvers with the best of
    each family first (``best_of_family``, as the report's performance-profile panels;
    ``best`` of them), then the others by solved share and SGM (``family_rank``); and
    ``profile``, the report's profile for the scene (``pick_profile``).  A solver is ranked by
    its summary at that profile, else at the first profile it ran at."""
    out = {}
    for scene, parts in summaries.items():
        lead = pick_profile(attempted(ctx.rows(scene)))
        mine: dict[str, agg.SolverSummary] = {}
        for _, summ in sorted(parts, key=lambda ps: ps[0] != lead):
            mine.update({s.solver: s for s in summ if s.solver not in mine and s.sgm_cells})
        for _, summ in parts:
            mine.update({s.solver: s for s in summ if s.solver not in mine})
        best = best_of_family(ctx, mine.values())
        firsts = [best[f] for f in sort_families(best)]
        rest = sorted((s for s in mine if s not in firsts),
                      key=lambda s: (*family_rank(mine[s]), natural_key(s)) if np.isfinite(mine[s].sgm_s)
                      else (np.inf, np.inf, natural_key(s)))
        out[scene] = {"order": firsts + rest, "best": len(firsts), "profile": lead}
    return out


#: The page's aggregate table: its columns (a share's header names its denominator, as
#: report.md's aggregates: sections/generic.py ``SOLVED_COLUMNS``), those shown in per cent,
#: and the column it is sorted by at first.
SGM_COLUMNS: tuple[str, ...] = ("solver", "family", *SOLVED_COLUMNS, "SGM [s]", "SGM / best", "SGM cells",
                                "median kkt (solved)", "false claims")
SGM_PERCENT: tuple[str, ...] = ("solved / problems", "solved / attempted")
SGM_SORT = "SGM / best"


def profiles_and_sgm(ctx: ReportContext, summaries: dict[str, list[tuple[str, list[agg.SolverSummary]]]]
                     ) -> tuple[dict[str, list[dict[str, Any]]], dict[str, list[dict[str, Any]]]]:
    """Per scene, one entry per profile (``scene_summaries``; ``profile`` None where the
    scene ran one): the performance profile curves and the aggregate (SGM) table."""
    pp: dict[str, list[dict[str, Any]]] = {}
    sgm: dict[str, list[dict[str, Any]]] = {}
    for scene in ctx.scenes():
        parts = dict(agg.profile_parts(ctx.rows(scene)))
        for profile, summ in summaries[scene]:
            r = parts[profile]
            named = profile if len(parts) > 1 else None
            acc = reached_accuracy(r)
            cells = agg.cell_table(r, natural_sorted(r["solver"].unique()))
            sgm.setdefault(scene, []).append({
                "profile": named, "problems": len(cells.problems), "columns": [*SGM_COLUMNS], "note": SGM_CAPTION,
                "percent": [SGM_COLUMNS.index(c) for c in SGM_PERCENT], "sort": SGM_COLUMNS.index(SGM_SORT),
                "rows": [[s.solver, ctx.family(s.solver), s.problems, s.attempted, s.solved,
                          as_finite(s.solved_share), as_finite(s.success_rate), as_finite(s.sgm_s),
                          as_finite(s.sgm_rel), s.sgm_cells, as_finite(acc.get(s.solver)), s.false_claims]
                         for s in summ]})
            prof = agg.performance_profile(cells)
            if len(prof.solvers) < 2 or not cells.problems:
                continue
            if empty := profile_empty_note(prof, r):  # the chart says why it has no curve, as report.md does
                pp.setdefault(scene, []).append({"profile": named, "taus": [], "n": prof.n_problems, "curves": {},
                                                 "empty": empty})
                continue
            taus, _ = profile_taus(prof, 120)
            curves = {s: prof.curve(s, taus) for s in prof.solvers}
            pp.setdefault(scene, []).append({
                "profile": named, "taus": [float(x) for x in taus], "n": prof.n_problems,
                "curves": {s: [float(v) for v in c] for s, c in curves.items()},
                "notes": curve_notes(curves, prof.solvers)})  # a curve at 0 or under another, as report.md's
    return pp, sgm


def trace_data(ctx: ReportContext) -> dict[str, Any]:
    """The representative trace of every solver (largest n, tightest profile) in the
    first scene with traces (the Markdown report's trace figure: sections/fields.py ``trace_scene``),
    but those of a single point (``short_traces``: no curve, as in report.md); where that
    leaves none, ``empty`` says why (``traces_empty_note``) and the trace charts write it.
    ``x`` is each point's place on the iteration axis (``iteration_axis``, in ``it_axis``);
    ``same``, where a trace equals an earlier solver's point for point (drawn under it), names
    that solver, and the legend says so."""
    scene, reps = trace_scene(ctx)
    if not reps:
        return {}
    out: dict[str, Any] = {}
    short = set(short_traces(reps))
    for s, row in ((s, row) for s, row in reps.items() if s not in short):
        tr = parse_trace(row["trace"])
        ok = np.isfinite(tr[:, 2]) & (tr[:, 2] > 0)
        out[s] = {"it": tr[ok, 0].tolist(), "t": tr[ok, 1].tolist(), "r": tr[ok, 2].tolist(),
                  "where": f"{row['instance']} step {int(row['step'])} ({row['profile']})"}
    axis = iteration_axis([i for d in out.values() for i in d["it"]])
    seen: list[str] = []
    for s, d in out.items():
        d["x"] = [i + axis["shift"] for i in d["it"]]
        twin = next((t for t in seen if (out[t]["it"], out[t]["r"]) == (d["it"], d["r"])), None)
        if twin is not None:
            d["same"] = twin
        seen.append(s)
    return {"scene": scene, "solvers": out, "it_axis": axis,
            **({"empty": empty} if (empty := traces_empty_note(reps)) else {})}


#: The page's load-area chart: report.md's (sections/fields.py ``_load_area_figure``) title and axes.
LOAD_AREA_TITLE = "load-area curve"
LOAD_AREA_AXES = ("P / (E* A0 h'_rms)  [-]", "A / A0  [-]")


def field_slopes(ctx: ReportContext) -> dict[tuple[str, str], float]:
    """(scene, instance) -> h'_rms of its surface, from the field the report draws for it
    (the highest step's ``arrays/field-*.npz``, as sections/fields.py ``fields_section``)."""
    keys = set(zip(ctx.table["scene"].astype(str), ctx.table["instance"].astype(str)))
    out: dict[tuple[str, str], float] = {}
    for (scene, inst, _), path in sorted(find_fields(ctx.out_dir, keys).items(),
                                         key=lambda kv: (kv[0][0], kv[0][1], -kv[0][2])):
        if (scene, inst) not in out:
            with np.load(path, allow_pickle=False) as z:
                out[(scene, inst)] = float(z["rms_slope"])
    return out


def load_area_data(ctx: ReportContext) -> dict[str, Any]:
    """The page's load-area chart, the numbers report.md's figure draws: per instance of a
    load history with a stored field (``load_area_series``, at most ``MAX_LOAD_AREA_SERIES``),
    A/A0 against P/(E* A0 h'_rms) by step, named with its kappa (``fit_kappa``), and the lines
    of Persson and of Bush-Gibson-Thomas over the same loads; {} where none has a field."""
    slopes = field_slopes(ctx)
    series = []
    for scene, inst, pi in load_area_series(ctx):
        hrms = slopes.get((scene, inst), float("nan"))
        if not (math.isfinite(hrms) and hrms > 0):
            continue
        fit = fit_kappa(pi["dim_load"].to_numpy(), pi["area"].to_numpy(), hrms)
        series.append({"scene": scene, "instance": inst, "x": (pi["dim_load"].to_numpy() / hrms).tolist(),
                       "y": pi["area"].tolist(), "step": pi["step"].tolist(),
                       "name": f"{scene} {inst}" + (f" (kappa = {fmt_num(fit.kappa)})" if math.isfinite(fit.kappa)
                                                    else "")})
    series = series[:MAX_LOAD_AREA_SERIES]
    xs = [x for sr in series for x in sr["x"] if math.isfinite(x) and x > 0]
    if not xs:
        return {}
    x = np.geomspace(min(xs), max(xs), 2)
    lines = [{"name": name, "x": x.tolist(), "y": (k * x).tolist(), "dash": dash}
             for k, name, dash in ((PERSSON_KAPPA, "Persson sqrt(8/pi)", "dash"), (BGT_KAPPA, "BGT sqrt(2 pi)", "dot"))]
    return {"title": LOAD_AREA_TITLE, "x_title": LOAD_AREA_AXES[0], "y_title": LOAD_AREA_AXES[1],
            "series": series, "lines": lines}


def embedded_images(ctx: ReportContext) -> list[dict[str, str]]:
    out = []
    for rel in ctx.page_figures:  # the figures a section saved with on_page=True
        data = base64.b64encode((ctx.fig_dir / Path(rel).name).read_bytes()).decode("ascii")
        out.append({"name": Path(rel).name, "src": f"data:image/png;base64,{data}"})
    return out


def page_data(ctx: ReportContext) -> dict[str, Any]:
    t = ctx.table
    fams = sort_families(ctx.family(s) for s in t["solver"].unique())
    summaries = scene_summaries(ctx)
    pp, sgm = profiles_and_sgm(ctx, summaries)
    return {
        "title": str(ctx.meta.get("suite") or ", ".join(ctx.scenes())),
        "scenes": ctx.scenes(),
        "profiles": natural_sorted(set(attempted(t)["profile"])),
        "families": [{"name": f, "solvers": [{"name": s, "color": ctx.styles.hex(s),
                                              "symbol": SOLVER_SYMBOLS[ctx.marker(s)],
                                              "dash": PLOTLY_DASHES[ctx.dash(s)]} for s in
                                             natural_sorted(x for x in t["solver"].unique() if ctx.family(x) == f)]}
                     for f in fams],
        "lead": scene_leads(ctx, summaries),
        "maxSeries": MAX_SERIES,
        "profileSizes": page_marker_sizes(),
        "markEvery": MARK_EVERY,
        "atZero": AT_ZERO,
        "rows": page_rows(ctx),
        "unsolved": unsolved_marks(),
        "pp": pp,
        "sgm": sgm,
        "traces": trace_data(ctx),
        "loadarea": load_area_data(ctx),
        "images": embedded_images(ctx),
        "charts": [{"scene": pc.scene, **pc.chart.to_plotly()} for pc in ctx.charts if isinstance(pc.chart, Chart)],
        "rowcharts": [{"scene": pc.scene, **asdict(pc.chart)} for pc in ctx.charts if isinstance(pc.chart, RowChart)],
    }


def _json_for_script(obj: Any) -> str:
    """JSON safe inside <script> (no '</' sequence)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def render_html(ctx: ReportContext) -> str:
    from plotly.offline import get_plotlyjs

    data = page_data(ctx)
    title = html.escape(f"{REPORT_TITLE}: {data['title']}")
    return (f"{HTML_HEAD}{title}</title>\n{VIEWPORT}\n"
            f"<style>{PAGE_CSS}{NARROW_CSS}</style>\n<script>{get_plotlyjs()}</script>\n</head><body>\n"
            f"<header><h1>{title}</h1><p>Interactive companion of <a href=\"report.md\">report.md</a> "
            f"(same table, same colours). Pick solvers (a family box toggles the whole family), scenes and "
            f"profiles; a chart of more than {MAX_SERIES} series draws the best solver of each family first "
            f"(by solved share, then SGM) and keeps the rest in its legend, a click away; hover a point for its instance, step, n, errors, time, iterations and status; click a "
            f"table header to sort.</p></header>\n"
            f"<div id=\"layout\"><nav id=\"picker\"></nav><main id=\"charts\"></main></div>\n"
            f"{tables_html(ctx)}"
            f"<script id=\"report-data\" type=\"application/json\">{_json_for_script(data)}</script>\n"
            f"<script>{PAGE_SCRIPT}</script>\n</body></html>\n")


def tables_html(ctx: ReportContext) -> str:
    """The report.md tables marked ``on_page`` (same numbers and cells), as HTML."""
    out = []
    for t in (t for t in ctx.tables if t.on_page):
        head = "".join(f"<th>{html.escape(h)}</th>" for h in t.headers)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in t.rows)
        out.append(f'<div class="tablebox"><table class="sgm"><caption>Table {t.number}: '
                   f"{html.escape(t.caption)}</caption><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>")
    return f'<section id="tables"><h2>Tables (as in report.md)</h2>{"".join(out)}</section>\n' if out else ""


def write_html_report(ctx: ReportContext) -> Path:
    """Write OUT/report.html (atomically); returns its path."""
    path = ctx.out_dir / HTML_NAME
    write_text_atomic(path, render_html(ctx))
    return path


PAGE_CSS = """
html{overflow-y:scroll}
body{font-family:system-ui,sans-serif;margin:0;color:#222}
header{padding:8px 16px;border-bottom:1px solid #ddd}
header h1{font-size:1.2em;margin:4px 0}
header p{margin:4px 0;font-size:.85em;color:#555}
#layout{display:flex;align-items:flex-start}
#picker{width:260px;flex:none;padding:8px 12px;font-size:.8em;position:sticky;top:0;max-height:100vh;overflow:auto;
 border-right:1px solid #ddd}
#picker fieldset{border:1px solid #ddd;margin:0 0 8px 0;padding:4px 8px}
#picker label{display:block;overflow-wrap:anywhere}
#picker .fam{font-weight:bold;margin-top:4px}
#picker .sw{display:inline-block;width:10px;height:10px;margin-right:4px;border-radius:2px}
#charts{flex:1;padding:8px 16px;min-width:0}
.scene{margin-bottom:24px}
.scene h2{font-size:1.05em;border-bottom:1px solid #eee}
.chart{width:100%;height:420px}
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(min(520px,100%),1fr));gap:8px}
.tablebox{overflow-x:auto;max-width:100%}
.note{font-size:.8em;color:#555;margin:4px 0}
#tables{padding:8px 16px}
table.sgm{border-collapse:collapse;font-size:.8em;margin:8px 0}
table.sgm th,table.sgm td{border:1px solid #ddd;padding:2px 6px;text-align:right}
table.sgm th{cursor:pointer;background:#f6f6f6}
table.sgm td:first-child,table.sgm td:nth-child(2){text-align:left}
table.sgm td:first-child{max-width:16em;overflow-wrap:break-word}
img.static{max-width:100%;border:1px solid #eee}
.hidden{display:none}
"""

#: Below this page width (CSS pixels: a phone, a narrow window) the picker stops being a
#: sidebar: it goes above the charts, a box of its own that scrolls, and the charts take the
#: whole width, one per row (a wide table scrolls sideways in its ``.tablebox``).
NARROW_MAX_PX = 800

#: Lays the page out at the device's width (a phone's browser otherwise draws it ~980 px wide,
#: zoomed out, and ``NARROW_CSS`` never applies).
VIEWPORT = '<meta name="viewport" content="width=device-width, initial-scale=1">'
NARROW_CSS = (f"@media (max-width:{NARROW_MAX_PX}px){{"
              "#layout{display:block}"
              "#picker{width:auto;position:static;max-height:40vh;border-right:none;border-bottom:1px solid #ddd}"
              "#picker label{white-space:normal}"
              "#charts{padding:8px}"
              ".grid{grid-template-columns:1fr}"
              ".chart{height:640px}"
              "#tables{padding:8px}"
              "}\n")
