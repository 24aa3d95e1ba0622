"""How large is CMR's load error, per surface family and coarse-level kind?

At N^2 (default 256^2), Hurst H (0.7), h (2), the top step of scene ``cmr-h-sweep``
(Delta = (z_max - z_mean)/2), over many seeds, this solves each instance directly with
``--base`` and with ``cmr+<base>`` for every (family, coarse) asked, and prints the signed
load error (P_cmr - P_direct)/P_direct as median, worst, 10 % / 90 % quantiles and the
share of seeds whose |error| is under 2 %.  With an exact base the error is the cascade's
own (pruning), not the base's.  The direct solve is shared by every coarse kind of a family.

``--timing`` adds seconds per solve (one process, side by side) of scipy-nnls (the paper's
dense Cholesky + NNLS base), cmr+scipy-nnls, fast-dual-pccg and cmr+fast-dual-pccg on the
first ``--timing-seeds`` seeds of the saupe family.

Run:  OMP_NUM_THREADS=1 .venv/bin/python benchmarks/check_cmr_families.py
      [--size 256] [--hurst 0.7] [--h 2] [--seeds 0-19] [--coarsest 16]
      [--base fast-dual-pccg] [--timing] [--timing-seeds 3] [--csv out.csv]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from contactbench.problems.instances import ContactInstance
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver

#: (family, coarse kind) pairs measured by default: the paper's generator with both kinds,
#: and the wrap-around generator (the default before the paper's generator, 26d4209) with exact sub-samples.
DEFAULT_CASES: tuple[tuple[str, str], ...] = (("saupe", "subsample"), ("saupe", "mean"), ("periodic", "subsample"))
#: |load error| below this counts as "the paper's claim holds" (paper section 5.2: < 2 %).
CLAIM = 0.02


@dataclass
class Case:
    family: str
    coarse: str


def parse_seeds(text: str) -> list[int]:
    """"0-19" or "0,3,5" -> a list of seeds."""
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def top_step(family: str, size: int, hurst: float, seed: int) -> ContactInstance:
    """The top-step instance of scene cmr-h-sweep for one family and seed."""
    sc = get_scene("cmr-h-sweep")
    cfg = sc.config(SceneConfig(size=size, seeds=(seed,), extra={"hursts": (hurst,), "family": family}))
    (spec,) = sc.instances(cfg)
    seq = spec.build()
    return seq.at(len(seq) - 1)


def timed_solve(name: str, inst: ContactInstance, params: dict | None = None) -> tuple[float, float, dict]:
    """(load, seconds, info) of one solve."""
    t = time.perf_counter()
    r = get_solver(name).solve(inst.qp, SolverSettings(params=dict(params or {})))
    return float(np.sum(r.p)), time.perf_counter() - t, dict(r.info or {})


def error_rows(cases: list[Case], seeds: list[int], size: int, hurst: float, h: float, coarsest: int,
               base: str) -> pd.DataFrame:
    rows = []
    for family in dict.fromkeys(c.family for c in cases):
        for seed in seeds:
            inst = top_step(family, size, hurst, seed)
            P, t_direct, _ = timed_solve(base, inst)
            for c in (c for c in cases if c.family == family):
                params = {"h": h, "coarse": c.coarse, "coarsest": coarsest}
                Pc, t_cmr, info = timed_solve(f"cmr+{base}", inst, params)
                rows.append({"family": family, "coarse": c.coarse, "seed": seed, "n": inst.n, "load_direct": P,
                             "load_cmr": Pc, "err": (Pc - P) / P, "n_p_over_n": info.get("n_p_over_n"),
                             "time_direct": t_direct, "time_cmr": t_cmr})
                print(f"{family:8s} {c.coarse:9s} seed {seed:2d} n={inst.n:6d} err={rows[-1]['err']:+.4f} "
                      f"n_p/n={info.get('n_p_over_n', float('nan')):.3f}", flush=True)
    return pd.DataFrame(rows)


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per (family, coarse): median, worst (most negative or largest |err|), 10/90 % quantiles,
    share under CLAIM, median n_p/n."""
    def one(g: pd.DataFrame) -> pd.Series:
        e = g["err"].to_numpy()
        return pd.Series({"seeds": len(e), "median": np.median(e), "worst": e[np.argmax(np.abs(e))],
                          "q10": np.quantile(e, 0.1), "q90": np.quantile(e, 0.9),
                          "share_under_2pct": float(np.mean(np.abs(e) < CLAIM)),
                          "median_n_p_over_n": float(np.median(g["n_p_over_n"]))})
    return df.groupby(["family", "coarse"], sort=False).apply(one)


def timing(seeds: list[int], size: int, hurst: float, h: float, coarsest: int) -> pd.DataFrame:
    """Seconds per solve, side by side in this process, on the saupe family."""
    solvers = [("scipy-nnls", None), ("cmr+scipy-nnls", "mean"), ("fast-dual-pccg", None),
               ("cmr+fast-dual-pccg", "mean")]
    rows = []
    for seed in seeds:
        inst = top_step("saupe", size, hurst, seed)
        for name, coarse in solvers:
            params = {"h": h, "coarse": coarse, "coarsest": coarsest} if coarse else {}
            P, t, _ = timed_solve(name, inst, params)
            rows.append({"seed": seed, "n": inst.n, "solver": name, "seconds": t, "load": P})
            print(f"timing seed {seed} n={inst.n} {name:20s} {t:8.2f} s  load={P:.6g}", flush=True)
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--hurst", type=float, default=0.7)
    ap.add_argument("--h", type=float, default=2.0)
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--coarsest", type=int, default=16)
    ap.add_argument("--base", default="fast-dual-pccg")
    ap.add_argument("--cases", default=",".join(f"{f}:{c}" for f, c in DEFAULT_CASES),
                    help="family:coarse pairs, comma-separated")
    ap.add_argument("--timing", action="store_true")
    ap.add_argument("--timing-only", action="store_true", help="skip the load-error table")
    ap.add_argument("--timing-seeds", default="0-2")
    ap.add_argument("--csv", default=None)
    a = ap.parse_args()
    cases = [Case(*pair.split(":")) for pair in a.cases.split(",")]
    if not a.timing_only:
        errors_table(a, cases)
    if a.timing or a.timing_only:
        t = timing(parse_seeds(a.timing_seeds), a.size, a.hurst, a.h, a.coarsest)
        print("\nseconds per solve (median over seeds):")
        print(t.groupby("solver", sort=False)["seconds"].median().to_string(float_format=lambda v: f"{v:.3f}"))


def errors_table(a: argparse.Namespace, cases: list[Case]) -> None:
    """Solve, print per seed and the summary, write --csv."""
    df = error_rows(cases, parse_seeds(a.seeds), a.size, a.hurst, a.h, a.coarsest, a.base)
    pd.set_option("display.width", 160)
    print(f"\nload error (P_cmr - P_direct)/P_direct, {a.size}^2, H={a.hurst:g}, h={a.h:g}, top step, "
          f"coarsest {a.coarsest}, base {a.base}")
    print(summary(df).to_string(formatters={"seeds": "{:.0f}".format, "share_under_2pct": "{:.0%}".format,
                                            "median_n_p_over_n": "{:.3f}".format},
                                float_format=lambda v: f"{v:+.2%}"))
    if a.csv:
        df.to_csv(a.csv, index=False)


if __name__ == "__main__":
    main()
