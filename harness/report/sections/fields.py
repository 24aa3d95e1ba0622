"""The pictures a contact-mechanics reader expects, from stored arrays and the table:
the height map, the contact pressure at the top step with the contact area outlined,
the gap distribution (OUT/arrays/field-*.npz, written by the worker: harness/table/fields.py),
the load-area curve A/A0 against P/(E* A0) with the fitted kappa and the small-load
slopes of Persson and Bush-Gibson-Thomas, and per solver family the convergence trace
(the table's ``trace`` column) against iteration and against time.

kappa.  At small loads A/A0 = (kappa / h'_rms) P/(E* A0) (h'_rms: rms slope of the
surface, stored with the field).  Persson's theory gives kappa = sqrt(8/pi) ~ 1.60,
Bush, Gibson & Thomas (Wear 35, 1975) kappa = sqrt(2 pi) ~ 2.51.  The fitted kappa is
h'_rms times the least-squares slope through the origin over the steps with
A/A0 <= ``SMALL_LOAD_AREA`` (at least the two smallest loads).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from matplotlib.ticker import MaxNLocator

from ...table.fields import ContactField, find_fields, load_field
from ..markdown_text import md_code
from ..core import (
    ReportContext,
    Section,
    attempted,
    fmt_num,
    grid_figure,
    legend_outside,
    log_if_wide,
    natural_key,
    natural_sorted,
    parse_trace,
    pick_profile,
    register_section,
    representative_traces,
    sort_scenes,
    status_counts,
    table_md,
    tidy_log_ticks,
)
from ..panels import MARK_EVERY, iteration_axis, mark_empty, no_figure
from ..style import family_panels, sort_families

PERSSON_KAPPA = math.sqrt(8.0 / math.pi)
BGT_KAPPA = math.sqrt(2.0 * math.pi)
#: Steps with A/A0 up to this are "small load" for the kappa fit.
SMALL_LOAD_AREA = 0.10
#: At most this many scenes get the field figure (one instance each).
MAX_FIELD_SCENES = 3
#: At most this many instances on the load-area figure.
MAX_LOAD_AREA_SERIES = 10


@dataclass(frozen=True)
class KappaFit:
    kappa: float
    slope: float  # d(A/A0) / d(P/(E A0))
    points: int
    rms_slope: float


def fit_kappa(dim_load: np.ndarray, area: np.ndarray, rms_slope: float) -> KappaFit:
    """kappa = h'_rms x the slope through the origin of A/A0 on P/(E A0), over the small
    loads (module doc); NaN without two usable points."""
    x, y = np.asarray(dim_load, float), np.asarray(area, float)
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    x, y = x[ok], y[ok]
    order = np.argsort(x)
    x, y = x[order], y[order]
    small = y <= SMALL_LOAD_AREA
    if small.sum() < 2:
        small = np.arange(len(x)) < 2
    x, y = x[small], y[small]
    if len(x) < 2 or not (rms_slope > 0):
        return KappaFit(float("nan"), float("nan"), int(len(x)), rms_slope)
    slope = float(np.dot(x, y) / np.dot(x, x))
    return KappaFit(slope * rms_slope, slope, int(len(x)), rms_slope)


def load_area_points(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (instance, step): P/(E A0) and A/A0, medians over the solved rows of the
    tightest profile present (the answers agree to the profile's accuracy)."""
    r = rows[(rows["status"] == "solved") & rows["dim_load"].notna() & rows["contact_fraction"].notna()]
    if r.empty:
        return pd.DataFrame(columns=["instance", "step", "dim_load", "area"])
    r = r[r["profile"] == pick_profile(r)]
    g = r.groupby(["instance", "step"])
    return pd.DataFrame({"dim_load": g["dim_load"].median(), "area": g["contact_fraction"].median()}).reset_index()


#: The length units a figure may draw in, in metres, largest first.
LENGTH_UNITS: tuple[tuple[str, float], ...] = (("m", 1.0), ("mm", 1e-3), ("um", 1e-6), ("nm", 1e-9))


