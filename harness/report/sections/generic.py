"""The report's summary sections, rendered for every table whatever its scenes: run time
against error (work-precision, with solver traces), aggregates (success and correct
rates, shifted geometric means and Dolan-More performance profiles from
harness/table/aggregates.py), skips and failures, and one table per scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from ...table import aggregates as agg
from ..panels import mark_empty
from ..style import GREY, MAX_SERIES, Panel, family_panels, panels_note
from ..core import (
    LOG_FLOOR,
    PROFILE_PREFERENCE,
    ReportContext,
    Section,
    attempted,
    floor_log,
    fmt_err,
    grid_figure,
    fmt_num,
    fmt_pct,
    legend_outside,
    log_if_wide,
    natural_key,
    natural_sorted,
    parse_trace,
    per_cell,
    register_section,
    representative_traces,
    scene_rank,
    table_md,
)

MAX_TABLE_ROWS = 80
MAX_FAILURE_ROWS = 40


def reached_accuracy(rows: pd.DataFrame) -> dict[str, float]:
    """Solver -> median kkt_error over its solved rows (the accuracy its times bought)."""
    ok = rows[(rows["status"] == "solved") & rows["kkt_error"].notna()]
    return {str(k): float(v) for k, v in ok.groupby("solver")["kkt_error"].median().items()}


# ---------------------------------------------------------------------------
# Run time against error
# ---------------------------------------------------------------------------

_PROFILE_MARKERS = {"low": "v", "default": "o", "mid": "s", "high": "^"}


@register_section("work-precision", title="Run time against error", group="summary", order=10)
def work_precision_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    parts = ["Each point is one solve: solve time against the harness's scaled `kkt_error` (left) and against "
             "the error in p relative to the scene's reference (right); marker shape = profile. Lines are "
             "the solver's own convergence trace (its residual, which is not the same figure as kkt_error) "
             "for one representative solve: the largest n at the tightest profile. Values below "
             f"{LOG_FLOOR:g} are drawn at {LOG_FLOOR:g}. Colours are fixed per solver in the whole report; a "
             f"family shares a hue. A scene with more than {MAX_SERIES} solvers gets one row of panels per "
             "family, the other families drawn in light grey.\n"]
    for scene in ctx.scenes():
        r = attempted(ctx.rows(scene))
        r = r[r["solve_time_s"].notna() & (r["solve_time_s"] > 0)]
        if r.empty:
            parts.append(f"### {scene}\n\nNo attempted solve with a time.\n")
            continue
        solvers = natural_sorted(r["solver"].unique())
        panels = family_panels(solvers, ctx.family)
        fig, axes = grid_figure(len(panels), 2, width=4.8, height=3.5, wspace=0.35)
        traced: dict[str, str] = {}
        for (a1, a2), panel in zip(axes, panels):
            _wp_panel(ctx, a1, a2, r, panel, traced)
            if len(panels) > 1:
                a1.set_title(f"{scene}, {panel.title}: KKT error", fontsize=9)
                a2.set_title(f"{scene}, {panel.title}: error against reference", fontsize=9)
            else:
                a1.set_title(f"{scene}: KKT error", fontsize=9)
                a2.set_title(f"{scene}: error against reference", fontsize=9)
        rel = ctx.save_figure(fig, f"wp-{scene}")
        cap = f"run time against error, scene `{scene}` ({len(r)} solves, {len(solvers)} solvers)."
        cap += panels_note(panels)
        if traced:
            cap += " Traces: " + ", ".join(traced[s] for s in solvers if s in traced) + "."
        parts.append(f"### {scene}\n\n" + ctx.figure_md(rel, cap))
    return Section("Run time against error", "\n".join(parts))


def _wp_points(ctx: ReportContext, a1: Any, a2: Any, c: pd.DataFrame, color: Any, size: float, alpha: float,
               hollow_failed: bool = True) -> None:
    for prof in natural_sorted(c["profile"].unique()):
        cp = c[c["profile"] == prof]
        mk = _PROFILE_MARKERS.get(prof, "D")
        for ok, face in ((True, color), (False, "none" if hollow_failed else color)):
            cs = cp[(cp["status"] == "solved") == ok]
            if cs.empty:
                continue
            for a, col in ((a1, "kkt_error"), (a2, "p_rel_error")):
                a.scatter(cs["solve_time_s"], floor_log(cs[col]), s=size, marker=mk, facecolors=face,
                          edgecolors=color, linewidths=0.8, alpha=alpha)


def _wp_panel(ctx: ReportContext, a1: Any, a2: Any, r: pd.DataFrame, panel: Panel, traced: dict[str, str]) -> None:
    """One row of the work-precision figure: every solve of the scene in grey, the
    panel's solvers in their colours with their representative traces."""
    others = r[~r["solver"].isin(panel.solvers)]
    if len(others):
        _wp_points(ctx, a1, a2, others, GREY, 8, 0.6, hollow_failed=False)
    xs, y1, y2 = list(r["solve_time_s"]), list(floor_log(r["kkt_error"])), list(floor_log(r["p_rel_error"]))
    for s in panel.solvers:
        c = r[r["solver"] == s]
        _wp_points(ctx, a1, a2, c, ctx.color(s), 16, 0.8)
        rep = representative_traces(c).get(s)
        if rep is not None:
            tr = parse_trace(rep["trace"])
            ok = (tr[:, 1] > 0) & np.isfinite(tr[:, 2])
            a1.plot(tr[ok, 1], floor_log(tr[ok, 2]), lw=1.0, color=ctx.color(s), alpha=0.8)
            xs += list(tr[ok, 1])
            y1 += list(floor_log(tr[ok, 2]))
            traced[s] = f"`{s}` ({rep['instance']}, step {int(rep['step'])}, {rep['profile']})"
        a1.plot([], [], ls="none", marker="s", color=ctx.color(s), label=s)
    for prof in [p for p in PROFILE_PREFERENCE[::-1] if p in set(r["profile"])] + \
            natural_sorted(set(r["profile"]) - set(PROFILE_PREFERENCE)):
        a1.plot([], [], ls="none", marker=_PROFILE_MARKERS.get(prof, "D"), color="gray", label=f"profile {prof}")
    if (r["status"] != "solved").any():
        a1.plot([], [], ls="none", marker="o", mfc="none", color="gray", label="hollow: not solved")
    if panel.solvers and any(s in traced for s in panel.solvers):
        a1.plot([], [], color="gray", lw=1.0, label="trace (own residual)")
    if len(others):
        a1.plot([], [], ls="none", marker="o", color=GREY, label="other families")
    for a, lab, ys in ((a1, "scaled KKT error  [-]", y1), (a2, "||p - p_ref||_inf / ||p_ref||_inf  [-]", y2)):
        a.set_xlabel("solve time  [s]")
        a.set_ylabel(lab, fontsize=8)
        a.grid(True, which="major", alpha=0.3)
        if not np.any(np.isfinite(ys)):
            continue  # nothing drawn here (no reference error): log axes would have no limits
        log_if_wide(a, "x", xs)
        if not log_if_wide(a, "y", ys, decades=0.0):
            a.set_yscale("log")  # a single error level: still an error axis
    if r["p_rel_error"].notna().sum() == 0:  # no axes to read: say why the panel is empty
        a2.set_xlabel("")
        a2.set_ylabel("")
        mark_empty(a2, "no reference solution in this run\n(run without --reference none\nto see the error in p)")
    h, lbl = a1.get_legend_handles_labels()
    a2.legend(h, lbl, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7, frameon=False)


