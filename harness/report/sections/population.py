"""Population statistics: load, real contact area, solve time and kappa across a Monte
Carlo population of rough surfaces (the ``population`` scene), with confidence intervals.

kappa.  For small loads the real contact area A of a randomly rough surface grows
linearly with the load P: A = kappa P / (E* h'_rms), h'_rms the rms surface slope
(Hyun, Pei, Molinari & Robbins, Phys. Rev. E 70, 026117 (2004) find kappa ~ 2 from
GFMD/BEM; Persson's theory gives sqrt(8/pi) ~ 1.6).  Per solve,

    kappa = A E* h'_rms / P,   A = contact_fraction * L^2  (L^2 = nominal_area),

with E* the table's ``E`` and P its ``load``.  h'_rms is not a column of the tidy
table: it is recomputed from the surface rebuilt from the instance's recipe (its seed),
using the scene configuration recorded in OUT/meta.json.

Intervals.  Across the N_s surfaces of one (H, N, load step): the Student-t interval
of the mean, and a percentile bootstrap interval of the mean (resampling surfaces).

The same statistics appear as the ``population`` section of ``contactbench report``
and in ``write_population_report``'s population.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd
from contactbench.problems.atomic_files import literal_path

from contactbench.problems.scenes import SceneConfig, get_scene

from ...table.meta import read_meta, scene_config_from_meta
from ..core import ReportContext, Section, markdown_table, register_section
from ..owned_files import refuse_foreign_page, write_own_page
from ...table.store import load_table

SCENE = "population"
#: Quantities summarised across the population, per (solver, H, N, step).
QUANTITIES: tuple[str, ...] = ("load", "dim_load", "contact_fraction", "kappa", "solve_time_s")
PERSSON_KAPPA = math.sqrt(8.0 / math.pi)
HYUN_ROBBINS_KAPPA = 2.0
#: population.md's title (its first line: how a report knows the page as its own).
POPULATION_TITLE = "Population statistics"


@dataclass(frozen=True)
class Interval:
    """Mean of a sample with a confidence interval [lo, hi] at ``level``."""

    mean: float
    lo: float
    hi: float
    n: int
    level: float


def t_interval(x: Sequence[float] | np.ndarray, level: float = 0.95) -> Interval:
    """Student-t confidence interval of the mean (NaN bounds for fewer than 2 values)."""
    from scipy import stats

    a = np.asarray(x, dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return Interval(math.nan, math.nan, math.nan, 0, level)
    m = float(a.mean())
    if a.size < 2:
        return Interval(m, math.nan, math.nan, 1, level)
    half = float(stats.t.ppf(0.5 + level / 2.0, a.size - 1) * a.std(ddof=1) / math.sqrt(a.size))
    return Interval(m, m - half, m + half, int(a.size), level)


def bootstrap_interval(x: Sequence[float] | np.ndarray, level: float = 0.95, n_boot: int = 4000,
                       seed: int = 0) -> Interval:
    """Percentile bootstrap interval of the mean (resampling with replacement)."""
    a = np.asarray(x, dtype=float)
    a = a[np.isfinite(a)]
    if a.size < 2:
        m = float(a.mean()) if a.size else math.nan
        return Interval(m, math.nan, math.nan, int(a.size), level)
    rng = np.random.default_rng(seed)
    means = a[rng.integers(0, a.size, size=(n_boot, a.size))].mean(axis=1)
    lo, hi = np.quantile(means, [0.5 - level / 2.0, 0.5 + level / 2.0])
    return Interval(float(a.mean()), float(lo), float(hi), int(a.size), level)


def surface_table(cfg: SceneConfig, instances: Sequence[str] | None = None) -> pd.DataFrame:
    """One row per population instance: hurst, seed, N and the rms slope h'_rms of its
    surface, rebuilt from the recipe's seed."""
    from contactbench.problems.scenes.population import population_surface

    scene = get_scene(SCENE)
    wanted = set(instances) if instances is not None else None
    out = []
    for spec in scene.instances(scene.config(cfg)):
        if wanted is not None and spec.instance not in wanted:
            continue
        s = population_surface(spec)
        out.append({"instance": spec.instance, "hurst": float(spec.params["hurst"]), "seed": int(spec.params["seed"]),
                    "rms_slope": s.rms_slope(), "rms_height": s.rms_height,
                    "separations": tuple(float(d) for d in spec.params["separations"])})
    return pd.DataFrame(out, columns=["instance", "hurst", "seed", "rms_slope", "rms_height", "separations"])


def kappa_table(table: pd.DataFrame, cfg: SceneConfig) -> pd.DataFrame:
    """The solved population rows with hurst, seed, rms_slope, real_area and kappa."""
    df = table[(table["scene"] == SCENE) & (table["status"] == "solved")].copy()
    if df.empty:
        return df.assign(hurst=[], seed=[], rms_slope=[], separation=[], real_area=[], kappa=[])
    surf = surface_table(cfg, sorted(df["instance"].unique()))
    missing = set(df["instance"]) - set(surf["instance"])
    if missing:
        raise ValueError(f"{len(missing)} instance(s) are not in the population scene under the recorded "
                         f"configuration (e.g. {sorted(missing)[0]}); pass the SceneConfig the run used")
    df = df.drop(columns=[c for c in ("hurst", "seed") if c in df.columns])  # (the recipe's own, below)
    df = df.merge(surf, on="instance", how="left")
    df["separation"] = [seps[int(k)] for seps, k in zip(df["separations"], df["step"])]
    df = df.drop(columns="separations")
    df["real_area"] = df["contact_fraction"] * df["nominal_area"]
    df["kappa"] = df["real_area"] * df["E"] * df["rms_slope"] / df["load"]
    return df


