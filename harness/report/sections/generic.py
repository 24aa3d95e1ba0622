"""The report's summary sections, rendered for every table whatever its scenes: run time
against error (work-precision, with solver traces), aggregates (solved / problems,
solved / attempted and correct rates, shifted geometric means and Dolan-More performance profiles from
harness/table/aggregates.py), skips and failures, and one table per scene.
"""

from __future__ import annotations

import math
import re
from typing import Any, Callable, Iterable, Sequence

import numpy as np
import pandas as pd

from ...table import aggregates as agg
from ...table.meta import references_asked
from ..style import GREY, MAX_SERIES, Panel, family_panels, panels_note
from ..markdown_text import md_code, md_escape
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
    status_counts,
    table_md,
)
from ..panels import AT_ZERO, MARK_EVERY, curve_note, curve_notes, no_figure

MAX_TABLE_ROWS = 80
MAX_FAILURE_ROWS = 40


def fmt_int(v: Any) -> str:
    """A whole number (a size n or N, a step, a count of iterations) written whole, "4096";
    any other value as ``fmt_num`` writes it ('-' where missing), whose three significant
    figures would write 4096 as "4.1e+03"."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return fmt_num(v)
    return f"{int(x)}" if math.isfinite(x) and x.is_integer() else fmt_num(x)


def reached_accuracy(rows: pd.DataFrame) -> dict[str, float]:
    """Solver -> median kkt_error over its solved rows (the accuracy its times bought)."""
    ok = rows[(rows["status"] == "solved") & rows["kkt_error"].notna()]
    return {str(k): float(v) for k, v in ok.groupby("solver")["kkt_error"].median().items()}


# ---------------------------------------------------------------------------
# Run time against error
# ---------------------------------------------------------------------------

#: The marker size (matplotlib scatter area) of a work-precision point by its profile, where a
#: scene ran several, growing with the profile's accuracy (harness/profiles.py: low 1e-3, the
#: solver's own default, mid 1e-6, paper 1e-8, high 1e-9): the shape stays the solver's own
#: (style.py), so that two solvers of one family differ in shape as well as in colour.  The
#: page's points take the same sizes (``page_marker_sizes``).
_PROFILE_SIZES = {"low": 9.0, "default": 18.0, "mid": 28.0, "paper": 36.0, "high": 46.0}
#: The size of a profile not in ``_PROFILE_SIZES``.
_OTHER_PROFILE_SIZE = 24.0


#: A page marker's diameter (Plotly px) per square root of a ``_PROFILE_SIZES`` area.
PAGE_MARKER_SCALE = 1.65


def page_marker_sizes() -> dict[str, float]:
    """The page's work-precision marker size (Plotly px) per profile, ``_PROFILE_SIZES``'s
    order and ratios; "" keys the size of a profile not listed."""
    sizes = {**_PROFILE_SIZES, "": _OTHER_PROFILE_SIZE}
    return {p: round(PAGE_MARKER_SCALE * math.sqrt(a), 1) for p, a in sizes.items()}


@register_section("work-precision", title="Run time against error", group="summary", order=10)
def work_precision_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    parts = ["Each point is one solve: solve time against the harness's scaled `kkt_error` (left) and against "
             "the error in p relative to the scene's reference (right, where the run had a reference); marker "
             "shape = the solver's own, marker size = profile where a scene ran several (larger: tighter). Lines are "
             "the solver's own convergence trace (its residual, which is not the same figure as kkt_error) "
             "for one representative solve: the largest n at the tightest profile. Values below "
             f"{LOG_FLOOR:g} are drawn at {LOG_FLOOR:g}. Each solver has one colour, marker and dash in "
             f"every report; a family shares a hue. A scene with more than {MAX_SERIES} solvers gets one row of panels per "
             "family, the other families drawn in light grey.\n"]
    for scene in ctx.scenes():
        r = attempted(ctx.rows(scene))
        r = r[r["solve_time_s"].notna() & (r["solve_time_s"] > 0)]
        if r.empty:
            parts.append(f"### {scene}\n\nNo attempted solve with a time.\n")
            continue
        solvers = natural_sorted(r["solver"].unique())
        panels = family_panels(solvers, ctx.family)
        r = r.assign(**{OWN_REF: agg.own_reference(r)})
        referenced = bool(r["p_rel_error"][~r[OWN_REF]].notna().any())
        fig, axes = grid_figure(len(panels), 2 if referenced else 1, width=4.8, height=3.5, wspace=0.35)
        traced: dict[str, str] = {}
        for row, panel in zip(axes, panels):
            _wp_panel(ctx, row, r, panel, traced, scene)
            where = f"{scene}, {panel.title}" if len(panels) > 1 else scene
            for a, what in zip(row, ("KKT error", "error against reference")):
                a.set_title(f"{where}: {what}", fontsize=9)
        rel = ctx.save_figure(fig, f"wp-{scene}")
        cap = f"run time against error, scene `{scene}` ({len(r)} solves, {len(solvers)} solvers)."
        if not referenced:
            asked = references_asked(ctx.meta)
            cap += (own_reference_only_note(r) if r[OWN_REF].any() else
                    unmeasured_note(r) if asked is not False and references_served(r) else no_reference_note(asked))
        else:
            cap += reference_note(r)
        cap += panels_note(panels)
        if traced:
            cap += " Traces: " + ", ".join(traced[s] for s in solvers if s in traced) + "."
        parts.append(f"### {scene}\n\n" + ctx.figure_md(rel, cap))
    return Section("Run time against error", "\n".join(parts))


#: The columns of the work-precision panels, left to right, and their axis labels.
_WP_ERRORS = (("kkt_error", "scaled KKT error  [-]"), ("p_rel_error", "||p - p_ref||_inf / ||p_ref||_inf  [-]"))


#: The column ``work_precision_section`` adds to its rows: the row's answer served as its
#: step's reference (``agg.own_reference``).
OWN_REF = "own_reference"
#: A table's cell for an error in p measured against the row's own answer.
REF_CELL = "ref"


def step_ranges(steps: Iterable[int]) -> str:
    """Steps as compact ranges: ``(0, 1, 2, 3, 5, 7, 8)`` -> ``"0-3, 5, 7-8"``."""
    ks = sorted(set(int(k) for k in steps))
    runs: list[list[int]] = []
    for k in ks:
        if runs and k == runs[-1][-1] + 1:
            runs[-1].append(k)
        else:
            runs.append([k])
    return ", ".join(str(r[0]) if len(r) == 1 else f"{r[0]}-{r[-1]}" for r in runs)


def references_served(rows: pd.DataFrame) -> str:
    """Which solver served as the reference of ``rows``' error in p, and on which steps:
    ``"`nnls@high` (steps 0-5), `pk@high` (steps 6-9)"`` ("" where no row names one)."""
    by_ref = agg.reference_steps(rows)
    if len(by_ref) == 1 and set(next(iter(by_ref.values()))) == set(pd.to_numeric(rows["step"]).dropna().astype(int)):
        return md_code(next(iter(by_ref)))
    return ", ".join(f"{md_code(name)} (step{'s' if len(ks) > 1 else ''} {step_ranges(ks)})"
                     for name, ks in by_ref.items())


def reference_note(rows: pd.DataFrame) -> str:
    """The work-precision caption's words on the reference of the error in p: who served
    (and where), and that the reference's own answers are not drawn."""
    out = f" Error in p against the reference solution of {references_served(rows)}."
    n_own = int(rows[OWN_REF].sum())
    if n_own:
        out += (f" The answers that served as the reference ({n_own} solve{'s' if n_own > 1 else ''}; error in p 0 "
                f"by construction) are left out of the error-in-p panel.")
    return out