# ---------------------------------------------------------------------------
# Aggregates
# ---------------------------------------------------------------------------


@register_section("aggregates", title="Aggregates across instances", group="summary", order=20)
def aggregates_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    parts = [f"Per scene. A problem is one (instance, step, profile). **Success**: the harness's KKT check "
             f"passes at the profile's `check_tol` (status `solved`), over attempted cells. **Correct**: the "
             f"solver's own convergence claim agrees with that verdict, over attempted rows with a claim; "
             f"**false claims** count rows claiming convergence that fail the check. **SGM**: shifted geometric "
             f"mean of solve time, shift s = {fmt_num(ctx.shift)} s, exp(mean(log(t + s))) - s, relative to the "
             f"best solver of the scene; every cell that is not solved (failed, inaccurate, timeout, crashed, "
             f"skipped or not run) counts at its time limit. Repeats: a cell is solved when every repeat is, at "
             f"the minimum time. **Performance profile** (Dolan & More 2002): the fraction of problems a "
             f"solver solves within tau times the best solver's time.\n"]
    for scene in ctx.scenes():
        r = ctx.rows(scene)
        summ = agg.summarize(r, ctx.shift, natural_sorted(r["solver"].unique()))
        cells = agg.cell_table(r, natural_sorted(r["solver"].unique()))
        parts.append(f"### {scene}\n")
        acc = reached_accuracy(r)
        rows_t = [(s.solver, s.problems, s.attempted, s.solved, fmt_pct(s.success_rate),
                   f"{fmt_pct(s.correct_rate)} ({s.claim_rows})", s.false_claims, fmt_num(s.sgm_s),
                   fmt_num(s.sgm_rel), fmt_err(acc.get(s.solver, np.nan)))
                  for s in sorted(summ, key=lambda s: natural_key(s.solver))]
        parts.append(table_md(ctx, f"aggregates, scene `{scene}` ({len(cells.problems)} problems; SGM shift "
                                   f"{fmt_num(ctx.shift)} s). A solved cell passed the profile's KKT check, but "
                                   f"solvers stop at their own tolerances: the last column is the median "
                                   f"kkt_error of the solver's solved cells, the accuracy its times were bought at.",
                              ["solver", "problems", "attempted", "solved", "success", "correct (rows)",
                               "false claims", "SGM [s]", "SGM / best", "median kkt (solved)"], rows_t,
                              "lrrrrrrrrr"))
        prof = agg.performance_profile(cells)
        if len(prof.solvers) >= 2 and cells.problems:
            parts.append(_profile_figure(ctx, scene, prof, {x.solver: x.sgm_s for x in summ}))
    parts.append("### All scenes\n")
    t = table
    summ = agg.summarize(t, ctx.shift, natural_sorted(t["solver"].unique()), with_time=False)
    parts.append(table_md(ctx, "success and correct rates over every scene (no time aggregate across scenes: "
                               "solvers do not all run on the same problems).",
                          ["solver", "attempted", "solved", "success", "correct (rows)", "false claims"],
                          [(s.solver, s.attempted, s.solved, fmt_pct(s.success_rate),
                            f"{fmt_pct(s.correct_rate)} ({s.claim_rows})", s.false_claims)
                           for s in sorted(summ, key=lambda s: natural_key(s.solver))], "lrrrrr"))
    return Section("Aggregates across instances", "\n".join(parts))