def population_statistics(kappas: pd.DataFrame, level: float = 0.95) -> pd.DataFrame:
    """Per (solver, hurst, N, step): number of surfaces, and for each quantity its mean
    with t-interval bounds (``_lo``/``_hi``); kappa also gets a bootstrap interval."""
    keys = ["solver", "hurst", "N", "step"]
    out = []
    for key, g in kappas.groupby(keys, sort=True):
        rec: dict[str, Any] = dict(zip(keys, key))
        rec["surfaces"] = int(g["instance"].nunique())
        rec["separation"] = float(g["separation"].iloc[0])  # flat above the mean plane, in h_rms
        for q in QUANTITIES:
            iv = t_interval(g[q], level)
            rec.update({q: iv.mean, f"{q}_lo": iv.lo, f"{q}_hi": iv.hi})
        b = bootstrap_interval(g["kappa"], level)
        rec.update(kappa_boot_lo=b.lo, kappa_boot_hi=b.hi, kappa_sd=float(g["kappa"].std(ddof=1)))
        out.append(rec)
    return pd.DataFrame(out)


def population_summary(out_dir: str | Path, cfg: SceneConfig | None = None, level: float = 0.95) -> pd.DataFrame:
    """Statistics of a run directory holding population rows (solves nothing)."""
    table = load_table(out_dir)
    cfg = cfg or scene_config_from_meta(read_meta(out_dir))
    return population_statistics(kappa_table(table, cfg), level)


def fmt_ci(mean: float, lo: float, hi: float, digits: int = 3) -> str:
    if not math.isfinite(mean):
        return "-"
    return f"{mean:.{digits}g} [{lo:.{digits}g}, {hi:.{digits}g}]"


def population_table(stats: pd.DataFrame) -> str:
    """kappa, contact fraction, dimensionless load and solve time, mean [95 % CI]."""
    headers = ["H", "N", "step", "d/h_rms", "surfaces", "A/A0 (%)", "P/(E* A0)", "kappa, t-interval",
               "kappa, bootstrap", "solve time (s)"]
    rows = [(f"{r.hurst:g}", int(r.N), int(r.step), f"{r.separation:g}", r.surfaces,
             fmt_ci(100 * r.contact_fraction, 100 * r.contact_fraction_lo, 100 * r.contact_fraction_hi),
             fmt_ci(r.dim_load, r.dim_load_lo, r.dim_load_hi), fmt_ci(r.kappa, r.kappa_lo, r.kappa_hi),
             f"[{r.kappa_boot_lo:.3g}, {r.kappa_boot_hi:.3g}]",
             fmt_ci(r.solve_time_s, r.solve_time_s_lo, r.solve_time_s_hi)) for r in stats.itertuples(index=False)]
    return markdown_table(headers, rows).rstrip("\n")


def write_population_report(out_dir: str | Path, dest: str | Path | None = None,
                            cfg: SceneConfig | None = None) -> Path:
    """OUT/population.md and OUT/population_stats.csv (or under ``dest``); a population.md
    that is not such a page stops it before it writes (``owned_files.write_own_page``)."""
    refuse_foreign_page(Path(dest or out_dir) / "population.md", POPULATION_TITLE)
    stats = population_summary(out_dir, cfg)
    dest = Path(dest or out_dir)
    dest.mkdir(parents=True, exist_ok=True)
    stats.to_csv(literal_path(dest / "population_stats.csv"), index=False)
    return write_own_page(dest / "population.md", POPULATION_TITLE, f"\n{_intro()}\n\n{population_table(stats)}\n")


def _intro() -> str:
    return (f"Mean [95 % confidence interval] across the surfaces of each (H, N, load step); kappa = A E* h'_rms / P "
            f"(Hyun & Robbins: ~{HYUN_ROBBINS_KAPPA:g}; Persson: sqrt(8/pi) = {PERSSON_KAPPA:.3f}).")


@register_section(SCENE, title="Population statistics", group="scenes", order=60)
def population_section(ctx: ReportContext, rows: pd.DataFrame) -> Section:
    title = "Population statistics (population)"
    try:
        stats = population_statistics(kappa_table(rows, scene_config_from_meta(ctx.meta)))
    except ValueError as e:
        return Section(title, f"The statistics cannot be computed from this table: {e}.\n")
    if stats.empty:
        return Section(title, "No population row was solved.\n")
    return Section(title, f"{_intro()}\n\n*Table {ctx.next_table()}: population statistics per solver, H, N and "
                          f"load step.*\n\n{population_table(stats)}\n")
