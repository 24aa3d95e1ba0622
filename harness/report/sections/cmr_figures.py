"""The CMR report sections and their figures: Fig. 8 against H, the load error along the
history, Fig. 9 against h, and where the cascade starts -- each a median line with its
10-90 % band over the seeds, one panel per base and coarse reading -- and the roll-off
section.  The numbers they draw (pairs, summaries, bands, tables) are computed in
harness/report/sections/cmr.py, which imports nothing from here.
"""

from __future__ import annotations

from typing import Any, Iterable, Sequence

import numpy as np
import pandas as pd

from ..charts import RowChart
from ..core import (
    ReportContext,
    Section,
    fmt_num,
    grid_figure,
    register_section,
    tidy_log_ticks,
)
from .cmr import (
    BAND,
    CMR_COARSEST,
    CMR_H,
    ERROR_TOL,
    FIG9_H,
    PAPER_TIME_RATIO,
    ROBUST_SHARE,
    Band,
    BaseRun,
    Table,
    base_runs,
    by_family,
    design_note,
    cmr_pairs,
    family_label,
    coarsest_table,
    fig8_reading,
    fig8_table,
    fig9_reading,
    finite,
    fmt_pct1,
    h_table,
    history_bands,
    history_table,
    instance_totals,
    of_variant,
    panel_title,
    summaries,
    variant_order,
)
from .paper import surface_family_note

#: The page charts of the CMR figures: CMR and direct solve time per instance.
FIG8_PAGE = (RowChart("Fig. 8: CMR and direct solve time against load", by_instance=True),)
FIG9_PAGE = (RowChart("Fig. 9: CMR and direct solve time against load", by_instance=True),)
CUTOFF_PAGE = (RowChart("cmr-cutoff: CMR and direct solve time against load", by_instance=True),)


def _band_line(ax: Any, x: Sequence[float], bands: Sequence[Band], label: str, color: Any, scale: float = 1.0) -> None:
    med = np.array([b.median for b in bands]) * scale
    lo = np.array([b.lo for b in bands]) * scale
    hi = np.array([b.hi for b in bands]) * scale
    ax.fill_between(x, lo, hi, color=color, alpha=0.2, lw=0)
    ax.plot(x, med, "o-", color=color, label=label, ms=4)


def _same_y(row: Sequence[Any], bottom: float | None = None, top: float | None = None) -> None:
    """One y range over a row of panels (the variants side by side), optionally pinned."""
    lims = [ax.get_ylim() for ax in row]
    lo = min(lo for lo, _ in lims) if bottom is None else bottom
    hi = max(hi for _, hi in lims) if top is None else top
    for ax in row:
        ax.set_ylim(lo, hi)


#: The mantissas of the labelled steps of a log time-ratio axis.
RATIO_STEPS = (1.0, 2.0, 5.0)


def ratio_limits(lo: float, hi: float) -> tuple[float, float]:
    """The y range of a log time-ratio axis over data from ``lo`` to ``hi`` (> 0): out to the
    labelled step at or below ``lo`` and the one at or above ``hi`` (``RATIO_STEPS`` where the
    data span under two decades, as ``tidy_log_ticks`` labels them, else powers of ten), so
    that a labelled tick lies beyond the data at both ends (ratios of 1.5-1.8 under a top
    label of 1 could not be read)."""
    mantissas = RATIO_STEPS if np.log10(hi / lo) < 2 else (1.0,)
    steps = np.array([m * 10.0 ** k for k in range(int(np.floor(np.log10(lo))) - 1, int(np.ceil(np.log10(hi))) + 1)
                      for m in mantissas])
    return float(steps[steps <= lo * (1 + 1e-9)].max()), float(steps[steps >= hi * (1 - 1e-9)].min())


def _ratio_axes(row: Sequence[Any], ratios: Iterable[float]) -> None:
    """One y range for a row of time-ratio panels: logarithmic when the ratios span more
    than a decade, out to a labelled step beyond the data at each end (``ratio_limits``),
    else linear from 0."""
    v = finite(ratios)
    v = v[v > 0]
    if len(v) and np.log10(v.max() / v.min()) > 1:
        for ax in row:
            ax.set_yscale("log")
        _same_y(row)
        lo0, hi0 = row[0].get_ylim()
        lo, hi = ratio_limits(lo0, hi0)
        _same_y(row, bottom=lo, top=hi)
        for ax in row:  # labelled as ``ratio_limits`` rounded: by the span of the data's range
            tidy_log_ticks(ax, "y", float(np.log10(hi0 / lo0)))
    else:
        _same_y(row, bottom=0.0)