def own_reference_only_note(rows: pd.DataFrame) -> str:
    """Why a work-precision figure draws no error in p although the run had a reference:
    every answer measured against it is the reference's own."""
    return (f" The only answers measured against the reference ({references_served(rows)}) are the "
            f"reference's own (error in p 0 by construction): the error in p is not drawn.")


def unmeasured_note(rows: pd.DataFrame) -> str:
    """Why a work-precision figure draws no error in p although a reference served: no
    answer of ``rows`` has one (each failed, or gave no answer to measure)."""
    return (f" The reference solution ({references_served(rows)}) served, but no answer here has an error in p "
            f"against it (none gave an answer to measure): the error in p is not drawn.")


def no_reference_note(asked: bool | None) -> str:
    """Why a work-precision figure draws no error in p, by whether the run asked for a
    reference (``meta.references_asked``; None: the record does not say)."""
    if asked is False:
        return " The run had no reference solution (`--reference none`): the error in p is not drawn."
    why = (" (the run asked for one, but no candidate served: each was skipped or failed, and the rows' "
           "`reference_solver` is empty)") if asked else ""
    return f" No answer of this scene was measured against a reference solution{why}: the error in p is not drawn."


def _wp_sizes(r: pd.DataFrame, size: float) -> Callable[[str], float]:
    """profile -> the scatter size of its points: ``size`` where ``r`` ran one profile, else
    by the profile (``_PROFILE_SIZES``, scaled so that "default" is ``size``)."""
    if r["profile"].nunique() > 1:
        return lambda prof: size * _PROFILE_SIZES.get(prof, _OTHER_PROFILE_SIZE) / _PROFILE_SIZES["default"]
    return lambda _prof: size


