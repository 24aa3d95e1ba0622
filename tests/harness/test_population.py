"""The population scene and its statistics (harness/report/sections/population.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from contactbench.harness.report.sections.population import (
    bootstrap_interval,
    kappa_table,
    population_summary,
    scene_config_from_meta,
    t_interval,
    write_population_report,
)
from contactbench.harness.table.meta import read_meta
from contactbench.harness import RunConfig
from contactbench.harness import run_benchmark
from contactbench.harness import load_table
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.scenes.population import population_displacements, population_surface, separations_for

TINY = SceneConfig(size=16, steps=2, seeds=(0, 1, 2), extra={"hursts": (0.6,)})


def test_instances_are_seeded_recipes_per_hurst_and_size() -> None:
    scene = get_scene("population")
    specs = scene.instances(scene.config(None))
    assert len(specs) == 3 * 20 and len({s.instance for s in specs}) == 60
    assert {s.params["hurst"] for s in specs} == {0.5, 0.7, 0.9}
    assert {s.params["size"] for s in specs} == {64} and specs[0].params["steps"] == 3
    small = scene.instances(scene.config(TINY))
    assert [s.instance for s in small] == ["pop-H0.6-N16-s0-K2", "pop-H0.6-N16-s1-K2", "pop-H0.6-N16-s2-K2"]
    assert small[0].params["separations"] == [2.0, 1.0]
    # rebuilt from the seed alone: the same surface twice, another one for another seed
    a, b, c = population_surface(small[0]), population_surface(small[0]), population_surface(small[1])
    assert np.array_equal(a.heights, b.heights) and not np.array_equal(a.heights, c.heights)


def test_loads_put_the_flat_d_rms_heights_above_the_mean_plane() -> None:
    spec = get_scene("population").instances(get_scene("population").config(TINY))[0]
    seq = spec.build()
    s = seq.surface
    assert seq.deltas == pytest.approx([s.z_max - s.z_mean - d * s.rms_height for d in (2.0, 1.0)])
    assert seq.deltas[0] < seq.deltas[1]  # increasing load: a load history
    with pytest.raises(ProblemInputError, match="above the highest point"):
        population_displacements(s, [50.0])
    assert separations_for(SceneConfig(steps=1)) == (2.0,)
    with pytest.raises(ProblemInputError, match="2\\^k"):
        get_scene("population").instances(get_scene("population").config(SceneConfig(size=24)))


def test_intervals() -> None:
    x = np.random.default_rng(3).normal(2.0, 0.5, size=40)
    iv = t_interval(x)
    lo, hi = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert (iv.lo, iv.hi) == pytest.approx((lo, hi)) and iv.n == 40
    b = bootstrap_interval(x)
    assert b.lo < x.mean() < b.hi and b.hi - b.lo == pytest.approx(hi - lo, rel=0.25)
    assert math.isnan(t_interval([1.0]).lo) and t_interval([]).n == 0


def test_kappa_from_a_small_population_run(tmp_path: Path) -> None:
    run_benchmark(["population"], TINY, ["fast-ccg"], RunConfig(reference="none", warmup=False, progress=False),
                  tmp_path)
    cfg = scene_config_from_meta(read_meta(tmp_path))
    assert cfg.seeds == (0, 1, 2) and cfg.size == 16
    table = load_table(tmp_path)
    k = kappa_table(table, cfg)
    assert len(k) == 6 and (k["status"] == "solved").all()
    # kappa recomputed by hand for one row, h'_rms from the surface rebuilt from its seed
    row = k.iloc[0]
    spec = next(s for s in get_scene("population").instances(get_scene("population").config(TINY))
                if s.instance == row["instance"])
    slope = population_surface(spec).rms_slope()
    assert row["kappa"] == pytest.approx(row["contact_fraction"] * row["nominal_area"] * row["E"] * slope / row["load"])
    assert (k["kappa"] > 0).all() and np.isfinite(k["kappa"]).all()
    s = population_summary(tmp_path)
    assert list(s["step"]) == [0, 1] and (s["surfaces"] == 3).all()
    assert (s["kappa_lo"] <= s["kappa"]).all() and (s["kappa"] <= s["kappa_hi"]).all()
    assert (s["contact_fraction"].diff().dropna() > 0).all()  # more load, more contact
    md = write_population_report(tmp_path).read_text()
    assert "| 0.6 | 16 | 0 | 2 | 3 |" in md
