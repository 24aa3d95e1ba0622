"""Figures of the CMR report sections (harness/report_cmr.py): Fig. 8 against H, the load
error along the history, Fig. 9 against h, and where the cascade starts -- each a median
line with its 10-90 % band over the seeds, one panel per base and coarse reading.  The
numbers they draw (pairs, summaries, bands) are computed in report_cmr.py.
"""

from __future__ import annotations

from typing import Any, Iterable, Sequence

import numpy as np
import pandas as pd

from .report import ReportContext, grid_figure, tidy_log_ticks
from .report_cmr import (
    ERROR_TOL,
    FIG9_H,
    PAPER_TIME_RATIO,
    ROBUST_SHARE,
    Band,
    finite,
    history_bands,
    of_variant,
    panel_title,
    summaries,
    variant_order,
)


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


def _ratio_axes(row: Sequence[Any], ratios: Iterable[float]) -> None:
    """One y range for a row of time-ratio panels: logarithmic when the ratios span more
    than a decade, else linear from 0."""
    v = finite(ratios)
    v = v[v > 0]
    if len(v) and np.log10(v.max() / v.min()) > 1:
        for ax in row:
            ax.set_yscale("log")
        _same_y(row)
        for ax in row:
            tidy_log_ticks(ax, "y", float(np.log10(v.max() / v.min())))
    else:
        _same_y(row, bottom=0.0)


def _tol_lines(ax: Any) -> None:
    for y in (-100 * ERROR_TOL, 100 * ERROR_TOL):
        ax.axhline(y, color="gray", ls="--", lw=0.8)


def fig8_figure(ctx: ReportContext, tot: pd.DataFrame, family: str) -> str:
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
        a1.set_title(panel_title(v), fontsize=8)
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
    return ctx.save_figure(fig, f"fig8-cmr-{family or 'all'}")


def history_figure(ctx: ReportContext, pairs: pd.DataFrame, family: str) -> str:
    import matplotlib

    variants = variant_order(pairs)
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
        _error_panel(ax, v, j, "load step (1: lowest load)", "load error [%]")
    return _error_row(ctx, fig, axes[0], f"fig8-history-{family or 'all'}")


def fig9_figure(ctx: ReportContext, tot: pd.DataFrame, family: str) -> str:
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
        axes[0][j].set_title(panel_title(v), fontsize=8)
        axes[2][j].set_xlabel("area-of-influence factor h")
    _same_y(axes[0], bottom=0.0, top=1.0)
    _ratio_axes(axes[1], tot["ratio"])
    _same_y(axes[2])
    return ctx.save_figure(fig, f"fig9-cmr-h-{family or 'all'}")


def coarsest_figure(ctx: ReportContext, tot: pd.DataFrame, family: str) -> str:
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
        _error_panel(ax, v, j, "first level (points per side)", "load error at the top step [%]")
    return _error_row(ctx, fig, axes[0], f"fig9-coarsest-{family or 'all'}")


def _error_panel(ax: Any, variant: tuple, j: int, xlabel: str, ylabel: str) -> None:
    """A load-error panel of one variant: the 2 % lines, title, labels (y on the first only), grid."""
    _tol_lines(ax)
    ax.set_title(panel_title(variant), fontsize=8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel if j == 0 else "")
    ax.grid(True, alpha=0.3)


def _error_row(ctx: ReportContext, fig: Any, row: Any, name: str) -> str:
    """Legend on the last panel, one y-range for the row, and the saved figure's path."""
    row[-1].legend(fontsize=7, loc="lower right")
    _same_y(row)
    return ctx.save_figure(fig, name)