def _tol_lines(ax: Any) -> None:
    for y in (-100 * ERROR_TOL, 100 * ERROR_TOL):
        ax.axhline(y, color="gray", ls="--", lw=0.8)


def fig8_figure(ctx: ReportContext, tot: pd.DataFrame, family: str, runs: dict[str, BaseRun]) -> str:
    """Fig. 8 of ``tot`` (``instance_totals``) per variant; ``runs``: ``base_runs`` of its pairs
    (the panel titles say how each base ran)."""
    variants = variant_order(tot)
    fig, axes = grid_figure(3, len(variants), width=3.4, height=2.6, wspace=0.35)
    for j, v in enumerate(variants):
        sub = of_variant(tot, v)
        s = summaries(sub, ["H"])
        Hs = [k[0] for k in s]
        a1, a2, a3 = axes[0][j], axes[1][j], axes[2][j]
        a1.scatter(sub["H"], sub["ratio"], s=6, color="tab:blue", alpha=0.35)
        _band_line(a1, Hs, [v.ratio for v in s.values()], "median", "tab:blue")
        a1.axhline(1.0, color="black", lw=0.8)
        a1.axhline(PAPER_TIME_RATIO, color="gray", ls=":", lw=0.8)
        a1.set_title(panel_title(v, runs), fontsize=8)
        a1.set_ylabel("time CMR / direct\n(summed over the history)" if j == 0 else "")
        a2.scatter(sub["H"], 100 * sub["err"], s=6, color="tab:red", alpha=0.35)
        _band_line(a2, Hs, [v.err for v in s.values()], "median", "tab:red", scale=100.0)
        _tol_lines(a2)
        a2.set_ylabel("load error at the\ntop step [%]" if j == 0 else "")
        a3.bar(Hs, [100 * v.share for v in s.values()], width=0.08, color="tab:green", alpha=0.7)
        a3.axhline(100 * ROBUST_SHARE, color="gray", ls="--", lw=0.8)
        a3.set_ylim(0, 105)
        a3.set_ylabel(f"seeds with |error|\n< {100 * ERROR_TOL:g} % [%]" if j == 0 else "")
        a3.set_xlabel("Hurst exponent H")
        for ax in (a1, a2, a3):
            ax.set_xticks(Hs)
            ax.margins(x=0.12)
            ax.grid(True, alpha=0.3)
    _ratio_axes(axes[0], tot["ratio"])
    _same_y(axes[1])
    return ctx.save_figure(fig, f"fig8-cmr-{family or 'all'}", on_page=True)


def history_figure(ctx: ReportContext, pairs: pd.DataFrame, family: str) -> str:
    import matplotlib

    variants = variant_order(pairs)
    runs = base_runs(pairs)
    hb = history_bands(pairs)
    Hs = sorted({k[3] for k in hb})
    cmap = matplotlib.colormaps["viridis"]
    colors = {H: cmap(i / max(len(Hs) - 1, 1) * 0.9) for i, H in enumerate(Hs)}
    fig, axes = grid_figure(1, len(variants), width=3.6, height=3.0, wspace=0.35)
    for j, v in enumerate(variants):
        ax = axes[0][j]
        for H in Hs:
            ks = sorted(k[4] for k in hb if k[:4] == (*v, H))
            if ks:
                _band_line(ax, [k + 1 for k in ks], [hb[(*v, H, k)] for k in ks], f"H = {H:g}", colors[H], 100.0)
        ax.set_xticks(sorted({k[4] + 1 for k in hb}))
        _error_panel(ax, panel_title(v, runs), j, "load step (1: lowest load)", "load error [%]")
    return _error_row(ctx, fig, axes[0], f"fig8-history-{family or 'all'}")


