"""The CMR report sections (harness/report/sections/cmr.py) and the CMR study design
(harness/run/studies.py) on a fabricated table whose answers are known here.

``fabricate_cmr`` writes cmr rows: H in HURSTS, SEEDS seeds, STEPS steps; the two direct
solves (the dense ``scipy-nnls``, whose row carries ASSEMBLY_S of dense-H assembly in its
build time, and ``fast-dual-pccg``, whose load is FAST_LOAD_FACTOR off the dense one, so a
CMR row paired with the wrong base shows a different error); and CMR over each base with
coarse = subsample and mean, whose load is its base's load times (1 + e) with e drawn
here and kept in ``errors``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from contactbench.harness.report import core as rp
from contactbench.harness.report.view import report_view
from contactbench.harness.report.sections import cmr as rc
from contactbench.harness.report.sections import cmr_figures as rcf
from contactbench.harness.report.sections.paper import surface_families
from contactbench.harness.table.schema import ALL_COLUMNS, apply_schema

HURSTS = (0.3, 0.7)
SEEDS = tuple(range(7))
STEPS = 3
ASSEMBLY_S = 0.4
STEP_BUILD_S = 0.1
FAST_LOAD_FACTOR = 1.03
#: solve time per step (k + 1) of each solver.
TIME = {"scipy-nnls": 1.0, "fast-dual-pccg": 0.2, "cmr+scipy-nnls": 0.3, "cmr+fast-dual-pccg": 0.15}


def _row(**kw: Any) -> dict[str, Any]:
    row: dict[str, Any] = {c: np.nan for c in ALL_COLUMNS}
    row.update(repeat=0, warm_start=False, status="solved", skip_reason="", profile="default", params="{}",
               family="wrapper", solver_message="", solver_status="converged", solver_converged=True, error="",
               trace="[]", kernel="bcc", periodic=False, operator="fft", history="warm", verdict="pass",
               kkt_error=1e-9, N=64)
    row.update(kw)
    row.setdefault("base_solver", row["solver"])
    return row


def fabricate_cmr(family: str = "saupe", seed: int = 0, scene: str = "cmr",
                  params: dict[str, Any] | None = None) -> tuple[pd.DataFrame, dict[tuple, float]]:
    """The table (module doc) and the drawn errors e[(base, coarse, H, seed, step)]."""
    rng = np.random.default_rng(seed)
    rows, errors = [], {}
    extra = params or {"h": 2.0, "coarsest": 16}
    for H in HURSTS:
        for s in SEEDS:
            inst = f"{family}-H{H:g}-N64-bcc-np-s{s}"
            for k in range(STEPS):
                base_load = {"scipy-nnls": 1.0 + k + 0.1 * s}
                base_load["fast-dual-pccg"] = base_load["scipy-nnls"] * FAST_LOAD_FACTOR
                common = dict(scene=scene, instance=inst, step=k, n=100 * (k + 1), surface_family=family, hurst=H,
                              seed=s, N=64)
                rows.append(_row(**common, solver="scipy-nnls", operator="dense", family="reference",
                                 build_time_s=STEP_BUILD_S + ASSEMBLY_S, solve_time_s=TIME["scipy-nnls"] * (k + 1),
                                 load=base_load["scipy-nnls"]))
                rows.append(_row(**common, solver="fast-dual-pccg", family="fast", build_time_s=STEP_BUILD_S,
                                 solve_time_s=TIME["fast-dual-pccg"] * (k + 1), load=base_load["fast-dual-pccg"]))
                for base in ("scipy-nnls", "fast-dual-pccg"):
                    for coarse in ("subsample", "mean"):
                        e = float(rng.uniform(-0.06, 0.005))
                        errors[(base, coarse, H, s, k)] = e
                        p = {**extra, "coarse": coarse}
                        rows.append(_row(**common, solver=f"cmr+{base} coarse={coarse} h={p['h']:g} from "
                                                          f"{p['coarsest']}",
                                         base_solver=f"cmr+{base}", params=json.dumps(p),
                                         build_time_s=STEP_BUILD_S, solve_time_s=TIME[f"cmr+{base}"] * (k + 1),
                                         load=base_load[base] * (1 + e),
                                         solver_message=f"CMR 16->32->64 h={p['h']:g} coarse={coarse}: "
                                                        f"n_p/n={0.4 + 0.01 * s:.4f} coarse-loads=[1]"))
    return report_view(apply_schema(pd.DataFrame(rows))), errors


def test_each_cmr_row_is_paired_with_the_direct_solve_of_its_own_base() -> None:
    table, errors = fabricate_cmr()
    pairs = rc.cmr_pairs(table)
    assert len(pairs) == len(errors)
    for r in pairs.itertuples():
        assert r.err == pytest.approx(errors[(r.base, r.coarse, r.H, r.seed, r.step)], rel=1e-9, abs=1e-12)
        dense = r.base == "scipy-nnls"
        assert r.direct_assembly_s == pytest.approx(ASSEMBLY_S if dense else 0.0)
        assert r.direct_time_s == pytest.approx(TIME[r.base] * (r.step + 1) + r.direct_assembly_s)
        assert r.n_p_over_n == pytest.approx(0.4 + 0.01 * r.seed)
        assert r.surface == "saupe" and r.h == 2.0 and r.coarsest == 16


def test_each_base_is_paired_under_its_own_profile() -> None:
    """The dense base and CMR over it under the paper's profile, the FFT base under another
    (as paper-claims runs them): both bases are paired, each within its profile, never
    across; with the dense base also under a second profile, the tightest one is kept."""
    table, errors = fabricate_cmr()
    dense = table["base_solver"].isin(["scipy-nnls", "cmr+scipy-nnls"])
    table.loc[dense, "profile"] = "paper"
    pairs = rc.cmr_pairs(table)
    assert len(pairs) == len(errors) and set(pairs["base"]) == {"scipy-nnls", "fast-dual-pccg"}
    assert set(pairs[pairs["base"] == "scipy-nnls"]["profile"]) == {"paper"}
    twice = pd.concat([table, table[dense].assign(profile="high")])
    pairs = rc.cmr_pairs(twice)
    assert len(pairs) == len(errors)
    tightest = rp.pick_profile(pd.DataFrame({"profile": ["paper", "high"]}))
    assert set(pairs[pairs["base"] == "scipy-nnls"]["profile"]) == {tightest}


def test_time_ratio_is_summed_over_the_history_and_the_error_is_the_top_steps() -> None:
    table, errors = fabricate_cmr()
    tot = rc.instance_totals(rc.cmr_pairs(table))
    steps = np.arange(1, STEPS + 1)
    for r in tot.itertuples():
        direct = TIME[r.base] * steps.sum() + (ASSEMBLY_S * STEPS if r.base == "scipy-nnls" else 0.0)
        assert r.ratio == pytest.approx(TIME[f"cmr+{r.base}"] * steps.sum() / direct)
        assert r.err == pytest.approx(errors[(r.base, r.coarse, r.H, r.seed, STEPS - 1)])
        assert r.steps == STEPS


def test_bands_and_share_under_two_percent_match_numpy() -> None:
    table, errors = fabricate_cmr(seed=3)
    tot = rc.instance_totals(rc.cmr_pairs(table))
    s = rc.summaries(tot, ["base", "coarse", "H"])
    assert len(s) == 2 * 2 * len(HURSTS)
    for (base, coarse, H), v in s.items():
        e = np.array([errors[(base, coarse, H, seed, STEPS - 1)] for seed in SEEDS])
        lo, med, hi = np.quantile(e, [0.1, 0.5, 0.9])
        assert (v.err.median, v.err.lo, v.err.hi) == pytest.approx((med, lo, hi))
        assert v.err.count == len(SEEDS)
        assert v.share == pytest.approx(np.mean(np.abs(e) < 0.02))
        assert v.worst == pytest.approx(e[np.argmax(np.abs(e))])
    assert rc.share_under([0.019, -0.021, 0.0, np.nan]) == pytest.approx(2 / 3)
    assert rc.band([]).count == 0 and np.isnan(rc.band([np.nan]).median)


def test_history_bands_are_per_step_over_the_seeds() -> None:
    table, errors = fabricate_cmr(seed=5)
    hb = rc.history_bands(rc.cmr_pairs(table))
    for k in range(STEPS):
        e = [errors[("fast-dual-pccg", "mean", 0.7, s, k)] for s in SEEDS]
        assert hb[("fast-dual-pccg", "mean", 64, 0.7, k)].median == pytest.approx(np.median(e))
    t = rc.history_table(rc.cmr_pairs(table), "saupe")
    assert t.headers[-1] == f"step {STEPS}" and len(t.rows) == 2 * 2 * len(HURSTS)


def test_missing_params_take_the_wrappers_declared_defaults() -> None:
    assert rc.variant_params("cmr+scipy-nnls", "{}") == (2.0, "subsample", 16)
    assert rc.variant_params("cmr+scipy-nnls", '{"coarse": "mean", "h": 1.5}') == (1.5, "mean", 16)


def _section(tmp_path: Path, table: pd.DataFrame, fn: Any) -> tuple[Path, str]:
    """One section rendered as the report renders it (title and body), and the folder its
    figures went to (the report's staging folder: ``build_report`` publishes them)."""
    ctx = rp.ReportContext(tmp_path, table, {})
    sec = fn(ctx, table)
    return ctx.fig_dir, f"### {sec.title}\n\n{sec.body}"


@pytest.mark.parametrize("family, shown", [("saupe", "MidPointFM2D"), ("rmd", "periodic wrap-around")])
def test_the_report_states_the_surface_family_and_reads_the_claim_in_numbers(
        tmp_path: Path, family: str, shown: str) -> None:
    table, errors = fabricate_cmr(family=family)
    out, section = _section(tmp_path, table, rcf.cmr_section)
    assert "**Surface family.**" in section and shown in section
    assert (out / f"fig8-cmr-{'periodic' if family == 'rmd' else family}.png").is_file()
    # the reading's median error over H > 0.5 for the dense base, coarse=mean, is the table's
    e = [errors[("scipy-nnls", "mean", 0.7, s, STEPS - 1)] for s in SEEDS]
    assert f"median error {100 * np.median(e):.1f} %" in section
    share = np.mean(np.abs(e) < 0.02)
    assert f"{100 * share:.1f} % of {len(SEEDS)} surfaces under 2 %" in section
    ratio = TIME["cmr+scipy-nnls"] * 6 / (TIME["scipy-nnls"] * 6 + ASSEMBLY_S * STEPS)
    assert f"time CMR / direct {rp.fmt_num(ratio)} [" in section


def test_a_table_without_the_hurst_exponent_says_why_fig8_is_not_drawn(tmp_path: Path) -> None:
    """A table written before the ``hurst`` column: the section says why Fig. 8 (against H) is
    not drawn instead of failing on an axis of NaN; the totals still carry the top step's error."""
    table, errors = fabricate_cmr()
    old = table.drop(columns=["hurst"])
    tot = rc.instance_totals(rc.cmr_pairs(old))
    assert tot["H"].isna().all() and np.isfinite(tot["err"]).all()
    assert sorted(tot["err"]) == pytest.approx(sorted(rc.instance_totals(rc.cmr_pairs(table))["err"]))
    out, section = _section(tmp_path, old, rcf.cmr_section)
    assert "no `hurst` column" in section and not out.exists()


def test_a_table_naming_no_surface_family_is_captioned_all_surfaces(tmp_path: Path) -> None:
    """A table whose rows name no surface family (written before the column): every caption
    and table title says "all surfaces", none an empty "()"."""
    table, _ = fabricate_cmr(family="")
    _, section = _section(tmp_path, table, rcf.cmr_section)
    assert "Fig. 8 (all surfaces): against H" in section and "load error along the load history (all surfaces)" in section
    assert "()" not in section


@pytest.mark.slow
def test_the_h_sweep_section_tables_h_and_the_first_level(tmp_path: Path) -> None:
    parts = []
    for i, (h, start) in enumerate(((1.25, 16), (2.0, 16), (3.0, 16), (2.0, 32), (2.0, 64))):
        t, _ = fabricate_cmr(seed=i, scene="cmr-h-sweep", params={"h": h, "coarsest": start})
        parts.append(t if i == 0 else t[t["base_solver"].str.startswith("cmr+")])
    table = pd.concat(parts, ignore_index=True)
    table = table[table["step"] == STEPS - 1]
    tot = rc.instance_totals(rc.cmr_pairs(table))
    assert sorted(tot["h"].unique()) == [1.25, 2.0, 3.0] and sorted(tot["coarsest"].unique()) == [16, 32, 64]
    h_rows = rc.h_table(tot[tot["coarsest"] == 16], "saupe").rows
    assert len(h_rows) == 2 * 2 * 3
    start_rows = rc.coarsest_table(tot[np.isclose(tot["h"], 2.0)], "saupe").rows
    assert len(start_rows) == 2 * 2 * len(HURSTS) * 3
    out, text = _section(tmp_path, table, rcf.cmr_h_section)
    assert "### Fig. 9" in text and "first level 64: worst error" in text
    assert (out / "fig9-cmr-h-saupe.png").is_file()
    assert (out / "fig9-coarsest-saupe.png").is_file()


def test_surface_families_read_the_column_and_its_old_name() -> None:
    df = pd.DataFrame({"instance": ["saupe-H0.7-N256-bcc-np-s1", "x", "N16-bcc", "y"],
                       "surface_family": ["saupe", "rmd", "", pd.NA]})
    assert surface_families(df) == ["periodic", "saupe"]
    # the family is read from the column, never from the name
    assert surface_families(pd.DataFrame({"instance": ["saupe-H0.7-N256-bcc-np-s1"], "surface_family": [""]})) == []


# ---------------------------------------------------------------------------
# The study design and the command line
# ---------------------------------------------------------------------------


def test_cmr_studies_run_both_bases_and_both_coarse_readings() -> None:
    from contactbench.harness.run.studies import CMR_DENSE_SIZE, expand, study_for

    cmr = study_for("cmr")  # the plain scene: the FFT base only (the budget)
    v = cmr.variants(cmr.solvers, {})
    assert [x.name for x in v] == ["fast-dual-pccg", "cmr+fast-dual-pccg coarse=subsample h=2 from 16",
                                   "cmr+fast-dual-pccg coarse=mean h=2 from 16"]
    dense = cmr.variants(["scipy-nnls", "cmr+scipy-nnls"], {})  # --solvers adds the dense base
    assert [(x.base, x.params.get("coarse")) for x in dense] == [
        ("scipy-nnls", None), ("cmr+scipy-nnls", "subsample"), ("cmr+scipy-nnls", "mean")]
    assert all(x.params["h"] == 2.0 and x.params["coarsest"] == 16 for x in dense[1:])
    hs = study_for("cmr-h-sweep")
    w = hs.variants([*hs.solvers, "scipy-nnls", "cmr+scipy-nnls"], {})
    assert len({x.name for x in w}) == len(w) == 2 + 8 * 2 + 2 * 2 + 8  # labels tell every variant apart
    fast = [x for x in w if x.base == "cmr+fast-dual-pccg"]
    assert len({json.dumps(x.params, sort_keys=True) for x in fast}) == len(fast) == 8 * 2 + 2 * 2
    assert {x.params["coarsest"] for x in fast if x.params["h"] == 2.0} == {16, 32, 64}
    assert {x.params["coarse"] for x in w if x.base == "cmr+scipy-nnls"} == {"mean"}
    # the composite that makes results/cmr: 20 seeds; the dense base at 128^2 beside the FFT base
    parts = [(st.scene, cfg.size, {x.base for x in st.variants(st.solvers, {})})
             for st, cfg in expand("cmr-paper", None)]
    assert {(sc, size) for sc, size, bases in parts if "scipy-nnls" in bases} == {
        ("cmr", CMR_DENSE_SIZE), ("cmr-h-sweep", CMR_DENSE_SIZE)}
    assert {(sc, size) for sc, size, bases in parts if "cmr+fast-dual-pccg" in bases} >= {
        ("cmr", 256), ("cmr-h-sweep", 256)}
    from contactbench.harness.run.plan import RunConfig, plan_run

    seeds = {}
    for job in plan_run(["cmr-paper"], None, None, RunConfig()).jobs:
        q = job.spec.params
        seeds.setdefault((job.spec.scene, q["size"], q["hurst"]), set()).add(q["seed"])
    assert all(len(s) >= 20 for s in seeds.values()) and len(seeds) == 2 * (4 + 1)  # 20 seeds per H


def test_surface_family_option_sets_the_scene_family_and_refuses_others(capsys: pytest.CaptureFixture) -> None:
    from contactbench.harness.cli import build_parser, main, scene_config

    args = build_parser().parse_args(["run", "cmr", "--surface-family", "periodic"])
    assert scene_config(args).extra == {"family": "periodic"}
    assert scene_config(build_parser().parse_args(["run", "cmr"])).extra == {}
    with pytest.raises(SystemExit) as exc:
        main(["run", "cmr", "--surface-family", "fbm"])
    assert exc.value.code == 2 and "--surface-family" in capsys.readouterr().err


def test_n_p_over_n_prefers_a_stored_column_to_the_message() -> None:
    cells = pd.DataFrame({"solver_message": ["CMR 16->32 h=2: n_p/n=0.5000 x", "CMR: n_p/n=0.2500"],
                          "n": [100.0, 200.0]})
    assert list(rc.projected_share(cells)) == [0.5, 0.25]
    cells["projected_n"] = [30.0, np.nan]
    assert list(rc.projected_share(cells)) == [0.3, 0.25]
