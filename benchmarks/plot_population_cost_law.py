"""The cost law per surface family: exponents of matvecs and seconds against the grid size,
refitted per family and variant from the surface population's CSV
(benchmarks/bench_surface_population.py), with its figure.

For each family (and "all") and variant, ``bench_cost_law.fit_exponent`` -- log-log least
squares of y against N^2, the number of grid points -- is fitted over every solved member's
cold top step (each member one point; sizes with one member count too).  Writes
OUT/surface-population-cost-law.md (the exponents, the sizes and solves behind each fit, and
the host(s), commit(s) and dates of the rows) and OUT/surface-population-cost-law.png (seconds
and matvecs against N^2: per family and variant the median over the members of each size, the
range as error bars, and the fit in the legend).  Runs nothing: it reads the CSV only.

Usage:
  python benchmarks/plot_population_cost_law.py [--csv results/perf/surface-population.csv]
      [--out results/perf] [--variants default,double-islands]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from bench_cost_law import Fit, fit_exponent
from bench_surface_population import FAMILIES, VARIANTS, PopulationRow, read_rows

METRICS = ("matvecs", "seconds")
STEM = "surface-population-cost-law"


def solved(rows: list[PopulationRow], family: str, variant: str) -> list[PopulationRow]:
    """The solved rows of one family ("all": every family) and variant."""
    return [r for r in rows if r.status == "solved" and r.variant == variant and family in ("all", r.family)]


def family_fit(rows: list[PopulationRow], metric: str) -> Fit | None:
    """``metric`` ~ (N^2)^a over ``rows`` (None with fewer than two sizes)."""
    return fit_exponent([r.N for r in rows], [float(getattr(r, metric)) for r in rows])


def fmt(f: Fit | None) -> str:
    return "-" if f is None else f"{f.exponent:.2f}"


def table_lines(rows: list[PopulationRow], variants: list[str]) -> list[str]:
    lines = ["| family | variant | sizes | solves | matvecs ~ (N^2)^a | seconds ~ (N^2)^b |", "|---|---|---|---|---|---|"]
    for fam in [f for f in FAMILIES if any(r.family == f for r in rows)] + ["all"]:
        for v in variants:
            sel = solved(rows, fam, v)
            if not sel:
                continue
            sizes = ", ".join(str(N) for N in sorted({r.N for r in sel}))
            lines.append(f"| {fam} | {v} | {sizes} | {len(sel)} | {fmt(family_fit(sel, 'matvecs'))} | "
                         f"{fmt(family_fit(sel, 'seconds'))} |")
    return lines


def write_markdown(rows: list[PopulationRow], variants: list[str], out: Path) -> None:
    times = sorted(r.timestamp for r in rows)
    lines = [
        "# Cost law per surface family: one cold top step per population member",
        "",
        "Written by `benchmarks/plot_population_cost_law.py` from `surface-population.csv` (the population and",
        "instance: benchmarks/bench_surface_population.py).  Exponents: log-log least squares against N^2 (grid",
        "points) over every solved member, each member one point.",
        (f"Host(s): {', '.join(sorted({r.host for r in rows}))}; "
         f"commit(s): {', '.join(sorted({r.commit for r in rows}))}; rows from {times[0]} to {times[-1]}."),
        "",
        *table_lines(rows, variants),
        "",
        f"![cost law per family]({STEM}.png)",
        "",
    ]
    (out / f"{STEM}.md").write_text("\n".join(lines))


def write_figure(rows: list[PopulationRow], variants: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    styles = {"default": "-", "double-islands": "--"}
    colours = dict(zip(FAMILIES, ("C0", "C1", "C2", "C3")))
    for fam in [f for f in FAMILIES if any(r.family == f for r in rows)]:
        for v in variants:
            sel = solved(rows, fam, v)
            sizes = sorted({r.N for r in sel})
            if not sizes:
                continue
            x = [float(N) ** 2 for N in sizes]
            for ax, metric in zip(axes, ("seconds", "matvecs")):
                vals = [[float(getattr(r, metric)) for r in sel if r.N == N] for N in sizes]
                med = np.array([np.median(a) for a in vals])
                err = np.array([[m - min(a) for m, a in zip(med, vals)], [max(a) - m for m, a in zip(med, vals)]])
                f = family_fit(sel, metric)
                ax.errorbar(x, med, yerr=err, fmt="o" + styles.get(v, ":"), color=colours[fam], capsize=3,
                            label=f"{fam}, {v}" + ("" if f is None else f" (a = {f.exponent:.2f})"))
    for ax, title in zip(axes, ("seconds per cold top step", "matvecs per cold top step")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("grid points N$^2$")
        ax.set_title(title + " (median, range)")
        ax.grid(True, which="both", alpha=0.3)
        sizes = sorted({r.N for r in rows if r.status == "solved"})
        ax.set_xticks([float(N) ** 2 for N in sizes])
        ax.set_xticklabels([f"{N}$^2$" for N in sizes])
        ax.minorticks_off()
        if ax.get_lines():
            ax.legend(fontsize=7)
    fig.suptitle("fast-dual-pccg over the surface population: cost against grid size per family")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--csv", default="results/perf/surface-population.csv")
    ap.add_argument("--out", default="results/perf")
    ap.add_argument("--variants", default="default,double-islands")
    args = ap.parse_args()
    variants = args.variants.split(",")
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        ap.error(f"unknown variant {bad[0]!r}: choose from {', '.join(VARIANTS)}")
    csv_path = Path(args.csv)
    if not csv_path.is_file():
        ap.error(f"--csv {csv_path}: no such file")
    rows = read_rows(csv_path)
    if not any(r.status == "solved" for r in rows):
        sys.exit(f"plot_population_cost_law: error: no solved row in {csv_path}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_markdown(rows, variants, out)
    write_figure(rows, variants, out / f"{STEM}.png")
    print("\n".join(table_lines(rows, variants)))
    print(f"wrote {out / (STEM + '.md')} and {out / (STEM + '.png')}")


if __name__ == "__main__":
    main()
