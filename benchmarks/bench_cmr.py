"""CMR against the direct solve: the paper's Fig. 8 (scene ``cmr``) and Fig. 9 (``cmr-h-sweep``).

Bemporad & Paggi 2015, section 5.2.  For every load step the direct base solver (NNLS by
default) and CMR+base solve the same fine QP; each runs the load sequence through the
harness's ``solve_sequence`` (warm started from its own solution of the previous step,
mapped by grid index, as in the paper; CMR's coarse levels start cold).  The cascade's
first level is the study's (``harness.studies``).  Writes tidy CSVs and PNG figures
under --out:

* ``cmr.csv``          one row per (H, seed, step): times, loads, n_p/n, KKT errors;
* ``cmr-levels.csv``   one row per (H, seed, step, level): the cascade's records;
* ``cmr-h-sweep.csv``  one row per (seed, h) at the top step of H = 0.7;
* ``cmr.png``, ``cmr-h-sweep.png``.

Run:  OMP_NUM_THREADS=1 python benchmarks/bench_cmr.py [--size 256] [--seeds 0 1]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from contactbench.harness.sequence import solve_sequence
from contactbench.harness.studies import study_for
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.cmr import make_cmr


def run_sequence(scene: str, cfg: SceneConfig, base: str, h: float, base_params: dict | None = None,
                 ) -> tuple[list[dict], list[dict]]:
    """Direct and CMR over every instance and step of ``scene``."""
    sc = get_scene(scene)
    cfg = sc.config(cfg)
    cmr_fixed = next(w.fixed for w in study_for(scene).sweeps if w.matches("cmr+" + base))
    bp = dict(base_params or {})
    rows, levels = [], []
    for spec in sc.instances(cfg):
        seq = spec.build()
        direct = solve_sequence(base, seq, SolverSettings(params=bp))
        cmr = solve_sequence(make_cmr(base), seq, SolverSettings(params={**cmr_fixed, "h": h, "base_params": bp}))
        for d, c in zip(direct, cmr):
            assert d.result is not None and c.result is not None, d.error or c.error
            k, inst, rd, rc, td, tc = d.step, d.inst, d.result, c.result, d.seconds, c.seconds
            Pd, Pc = float(rd.p.sum()), float(rc.p.sum())
            rows.append({
                "scene": scene, "instance": spec.instance, "hurst": spec.params.get("hurst"),
                "seed": spec.params.get("seed"), "step": k, "far_field": inst.delta, "n": inst.n, "h": h,
                "time_direct": td, "time_cmr": tc, "time_ratio": tc / td,
                "load_direct": Pd, "load_cmr": Pc, "load_rel_error": (Pc - Pd) / Pd if Pd else 0.0,
                "n_p_over_n": rc.info["n_p_over_n"], "kkt_direct": d.kkt_error,
                "kkt_cmr": c.kkt_error, "psd_power_law": rc.info["psd_power_law"],
                "contact_direct": inst.contact_fraction(rd.p), "contact_cmr": inst.contact_fraction(rc.p),
            })
            for lv in rc.info["levels"]:
                levels.append({"instance": spec.instance, "hurst": spec.params.get("hurst"), "step": k, "h": h,
                               **lv, "load_rel_error_vs_direct": (lv["load"] - Pd) / Pd if Pd else 0.0})
            print(f"{spec.instance} step {k}: n={inst.n} direct {td:.3f}s cmr {tc:.3f}s "
                  f"err {rows[-1]['load_rel_error']:+.2%} np/n {rows[-1]['n_p_over_n']:.2f}", flush=True)
    return rows, levels


def summarize_fig8(df: pd.DataFrame) -> pd.DataFrame:
    """Per H: total time ratio over the load history and the error at the maximum load."""
    out = []
    for (H, seed), g in df.groupby(["hurst", "seed"]):
        top = g[g.step == g.step.max()].iloc[0]
        out.append({"hurst": H, "seed": seed, "time_direct_s": g.time_direct.sum(), "time_cmr_s": g.time_cmr.sum(),
                    "time_ratio": g.time_cmr.sum() / g.time_direct.sum(),
                    "max_load_rel_error": top.load_rel_error, "n_p_over_n_top": top.n_p_over_n, "n_top": top.n})
    return pd.DataFrame(out)


def plot(df8: pd.DataFrame, df9: pd.DataFrame, out: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.6))
    ax1, ax2 = fig.subplots(1, 2)
    for H, g in df8.groupby("hurst"):
        g = g[g.seed == g.seed.min()]
        ax1.plot(g.load_direct, g.time_direct.cumsum(), "o-", label=f"NNLS H={H:g}")
        ax1.plot(g.load_cmr, g.time_cmr.cumsum(), "s--", label=f"CMR+NNLS H={H:g}")
    ax1.set(xlabel="total load P (N)", ylabel="cumulative CPU time (s)", title="Fig. 8 a-c (h = 2)")
    ax1.legend(fontsize=7)
    s8 = summarize_fig8(df8)
    ax2.semilogy(s8.hurst, np.maximum(np.abs(s8.max_load_rel_error), 1e-6), "o")
    ax2.set(xlabel="Hurst exponent H", ylabel="|relative error| of max load", title="Fig. 8 d")
    fig.tight_layout()
    fig.savefig(out / "cmr.png", dpi=110)
    fig = Figure(figsize=(5, 3.6))
    ax = fig.subplots()
    m = df9.groupby("h").mean(numeric_only=True).reset_index()
    ax.plot(m.h, m.n_p_over_n, "o-", label="n_p / n")
    ax.plot(m.h, m.time_ratio, "s-", label="time CMR / NNLS")
    ax.plot(m.h, np.abs(m.load_rel_error), "^-", label="|load rel. error|")
    ax.set(xlabel="h", title="Fig. 9: H = 0.7, top step")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "cmr-h-sweep.png", dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--base", default="nnls")
    ap.add_argument("--hs", type=float, nargs="+", default=[1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0])
    ap.add_argument("--out", type=Path, default=Path("results/cmr"))
    ap.add_argument("--skip-fig8", action="store_true")
    ap.add_argument("--base-params", type=json.loads, default={"linear": "cholesky"},
                    help='JSON params for the base solver in both runs (default {"linear": "cholesky"}: '
                         'nnls would switch to its slower CG backend above n = 2000 in one run only)')
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    cfg = SceneConfig(size=a.size, steps=a.steps, seeds=tuple(a.seeds))
    if a.skip_fig8 and (a.out / "cmr.csv").exists():
        df8 = pd.read_csv(a.out / "cmr.csv")
    else:
        rows, levels = run_sequence("cmr", cfg, a.base, 2.0, a.base_params)
        df8 = pd.DataFrame(rows)
        df8.to_csv(a.out / "cmr.csv", index=False)
        pd.DataFrame(levels).to_csv(a.out / "cmr-levels.csv", index=False)
    rows9 = []
    for h in a.hs:
        r, _ = run_sequence("cmr-h-sweep", SceneConfig(size=a.size, steps=1, seeds=tuple(a.seeds)), a.base, h,
                             a.base_params)
        rows9 += r
    df9 = pd.DataFrame(rows9)
    df9.to_csv(a.out / "cmr-h-sweep.csv", index=False)
    plot(df8, df9, a.out)
    s8 = summarize_fig8(df8)
    s9 = df9.groupby("h")[["n_p_over_n", "time_ratio", "load_rel_error"]].mean().reset_index()
    print("\nFig. 8 summary (h = 2)\n" + s8.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print("\nFig. 9 summary (H = 0.7)\n" + s9.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    (a.out / "summary.json").write_text(json.dumps({"fig8": s8.to_dict("records"), "fig9": s9.to_dict("records"),
                                                    "size": a.size, "steps": a.steps, "seeds": a.seeds,
                                                    "base": a.base, "base_params": a.base_params}, indent=1, default=float))


if __name__ == "__main__":
    main()
