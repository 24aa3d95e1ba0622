"""The honest cost law of the fast solvers: matvecs and seconds of one cold
top step of the paper-sweep scene against the grid size N, with fitted exponents.

For each N and solver, one child process builds the paper-sweep scene's own surface
recipe (``get_scene("paper-sweep")``, ``SceneConfig(size=N, steps=K)``: RMD H = 0.7,
L = 100 um, non-periodic BCC; the recipe name is recorded), takes its last (top) step
Delta = (z_max - z_mean)/2, and solves it cold (no warm start) through the harness's
``solve_sequence`` at the "high" profile (tol 1e-9, judged by ``harness/judging.py``).
Recorded per solve: n, iterations, matvecs, seconds, ms per matvec, kkt, load, the
judge's status and the child's peak RSS.

Each solve runs in its own process, with ``SolverSettings(time_limit=--timeout)`` and a
hard kill a little later, so a slow one cannot hang the run; rows are appended to
``cost-law.csv`` as they finish (a kill loses nothing).  The table, the exponents
(log-log least squares of matvecs and seconds against N^2, over the solved rows of
each solver) and the figure are rebuilt from the whole CSV at the end, keeping the
latest row of each (solver, operator, threads, params, N).

Usage:
  python benchmarks/bench_cost_law.py [--sizes 256 512 1024 2048] [--solvers fast-ccg,...]
      [--timeout 600] [--params '{"precision": "mixed"}'] [--threads 2] [--operator fft|gpu]
      [--steps 10] [--out results/perf] [--fresh] [--plot-only]
Writes OUT/cost-law.csv, OUT/cost-law.md and OUT/cost-law.png.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from contactbench.harness.run.isolation import set_parent_death_signal
from device_warmup import warm_up_device
from csv_rows import append_row, child_result, read_latest, host_name, refuse_missing_device

FAST_SOLVERS = ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg", "fast-pdas")
DEFAULT_SIZES = (256, 512, 1024, 2048)
#: Seconds a child may run past its solve time limit (surface, kernel transform, judge).
KILL_MARGIN_S = 120.0
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "CONTACTBENCH_FFT_WORKERS")


@dataclass
class CostRow:
    """One cold top-step solve."""

    N: int
    instance: str  # the scene's recipe name (surface family, Hurst, N, kernel, seed)
    n: int
    solver: str
    operator: str
    threads: int
    params: str  # JSON of the solver params
    status: str  # the judge's "solved"/"inaccurate", or "timeout"/"failed" (no answer)
    iterations: int
    matvecs: int
    seconds: float
    ms_per_matvec: float
    kkt: float
    load_N: float
    setup_s: float
    peak_rss_mib: float
    device_pool_mib: float  # CuPy's memory pool after the solve (--operator gpu; NaN otherwise)
    host: str
    timestamp: str
    warmup_s: float = math.nan  # the untimed solve of a twin before it: the cold figure (--operator gpu: device_warmup.py)


def top_step(N: int, steps: int, operator: str):
    """The paper-sweep scene's top step at size N (the scene's own recipe) and the recipe's name."""
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("paper-sweep")
    cfg = scene.config(SceneConfig(size=N, steps=steps, operator=operator))
    (spec,) = scene.instances(cfg)
    seq = scene.build(spec)
    return seq.at(len(seq) - 1), spec.instance


