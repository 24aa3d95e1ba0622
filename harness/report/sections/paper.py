"""Report sections of the paper reproductions (Bemporad & Paggi 2015, sec. 4): Fig. 4
(``paper-sweep``), Fig. 5 (``greedy-linear-solvers``), Fig. 6 (``gp-k-sweep``), and the
closed-form checks (``hertz``, ``flat-punch``).  Example 1 is in
sections/counterexample.py.

Each section draws its scene once per condition (sections/paper_conditions.py
``condition_blocks``: each operator at its tightest profile -- Fig. 4: where the most of its
solvers ran, sections/fig4_profile.py -- so no solver's rows are dropped for another
condition's) and ends each with a reading computed from the
table that says where we agree with the paper's claims and where not.  A verdict on a
claim of the paper is the claims ledger's, read on the ledger's own measurement
(paper_conditions.py); the section's own pooled numbers come without one.  The paper's
algorithms are found through ``PAPER_ROLES``: by the table's ``base_solver`` (registry
name) and ``params`` columns, never by the solver's label.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import replace
from typing import Any, Callable

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.colors import to_hex
from matplotlib.ticker import MaxNLocator

from contactbench.problems.surfaces import RMD_FAMILIES

from ..style import GREY, Panel, family_panels, panels_note, register_scene_colors, sort_families
from ...table import aggregates as agg
from ..charts import RowChart
from ..panels import no_figure
from ..markdown_text import md_code
from ..core import (
    WARM_SUFFIX,
    ReportContext,
    Section,
    attempted,
    floor_log,
    fmt_err,
    fmt_num,
    fmt_ratio,
    grid_figure,
    integer_ticks,
    legend_outside,
    log_if_wide,
    md_escape,
    natural_sorted,
    new_figure,
    per_cell,
    register_section,
    status_counts,
    table_md,
)
from .generic import OWN_REF, fmt_int
from ..claim_measures import FIG5_MIN_N, Spread, k_of as k_of, paired_median_ratio, tied_with  # (k_of: html.py)
from ..claim_tables import PAPER_ROLES, paper_roles, resolve_role as resolve_role  # (counterexample.py reads it here)
from .fig4_profile import fig4_rows, other_profiles_note
from .paper_conditions import (
    Block,
    absent,
    condition_blocks,
    fig4_elsewhere,
    fig5_ledger,
    fig6_elsewhere,
    fig6_ledger,
    operators_of,
    paper_admm,
)
from .paper_readings import (
    SMALL_N_TEXT,
    agreement as agreement,  # (the readings' words, re-exported)
    claim_sentence,
    fig6_reading,
    k_cells,
    k_totals,
    largest_n,
    ledger_claim,
    ledger_words,
    paired_count_text,
    ties_text,
    timing_spread,
    too_small,
)
from .sweep_totals import (
    BEST_RULE,
    WORST_RULE,
    best_per_family,
    fastest_at_accuracy,
    skipped_note,
    sweep_steps,
    sweep_totals,
    time_at,
    total_ratio,
    totals_rows,
)

#: The page charts of the paper's figures (report.html draws them from the rows).
FIG4_PAGE = (RowChart("Fig. 4: solve time against load"),)
FIG5_PAGE = (RowChart("Fig. 5: solve time against n", x="n", x_title="trial-set size n"),)
FIG6_PAGE = (RowChart("Fig. 6: NNLS+GP time per step, per K"),)


def drawn_as_png(page: tuple[RowChart, ...], block: Block, instance: str | None = None) -> tuple[RowChart, ...]:
    """``page`` drawing only the rows its section's PNG of ``block`` draws: those of the
    block's profile ("" where nothing ran: any) and, where given, ``instance``; in a scene
    of several blocks the title names the block's condition."""
    where = "" if block.alone else f" ({block.where.replace('`', '')})"
    return tuple(replace(c, title=c.title + where, profile=block.profile or None, instance=instance) for c in page)

# ---------------------------------------------------------------------------
# Which surfaces ran: the instance names of generated rough surfaces
# ---------------------------------------------------------------------------

#: Names of a family in tables written before the families had names ("rmd" was the
#: periodic wrap-around diamond-square, the generator of every scene then).
LEGACY_FAMILIES: dict[str, str] = {"rmd": "periodic"}
#: What each RMD family is (problems/surfaces.py RMD_FAMILIES), for the reports.
FAMILY_TEXT: dict[str, str] = {
    "saupe": "Saupe's non-periodic MidPointFM2D on the (2^k+1)^2 grid, the paper's generator (ref. PS88)",
    "periodic": "the periodic wrap-around diamond-square RMD (not the paper's generator)",
}
#: The surface family of an older table's "rmd-..." instances (the periodic family's old name).
GENERATED_FAMILIES: frozenset[str] = frozenset({*RMD_FAMILIES, *LEGACY_FAMILIES})


def family_name(family: object) -> str:
    """A table's ``surface_family`` value as a generated RMD family ("" for others)."""
    text = "" if family is None or pd.isna(family) else str(family)
    return LEGACY_FAMILIES.get(text, text) if text in GENERATED_FAMILIES else ""