def drawn_errors(c: pd.DataFrame, col: str) -> pd.Series:
    """The values of error column ``col`` a work-precision panel draws: the error in p of
    the reference's own answers (``OWN_REF``: 0 by construction, at the log floor it would
    read as exact) is left out (NaN)."""
    v = pd.to_numeric(c[col], errors="coerce")
    return v.mask(c[OWN_REF]) if col == "p_rel_error" and OWN_REF in c else v


def _wp_points(axes: list[Any], c: pd.DataFrame, color: Any, size: Callable[[str], float], alpha: float,
               marker: Callable[[str], str], hollow_failed: bool = True) -> None:
    """Scatter each solve of ``c`` on ``axes`` (one per ``_WP_ERRORS`` column): time against
    error, the solver's ``marker``, its profile's ``size``, hollow where not solved (unless
    ``hollow_failed`` is False)."""
    c = c[["solver", "profile", "status", "solve_time_s", OWN_REF, *(col for col, _ in _WP_ERRORS)]]  # drawn
    for (s, prof), cp in c.groupby(["solver", "profile"], sort=True):
        for ok, face in ((True, color), (False, "none" if hollow_failed else color)):
            cs = cp[(cp["status"] == "solved") == ok]
            if cs.empty:
                continue
            for a, (col, _) in zip(axes, _WP_ERRORS):
                y = drawn_errors(cs, col)
                if y.notna().any():
                    a.scatter(cs["solve_time_s"][y.notna()], floor_log(y[y.notna()]), s=size(str(prof)),
                              marker=marker(str(s)), facecolors=face, edgecolors=color, linewidths=0.8,
                              alpha=alpha)


def _wp_panel(ctx: ReportContext, axes: list[Any], r: pd.DataFrame, panel: Panel, traced: dict[str, str],
              scene: str) -> None:
    """One row of the work-precision figure (``axes``: the KKT error's panel, then the error
    against the reference where the run had one): every solve of the scene in grey, the
    panel's solvers in their colours with their representative traces."""
    a1 = axes[0]
    others = r[~r["solver"].isin(panel.solvers)]
    if len(others):
        _wp_points(axes, others, GREY, _wp_sizes(r, 8.0), 0.6, ctx.marker, hollow_failed=False)
    xs = list(r["solve_time_s"])
    ys = [list(floor_log(drawn_errors(r, col))) for col, _ in _WP_ERRORS]
    for s in panel.solvers:
        c = r[r["solver"] == s]
        _wp_points(axes, c, ctx.color(s, scene), _wp_sizes(r, 16.0), 0.8, ctx.marker)
        rep = representative_traces(c).get(s)
        if rep is not None:
            tr = parse_trace(rep["trace"])
            ok = (tr[:, 1] > 0) & np.isfinite(tr[:, 2])
            a1.plot(tr[ok, 1], floor_log(tr[ok, 2]), lw=1.0, color=ctx.color(s, scene), alpha=0.8)
            xs += list(tr[ok, 1])
            ys[0] += list(floor_log(tr[ok, 2]))
            traced[s] = f"{md_code(s)} ({rep['instance']}, step {int(rep['step'])}, {rep['profile']})"
        a1.plot([], [], ls="none", marker=ctx.marker(s), color=ctx.color(s, scene), label=s)
    if r["profile"].nunique() > 1:
        for prof in [p for p in PROFILE_PREFERENCE[::-1] if p in set(r["profile"])] + \
                natural_sorted(set(r["profile"]) - set(PROFILE_PREFERENCE)):
            area = _PROFILE_SIZES.get(prof, _OTHER_PROFILE_SIZE) * 16.0 / _PROFILE_SIZES["default"]
            a1.plot([], [], ls="none", marker="o", ms=float(np.sqrt(area)), color="gray",
                    label=f"profile {prof} (marker size)")
    if (r["status"] != "solved").any():
        a1.plot([], [], ls="none", marker="o", mfc="none", color="gray", label="hollow: not solved")
    if panel.solvers and any(s in traced for s in panel.solvers):
        a1.plot([], [], color="gray", lw=1.0, label="trace (own residual)")
    if len(others):
        a1.plot([], [], ls="none", marker="o", color=GREY, label="other families")
    for a, (_, lab), y in zip(axes, _WP_ERRORS, ys):
        a.set_xlabel("solve time  [s]")
        a.set_ylabel(lab, fontsize=8)
        a.grid(True, which="major", alpha=0.3)
        if not np.any(np.isfinite(y)):
            continue  # nothing drawn here (no finite error): log axes would have no limits
        log_if_wide(a, "x", xs)
        if not log_if_wide(a, "y", y, decades=0.0):
            a.set_yscale("log")  # a single error level: still an error axis
    h, lbl = a1.get_legend_handles_labels()
    axes[-1].legend(h, lbl, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7, frameon=False)