def solve_top_step(N: int, solver: str, steps: int, operator: str, timeout: float, params: dict) -> CostRow:
    """One cold solve, in this process (the child)."""
    from contactbench.harness import get_profile
    from contactbench.harness import solve_sequence
    from contactbench.problems.operators import fft_workers
    from contactbench.solvers.base import SolverSettings

    profile = get_profile("high")
    warmup = warm_up_device(solver, params, operator, lambda: top_step(N, steps, operator)[0].qp)
    t0 = time.perf_counter()
    inst, recipe = top_step(N, steps, operator)
    setup = time.perf_counter() - t0
    settings = SolverSettings(tol=profile.tol, time_limit=timeout, params=dict(params))
    (step,) = solve_sequence(solver, [inst], settings, warm=False, check_tol=profile.check_tol)
    res = step.result
    status = step.verdict.status if step.verdict is not None else "failed"
    matvecs = int(res.matvecs) if res is not None else 0
    return CostRow(
        N=N, instance=recipe, n=inst.n, solver=solver, operator=operator, threads=fft_workers(),
        params=json.dumps(params, sort_keys=True),
        status=status, iterations=int(res.iterations) if res is not None else 0, matvecs=matvecs,
        seconds=round(step.seconds, 3), ms_per_matvec=round(1e3 * step.seconds / max(matvecs, 1), 2),
        kkt=float(f"{step.kkt_error:.3e}"), load_N=float(f"{inst.load(res.p):.10e}") if res is not None else math.nan,
        setup_s=round(setup, 2), peak_rss_mib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
        device_pool_mib=device_pool_mib(operator), host=host_name(), timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"),
        warmup_s=round(warmup, 2),
    )


def device_pool_mib(operator: str) -> float:
    """Bytes CuPy's default memory pool holds (its high-water mark: the pool keeps freed
    blocks), in MiB; NaN for a CPU operator."""
    if operator != "gpu":
        return math.nan
    import cupy

    return round(cupy.get_default_memory_pool().total_bytes() / 2**20, 1)


def child_env(threads: int | None) -> dict[str, str]:
    env = dict(os.environ)
    if threads:
        env.update({v: str(threads) for v in THREAD_VARS})
    return env