def surface_families(rows: pd.DataFrame) -> list[str]:
    """The RMD families of the rows' instances (column ``surface_family``), sorted; none
    for other instances."""
    if "surface_family" not in rows.columns:
        return []
    return sorted({f for f in map(family_name, rows["surface_family"].unique()) if f})


def surface_family_note(rows: pd.DataFrame) -> str:
    """One line naming the surface family (families) the rows ran on; "" when no
    instance is a generated rough surface."""
    fams = surface_families(rows)
    if not fams:
        return ""
    what = "; ".join(f"`{f}` -- {FAMILY_TEXT.get(f, 'an RMD family unknown to this report')}" for f in fams)
    return f"**Surface family.** {what}.\n"


# ---------------------------------------------------------------------------
# Figs. 4, 5 and 6
# ---------------------------------------------------------------------------

def _curve_label(solver: str, warm: bool) -> str:
    return f"{solver}{WARM_SUFFIX}" if warm else solver


#: How a time plot marks a step that was not solved, by the cell's status (``unsolved_kind``):
#: (marker, colour, legend label).  A timed-out or failed solve is drawn at the time it took.
UNSOLVED_MARKS: dict[str, tuple[str, str, str]] = {
    "inaccurate": ("x", "red", "not solved (KKT check)"),
    "timeout": ("s", "darkorange", "timed out"),
    "failed": ("D", "purple", "failed or crashed"),
}


def unsolved_kind(status: str) -> str:
    """The key of ``UNSOLVED_MARKS`` for a cell that was not solved: "inaccurate" (the
    answer failed the KKT check), "timeout", else "failed" (failed or crashed)."""
    return status if status in UNSOLVED_MARKS else "failed"


def _mark_unsolved(ax: Any, x: pd.Series, y: pd.Series, status: pd.Series) -> set[str]:
    """Draw the ``UNSOLVED_MARKS`` marker of each point (x, y) by its status; return the
    kinds drawn at a finite point."""
    kinds = status.map(unsolved_kind)
    drawn = set()
    for kind, (marker, color, _) in UNSOLVED_MARKS.items():
        sel = (kinds == kind) & np.isfinite(x.astype(float)) & np.isfinite(y.astype(float))
        if sel.any():
            ax.plot(x[sel], y[sel], ls="none", marker=marker, ms=8, mew=2, color=color,
                    mfc=color if marker == "x" else "none")
            drawn.add(kind)
    return drawn


def _plot_time_curves(ax: Any, cells: pd.DataFrame, x_of: Callable[[pd.DataFrame], pd.Series], sort_by: str,
                      color_of: Callable[[str], Any], xlabel: str,
                      label_of: Callable[[str], str] = str, background: pd.DataFrame | None = None,
                      marker_of: Callable[[str], str] = lambda s: "o") -> None:
    """Solve time against ``x_of(rows)``, one curve per solver (dashed when warm
    started), each step not solved marked by its status (``UNSOLVED_MARKS``: a red cross
    on an answer that failed the KKT check, its own marker on a timeout or a failure);
    the solvers of ``background`` drawn first as thin grey context lines."""
    xs_all, ys_all = [], []
    kinds: set[str] = set()
    if background is not None and len(background):
        for s in natural_sorted(background["solver"].unique()):
            c = background[background["solver"] == s].sort_values(sort_by)
            x = x_of(c)
            ax.plot(x, c["solve_time_s"], lw=0.8, color=GREY, zorder=0)
            xs_all += list(x)
            ys_all += list(c["solve_time_s"])
        ax.plot([], [], lw=0.8, color=GREY, label="other families")
    for s in natural_sorted(cells["solver"].unique()):
        c = cells[cells["solver"] == s].sort_values(sort_by)
        x = x_of(c)
        y = c["solve_time_s"]
        ax.plot(x, y, marker=marker_of(s), ms=4, lw=1.3, color=color_of(s), label=label_of(s),
                ls="--" if s.endswith(WARM_SUFFIX) else "-")
        bad = ~c["solved"]
        kinds |= _mark_unsolved(ax, x[bad], y[bad], c.loc[bad, "status"])
        xs_all += list(x)
        ys_all += list(y)
    for kind, (marker, color, label) in UNSOLVED_MARKS.items():
        if kind in kinds:
            ax.plot([], [], ls="none", marker=marker, ms=8, mew=2, color=color, mfc=color if marker == "x" else "none",
                    label=label)
    log_if_wide(ax, "x", xs_all)
    log_if_wide(ax, "y", ys_all)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("solve time  [s]")
    ax.grid(True, which="both", alpha=0.3)


def load_abscissa(cells: pd.DataFrame, every: pd.DataFrame) -> pd.Series:
    """The x of each of ``cells`` against the load: its step's median P/(E A) over the
    solved answers of ``every`` at that (instance, step) (a wrong or late answer's own load
    would put its point elsewhere); NaN where no answer there was solved or the load is
    not positive."""
    step_load = every[every["solved"]].groupby(["instance", "step"])["dim_load"].median()
    x = pd.Series([step_load.get((i, k), np.nan) for i, k in zip(cells["instance"], cells["step"])],
                  index=cells.index, dtype=float)
    return x.where(x > 0)