# ---------------------------------------------------------------------------
# Aggregates
# ---------------------------------------------------------------------------


#: The aggregate tables' columns of solved cells: the count and its two shares, each header
#: naming its denominator (harness/table/aggregates.py: ``SolverSummary``).
SOLVED_COLUMNS = ("problems", "attempted", "solved", "solved / problems", "solved / attempted")


def solved_cells(s: agg.SolverSummary) -> tuple[Any, ...]:
    """A summary's cells under ``SOLVED_COLUMNS``."""
    return s.problems, s.attempted, s.solved, fmt_pct(s.solved_share), fmt_pct(s.success_rate)


#: What the aggregate tables' SGM counts, for their captions (report.md and report.html): the
#: definition of harness/table/aggregates.py (``time_aggregate``), in the report's words.
SGM_CAPTION = ("**SGM**: shifted geometric mean of solve time, exp(mean(log(t + s))) - s, over the cells the "
               "solver was planned to run (those with a row in the table: the column **SGM cells** counts them); a "
               "planned cell that is not solved (failed, inaccurate, timeout, crashed or skipped) counts at the largest "
               "time limit of the scene's rows (at least their largest solved time), and a problem the solver was never planned to run is not counted. **SGM / best**: that over "
               "the smallest SGM over the same cells among the solvers planned on every one of them that solved a "
               "problem (1: the best on its own problems). A solver skipped on every problem has no SGM (-), nor has "
               "any solver of a scene where none solved a problem.")


@register_section("aggregates", title="Aggregates across instances", group="summary", order=20)
def aggregates_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    parts = [f"Per scene. A problem is one (instance, step, profile, history): a step along a warm-started load "
             f"history and the same step of a `--cold` run are two problems. A cell is solved when the harness's KKT "
             f"check passes at the profile's `check_tol` (status `solved`). **solved / problems**: the share of "
             f"all the scene's problems, a skipped or not run cell counting as not solved. **solved / "
             f"attempted**: the share of the cells the solver ran (skipped cells are not attempted); read it "
             f"beside the attempted count: 3 solved of 3 attempted is 100 % however many were skipped. **Correct**: the "
             f"solver's own convergence claim agrees with that verdict, over attempted rows with a claim; "
             f"**false claims** count rows claiming convergence that fail the check. "
             f"{SGM_CAPTION.replace('exp(', f'shift s = {fmt_num(ctx.shift)} s, exp(', 1)} Repeats: a cell is "
             f"solved when every repeat is, at "
             f"the minimum time. **Performance profile** (Dolan & More 2002): the fraction of problems a "
             f"solver solves within tau times the best solver's time.\n"]
    for scene in ctx.scenes():
        parts.append(f"### {scene}\n")
        by_profile = agg.profile_parts(ctx.rows(scene))
        if len(by_profile) > 1:
            parts.append(f"The scene's rows ran at {len(by_profile)} profiles "
                         f"({', '.join(f'`{p}`' for p, _ in by_profile)}): a profile is its own accuracy target, so "
                         f"the solvers are compared within each profile, one table and one performance profile "
                         f"each, never across them.\n")
        for profile, r in by_profile:
            parts.extend(_scene_aggregates(ctx, scene, r, profile if len(by_profile) > 1 else None))
    parts.append("### All scenes\n")
    by_profile = agg.profile_parts(table)
    for profile, t in by_profile:
        at, of = (f", profile `{profile}`", " at this profile (a profile is its own accuracy target: one table "
                  "each, a solver counted only at the profiles it ran)") if len(by_profile) > 1 else ("", "")
        summ = agg.summarize(t, ctx.shift, natural_sorted(t["solver"].unique()), with_time=False)
        parts.append(table_md(ctx, f"solved shares and correct rates over every scene{at} (no time aggregate across "
                                   f"scenes: solvers do not all run on the same problems). problems: every problem of "
                                   f"every scene{of}, so a scene a solver did not run counts as not solved in "
                                   f"solved / problems.",
                              ["solver", *SOLVED_COLUMNS, "correct (rows)", "false claims"],
                              [(s.solver, *solved_cells(s), f"{fmt_pct(s.correct_rate)} ({s.claim_rows})",
                                s.false_claims) for s in sorted(summ, key=lambda s: natural_key(s.solver))],
                              "lrrrrrrr"))
    return Section("Aggregates across instances", "\n".join(parts))


