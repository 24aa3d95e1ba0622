"""Population benchmarks (scripts, not tests).

speedup : a population of --surfaces RMD surfaces (default 200) at --size (default 128^2)
          run through the Dask executor on a LocalCluster of 1 worker, then of 2 workers
          (1 thread each); prints and writes the wall-clock speed-up.
kappa   : the ``population`` scene at H = 0.5, 0.7, 0.9 (--seeds, --size) run on a
          LocalCluster, then the kappa = A E* h'_rms / P estimate with its confidence
          intervals written to results/population/ (harness/report/sections/population.py).

    .venv/bin/python benchmarks/bench_population.py speedup --surfaces 200 --size 128
    .venv/bin/python benchmarks/bench_population.py kappa --seeds 0-49 --size 64 --out results/population
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "CONTACTBENCH_FFT_WORKERS"):
    os.environ.setdefault(_var, "1")

from distributed import Client  # noqa: E402

from contactbench.harness.cli import parse_seeds  # noqa: E402
from contactbench.harness.run.distributed import run_benchmark_on_dask, start_local_cluster  # noqa: E402
from contactbench.harness.report.sections.population import write_population_report  # noqa: E402
from contactbench.harness import RunConfig  # noqa: E402
from contactbench.harness import load_table  # noqa: E402
from contactbench.problems.scenes import SceneConfig  # noqa: E402

SOLVER = "fast-ccg"


def population_config(surfaces: int, size: int, steps: int | None, hursts: tuple[float, ...]) -> SceneConfig:
    per_h = -(-surfaces // len(hursts))
    return SceneConfig(size=size, steps=steps, seeds=tuple(range(per_h)), extra={"hursts": hursts})


def timed_run(workers: int, cfg: SceneConfig, run: RunConfig, out: Path) -> tuple[float, int]:
    """Seconds to run the population on a fresh LocalCluster of ``workers`` processes
    (cluster start-up excluded), and the rows solved."""
    shutil.rmtree(out, ignore_errors=True)
    cluster = start_local_cluster(n_workers=workers, threads_per_worker=1, silence_logs=40)
    client = Client(cluster)
    try:
        client.wait_for_workers(workers)
        t0 = time.perf_counter()
        summary = run_benchmark_on_dask(["population"], cfg, [SOLVER], run, out, client, command=sys.argv)
        elapsed = time.perf_counter() - t0
    finally:
        client.close()
        cluster.close()
    return elapsed, summary.statuses.get("solved", 0)


def cmd_speedup(args: argparse.Namespace) -> int:
    cfg = population_config(args.surfaces, args.size, args.steps, (0.5, 0.7, 0.9)[: args.hursts])
    run = RunConfig(reference="none", warmup=False, progress=False, timeout=120.0)
    root = Path(tempfile.mkdtemp(prefix="bench-population-"))
    record = {"surfaces": len(cfg.seeds) * args.hursts, "size": args.size, "steps": args.steps, "solver": SOLVER,
              "cpu_count": os.cpu_count(), "load_avg_before": os.getloadavg()}
    times = {}
    for workers in args.workers:
        t, solved = timed_run(workers, cfg, run, root / f"w{workers}")
        times[workers] = t
        print(f"{workers} worker(s): {t:.1f} s, {solved} rows solved", flush=True)
        record[f"rows_solved_w{workers}"] = solved
    record["seconds"] = times
    record["load_avg_after"] = os.getloadavg()
    base = times[min(times)]
    record["speedup"] = {w: base / t for w, t in times.items()}
    for w, s in record["speedup"].items():
        print(f"speed-up {w} workers vs {min(times)}: {s:.2f}x")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(record, indent=2))
    shutil.rmtree(root, ignore_errors=True)
    return 0


def cmd_kappa(args: argparse.Namespace) -> int:
    cfg = SceneConfig(size=args.size, seeds=args.seeds, extra={"hursts": (0.5, 0.7, 0.9)})
    run = RunConfig(reference="none", warmup=False, progress=False, timeout=120.0)
    out = Path(args.out)
    run_dir = out / f"run-N{args.size}"
    cluster = start_local_cluster(n_workers=args.workers, threads_per_worker=1, silence_logs=40)
    client = Client(cluster)
    try:
        summary = run_benchmark_on_dask(["population"], cfg, [SOLVER], run, run_dir, client, command=sys.argv)
    finally:
        client.close()
        cluster.close()
    print(summary.line())
    path = write_population_report(run_dir, out / f"N{args.size}")
    print(path.read_text())
    print(f"{len(load_table(run_dir))} rows in {run_dir}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    sp = sub.add_parser("speedup")
    sp.add_argument("--surfaces", type=int, default=200)
    sp.add_argument("--size", type=int, default=128)
    sp.add_argument("--steps", type=int, default=None, help="load steps per surface (default: the scene's 3)")
    sp.add_argument("--hursts", type=int, default=3, choices=(1, 2, 3))
    sp.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    sp.add_argument("--json", default=None)
    kp = sub.add_parser("kappa")
    kp.add_argument("--seeds", type=parse_seeds, default=tuple(range(50)))
    kp.add_argument("--size", type=int, default=64)
    kp.add_argument("--workers", type=int, default=2)
    kp.add_argument("--out", default="results/population")
    args = ap.parse_args(argv)
    return cmd_speedup(args) if args.cmd == "speedup" else cmd_kappa(args)


if __name__ == "__main__":
    sys.exit(main())