def _length_scale(values: np.ndarray, unit: str) -> tuple[float, str]:
    """(factor, unit) to draw lengths ``values`` given in ``unit`` with: the largest of
    ``LENGTH_UNITS`` in which the largest magnitude is at least 1, so that tick values fall in
    [1, 1000) (2e-3 m reads 2 mm, never 0.0020 m); (1, ``unit``) for a unit not among them,
    nothing finite or all zero."""
    v = float(np.nanmax(np.abs(values))) if np.any(np.isfinite(values)) else 0.0
    size = dict(LENGTH_UNITS).get(unit)
    if size is None or not v > 0:
        return 1.0, unit
    metres = v * size
    name, to = next(((n, t) for n, t in LENGTH_UNITS if metres >= t), LENGTH_UNITS[-1])
    return size / to, name


def zoom_window(pressure: np.ndarray, frac: float = 1 / 6) -> tuple[slice, slice]:
    """The square window of side ``frac`` of the map that carries the most load."""
    from scipy.ndimage import uniform_filter

    m0, m1 = pressure.shape
    w = max(8, int(round(min(m0, m1) * frac)))
    if w >= min(m0, m1):
        return slice(0, m0), slice(0, m1)
    s = uniform_filter(np.nan_to_num(pressure), size=w, mode="constant")
    i, j = np.unravel_index(int(np.argmax(s)), s.shape)
    i0, j0 = min(max(i - w // 2, 0), m0 - w), min(max(j - w // 2, 0), m1 - w)
    return slice(i0, i0 + w), slice(j0, j0 + w)


def _pressure_panel(fig: object, a: object, f: ContactField, rows: slice, cols: slice, sx: float, title: str) -> None:
    from matplotlib.colors import LogNorm

    d = f.spacing * sx
    ext = (cols.start * d, cols.stop * d, rows.start * d, rows.stop * d)
    pr = f.pressure[rows, cols] / f.E
    pos = pr[pr > 0]
    norm = LogNorm(vmin=max(float(pos.min()), float(pos.max()) * 1e-4), vmax=float(pos.max())) if pos.size else None
    im = a.imshow(np.where(pr > 0, pr, np.nan), origin="lower", extent=ext, cmap="viridis", norm=norm,
                  interpolation="nearest")
    fig.colorbar(im, ax=a, fraction=0.046, pad=0.04).set_label("p / E*  [-]", fontsize=8)
    c = f.contact[rows, cols]
    if c.any() and not c.all():
        k = 6  # outline the pixel edges: contour a finer copy of the mask at its sample centres
        fine = np.kron(c.astype(float), np.ones((k, k)))
        xs = ext[0] + (np.arange(fine.shape[1]) + 0.5) * d / k
        ys = ext[2] + (np.arange(fine.shape[0]) + 0.5) * d / k
        a.contour(xs, ys, fine, levels=[0.5], colors="red", linewidths=0.4)
    a.set_facecolor("white")
    a.set_title(title, fontsize=9)


def field_rows(ctx: ReportContext, f: ContactField) -> pd.DataFrame:
    """The table's rows of the field's (scene, instance, step)."""
    r = ctx.rows(f.scene)
    return r[(r["instance"] == f.instance) & (r["step"] == f.step)]


def field_approach(ctx: ReportContext, f: ContactField) -> tuple[float, str]:
    """(Delta, control) of the field's step: the stored far-field displacement, else (a
    field stored without it under load control) the approach the judge fitted to the same
    solver's answer in the table; control "displacement", "load" or "" (no surface: Example
    1 draws ubar, there is no far-field displacement)."""
    rows = field_rows(ctx, f)
    control = str(rows["control"].dropna().iloc[0]) if "control" in rows and rows["control"].notna().any() else ""
    delta = f.far_field
    if not math.isfinite(delta):
        own = rows[rows["solver"] == f.solver]["delta"].dropna()
        delta = float(own.iloc[0]) if len(own) else float("nan")
    return delta, control if math.isfinite(delta) else ""


def _approach_text(delta: float, control: str, unit: str) -> str:
    if control == "load":
        return f"load control: approach Delta = {fmt_num(delta)} {unit}, the load equality's multiplier"
    if math.isfinite(delta):
        return f"far-field displacement Delta = {fmt_num(delta)} {unit}"
    return "no far-field displacement: ubar is drawn, not derived from heights"


def has_surface(f: ContactField) -> bool:
    """Whether ``f`` has a height map to draw (not constant heights: Example 1's drawn ubar)."""
    h = f.heights - np.nanmean(f.heights) if np.isfinite(f.heights).any() else f.heights
    return bool(np.isfinite(h).any() and float(np.nanmax(np.abs(h))) > 0.0)


def _surface_panel(fig: object, a: object, f: ContactField, ext: tuple[float, ...]) -> bool:
    """The height map on ``a``; a note instead when the field has no surface (constant
    heights: Example 1).  Returns whether it drew the map."""
    if not has_surface(f):
        mark_empty(a, "no surface: this problem's ubar\nis drawn, not derived from heights")
        a.set_title(f"surface ({f.N}x{f.N1 or f.N}): none", fontsize=9)
        return False
    h = f.heights - np.nanmean(f.heights)
    sh, uh = _length_scale(h, f.unit)
    im = a.imshow(h * sh, origin="lower", extent=ext, cmap="terrain")
    fig.colorbar(im, ax=a, fraction=0.046, pad=0.04).set_label(f"height - mean  [{uh}]", fontsize=8)
    a.set_title(f"surface ({f.N}x{f.N1 or f.N})", fontsize=9)
    return True


def _gap_panel(a: object, f: ContactField) -> bool:
    """The distribution of the gap out of contact on ``a``; a note when the field stores
    none (a field written before the gap was kept under load control).  Returns whether
    it drew it."""
    gaps = np.maximum(f.gap[np.isfinite(f.gap) & ~f.contact], 0.0)
    a.set_title(f"gap distribution, step {f.step} (out of contact)", fontsize=9)
    if not gaps.size:
        mark_empty(a, "no gap stored with this field\n(harness.run.backfill re-solves\nthe step to store it)")
        return False
    sg, ug = _length_scale(gaps, f.unit)
    density, _, _ = a.hist(gaps * sg, bins=60, density=True, color="tab:gray", alpha=0.85)
    log_if_wide(a, "y", density, decades=1.0)  # a log scale only where the densities span decades
    a.set_xlabel(f"gap g  [{ug}]")
    a.set_ylabel("probability density  [1/" + ug + "]")
    a.yaxis.tick_right()  # on the right: clear of the pressure panel's colour bar to its left
    a.yaxis.set_label_position("right")
    a.grid(True, alpha=0.3)
    return True


def _field_figure(ctx: ReportContext, f: ContactField) -> str:
    drawn = has_surface(f)  # else no surface panel: it would say only that there is none
    # wide gaps: a colour bar's label and the next panel's y label and ticks must not meet
    fig, axes = grid_figure(1, 4 if drawn else 3, width=4.3, height=3.8, wspace=0.8)
    a1, a2, a2z, a3 = axes[0] if drawn else (None, *axes[0])
    L0, L1 = f.extent
    sx, ux = _length_scale(np.array([max(L0, L1)]), f.unit)
    ext = (0, L1 * sx, 0, L0 * sx)
    surface = drawn and _surface_panel(fig, a1, f, ext)
    a2.imshow(np.where(f.contact, 1.0, np.nan), origin="lower", extent=ext, cmap="gray_r", vmin=0, vmax=1,
              interpolation="nearest")
    a2.set_title(f"contact area, step {f.step} (A/A0 = {fmt_num(f.contact_fraction)})", fontsize=9)
    zr, zc = zoom_window(f.pressure, 1 / 10)
    _pressure_panel(fig, a2z, f, zr, zc, sx, "pressure, zoom on the most loaded window")
    d = f.spacing * sx
    a2.add_patch(__import__("matplotlib.patches", fromlist=["Rectangle"]).Rectangle(
        (zc.start * d, zr.start * d), (zc.stop - zc.start) * d, (zr.stop - zr.start) * d, fill=False,
        edgecolor="black", lw=0.8, ls="--"))
    for a in (a1, a2, a2z) if surface else (a2, a2z):
        for axis in (a.xaxis, a.yaxis):
            axis.set_major_locator(MaxNLocator(5))  # a zoom's many-digit ticks ran together
        a.set_xlabel(f"x  [{ux}]" if surface else "element index mod N  (no position)")
        a.set_ylabel(f"y  [{ux}]" if surface else "element index div N")
    has_gap = _gap_panel(a3, f)
    rel = ctx.save_figure(fig, f"field-{f.scene}-{f.instance}-k{f.step}", on_page=True)
    delta, control = field_approach(ctx, f)
    what = [("the surface heights" if surface else "no surface panel (the problem has no height map: its "
                                                       "elements have no positions, and are laid out N x N in "
                                                       "index order only to be shown)"),
            "the contact area (black)",
            "the contact pressure p/E* (log colour scale) in the most loaded window (dashed) with the contact "
            "area outlined in red"]
    what.append(f"the distribution of the gap over the points out of contact "
                f"({contact_gap_text(f, *field_bound_and_check(ctx, f))})" if has_gap
                else "no gap panel: the stored field has no gap")
    return ctx.figure_md(rel, f"the contact field of `{f.scene}` instance `{f.instance}` at step {f.step} (of "
                              f"{f.steps}; {_approach_text(delta, control, f.unit)}, P/(E* A0) = "
                              f"{fmt_num(f.dim_load)}, answer of `{f.solver}`): " + "; ".join(what) + ".")


#: A contact point whose gap is below -this x the heights' range (or -check_tol x it, where
#: that is larger) is pressed past g = 0 (an element at its hardness bound: plastic), not
#: closed within the answer's tolerance.
PRESSED_GAP = 1e-9


def field_bound_and_check(ctx: ReportContext, f: ContactField) -> tuple[bool, float]:
    """(whether the field's problem bounds the pressure by a hardness, the check its answer
    was judged at; NaN: none recorded), read from the table's rows of the field's step and
    solver (columns ``hardness``, ``check_tol``)."""
    rows = field_rows(ctx, f)
    own = rows[rows["solver"] == f.solver] if "solver" in rows else rows
    hard = own["hardness"] if "hardness" in own else pd.Series(dtype=float)
    tol = own["check_tol"].dropna() if "check_tol" in own else pd.Series(dtype=float)
    return bool(pd.to_numeric(hard, errors="coerce").notna().any()), float(tol.iloc[0]) if len(tol) else math.nan


def contact_gap_text(f: ContactField, bounded: bool, check_tol: float = math.nan) -> str:
    """What the stored gap says of the contact points: "g = 0" where the problem has no
    hardness (``bounded``: its contact is closed, within the answer's tolerance) or every
    point is closed within it; otherwise the share pressed below g = 0 (elements at the
    hardness bound, whose gap is negative) and how far, read from the field itself."""
    share = f"the contact points, {fmt_num(100 * f.contact_fraction)} % of the area"
    g = f.gap[f.contact]
    g = g[np.isfinite(g)]
    scale = float(np.ptp(f.heights)) if f.heights.size else 0.0
    floor = max(PRESSED_GAP, check_tol if math.isfinite(check_tol) else 0.0) * scale
    pressed = g < -floor if bounded and scale > 0 else np.zeros(g.shape, bool)
    if not pressed.any():
        return f"{share}, have g = 0"
    return (f"{share}, have g = 0 where elastic; {fmt_num(100 * pressed.mean())} % of them are pressed below it "
            f"(g down to {fmt_num(float(g.min()))} {f.unit}: elements at the hardness bound)")


def load_area_series(ctx: ReportContext) -> list[tuple[str, str, pd.DataFrame]]:
    """(scene, instance, its load-area points by step) for every instance of a load
    history with two steps or more, each instance once."""
    out: list[tuple[str, str, pd.DataFrame]] = []
    seen: set[str] = set()
    for scene in ctx.scenes():
        rows = ctx.rows(scene)
        if rows["delta"].isna().all():
            continue
        pts = load_area_points(rows)
        for inst in natural_sorted(pts["instance"].unique()):
            pi = pts[pts["instance"] == inst].sort_values("step")
            if inst in seen or len(pi) < 2:
                continue
            seen.add(inst)
            out.append((scene, inst, pi))
    return out


def _load_area_figure(ctx: ReportContext, fields: dict[tuple[str, str], ContactField]) -> str:
    series: list[tuple[str, str, pd.DataFrame, float]] = []
    for scene, inst, pi in load_area_series(ctx):
        f = fields.get((scene, inst))
        series.append((scene, inst, pi, f.rms_slope if f is not None else float("nan")))
    if not series:
        return ""
    sloped = [sr for sr in series if math.isfinite(sr[3]) and sr[3] > 0]  # (h'_rms from the stored field)
    if not sloped:
        return ""
    shown = sloped[:MAX_LOAD_AREA_SERIES]
    fig, axes = grid_figure(1, 1, width=6.4, height=4.4)
    ax = axes[0][0]
    xs_all: list[float] = []
    for i, (scene, inst, pi, hrms) in enumerate(shown):
        fit = fit_kappa(pi["dim_load"].to_numpy(), pi["area"].to_numpy(), hrms)
        x = pi["dim_load"].to_numpy() / hrms  # the load over h'_rms: one law for every surface
        ax.plot(x, pi["area"], "o-", ms=4, color=f"C{i % 10}", label=f"{scene} {inst}"
                + (f" (kappa = {fmt_num(fit.kappa)})" if math.isfinite(fit.kappa) else ""))
        xs_all += list(x)
    x = np.geomspace(min(xs_all), max(xs_all), 50)
    for k, name, ls in ((PERSSON_KAPPA, "Persson sqrt(8/pi)", "--"), (BGT_KAPPA, "BGT sqrt(2 pi)", ":")):
        ax.plot(x, k * x, ls=ls, color="black", lw=1, label=name)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("P / (E* A0 h'_rms)  [-]")
    ax.set_ylabel("A / A0  [-]")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("load-area curve", fontsize=9)
    legend_outside(ax)
    rel = ctx.save_figure(fig, "load-area", on_page=True)
    left = len(series) - len(shown)
    cap = ("the load-area curve: real contact area A/A0 against the load P/(E* A0) over each surface's own rms "
           "slope h'_rms, per load step (median over the solved answers of the tightest profile), so that one "
           "small-load law A/A0 = kappa P/(E* A0 h'_rms) holds for every surface; black lines: Persson's "
           f"(kappa = {PERSSON_KAPPA:.2f}) and Bush-Gibson-Thomas's (kappa = {BGT_KAPPA:.2f}); each curve's kappa "
           f"is the slope through the origin over its steps with A/A0 <= {SMALL_LOAD_AREA:g}.")
    if left:
        cap += (f" {left} further instance(s) are not drawn (beyond {MAX_LOAD_AREA_SERIES}, or with no stored "
                "field to give h'_rms); the table below lists them all.")
    body = [ctx.figure_md(rel, cap)]
    rows_t = []
    for scene, inst, pi, hrms in series:
        fit = fit_kappa(pi["dim_load"].to_numpy(), pi["area"].to_numpy(), hrms)
        rows_t.append((scene, inst, len(pi), fmt_num(hrms), fit.points, fmt_num(fit.kappa),
                       fmt_num(fit.kappa / PERSSON_KAPPA) if math.isfinite(fit.kappa) else "-"))
    body.append(table_md(ctx, "kappa per instance (h'_rms from the stored field; '-' where no field was stored).",
                         ["scene", "instance", "steps", "h'_rms", "fit points", "kappa", "kappa / Persson"],
                         rows_t, "llrrrrr"))
    return "\n".join(body)


def trace_scene(ctx: ReportContext) -> tuple[str, dict[str, pd.Series]]:
    """The first scene (report order: the paper's sweep when present) with traced
    solves, and each solver's representative traced row there (report.representative_traces);
    ("", {}) when no solve has a trace."""
    t = attempted(ctx.table)
    t = t[t["trace"].str.len() > 2]
    if t.empty:
        return "", {}
    scene = sort_scenes(t["scene"])[0]
    return scene, representative_traces(t[t["scene"] == scene])


def _trace_points(trace: str) -> int:
    """The points of a stored trace with a positive finite residual (what the figure draws)."""
    tr = parse_trace(trace)
    return int((np.isfinite(tr[:, 2]) & (tr[:, 2] > 0)).sum())


#: A log axis whose data span less than a decade is widened by this factor each side, so
#: that at least two of its 1-2-5 labels fall on it.
NARROW_LOG_MARGIN = 3.0


def _log_axis(ax: object, axis: str, values: list[float]) -> None:
    """Log scale on ``axis`` with plain 1-2-5 labels (``tidy_log_ticks``); data spanning
    under a decade (one point, or a few close ones) get ``NARROW_LOG_MARGIN`` each side."""
    (ax.set_xscale if axis == "x" else ax.set_yscale)("log")
    v = np.asarray([x for x in values if np.isfinite(x) and x > 0], dtype=float)
    if not len(v):
        return
    lo, hi = float(v.min()), float(v.max())
    if hi / lo < 10.0:
        lo, hi = lo / NARROW_LOG_MARGIN, hi * NARROW_LOG_MARGIN
        (ax.set_xlim if axis == "x" else ax.set_ylim)(lo, hi)
    tidy_log_ticks(ax, axis, float(np.log10(hi / lo)))


def short_traces(reps: dict[str, pd.Series]) -> list[str]:
    """The solvers of ``reps`` (``trace_scene``) whose trace has fewer than two points to
    draw (their final residual only): no curve; by name."""
    return sorted((s for s in reps if _trace_points(reps[s]["trace"]) < 2), key=natural_key)


def traces_empty_note(reps: dict[str, pd.Series]) -> str:
    """Why the traces of ``reps`` draw no curve ("" when one is drawn, or when no solve
    stored a trace): every one is a single point.  report.md writes it in place of the
    figure, report.html on its trace charts."""
    short = short_traces(reps)
    if not reps or len(short) < len(reps):
        return ""
    return (f"every stored trace is a single point, its solver's final residual only ({', '.join(short)}), and a "
            f"convergence curve needs two")


def _trace_figure(ctx: ReportContext) -> str:
    """Per family, the representative solve's trace of every solver: residual against
    iteration and against time, in the first scene with traces (trace_scene)."""
    scene, reps = trace_scene(ctx)
    short = short_traces(reps)
    solvers = sorted(set(reps) - set(short), key=lambda s: (natural_key(ctx.family(s)), natural_key(s)))
    if not solvers:
        empty = traces_empty_note(reps)
        return no_figure(f"Convergence traces, scene `{scene}`: {empty}.") if empty else ""
    panels = [q for f in sort_families(ctx.family(s) for s in solvers)
              for q in family_panels([s for s in solvers if ctx.family(s) == f], ctx.family)]
    traces = {s: parse_trace(reps[s]["trace"]) for s in solvers}
    axis = iteration_axis([i for tr in traces.values() for i in tr[np.isfinite(tr[:, 2]) & (tr[:, 2] > 0), 0]])
    fig, axes = grid_figure(len(panels), 2, width=4.6, height=3.2, wspace=0.30)
    for (a1, a2), panel in zip(axes, panels):
        its: list[float] = []
        secs: list[float] = []
        res: list[float] = []
        seen: list[str] = []
        for s in panel.solvers:
            tr = traces[s]
            ok = np.isfinite(tr[:, 2]) & (tr[:, 2] > 0)
            # a trace equal to another against iteration: one hides the other on the left, and the
            # legend says so
            twin = next((t for t in seen if np.array_equal(traces[t][:, [0, 2]], tr[:, [0, 2]], equal_nan=True)),
                        None)
            seen.append(s)
            label = f"{s} (left: same as {twin})" if twin else s
            ok2 = ok & (tr[:, 1] > 0)
            # each line wears its solver's marker, sparsely (MARK_EVERY): two solvers of one shade
            # and dash differ in shape; a trace with one timed point is that marker alone
            mark = {"marker": ctx.marker(s), "ms": 4, "markevery": MARK_EVERY}
            # iteration + 1 on a log axis (panels.iteration_axis): iteration 0 is drawn, as on the page
            a1.plot(tr[ok, 0] + axis["shift"], tr[ok, 2], lw=1.2, color=ctx.color(s, scene), ls=ctx.dash(s), label=label,
                    **mark)
            a2.plot(tr[ok2, 1], tr[ok2, 2], lw=1.2, color=ctx.color(s, scene), ls=ctx.dash(s), label=label, **mark)
            its += list(tr[ok, 0] + axis["shift"])
            secs += list(tr[ok2, 1])
            res += list(tr[ok, 2])
        # a family's panel names it (and its part, "(1/2)"); a family in one panel is "all solvers"
        title = panel.title if panel.family or not panel.solvers else f"family {ctx.family(panel.solvers[0])}"
        a1.set_title(f"{title}: residual against iteration", fontsize=9)
        a2.set_title(f"{title}: residual against time", fontsize=9)
        for a, xl in ((a1, f"{axis['title']}  [-]"), (a2, "elapsed  [s]")):
            _log_axis(a, "y", res)
            a.set_xlabel(xl)
            a.set_ylabel("own residual  [-]", fontsize=8)
            a.grid(True, which="major", alpha=0.3)
        _log_axis(a2, "x", secs)
        if axis["log"]:
            a1.set_xscale("log")
            tidy_log_ticks(a1, "x", float(np.log10(max(its) / min(its))) if its else 0.0)
        legend_outside(a2)
        for a, xs in ((a1, its), (a2, secs)):
            if not xs:
                mark_empty(a, "no trace point with a positive residual" + (" and time" if a is a2 else ""))
    rel = ctx.save_figure(fig, f"traces-{scene}")
    where = ", ".join(f"{md_code(s)}: {reps[s]['instance']} step {int(reps[s]['step'])} ({reps[s]['profile']})"
                      for s in solvers)
    return ctx.figure_md(rel, f"convergence traces per solver family, scene `{scene}`: each solver's own residual "
                              f"(the figure it stops on, not the harness's kkt_error) against iteration (left) and "
                              f"elapsed time (right) for one representative solve, the largest n at the tightest "
                              f"profile ({where}). Solvers without a stored trace are not drawn"
                              + (f", nor those whose trace is a single point (their final residual only: "
                                 f"{', '.join(md_code(s) for s in short)})." if short else "."))


def top_step_rows(table: pd.DataFrame) -> pd.DataFrame:
    """The rows at the top step of their (scene, instance): its highest step in the table,
    the step whose first solved answer the runner keeps as the field (harness/table/fields.py)."""
    steps = pd.to_numeric(table["step"], errors="coerce")
    top = steps.groupby([table["scene"], table["instance"]]).transform("max")
    return table[steps == top]


def no_fields_note(table: pd.DataFrame) -> str:
    """Why a table has no field file: no answer at an instance's top step was solved (the
    runner keeps only a solved one), or the folder kept none of those solved (the backfill
    command adds them).  The table tells the two apart; meta.json records no field policy."""
    top = top_step_rows(table)
    solved = top[top["status"] == "solved"][["scene", "instance"]].drop_duplicates()
    if solved.empty:
        return ("No field arrays are stored with this table: the runner keeps the first solved answer at the top "
                f"step of each instance, and no answer at a top step was solved (the top steps' rows: {status_counts(top)}).\n")
    return (f"No field arrays are stored with this table, although {len(solved)} instance(s) have a solved answer "
            f"at their top step: this folder keeps no `arrays/field-*.npz` for them. "
            f"`python -m contactbench.harness.run.backfill OUT` re-solves the top steps to add them.\n")


@register_section("fields", title="The contact fields", group="summary", order=5)
def fields_section(ctx: ReportContext, table: pd.DataFrame) -> Section | None:
    keys = set(zip(table["scene"], table["instance"]))
    found = find_fields(ctx.out_dir, keys)
    top: dict[tuple[str, str], ContactField] = {}
    for (scene, inst, step), path in sorted(found.items(), key=lambda kv: (kv[0][0], kv[0][1], -kv[0][2])):
        if (scene, inst) not in top:
            top[(scene, inst)] = load_field(path, scene, inst)
    parts = ["The pictures of the field: surfaces, contact pressure and gap from the arrays the runner keeps "
             "(`arrays/field-*.npz`: the first solved answer at the top step of each instance, harness/table/fields.py), "
             "the load-area curve from the table, and the solvers' convergence traces.\n"]
    drawn, seen = 0, set()
    for scene in sort_scenes({s for s, _ in top}):
        if drawn >= MAX_FIELD_SCENES:
            break
        inst = natural_sorted(i for s, i in top if s == scene)[0]
        if inst in seen:  # the same surface in another scene (gp-k-sweep repeats paper-sweep's)
            continue
        seen.add(inst)
        parts.append(_field_figure(ctx, top[(scene, inst)]))
        drawn += 1
    if not top:
        parts.append(no_fields_note(table))
    elif len({s for s, _ in top}) > drawn:
        rest = [s for s in sort_scenes({s for s, _ in top}) if not any(f"field-{s}-" in x for x in ctx.figures)]
        parts.append(f"Fields are stored but not drawn for scene(s) {', '.join(md_code(s) for s in rest)} "
                     f"(at most {MAX_FIELD_SCENES} field figures per report).\n")
    la = _load_area_figure(ctx, top)
    if la:
        parts.append(la)
    tr = _trace_figure(ctx)
    if tr:
        parts.append(tr)
    if len(parts) == 1:
        return None
    return Section("The contact fields", "\n".join(parts))