def _scene_aggregates(ctx: ReportContext, scene: str, r: pd.DataFrame, profile: str | None) -> list[str]:
    """The aggregate table and the performance profile of ``r``, the rows of ``scene`` at
    one profile (``profile``, named in the captions and the figure's file where the scene
    ran several; None where it ran one)."""
    parts: list[str] = []
    summ = agg.summarize(r, ctx.shift, natural_sorted(r["solver"].unique()))
    cells = agg.cell_table(r, natural_sorted(r["solver"].unique()))
    at = f", profile `{profile}`" if profile else ""
    acc = reached_accuracy(r)
    rows_t = [(s.solver, *solved_cells(s), f"{fmt_pct(s.correct_rate)} ({s.claim_rows})", s.false_claims,
               fmt_num(s.sgm_s), fmt_num(s.sgm_rel), s.sgm_cells, fmt_err(acc.get(s.solver, np.nan)))
              for s in sorted(summ, key=lambda s: natural_key(s.solver))]
    none_solved = " No solver solved a problem of this scene: no SGM (-)." if not any(s.solved for s in summ) \
        else ""
    parts.append(table_md(ctx, f"aggregates, scene `{scene}`{at} ({len(cells.problems)} problems; SGM shift "
                               f"{fmt_num(ctx.shift)} s). A solved cell passed the profile's KKT check, but "
                               f"solvers stop at their own tolerances: the last column is the median "
                               f"kkt_error of the solver's solved cells, the accuracy its times were bought at."
                               + none_solved,
                          ["solver", *SOLVED_COLUMNS, "correct (rows)",
                           "false claims", "SGM [s]", "SGM / best", "SGM cells", "median kkt (solved)"], rows_t,
                          "lrrrrrrrrrrr"))
    prof = agg.performance_profile(cells)
    if len(prof.solvers) >= 2 and cells.problems:
        empty = profile_empty_note(prof, r)
        parts.append(no_figure(f"Performance profile, scene `{scene}`{at}: {empty}.") if empty
                     else _profile_figure(ctx, scene, prof, summ, profile))
    return parts


def family_rank(s: agg.SolverSummary) -> tuple[float, float]:
    """How ``best_of_family`` ranks a solver, smaller first: its solved share of every problem
    (a solver planned on few problems is not the best for its speed on them), then its SGM."""
    share = s.solved_share if np.isfinite(s.solved_share) else 0.0
    return -share, s.sgm_s


def best_of_family(ctx: ReportContext, summaries: Iterable[agg.SolverSummary]) -> dict[str, str]:
    """Family -> its best solver by ``family_rank`` among those with a finite SGM (ties by
    name)."""
    best: dict[str, agg.SolverSummary] = {}
    for s in sorted(summaries, key=lambda x: natural_key(x.solver)):
        if not np.isfinite(s.sgm_s):
            continue
        f = ctx.family(s.solver)
        if f not in best or family_rank(s) < family_rank(best[f]):
            best[f] = s
    return {f: s.solver for f, s in best.items()}


def planned_counts(prof: agg.PerformanceProfile, summ: Sequence[agg.SolverSummary]) -> str:
    """The caption's words on the solvers of ``prof`` planned on fewer than all its problems
    (their curves cannot rise above that share); "" where every one was planned on all."""
    few = [(s.solver, s.sgm_cells) for s in summ if s.solver in prof.solvers and 0 < s.sgm_cells < prof.n_problems]
    if not few:
        return ""
    return (" Planned on fewer problems than the scene holds (a curve stops at most at that share): "
            + ", ".join(f"{md_escape(s)} ({k} of {prof.n_problems})" for s, k in few) + ".")


def profile_empty_note(prof: agg.PerformanceProfile, rows: pd.DataFrame) -> str:
    """Why a scene's performance profile ``prof`` has nothing to draw ("" when it has): no
    solver solved any of its problems, so every curve would lie at 0.  ``rows``: the
    scene's rows, whose statuses the note counts.  report.md writes it in place of the
    figure, report.html on the chart."""
    if any(np.isfinite(r).any() for r in prof.ratios.values()):
        return ""
    return (f"no solver solved any of the scene's {prof.n_problems} problems ({status_counts(rows)}), and a "
            f"performance profile compares the times of solved problems: every curve would lie at 0")


def profile_taus(prof: agg.PerformanceProfile, points: int) -> tuple[np.ndarray, float]:
    """The tau axis of a performance profile: ``points`` geometric steps from 1 to
    ``hi`` (1.5 x the largest finite ratio, at least 2) plus every ratio in that range,
    so each step of a curve is drawn where it happens; returns (taus, hi)."""
    hi = max(2.0, prof.max_finite_ratio() * 1.5)
    taus = np.unique(np.concatenate([np.geomspace(1.0, hi, points),
                                     *[r[np.isfinite(r)] for r in prof.ratios.values()]]))
    return taus[(taus >= 1.0) & (taus <= hi)], hi