def _plot_time_vs_load(ax: Any, cells: pd.DataFrame, color_of: Callable[[str], Any],
                       label_of: Callable[[str], str] = str, background: pd.DataFrame | None = None,
                       marker_of: Callable[[str], str] = lambda s: "o") -> None:
    every = cells if background is None else pd.concat([cells, background])

    def x_of(c: pd.DataFrame) -> pd.Series:
        return load_abscissa(c, every)

    _plot_time_curves(ax, cells, x_of, "step", color_of, "dimensionless load P/(E A)  [-]", label_of, background,
                      marker_of)
    if ax.get_xscale() == "linear":  # loads are positive: log from half a decade on, else few ticks
        xs = list(x_of(every))
        if not log_if_wide(ax, "x", xs, decades=0.5):
            ax.xaxis.set_major_locator(MaxNLocator(4))


FIG4_TITLE = "Fig. 4: solve time against load (paper-sweep)"
#: What each ``UNSOLVED_MARKS`` marker means, as Fig. 4's caption says it.
UNSOLVED_TEXT: dict[str, str] = {
    "inaccurate": "red crosses: answers that failed the KKT check",
    "timeout": "open orange squares: solves stopped at the time limit, drawn at the time they took",
    "failed": "open purple diamonds: solves that failed or crashed, drawn at the time they took",
}
#: At most this many names in a caption's list of solvers.
MAX_NAMED = 12
#: How a total over a sweep (per_cell) counts repeats, as the tables' captions say it.
MIN_OVER_REPEATS = "each step's time the minimum over its repeats"


def named(solvers: list[str]) -> str:
    """Caption text naming ``solvers`` (at most ``MAX_NAMED``, then how many more)."""
    more = f" and {len(solvers) - MAX_NAMED} more" if len(solvers) > MAX_NAMED else ""
    return ", ".join(md_code(s) for s in solvers[:MAX_NAMED]) + more


def blocks_section(title: str, rows: pd.DataFrame,
                   one: Callable[[Block], tuple[str, tuple[RowChart, ...]]]) -> Section:
    """A paper section of one block per condition (``condition_blocks``): ``one(block)``
    gives each block's body and page charts, in the blocks' order."""
    parts = [one(b) for b in condition_blocks(rows)]
    return Section(title, "\n".join(body for body, _ in parts), page_charts=tuple(c for _, cs in parts for c in cs))


@register_section("paper-sweep", title=FIG4_TITLE, group="paper", order=10)
def fig4_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    return blocks_section(FIG4_TITLE, fig4_rows(rows), lambda b: _fig4_block(ctx, b, other_profiles_note(rows, b)))


def _fig4_block(ctx: ReportContext, block: Block, others: str = "") -> tuple[str, tuple[RowChart, ...]]:
    """Fig. 4, its totals table and its reading for one block of the scene (``fig4_rows``);
    ``others``: the captions' words on the profiles not drawn (``other_profiles_note``)."""
    prof, at_prof = block.profile, block.rows
    r = attempted(at_prof)
    if r.empty:
        return "Every pair of this scene was skipped.\n", drawn_as_png(FIG4_PAGE, block)
    cells = _curve_cells(r, own_ref=True)
    n_steps = sweep_steps(at_prof)
    tot = sweep_totals(cells, n_steps, _curve_cells(at_prof))

    def spread_of(a: str, b: str) -> Spread:
        return timing_spread(r, lambda g: total_ratio(sweep_totals(_curve_cells(g), n_steps), a, b))

    n_max = largest_n(at_prof)
    inst = natural_sorted(cells["instance"].unique())[0]
    sub = cells[cells["instance"] == inst]
    body = [block.lead() + surface_family_note(r)]
    placed = load_abscissa(sub, sub).notna() & sub["solve_time_s"].notna()
    if placed.any():
        body.append(_fig4_figure(ctx, block, sub, tot, placed, others))
    else:
        body.append(no_figure(f"Instance {inst} at profile `{prof}` has no time to draw against the load: the "
                              f"load axis takes a step's load from its solved answers, and no step was solved "
                              f"({status_counts(at_prof[at_prof['instance'] == inst])})."))
    body.append(table_md(ctx, f"total solve time over the sweep's {int(tot['steps'].iloc[0])} steps (instances x load "
                              f"steps), profile `{prof}`, {MIN_OVER_REPEATS}, with the accuracy it bought. A total "
                              f"is given only for a solver that solved every step; the others show '-' and, in "
                              f"parentheses, their time over the steps they ran, which is not comparable to a "
                              f"total. Rows: the solvers that solved every step by total time, then the others by "
                              f"steps solved; {WORST_RULE}.{others}",
                         ["solver", "family", "steps solved", "total [s]", "worst kkt", "worst p err"],
                         totals_rows(tot, ctx.family), "llrrrr"))
    body.append(_fig4_reading(ctx, block, cells, tot, n_max, spread_of))
    return "\n".join(body), drawn_as_png(FIG4_PAGE, block, inst)