def fig9_figure(ctx: ReportContext, tot: pd.DataFrame, family: str, runs: dict[str, BaseRun]) -> str:
    """Fig. 9 of ``tot`` (``instance_totals``) per variant; ``runs`` as ``fig8_figure``'s."""
    variants = variant_order(tot)
    metrics = (("np_n", "n_p / n", 1.0, "tab:purple"), ("ratio", "time CMR / direct", 1.0, "tab:blue"),
               ("err", "load error [%]", 100.0, "tab:red"))
    fig, axes = grid_figure(3, len(variants), width=3.6, height=2.6, wspace=0.35)
    for j, v in enumerate(variants):
        sub = of_variant(tot, v)
        s = summaries(sub, ["h"])
        hs = [k[0] for k in s]
        for i, (attr, label, scale, color) in enumerate(metrics):
            ax = axes[i][j]
            _band_line(ax, hs, [getattr(x, attr) for x in s.values()], "median", color, scale)
            if attr == "err":
                _tol_lines(ax)
            if attr == "ratio":
                ax.axhline(1.0, color="black", lw=0.8)
            ax.set_ylabel(label if j == 0 else "")
            ax.grid(True, alpha=0.3)
        axes[0][j].set_title(panel_title(v, runs), fontsize=8)
        axes[2][j].set_xlabel("area-of-influence factor h")
    _same_y(axes[0], bottom=0.0, top=1.0)
    _ratio_axes(axes[1], tot["ratio"])
    _same_y(axes[2])
    return ctx.save_figure(fig, f"fig9-cmr-h-{family or 'all'}", on_page=True)


def coarsest_figure(ctx: ReportContext, tot: pd.DataFrame, family: str, runs: dict[str, BaseRun]) -> str:
    """Where the cascade starts, per variant; ``runs`` as ``fig8_figure``'s."""
    Hs = sorted(tot["H"].dropna().unique())
    H = FIG9_H if FIG9_H in Hs else (Hs[-1] if Hs else np.nan)
    tot = tot[tot["H"] == H] if Hs else tot
    variants = variant_order(tot)
    fig, axes = grid_figure(1, len(variants), width=3.6, height=3.0, wspace=0.35)
    for j, v in enumerate(variants):
        ax = axes[0][j]
        sub = of_variant(tot, v)
        s = summaries(sub, ["coarsest"])
        ks = [k[0] for k in s]
        ax.scatter(sub["coarsest"], 100 * sub["err"], s=6, color="tab:red", alpha=0.35)
        _band_line(ax, ks, [x.err for x in s.values()], "median", "tab:red", 100.0)
        ax.plot(ks, [100 * x.worst for x in s.values()], "x--", color="black", label="worst seed")
        ax.set_xscale("log", base=2)
        ax.set_xticks(ks, [str(k) for k in ks])
        _error_panel(ax, panel_title(v, runs), j, "first level (points per side)", "load error at the top step [%]")
    return _error_row(ctx, fig, axes[0], f"fig9-coarsest-{family or 'all'}")


def _error_panel(ax: Any, title: str, j: int, xlabel: str, ylabel: str) -> None:
    """A load-error panel of one variant: the 2 % lines, title, labels (y on the first only), grid."""
    _tol_lines(ax)
    ax.set_title(title, fontsize=8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel if j == 0 else "")
    ax.grid(True, alpha=0.3)


def _error_row(ctx: ReportContext, fig: Any, row: Any, name: str) -> str:
    """Legend on the last panel, one y-range for the row, and the saved figure's path."""
    row[-1].legend(fontsize=7, loc="lower right")
    _same_y(row)
    return ctx.save_figure(fig, name, on_page=True)


@register_section("cmr", title="Fig. 8: CMR against the direct solve", group="paper", order=50)
def cmr_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "Fig. 8: cascade multi-resolution (CMR) against the direct solve, as distributions (cmr)"
    pairs = cmr_pairs(rows)
    if pairs.empty:
        return Section(title, "No CMR row could be paired with its direct base solve.\n", page_charts=FIG8_PAGE)
    sources = pairs["surface_source"] if "surface_source" in pairs else pd.Series("", index=pairs.index)
    measured = sources.fillna("").astype(str) != ""  # (a measured map's instance has no Hurst exponent)
    if not np.isfinite(pairs["H"]).any():
        why = ("its instances are measured maps, which have none" if measured.all() else
               "no `hurst` column: a table written before it existed; re-run the scene to draw it")
        return Section(title, f"Fig. 8 is drawn against the Hurst exponent H, and this table gives no instance one "
                              f"({why}).\n", page_charts=FIG8_PAGE)
    unplaced = sorted(set(pairs.loc[~np.isfinite(pairs["H"]), "instance"]))
    left_out = (f"Left out of Fig. 8: {len(unplaced)} instance(s) with no Hurst exponent ({', '.join(unplaced)}).\n"
                if unplaced else "")
    pairs = pairs[np.isfinite(pairs["H"])]
    body = [surface_family_note(pairs), design_note(pairs), left_out]
    for family, fp in by_family(pairs):
        tot = instance_totals(fp)
        if len(by_family(pairs)) > 1:
            body.append(f"#### Surface family `{family or 'other'}`\n")
        body.append(ctx.figure_md(fig8_figure(ctx, tot, family, base_runs(fp)),
                                  f"Fig. 8 ({family_label(family)}): against H, per base and coarse reading: (top) time CMR / "
                                  f"direct summed over the load history (dotted: the paper's ~{PAPER_TIME_RATIO:g}); "
                                  f"(middle) error in the load at the top step (dashed: +-{100 * ERROR_TOL:g} %); "
                                  f"line: median, band: {100 * BAND[0]:g}-{100 * BAND[1]:g} %, dots: seeds; "
                                  f"(bottom) share of seeds with |error| < {100 * ERROR_TOL:g} % (dashed: "
                                  f"{100 * ROBUST_SHARE:g} %)."))
        body.append(fig8_table(tot, family).md(ctx))
        body.append(ctx.figure_md(history_figure(ctx, fp, family),
                                  f"load error along the load history ({family_label(family)}) per H: median and "
                                  f"{100 * BAND[0]:g}-{100 * BAND[1]:g} % band over the seeds."))
        body.append(history_table(fp, family).md(ctx))
        body.append(fig8_reading(tot, fp))
    return Section(title, "\n".join(b for b in body if b), page_charts=FIG8_PAGE)