def _profile_figure(ctx: ReportContext, scene: str, prof: agg.PerformanceProfile,
                    summ: Sequence[agg.SolverSummary], profile: str | None) -> str:
    taus, hi = profile_taus(prof, 200)
    panels = family_panels(list(prof.solvers), ctx.family, best_of_family(ctx, summ))
    ncols = 1 if len(panels) == 1 else 2
    nrows = -(-len(panels) // ncols)
    fig, axes = grid_figure(nrows, ncols, width=6.0 if ncols == 1 else 5.6, height=4.0 if ncols == 1 else 3.5,
                            wspace=0.85)
    flat = [a for row in axes for a in row]
    curves = {s: prof.curve(s, taus) for s in prof.solvers}
    hidden: dict[str, str | None] = {}
    for ax, panel in zip(flat, panels):
        if len(panels) > 1:
            for s in prof.solvers:
                if s not in panel.solvers:
                    ax.step(taus, curves[s], where="post", color=GREY, lw=0.8)
        notes = curve_notes(curves, panel.solvers)
        for s in panel.solvers:
            ax.step(taus, curves[s], where="post", color=ctx.color(s, scene), ls=ctx.dash(s), lw=1.5,
                    label=f"{s} ({curve_note(notes[s])})" if s in notes else s, marker=ctx.marker(s), ms=4,
                    markevery=MARK_EVERY)
        if panel.solvers and all(s in notes and notes[s] is None for s in panel.solvers):
            ax.text(0.5, 0.5, f"none of the {len(panel.solvers)} solvers of this panel solved a problem:\n"
                              f"every curve of the panel lies at 0", transform=ax.transAxes, ha="center", va="center",
                    fontsize=8, color="dimgray", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})
        hidden.update({s: n for s, n in notes.items() if s not in hidden})
        ax.set_xscale("log", base=2)
        ax.set_xlim(1.0, hi)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("tau: within tau x the best time  [-]", fontsize=8)
        ax.set_ylabel("fraction of problems solved  [-]", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        where = "" if len(panels) == 1 else f", {panel.title}"
        at = f", profile {profile}" if profile else ""
        ax.set_title(f"performance profile, {scene}{at}{where} ({prof.n_problems} problems)", fontsize=9)
        legend_outside(ax, "solver")
    for ax in flat[len(panels):]:
        ax.set_visible(False)
    rel = ctx.save_figure(fig, f"pp-{scene}" + (f"-{profile}" if profile else ""))
    note = panels_note(panels).replace("best solver of each family",
                                       "best solver of each family by solved share, then SGM")
    planned = planned_counts(prof, summ)
    lies = (f" Curves drawn on the axis at 0 (\"{AT_ZERO}\") or under another's (\"= ...\"), as their legend "
            f"entries say: "
            f"{', '.join(f'{md_escape(s)} ({curve_note(t if t is None else md_escape(t))})' for s, t in hidden.items())}."
            if hidden else "")
    at = f", profile `{profile}`" if profile else ""
    return ctx.figure_md(rel, f"Dolan-More performance profile, scene `{scene}`{at}: the y axis is a share of all "
                              f"the {prof.n_problems} problems of the scene{' at this profile' if profile else ''}, "
                              f"those a solver was not planned on counted as not solved; rho(1) is the share on "
                              f"which a solver is fastest among those that pass the same KKT check; the right "
                              f"end is its solved / problems share.{planned}{note}{lies}"
                              + (f" Not drawn, skipped on every problem (the skips say why): "
                                 f"{', '.join(prof.left_out)}." if prof.left_out else ""))


# ---------------------------------------------------------------------------
# Skips and failures
# ---------------------------------------------------------------------------



#: A number in a skip reason (an integer, a decimal, a float in e-notation).  The reason text
#: is all a skip records of its cause, and a prediction or an estimate puts each step's own
#: n and time in it; so the reasons of one cause are grouped by their text with the numbers
#: masked (``reason_kind``), the only thing read from the text.
REASON_NUMBER = re.compile(r"\d+(?:\.\d+)?(?:[eE][+-]?\d+)?")


def reason_kind(reason: str) -> str:
    """A skip reason with each number replaced by "#": the reasons of one cause at different
    steps (n, predicted time) read the same."""
    return REASON_NUMBER.sub("#", reason)


def skip_rows(skipped: pd.DataFrame) -> list[tuple[Any, ...]]:
    """The Skips table's rows: per (scene, solver, ``reason_kind``) of the skipped rows,
    (scene, solver, rows, instances, steps as ranges, the reason of its first step in full,
    "e.g. " in front where the group's reasons differ), by scene, solver and first step."""
    sk = skipped.assign(_reason=skipped["skip_reason"].fillna("").astype(str))
    sk = sk.assign(_kind=sk["_reason"].map(reason_kind)).sort_values(["step", "instance"], kind="stable")
    out = []
    for (sc, so, _), x in sk.groupby(["scene", "solver", "_kind"], sort=False):
        first = x["_reason"].iloc[0] or "(no reason recorded)"
        steps = pd.to_numeric(x["step"], errors="coerce").dropna()
        out.append((sc, so, len(x), x["instance"].nunique(), step_ranges(steps) if len(steps) else "-",
                    f"e.g. {first}" if x["_reason"].nunique() > 1 else first, steps.min() if len(steps) else -1))
    out.sort(key=lambda r: (scene_rank(r[0]), natural_key(r[1]), r[-1], r[5]))
    return [r[:-1] for r in out]

@register_section("skips", title="Skips and failures", group="summary", order=30)
def skips_section(ctx: ReportContext, table: pd.DataFrame) -> Section:
    t = table
    parts = []
    sk = t[t["status"] == "skipped"]
    if sk.empty:
        parts.append("No pair was skipped.\n")
    else:
        parts.append(table_md(ctx, "skipped pairs, by scene, solver and kind of reason (the reason with its "
                                   "numbers left out: a prediction for each step is one kind; rows: skipped cells; "
                                   "instances: distinct instances; steps: the steps skipped for it; reason: that "
                                   "of its first step, in full, 'e.g.' where the others differ in their numbers).",
                              ["scene", "solver", "rows", "instances", "steps", "reason"], skip_rows(sk), "llrrll"))
    bad = t[t["status"].isin(["failed", "timeout", "crashed"])]
    if bad.empty:
        parts.append("No solve failed, timed out or crashed.\n")
    else:
        bad = bad.sort_values(["scene", "solver", "profile", "instance", "step", "repeat"], kind="stable",
                              key=lambda c: c.map(natural_key) if c.dtype == object else c)
        rows_t = [(r.scene, r.solver, r.profile, r.instance, fmt_int(r.step), r.status,
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
        parts.append(own_accounts(ina))
    return Section("Skips and failures", "\n".join(parts))


#: At most this many characters of a solver's own words in ``own_accounts``.
ACCOUNT_CHARS = 200


def own_accounts(inaccurate: pd.DataFrame) -> str:
    """Why the inaccurate answers failed, in their solvers' own words: per (scene, solver,
    profile), its answers that failed the check while the solver did not claim convergence
    (``solver_converged`` False: it knew, and its ``solver_message`` says why), how many, and
    the message of the worst of them (largest kkt_error), its middle left out past
    ``ACCOUNT_CHARS`` (``ends_of``).  Read from
    the table's columns only, whatever the solver; "" when no such answer has a message."""
    msg = inaccurate["solver_message"].fillna("").astype(str).str.strip()
    own = inaccurate[inaccurate["solver_converged"].eq(False).fillna(False).to_numpy(dtype=bool) & (msg != "")]
    if own.empty:
        return ""
    lines = []
    for (sc, so, pr), x in own.groupby(["scene", "solver", "profile"], sort=False):
        worst = x.loc[x["kkt_error"].fillna(np.inf).idxmax()]
        text = ends_of(error_line(worst["solver_message"]), ACCOUNT_CHARS).replace("|", "/")
        lines.append((natural_key(sc), natural_key(so), pr,
                      f"- {md_code(so)} ({sc}, profile `{pr}`): {len(x)} of its answers; at the worst "
                      f"(instance {worst['instance']}, step {int(worst['step'])}): \"{text}\""))
    return ("**In the solvers' own words.** Why the answers above that their solver did not claim as converged "
            "failed, as the solver's message says (column `solver_message`; the verdict is the judge's):\n\n"
            + "\n".join(line for *_, line in sorted(lines, key=lambda r: r[:3])) + "\n")


#: The first line of a Python traceback (``traceback.format_exc``).
TRACEBACK_HEAD = "Traceback (most recent call last):"


def error_line(text: str) -> str:
    """The line of a multi-line error message that says the most, stripped: for a Python
    traceback (its first line ``TRACEBACK_HEAD``) the exception's line -- the first
    unindented line after the last ``  File`` frame (in a chain, the last exception's),
    else its last line; for any other message its first line with text ("" for none)."""
    lines = [line for line in str(text).splitlines() if line.strip()]
    if not lines:
        return ""
    if lines[0].strip() != TRACEBACK_HEAD:
        return lines[0].strip()
    frames = [i for i, line in enumerate(lines) if line.startswith("  File ")]
    after = lines[frames[-1] + 1:] if frames else lines[1:]
    return next((line.strip() for line in after if not line[:1].isspace()), lines[-1].strip())


def ends_of(line: str, n: int) -> str:
    """``line`` cut to about ``n`` characters by leaving out its middle (" ... "): a solver's
    message names what it did first and its verdict last."""
    if len(line) <= n:
        return line
    half = max((n - 5) // 2, 1)
    return f"{line[:half].rstrip()} ... {line[-half:].lstrip()}"


def _short(text: str, n: int = 90) -> str:
    """An error cell: ``error_line(text)``, cut to ``n`` characters."""
    line = error_line(text)
    return line if len(line) <= n else line[: n - 3] + "..."


# ---------------------------------------------------------------------------
# Per-scene tables
# ---------------------------------------------------------------------------


def reference_caption(cells: pd.DataFrame, column: str, meaning: str) -> str:
    """A scene table's words on its error in p: the reference solution's solver (and steps),
    and what a ``REF_CELL`` in ``column`` means (``meaning``) where one is shown ("" where no
    row names a reference)."""
    served = references_served(cells)
    if not served:
        return ""
    own = f" {column} {md_code(REF_CELL)}: {meaning} (error in p 0 by construction)." if cells[OWN_REF].any() else ""
    return f" The reference solution: {served}.{own}"


def worst_p_error(cells: pd.DataFrame) -> str:
    """The largest error in p of ``cells`` other than the reference's own (``OWN_REF``);
    ``REF_CELL`` where every measured cell is the reference's own."""
    p = pd.to_numeric(cells["p_rel_error"], errors="coerce")
    others = p[~cells[OWN_REF]].dropna()
    if others.empty and p[cells[OWN_REF]].notna().any():
        return REF_CELL
    return fmt_err(others.max() if len(others) else np.nan)


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
        cells = cells.assign(**{OWN_REF: agg.own_reference(cells)})
        if len(cells) <= MAX_TABLE_ROWS:
            ref = reference_caption(cells, "p err", "the cell's own answer is the reference")
            cells = cells.assign(_k=[(natural_key(i), s, natural_key(so), natural_key(p)) for i, s, so, p in
                                     zip(cells["instance"], cells["step"], cells["solver"], cells["profile"])])
            cells = cells.sort_values("_k", kind="stable")
            rows_t = [(c.instance, fmt_int(c.step), fmt_int(c.n), c.solver, c.profile, "yes" if c.warm_start else "no",
                       c.status, fmt_num(c.solve_time_s), fmt_int(c.iterations), fmt_err(c.kkt_error),
                       REF_CELL if getattr(c, OWN_REF) else fmt_err(c.p_rel_error), fmt_err(c.load_rel_error),
                       fmt_num(c.contact_fraction))
                      for c in cells.itertuples()]
            parts.append(table_md(ctx, f"scene `{scene}`: one row per (instance, step, solver, profile), time = "
                                       f"minimum over repeats, status = worst over repeats; errors are relative "
                                       f"to the scene's reference; contact = A/A0.{ref}",
                                  ["instance", "step", "n", "solver", "profile", "warm", "status", "time [s]",
                                   "iters", "kkt_error", "p err", "load err", "contact"], rows_t,
                                  "lrrlllrrrrrrr"))
        else:
            ref = reference_caption(cells, "worst p err", "every cell of the line with an error in p is the "
                                                          "reference's own answer")
            g = cells.groupby(["n", "solver", "profile"], sort=True)
            rows_t = []
            for (n, s, p), c in g:
                won = c["solved"].astype(bool)  # an unsolved cell's time is no solve time
                rows_t.append((fmt_int(n), s, p, len(c), int(won.sum()), fmt_num(c.loc[won, "solve_time_s"].median()),
                               fmt_int(c["iterations"].median()), fmt_err(c["kkt_error"].median()),
                               fmt_err(c["kkt_error"].max()), worst_p_error(c)))
            rows_t.sort(key=lambda x: (float(x[0]) if x[0] != "-" else -1, natural_key(x[1]), natural_key(x[2])))
            parts.append(table_md(ctx, f"scene `{scene}` ({len(cells)} cells, summarised by n, solver and profile): "
                                       f"median time over the solved cells (- where none), median iterations, median "
                                       f"and worst kkt_error over every cell, worst error in p over the cells that "
                                       f"are not the reference's own.{ref}",
                                  ["n", "solver", "profile", "cells", "solved", "median solved time [s]", "median iters",
                                   "median kkt", "worst kkt", "worst p err"], rows_t, "rllrrrrrrr"))
    return Section("Tables per scene", "\n".join(parts))


# ---------------------------------------------------------------------------