def run_child(N: int, solver: str, args: argparse.Namespace) -> CostRow:
    """The row of one solve in a child process; a "timeout"/"failed" row when it gives none."""
    cmd = [sys.executable, __file__, "--child", f"{N}:{solver}", "--steps", str(args.steps), "--operator",
           args.operator, "--timeout", str(args.timeout), "--params", args.params]
    result, status, detail = child_result(cmd, child_env(args.threads), args.timeout + KILL_MARGIN_S)
    if result is not None:
        return CostRow(**result)
    print(f"  N={N} {solver}: {status}: {detail}", file=sys.stderr, flush=True)
    from contactbench.problems.operators import fft_workers

    return CostRow(N=N, instance="", n=0, solver=solver, operator=args.operator, threads=int(args.threads or fft_workers()),
                   params=json.dumps(json.loads(args.params), sort_keys=True), status=status, iterations=0,
                   matvecs=0, seconds=math.nan, ms_per_matvec=math.nan, kkt=math.nan, load_N=math.nan,
                   setup_s=math.nan, peak_rss_mib=math.nan, device_pool_mib=math.nan, host=host_name(),
                   timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"))


def read_rows(path: Path) -> list[CostRow]:
    """The CSV's rows, the latest of each (solver, operator, threads, params, N)."""
    return read_latest(path, CostRow, key=lambda r: (r.solver, r.operator, r.threads, r.params, r.N),
                       order=lambda r: (r.solver, r.operator, r.threads, r.params, r.N))


@dataclass(frozen=True)
class Fit:
    """y ~ c (N^2)^exponent over the solved rows of one series."""

    exponent: float
    points: int


def fit_exponent(N: list[int], y: list[float]) -> Fit | None:
    """Log-log least squares of y against N^2 (None with fewer than two sizes)."""
    ok = [(a, b) for a, b in zip(N, y) if b > 0 and math.isfinite(b)]
    if len({a for a, _ in ok}) < 2:
        return None
    x = np.log([float(a) ** 2 for a, _ in ok])
    slope = float(np.polyfit(x, np.log([b for _, b in ok]), 1)[0])
    return Fit(slope, len(ok))


def series(rows: list[CostRow]) -> dict[str, list[CostRow]]:
    """Rows grouped by solver (with operator/threads/params in the label when they vary)."""
    keys = {(r.operator, r.threads, r.params) for r in rows}
    out: dict[str, list[CostRow]] = {}
    for r in rows:
        label = r.solver
        if len(keys) > 1:
            label += f" [{r.operator}, {r.threads} thr{'' if r.params == '{}' else ', ' + r.params}]"
        out.setdefault(label, []).append(r)
    return out


def fits_of(rows: list[CostRow]) -> dict[str, tuple[Fit | None, Fit | None]]:
    """label -> (matvec fit, seconds fit), over solved rows."""
    out = {}
    for label, rs in series(rows).items():
        good = [r for r in rs if r.status == "solved"]
        out[label] = (fit_exponent([r.N for r in good], [r.matvecs for r in good]),
                      fit_exponent([r.N for r in good], [r.seconds for r in good]))
    return out


def fmt_fit(f: Fit | None) -> str:
    return "-" if f is None else f"{f.exponent:.2f} ({f.points} sizes)"


def fmt_mib(v: float) -> str:
    return "-" if not math.isfinite(v) else f"{v:.0f}"


def write_markdown(rows: list[CostRow], path: Path, png: Path) -> None:
    lines = [
        "# Cost law of the fast solvers: one cold top step of paper-sweep",
        "",
        "Written by `benchmarks/bench_cost_law.py` from `cost-law.csv` (latest row per solver and size).",
        "Scene: paper-sweep, its own surface recipe at each N (BCC, non-periodic; recipes: "
        + ", ".join(sorted({r.instance for r in rows if r.instance})) + "),",
        "top step Delta = (z_max - z_mean)/2, cold start, tol 1e-9, judged at kkt <= 1e-8 (profile \"high\").",
        f"Host(s): {', '.join(sorted({r.host for r in rows}))}.",
        "",
        "## Fitted exponents (log-log least squares against N^2 = number of grid points, solved rows only)",
        "",
        "| solver | matvecs ~ (N^2)^a | seconds ~ (N^2)^b |",
        "|---|---|---|",
    ]
    lines += [f"| {label} | {fmt_fit(fm)} | {fmt_fit(fs)} |" for label, (fm, fs) in fits_of(rows).items()]
    lines += ["", "## Solves", "",
              "| solver | operator | threads | params | N | n | status | iterations | matvecs | seconds | ms/matvec | kkt | "
              "peak RSS MiB | device pool MiB | cold twin s |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r.solver} | {r.operator} | {r.threads} | `{r.params}` | {r.N} | {r.n} | {r.status} | {r.iterations} | "
              f"{r.matvecs} | {r.seconds:.2f} | {r.ms_per_matvec:.1f} | {r.kkt:.2e} | {r.peak_rss_mib:.0f} | {fmt_mib(r.device_pool_mib)} | "
              f"{'-' if math.isnan(r.warmup_s) else f'{r.warmup_s:.2f}'} |" for r in rows]
    lines += ["", "A device row's seconds are a warm solve: it follows an untimed solve of a twin instance "
              "(benchmarks/device_warmup.py), whose seconds, the cold figure, are the last column.", ""]
    lines += ["", f"![cost law]({png.name})", ""]
    path.write_text("\n".join(lines))


def add_linear_guide(ax, sizes: list[int]) -> None:
    """A dashed grey line of slope 1 (cost ~ N^2, linear in the unknowns) from the
    lowest point at the smallest size."""
    x0 = float(sizes[0]) ** 2 if sizes else math.nan
    firsts = [float(ln.get_ydata()[0]) for ln in ax.get_lines() if float(ln.get_xdata()[0]) == x0]
    if len(sizes) < 2 or not firsts:
        return
    xs = [float(n) ** 2 for n in sizes]
    ax.plot(xs, [min(firsts) * x / x0 for x in xs], "--", color="0.6", lw=1, label="slope 1 (~ N$^2$)")


def write_figure(rows: list[CostRow], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import (
        LogLocator,
        NullFormatter,
        NullLocator,
        ScalarFormatter,
    )

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    fits = fits_of(rows)
    for label, rs in series(rows).items():
        good = [r for r in rs if r.status == "solved"]
        if not good:
            continue
        x = [float(r.N) ** 2 for r in good]
        for ax, attr, fit in ((axes[0], "seconds", fits[label][1]), (axes[1], "matvecs", fits[label][0])):
            tag = "" if fit is None else f" (a = {fit.exponent:.2f})"
            ax.plot(x, [getattr(r, attr) for r in good], "o-", label=label + tag)
    for ax, title in ((axes[0], "seconds per cold top step"), (axes[1], "matvecs per cold top step")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("grid points N$^2$")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    sizes = sorted({r.N for r in rows if r.status == "solved"})
    for ax in axes:
        ax.set_xticks([float(n) ** 2 for n in sizes])
        ax.set_xticklabels([f"{n}$^2$" for n in sizes])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ScalarFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
    add_linear_guide(axes[0], sizes)
    for ax in axes:
        if ax.get_lines():
            ax.legend(fontsize=7)
    fig.suptitle("paper-sweep top step, cold, kkt <= 1e-8: cost against grid size (exponent a of (N$^2$)$^a$)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_outputs(out: Path) -> None:
    rows = read_rows(out / "cost-law.csv")
    write_markdown(rows, out / "cost-law.md", out / "cost-law.png")
    write_figure(rows, out / "cost-law.png")
    for label, (fm, fs) in fits_of(rows).items():
        print(f"{label:24s} matvecs ~ (N^2)^{fmt_fit(fm)}   seconds ~ (N^2)^{fmt_fit(fs)}")
    print(f"wrote {out / 'cost-law.md'} and {out / 'cost-law.png'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(DEFAULT_SIZES))
    ap.add_argument("--solvers", default=",".join(FAST_SOLVERS))
    ap.add_argument("--timeout", type=float, default=600.0, help="time limit of one solve (s)")
    ap.add_argument("--params", default="{}", help="solver params as JSON, e.g. '{\"precision\": \"mixed\"}'")
    ap.add_argument("--threads", type=int, default=None, help="BLAS/OpenMP/FFT threads (default: all cores)")
    ap.add_argument("--operator", default="fft", choices=("fft", "gpu"))
    ap.add_argument("--steps", type=int, default=10, help="load steps of the scene (the top one is solved)")
    ap.add_argument("--out", default="results/perf")
    ap.add_argument("--plot-only", action="store_true", help="rebuild the table and figure from the CSV")
    ap.add_argument("--fresh", action="store_true", help="start a new CSV (the old one is renamed to .csv.old)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    params = json.loads(args.params)
    if not isinstance(params, dict):
        ap.error("--params must be a JSON object")
    if args.child:
        set_parent_death_signal()  # a killed run takes its solve with it
        N, solver = args.child.split(":")
        row = solve_top_step(int(N), solver, args.steps, args.operator, args.timeout, params)
        print("RESULT " + json.dumps(asdict(row)), flush=True)
        return
    out = Path(args.out)
    if args.fresh and (out / "cost-law.csv").exists():
        (out / "cost-law.csv").replace(out / "cost-law.csv.old")
    if not args.plot_only:
        refuse_missing_device(ap, args.operator)
        for N in args.sizes:
            for solver in args.solvers.split(","):
                row = run_child(N, solver, args)
                append_row(out / "cost-law.csv", row)
                print(f"N={row.N} n={row.n} {row.solver}: {row.status} {row.matvecs} matvecs {row.seconds:.2f} s "
                      f"kkt={row.kkt:.1e} rss={row.peak_rss_mib:.0f} MiB", flush=True)
    write_outputs(out)


if __name__ == "__main__":
    main()