def best_of_family(ctx: ReportContext, score: dict[str, float]) -> dict[str, str]:
    """Family -> its solver with the smallest finite ``score`` (e.g. SGM; ties by name)."""
    best: dict[str, str] = {}
    for s in natural_sorted(score):
        v = score[s]
        if not np.isfinite(v):
            continue
        f = ctx.family(s)
        if f not in best or v < score[best[f]]:
            best[f] = s
    return best


def profile_taus(prof: agg.PerformanceProfile, points: int) -> tuple[np.ndarray, float]:
    """The tau axis of a performance profile: ``points`` geometric steps from 1 to
    ``hi`` (1.5 x the largest finite ratio, at least 2) plus every ratio in that range,
    so each step of a curve is drawn where it happens; returns (taus, hi)."""
    hi = max(2.0, prof.max_finite_ratio() * 1.5)
    taus = np.unique(np.concatenate([np.geomspace(1.0, hi, points),
                                     *[r[np.isfinite(r)] for r in prof.ratios.values()]]))
    return taus[(taus >= 1.0) & (taus <= hi)], hi


def _profile_figure(ctx: ReportContext, scene: str, prof: agg.PerformanceProfile, sgm: dict[str, float]) -> str:
    taus, hi = profile_taus(prof, 200)
    panels = family_panels(list(prof.solvers), ctx.family, best_of_family(ctx, sgm))
    ncols = 1 if len(panels) == 1 else 2
    nrows = -(-len(panels) // ncols)
    fig, axes = grid_figure(nrows, ncols, width=6.0 if ncols == 1 else 5.6, height=4.0 if ncols == 1 else 3.5,
                            wspace=0.85)
    flat = [a for row in axes for a in row]
    curves = {s: prof.curve(s, taus) for s in prof.solvers}
    for ax, panel in zip(flat, panels):
        if len(panels) > 1:
            for s in prof.solvers:
                if s not in panel.solvers:
                    ax.step(taus, curves[s], where="post", color=GREY, lw=0.8)
        for s in panel.solvers:
            ax.step(taus, curves[s], where="post", color=ctx.color(s), ls=ctx.dash(s), lw=1.5, label=s)
        ax.set_xscale("log", base=2)
        ax.set_xlim(1.0, hi)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("tau: within tau x the best time  [-]", fontsize=8)
        ax.set_ylabel("fraction of problems solved  [-]", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        where = "" if len(panels) == 1 else f", {panel.title}"
        ax.set_title(f"performance profile, {scene}{where} ({prof.n_problems} problems)", fontsize=9)
        legend_outside(ax, "solver")
    for ax in flat[len(panels):]:
        ax.set_visible(False)
    rel = ctx.save_figure(fig, f"pp-{scene}")
    note = panels_note(panels).replace("best solver of each family", "best solver of each family by SGM")
    return ctx.figure_md(rel, f"Dolan-More performance profile, scene `{scene}`: rho(1) is the share of problems on "
                              f"which a solver is fastest among those that pass the same KKT check; the right "
                              f"end is its success share.{note}"
                              + (f" Not drawn, skipped on every problem (the skips say why): "
                                 f"{', '.join(prof.left_out)}." if prof.left_out else ""))


# ---------------------------------------------------------------------------
# Skips and failures
# ---------------------------------------------------------------------------


@register_section("skips", title="Skips and failures", group="summary", order=30)
def skips_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    t = table
    parts = []
    sk = t[t["status"] == "skipped"]
    if sk.empty:
        parts.append("No pair was skipped.\n")
    else:
        g = sk.groupby(["scene", "solver", "skip_reason"], sort=False)
        rows_t = sorted(((sc, so, len(x), x["instance"].nunique(), re_ or "(no reason recorded)")
                         for (sc, so, re_), x in g),
                        key=lambda r: (scene_rank(r[0]), natural_key(r[1]), r[4]))
        parts.append(table_md(ctx, "skipped pairs, by scene, solver and reason (rows: skipped cells; instances: "
                                   "distinct instances).", ["scene", "solver", "rows", "instances", "reason"],
                              rows_t, "llrrl"))
    bad = t[t["status"].isin(["failed", "timeout", "crashed"])]
    if bad.empty:
        parts.append("No solve failed, timed out or crashed.\n")
    else:
        bad = bad.sort_values(["scene", "solver", "profile", "instance", "step", "repeat"], kind="stable",
                              key=lambda c: c.map(natural_key) if c.dtype == object else c)
        rows_t = [(r.scene, r.solver, r.profile, r.instance, fmt_num(r.step), r.status,
                   _short(r.error or r.solver_message)) for r in bad.head(MAX_FAILURE_ROWS).itertuples()]
        cap = "solves that failed (raised), timed out or crashed"
        if len(bad) > MAX_FAILURE_ROWS:
            cap += f" (first {MAX_FAILURE_ROWS} of {len(bad)})"
        parts.append(table_md(ctx, cap + ".", ["scene", "solver", "profile", "instance", "step", "status", "error"],
                              rows_t, "llllrll"))
    ina = t[t["status"] == "inaccurate"]
    if len(ina):
        g = ina.groupby(["scene", "solver", "profile"], sort=True)
        rows_t = [(sc, so, pr, len(x), fmt_err(x["kkt_error"].max()), fmt_err(x["check_tol"].max()))
                  for (sc, so, pr), x in g]
        rows_t.sort(key=lambda r: (natural_key(r[0]), natural_key(r[1]), r[2]))
        parts.append(table_md(ctx, "inaccurate answers (returned, but the KKT check failed at the profile's "
                                   "tolerance).", ["scene", "solver", "profile", "rows", "worst kkt_error",
                                                   "check_tol"], rows_t, "lllrrr"))
    return Section("Skips and failures", "\n".join(parts))


def _short(text: str, n: int = 90) -> str:
    line = str(text).strip().splitlines()[-1] if str(text).strip() else ""
    return line if len(line) <= n else line[: n - 3] + "..."


# ---------------------------------------------------------------------------
# Per-scene tables
# ---------------------------------------------------------------------------


@register_section("scene-tables", title="Tables per scene", group="summary", order=40)
def scene_tables_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    parts = []
    for scene in ctx.scenes():
        r = attempted(ctx.rows(scene))
        parts.append(f"### {scene}\n")
        if r.empty:
            parts.append("Every pair was skipped (see Skips and failures).\n")
            continue
        cells = per_cell(r)
        if len(cells) <= MAX_TABLE_ROWS:
            cells = cells.assign(_k=[(natural_key(i), s, natural_key(so), natural_key(p)) for i, s, so, p in
                                     zip(cells["instance"], cells["step"], cells["solver"], cells["profile"])])
            cells = cells.sort_values("_k", kind="stable")
            rows_t = [(c.instance, fmt_num(c.step), fmt_num(c.n), c.solver, c.profile, "yes" if c.warm_start else "no",
                       c.status, fmt_num(c.solve_time_s), fmt_num(c.iterations), fmt_err(c.kkt_error),
                       fmt_err(c.p_rel_error), fmt_err(c.load_rel_error), fmt_num(c.contact_fraction))
                      for c in cells.itertuples()]
            parts.append(table_md(ctx, f"scene `{scene}`: one row per (instance, step, solver, profile), time = "
                                       f"minimum over repeats, status = worst over repeats; errors are relative "
                                       f"to the scene's reference; contact = A/A0.",
                                  ["instance", "step", "n", "solver", "profile", "warm", "status", "time [s]",
                                   "iters", "kkt_error", "p err", "load err", "contact"], rows_t,
                                  "lrrlllrrrrrrr"))
        else:
            g = cells.groupby(["n", "solver", "profile"], sort=True)
            rows_t = []
            for (n, s, p), c in g:
                rows_t.append((fmt_num(n), s, p, len(c), int(c["solved"].sum()), fmt_num(c["solve_time_s"].median()),
                               fmt_num(c["iterations"].median()), fmt_err(c["kkt_error"].median()),
                               fmt_err(c["kkt_error"].max()), fmt_err(c["p_rel_error"].max())))
            rows_t.sort(key=lambda x: (float(x[0]) if x[0] != "-" else -1, natural_key(x[1]), natural_key(x[2])))
            parts.append(table_md(ctx, f"scene `{scene}` ({len(cells)} cells, summarised by n, solver and profile): "
                                       f"median time and iterations, median and worst kkt_error, worst error in p.",
                                  ["n", "solver", "profile", "cells", "solved", "median time [s]", "median iters",
                                   "median kkt", "worst kkt", "worst p err"], rows_t, "rllrrrrrrr"))
    return Section("Tables per scene", "\n".join(parts))


# ---------------------------------------------------------------------------