def _curve_cells(rows: pd.DataFrame, own_ref: bool = False) -> pd.DataFrame:
    """``per_cell`` of ``rows`` with one label per curve: a solver's warm-started runs
    are the label "pk (warm)" beside its cold "pk"; with ``own_ref``, the ``OWN_REF``
    column, read on the solver's own name before the curve label."""
    cells = per_cell(rows)
    if own_ref:
        cells[OWN_REF] = agg.own_reference(cells)
    cells["warm"] = cells.groupby(["solver", "history"])["warm_start"].transform("any").astype(bool)
    cells["solver"] = [_curve_label(s, w) for s, w in zip(cells["solver"], cells["warm"])]
    return cells


def _panels_figure(panels: list[Panel], cells: pd.DataFrame, draw: Callable[[Any, pd.DataFrame, Any], None],
                   title: Callable[[str], str]) -> Any:
    """A figure of one axes per panel of ``panels`` (two columns where several): ``draw(ax,
    the panel's cells, the other cells to draw in grey or None)``, titled ``title(where)``
    (``where``: the panel's title and "; ", or "" for a single panel), its legend beside."""
    ncols = 1 if len(panels) == 1 else 2
    fig, axes = grid_figure(-(-len(panels) // ncols), ncols, width=6.4 if ncols == 1 else 5.6,
                            height=4.2 if ncols == 1 else 3.6, wspace=0.85)
    flat = [a for row in axes for a in row]
    for ax, panel in zip(flat, panels):
        mine = cells["solver"].isin(panel.solvers)
        draw(ax, cells[mine], cells[~mine] if len(panels) > 1 else None)
        ax.set_title(title("" if len(panels) == 1 else f"{panel.title}; "), fontsize=8)
        legend_outside(ax, "solver")
    for ax in flat[len(panels):]:
        ax.set_visible(False)
    return fig


def _fig4_figure(ctx: ReportContext, block: Block, sub: pd.DataFrame, tot: pd.DataFrame, placed: pd.Series,
                 others: str = "") -> str:
    """Fig. 4 of one instance's cells ``sub`` (``placed``: those with a load and a time to
    draw) of ``block``, saved, with its caption (``others``: words on the profiles not drawn)."""
    inst, prof, at_prof = sub["instance"].iloc[0], block.profile, block.rows
    labels = natural_sorted(sub["solver"].unique())
    best = best_per_family(tot.loc[labels], ctx.family)
    panels = family_panels(labels, ctx.family, best)
    fig = _panels_figure(panels, sub, lambda ax, c, bg: _plot_time_vs_load(ax, c, ctx.color, background=bg,
                                                                            marker_of=ctx.marker),
                         lambda where: f"paper-sweep {inst}, {where}profile {prof}")
    rel = ctx.save_figure(fig, block.name("fig4-paper-sweep"))
    n_max = largest_n(at_prof)
    marks = [UNSOLVED_TEXT[k] for k in UNSOLVED_MARKS
             if (placed & ~sub["solved"] & (sub["status"].map(unsolved_kind) == k)).any()]
    best_rule = f" In the first panel {BEST_RULE}." if len(panels) > 1 and not panels[0].family else ""
    grid = sorted(int(n) for n in sub["N"].dropna().unique())
    return ctx.figure_md(rel, f"solve time per load step against P/(E A), instance {inst} (N = "
                              f"{', '.join(map(fmt_int, grid)) or '-'}; the sweep's largest trial set has n = {n_max}), "
                              f"{block.profile_text}; dashed: warm started"
                              + "".join(f"; {m}" for m in marks) + ". "
                              + _drawn_note(ctx, block, sub, labels) + skipped_note(tot.loc[labels])
                              + _unplaced_note(sub, placed) + panels_note(panels) + best_rule
                              + " Paper Fig. 4 ran at eps = 1e-8." + others)


def _drawn_note(ctx: ReportContext, block: Block, sub: pd.DataFrame, labels: list[str]) -> str:
    """Caption text: which solvers of the scene's ``block`` the figure draws, and which it
    does not (those that ran no step of the drawn instance)."""
    fams = ", ".join(sort_families(ctx.family(x) for x in labels))
    ran = {s.removesuffix(WARM_SUFFIX) for s in labels}
    missing = [s for s in natural_sorted(block.rows["solver"].unique()) if s not in ran]
    scope = "the scene" if block.alone else f"the scene under this condition ({block.where}; the others have their own)"
    if not missing:
        return f"Every solver of {scope} is drawn (families: {fams})."
    return (f"Drawn: the {len(labels)} curves of the solvers of {scope} that ran a step of this instance (families: "
            f"{fams}); not drawn, {len(missing)} solvers that ran no step of it (skipped at every step; Skips and "
            f"failures says why): {named(missing)}.")


def _unplaced_note(sub: pd.DataFrame, placed: pd.Series) -> str:
    """Caption text naming the solves with a time that no load places (no solver solved
    their step); "" when none."""
    off = sub[~placed & sub["solve_time_s"].notna()]
    if off.empty:
        return ""
    what = ", ".join(f"{md_code(s)} step {fmt_int(k)} ({st})"
                     for s, k, st in zip(off["solver"], off["step"], off["status"]))
    return f" Not drawn, as no solver solved their step to give it a load: {what}."


#: Fig. 4's checks of the paper's speed-ups: (role key, words, ledger row, what the paper says beyond the number).
FIG4_CHECKS = (("pk-printed", "P&K as printed (Algorithm 2) / NNLS+GP", "fig4-pkprinted-over-nnlsgp", ""),
               ("pk", "P&K 1999 / NNLS+GP", "fig4-pk-cold-over-nnlsgp", ""),
               ("greedy-cg", "greedy CG / NNLS+GP", "fig4-greedy-over-nnlsgp", " (two orders of magnitude)"),
               ("admm", "ADMM / NNLS+GP", "fig4-admm-over-nnlsgp", " (two orders of magnitude)"))


def _fig4_reading(ctx: ReportContext, block: Block, cells: pd.DataFrame, tot: pd.DataFrame, n_max: int,
                  spread_of: Callable[[str, str], Spread]) -> str:
    """Fig. 4's reading of one block: the paper's speed-ups against NNLS+GP from the sweep
    totals ``tot`` of its curve ``cells``, and the fastest solver, overall and at each
    common accuracy, named only when every other is slower by more than the timing spread
    (``spread_of(a, b)``: the spread of the ratio of a's total to b's).  A speed-up is
    judged (paper_readings.py ``agreement``) only where the claims ledger reads no other
    measurement of it (``fig4_elsewhere``; ADMM: never, the ledger reads the paper's ADMM on
    its own totals); else its ratio is given with the ledger's row named."""
    role = paper_roles(cells)
    ref = role["nnls-gp"]
    parts = [f"**Reading.** The paper (sec. 4, n up to 35555 at 512²) finds NNLS+GP (K = 100) fastest. "
             f"Here the largest trial set has n = {n_max}. Solvers stop at their own tolerances, so every time "
             f"below comes with the worst kkt_error of its sweep."]
    if too_small(n_max):
        parts.append(SMALL_N_TEXT)
    if ref is None:
        parts.append(f"NNLS+GP {absent(ctx.table, 'paper-sweep', 'nnls-gp', block)}, so the paper's speed-ups "
                     f"cannot be checked here.")
    else:
        papers_admm, other_admm = paper_admm(cells)
        role["admm"] = papers_admm
        for key, label, ledger, beyond in FIG4_CHECKS:
            s, claim = role[key], ledger_claim(ledger, beyond)
            if s is None and key == "admm" and other_admm:
                parts.append(f"{label}: {md_code(other_admm)} is not ADMM as the paper states it (alpha = 1.5, "
                             f"rho = 1, the printed stop), so it is not read against the paper's {claim.text} (the "
                             f"claims ledger reads only the paper's ADMM, row `{ledger}`).")
            elif s is None:
                parts.append(f"{PAPER_ROLES[key].label} {absent(ctx.table, 'paper-sweep', PAPER_ROLES[key].base_solver, block)}.")
            elif not tot.loc[s, "complete"]:
                parts.append(f"{label}: `{s}` did not solve every step, so its ratio is not comparable here (the "
                             f"claims ledger's row `{ledger}` totals its answers, solved or not).")
            else:
                kkt = f"worst kkt {fmt_err(tot.loc[s, 'worst_kkt'])} against {fmt_err(tot.loc[ref, 'worst_kkt'])})."
                ops = operators_of(cells[cells["solver"].isin([s, ref])])
                why = fig4_elsewhere(ctx.table, attempted(block.rows), PAPER_ROLES[key].base_solver, ops)
                if key == "admm":
                    why = why or "the claims ledger totals the paper's ADMM one repeat at a time and takes the median"
                m = total_ratio(tot, s, ref)
                parts.append(claim_sentence(label, m, claim, spread_of(s, ref)).rstrip(".") + " (" + kkt if not why
                             else f"{label}: measured {fmt_ratio(m)} against the paper's {claim.text} -- no verdict "
                                  f"here: {why} (row `{ledger}`; {kkt}")
        warm, cold = role["pk-warm"], role["pk"]
        if warm and cold and warm != cold:
            w = total_ratio(tot, warm, cold)
            sp = spread_of(warm, cold)
            parts.append(f"Warm-started P&K takes {fmt_ratio(w)} the time of the cold one"
                         + (f", a tie within the timing spread of {sp.source}." if sp.ties(w) else "."))
    complete = tot[tot["complete"]]
    if len(complete):
        times = complete["total_s"]
        best = str(times.idxmin())
        tied = tied_with(times, best, spread_of)
        if tied:
            parts.append(f"No solver is the fastest over the whole sweep here: the least total, "
                         f"{time_at(tot, best)}, is "
                         + ties_text(times, best, tied, spread_of(tied[0], best), lambda x: time_at(tot, x)) + ".")
        else:
            extra = ""
            if ref and best != ref and ref in complete.index:
                extra = f", {fmt_ratio(total_ratio(tot, ref, best))} faster than NNLS+GP's {time_at(tot, ref)}"
            parts.append(f"The fastest solver over the whole sweep here is {md_code(best)} with "
                         f"{fmt_num(complete.loc[best, 'total_s'])} s at worst kkt "
                         f"{fmt_err(complete.loc[best, 'worst_kkt'])}{extra}.")
        levels = fastest_at_accuracy(tot)
        if levels:
            words = []
            for lv, s in levels:
                at_lv = times[complete["worst_kkt"] <= lv]
                near = tied_with(at_lv, s, spread_of)
                words.append(f"<= {lv:.0e}: {time_at(tot, s)}" + (
                    f", {ties_text(at_lv, s, near, spread_of(near[0], s), lambda x: time_at(tot, x))}" if near else ""))
            parts.append("Fastest at a common accuracy (every step solved with kkt_error at most the level; a "
                         "solver within the timing spread of the fastest is named as tied): "
                         + "; ".join(words) + ".")
    elif len(tot):
        parts.append(f"No solver solved all {int(tot['steps'].iloc[0])} steps of the sweep, so none is named "
                     f"fastest: a sum over part of the sweep is not a total.")
    return " ".join(parts) + "\n"


#: The paper's greedy solvers (keys of PAPER_ROLES) that Fig. 5 compares: CG, Gauss-Seidel, Cholesky.
GREEDY_ROLES = ("greedy-cg", "greedy-gs", "greedy-chol")


@register_section("greedy-linear-solvers", title="Fig. 5: greedy with CG, Gauss-Seidel and Cholesky",
                  group="paper", order=20)
def fig5_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "Fig. 5: greedy with CG, Gauss-Seidel and Cholesky (greedy-linear-solvers)"
    return blocks_section(title, rows, lambda block: _fig5_block(ctx, block))


def _fig5_block(ctx: ReportContext, block: Block) -> tuple[str, tuple[RowChart, ...]]:
    """Fig. 5 and its reading for one block of the scene."""
    prof, r = block.profile, block.rows
    cells = per_cell(attempted(r))
    if cells.empty:
        return "Every pair of this scene was skipped.\n", drawn_as_png(FIG5_PAGE, block)
    drawn = natural_sorted(cells["solver"].unique())
    panels = family_panels(drawn, ctx.family, best_per_family(sweep_totals(cells, 0), ctx.family))
    fig = _panels_figure(panels, cells, lambda ax, c, bg: _plot_time_curves(
        ax, c, lambda x: x["n"], "n", ctx.color, "trial-set size n  [points]", background=bg, marker_of=ctx.marker),
        lambda where: f"greedy-linear-solvers, {where}profile {prof}")
    rel = ctx.save_figure(fig, block.name("fig5-greedy-linear-solvers"))
    body = [block.lead() + surface_family_note(cells)]
    greedy = any(resolve_role(cells, k) is not None for k in GREEDY_ROLES)
    body.append(ctx.figure_md(rel, f"solve time against the trial-set size n of {named(drawn)}, {block.profile_text} "
                              + ("(" if greedy else "-- no greedy solver ran in this scene, so this is not ")
                              + "paper Fig. 5: greedy with CG against MATLAB's mldivide (Cholesky) and Gauss-Seidel"
                              + (")." if greedy else ".") + panels_note(panels)
                              + (f" In the first panel {BEST_RULE}." if len(panels) > 1 and not panels[0].family
                                 else "")))
    body.append(_fig5_reading(ctx, block, cells, r))
    return "\n".join(body), drawn_as_png(FIG5_PAGE, block)


def _fig5_reading(ctx: ReportContext, block: Block, cells: pd.DataFrame, rows: pd.DataFrame) -> str:
    """Fig. 5's reading of one block: the paper's ratios of greedy Cholesky and
    Gauss-Seidel to greedy CG, first as the section pools them (the median of the paired
    per-step ratios of ``cells``, ``per_cell`` of the attempted ``rows``; no verdict), then
    as the claims ledger measures and judges them (``fig5_ledger``: per operator and grid
    size, the steps with n >= ``FIG5_MIN_N``, the median over the repeats); and where
    Cholesky ran out of memory."""
    cg, gs, ch = (resolve_role(rows, k) for k in GREEDY_ROLES)
    parts = ["**Reading.**"]
    if cg is None:
        parts.append(f"Greedy CG {absent(ctx.table, 'greedy-linear-solvers', 'greedy-cg', block)}, so the paper's "
                     f"ratios cannot be checked here.")
    for other, key, label, ledger, beyond in ((ch, "greedy-chol", "greedy Cholesky / greedy CG time",
                                               "fig5-chol-over-cg", " (30-40 % faster)"),
                                              (gs, "greedy-gs", "greedy Gauss-Seidel / greedy CG time",
                                               "fig5-gs-over-cg", " slower")):
        if cg is None:
            break
        if other is None:
            parts.append(f"{label.split(' /')[0]} {absent(ctx.table, 'greedy-linear-solvers', key, block)}.")
            continue
        claim = ledger_claim(ledger, beyond)
        m, k, n_inst = paired_median_ratio(cells, other, cg)
        sizes = "; ".join(f"N = {fmt_int(x.N)}" + (f" ({x.operator})" if len(block.operators) > 1 else "") + (
            f": {fmt_ratio(x.measured)} over {x.count} step{'s' if x.count != 1 else ''} -- "
            + ledger_words(x.verdict, x.measured, claim, x.repeats) if x.count else
            f": no step with n >= {FIG5_MIN_N} both solved") for x in fig5_ledger(rows, key, "greedy-cg", ledger))
        parts.append(f"{label} ({paired_count_text(k, n_inst)}): measured {fmt_ratio(m)} against the paper's "
                     f"{claim.text}, each step's time the minimum over its repeats, pooled as drawn (no verdict on it); "
                     + (f"the claims ledger's measurement (row `{ledger}`: per grid size, the steps with n >= "
                        f"{FIG5_MIN_N} both solved, the median over the repeats): {sizes}." if sizes else
                        f"no operator and grid size holds both, so the claims ledger's row `{ledger}` has no "
                        f"measurement here."))
    if ch is not None:
        sk = rows[(rows["solver"] == ch) & (rows["status"] == "skipped")]
        if len(sk):
            i = sk["n"].idxmin()
            parts.append(f"Cholesky was skipped from n = {fmt_int(sk.loc[i, 'n'])} on "
                         f"({md_escape(sk.loc[i, 'skip_reason'])}); the paper ran out of memory for n > 20000.")
        else:
            parts.append("Cholesky was not skipped for memory at any size in this table (the paper ran out of "
                         "memory for n > 20000).")
    return " ".join(parts) + "\n"


@register_scene_colors("gp-k-sweep")
def k_colors(rows: pd.DataFrame) -> dict[str, str]:
    """Fig. 6's K variants dark to light along K (viridis), in every figure of the scene:
    one method's shades of its family would hide the order of K."""
    cells = k_cells(attempted(rows))
    Ks = sorted(cells["K"].unique())
    cmap = colormaps["viridis"]
    return {str(s): to_hex(cmap(Ks.index(k) / max(len(Ks) - 1, 1))) for s, k in zip(cells["solver"], cells["K"])}


@register_section("gp-k-sweep", title="Fig. 6: NNLS+GP time against K", group="paper", order=30)
def fig6_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "Fig. 6: NNLS+GP time against the number K of GP steps (gp-k-sweep)"
    return blocks_section(title, rows, lambda block: _fig6_block(ctx, block))


def _fig6_block(ctx: ReportContext, block: Block) -> tuple[str, tuple[RowChart, ...]]:
    """Fig. 6, its totals table and its reading for one block of the scene."""
    prof = block.profile
    at_prof = attempted(block.rows)
    cells = k_cells(at_prof)
    if per_cell(at_prof).empty:
        return "Every pair of this scene was skipped.\n", drawn_as_png(FIG6_PAGE, block)
    if cells.empty:
        return (block.lead() + f"No NNLS+GP K-variant was run in this scene (no row names its K, params JSON "
                f"{{\"K\": ...}}), so there is no K to plot; the solvers that ran: "
                f"{named(natural_sorted(at_prof['solver'].unique()))}.\n", drawn_as_png(FIG6_PAGE, block))
    label_of_solver = dict(zip(cells["solver"], cells["K"]))
    inst = natural_sorted(cells["instance"].unique())[0]
    fig, (ax1, ax2) = new_figure(ncols=2, width=5.2, height=4.0)
    sub = cells[cells["instance"] == inst]
    order = sorted(sub["solver"].unique(), key=lambda s: label_of_solver[s])
    _plot_time_vs_load(ax1, sub[sub["solver"].isin(order)], lambda s: ctx.color(s, "gp-k-sweep"),
                       lambda s: f"K = {int(label_of_solver[s])}")
    ax1.set_title(f"per step, instance {inst}", fontsize=9)
    tot = k_totals(cells)
    ax2.plot(tot.index, tot["total_s"], marker="o", color="tab:blue", label="total over steps")
    inc = tot[~tot["complete"]]
    if len(inc):
        ax2.plot(inc.index, inc["total_s"], ls="none", marker="x", ms=8, mew=2, color="red",
                 label="some step not solved")
    ax2.axvline(100, color="gray", ls="--", lw=1, label="paper's minimum (K = 100)")
    log_if_wide(ax2, "y", tot["total_s"])
    ax2.set_xlabel("GP steps before NNLS, K  [-]")
    ax2.set_ylabel("total solve time over the sweep  [s]")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.set_title("total", fontsize=9)
    handles1, labels1 = ax1.get_legend_handles_labels()
    ax1.legend(handles1, labels1, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=4,
               frameon=False)
    legend_outside(ax2)
    rel = ctx.save_figure(fig, block.name("fig6-gp-k-sweep"))
    body = [block.lead() + surface_family_note(cells)]
    body.append(ctx.figure_md(rel, f"NNLS+GP against K, {block.profile_text}: (left) time per step against P/(E A); "
                               f"(right) total time summed over all steps and instances."))
    body.append(table_md(ctx, f"total NNLS+GP time against K, profile `{prof}`, {MIN_OVER_REPEATS}.",
                         ["K", "total [s]", "all solved"],
                         [(int(k), fmt_num(tot.loc[k, "total_s"]), "yes" if tot.loc[k, "complete"] else "no")
                          for k in tot.index], "rrl"))

    def spread_of(k1: Hashable, k2: Hashable) -> Spread:
        return timing_spread(at_prof, lambda g: float(k_totals(k_cells(g))["total_s"].get(k1, np.nan)
                                                      / k_totals(k_cells(g))["total_s"].get(k2, np.nan)))

    ledgers = fig6_ledger(at_prof)
    body.append(fig6_reading(tot, spread_of, largest_n(at_prof), ledgers[0] if len(ledgers) == 1 else None,
                             fig6_elsewhere(ctx.table, at_prof, len(ledgers))))
    page = replace(drawn_as_png(FIG6_PAGE, block, inst)[0], colors=tuple(
        (s, ctx.color(s, "gp-k-sweep")) for s in sorted(label_of_solver, key=label_of_solver.get)))
    return "\n".join(body), (page,)


# ---------------------------------------------------------------------------
# Closed-form checks
# ---------------------------------------------------------------------------


def _analytic_section(ctx: ReportContext, rows: pd.DataFrame, scene: str) -> Section | None:
    title = f"Closed-form check ({scene})"
    blocks = condition_blocks(rows)  # every condition; a label that ran under several is named with its profile
    twice = {s for b in blocks for s in set(b.rows["solver"]) if sum(s in set(c.rows["solver"]) for c in blocks) > 1}
    r = per_cell(pd.concat([attempted(b.rows).assign(solver=lambda d, p=b.profile: [
        f"{s} ({p})" if s in twice else s for s in d["solver"]]) for b in blocks]))
    r = r[r["analytic_load_rel_error"].notna()]
    if r.empty:
        return Section(title, "No row carries an analytic load error.\n")
    xcol = "N" if r["N"].notna().all() else "n"
    fig, (ax,) = new_figure(width=6.0, height=4.0)
    lines = []
    solvers = natural_sorted(r["solver"].unique())
    for i, s in enumerate(solvers):  # (coinciding curves stay visible: each its marker, dash and a shrinking size)
        c = r[r["solver"] == s].groupby(xcol)["analytic_load_rel_error"].max().sort_index()
        ax.plot(c.index, floor_log(c.to_numpy()), marker=ctx.marker(s), ms=7 - 3 * i / max(len(solvers) - 1, 1),
                mfc="none", ls=ctx.dash(s), color=ctx.color(s), label=s)
        order = _observed_order(c.index.to_numpy(float), c.to_numpy(float))
        lines.append((s, fmt_err(c.iloc[-1]), f"{int(c.index[-1])}", fmt_num(order, 2)))
    ax.set_xscale("log")
    ax.set_yscale("log")
    integer_ticks(ax, r[xcol].unique())
    ax.set_xlabel("grid points per side N  [-]" if xcol == "N" else "trial-set size n  [-]")
    ax.set_ylabel("|P - P_analytic| / P_analytic  [-]")
    ax.grid(True, which="both", alpha=0.3)
    legend_outside(ax, "solver")
    rel = ctx.save_figure(fig, f"analytic-{scene}", on_page=True)
    body = [ctx.figure_md(rel, f"{scene}: relative error of the total load against the closed form, over mesh "
                               f"refinement (the largest error over the load steps of each mesh).")]
    body.append(table_md(ctx, f"{scene}: finest-mesh load error and observed order (slope of log error "
                              f"against log {xcol} over the finest three meshes).",
                         ["solver", "error (finest)", xcol, "observed order"], lines, "lrrr"))
    return Section(title, "\n".join(body))


def _observed_order(x: np.ndarray, e: np.ndarray) -> float:
    ok = np.isfinite(e) & (e > 0) & (x > 0)
    x, e = x[ok][-3:], e[ok][-3:]
    if len(x) < 2:
        return float("nan")
    return float(-np.polyfit(np.log(x), np.log(e), 1)[0])


register_section("hertz", title="Hertz", group="scenes", order=50)(
    lambda ctx, rows: _analytic_section(ctx, rows, "hertz"))
register_section("flat-punch", title="Flat punch", group="scenes", order=51)(
    lambda ctx, rows: _analytic_section(ctx, rows, "flat-punch"))