@register_section("cmr-h-sweep", title="Fig. 9: CMR against h", group="paper", order=51)
def cmr_h_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "Fig. 9: CMR against the area-of-influence factor h, and where the cascade starts (cmr-h-sweep)"
    pairs = cmr_pairs(rows)
    if pairs.empty:
        return Section(title, "No CMR row could be paired with its direct base solve.\n", page_charts=FIG9_PAGE)
    body = [surface_family_note(pairs), design_note(pairs)]
    for family, fp in by_family(pairs):
        tot = instance_totals(fp)
        if len(by_family(pairs)) > 1:
            body.append(f"#### Surface family `{family or 'other'}`\n")
        hs = tot[tot["coarsest"] == CMR_COARSEST]
        if hs["h"].nunique() > 1:
            body.append(ctx.figure_md(fig9_figure(ctx, hs, family, base_runs(fp)),
                                      f"Fig. 9 ({family_label(family)}): n_p/n, time CMR / direct and load error at the top step "
                                      f"against h, first level {CMR_COARSEST}; median and "
                                      f"{100 * BAND[0]:g}-{100 * BAND[1]:g} % band over the seeds."))
        body.append(h_table(hs, family).md(ctx))
        starts = tot[np.isclose(tot["h"], CMR_H)]
        if starts["coarsest"].nunique() > 1:
            body.append(ctx.figure_md(coarsest_figure(ctx, starts, family, base_runs(fp)),
                                      f"where the cascade starts ({family_label(family)}), h = {CMR_H:g}, H = {FIG9_H:g} (else the "
                                      f"largest H that ran): load error at the top step per first level; median, "
                                      f"{100 * BAND[0]:g}-{100 * BAND[1]:g} % band, seeds and the worst seed."))
            body.append(coarsest_table(starts, family).md(ctx))
        body.append(fig9_reading(tot))
    return Section(title, "\n".join(b for b in body if b), page_charts=FIG9_PAGE)


@register_section("cmr-cutoff", title="CMR on a PSD with a roll-off", group="paper", order=52)
def cmr_cutoff_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "CMR on a PSD with a roll-off plateau against a pure power law (cmr-cutoff)"
    pairs = cmr_pairs(rows)
    if pairs.empty:
        return Section(title, "No CMR row could be paired with its direct base solve.\n", page_charts=CUTOFF_PAGE)
    pairs = pairs.assign(ratio=pairs["solve_time_s"] / pairs["direct_time_s"],
                         warned=pairs["solver_message"].fillna("").str.contains("NOT a power law"))
    body = [Table("CMR on the two surfaces (paper: -98 % error on the 10x scan with a roll-off, -0.4 % on the "
                  "power-law 100x scan).", ("instance", "load error", "time ratio", "n_p/n", "PSD warning"),
                  [(r.instance, fmt_pct1(r.err), fmt_num(r.ratio), fmt_num(r.n_p_over_n),
                    "yes" if r.warned else "no") for r in pairs.itertuples()], "lrrrl").md(ctx)]
    return Section(title, "\n".join(body), page_charts=CUTOFF_PAGE)

