"""Harness overhead against a bare solver call on a 256^2 instance (target: <= 5 %).

    .venv/bin/python benchmarks/bench_harness_overhead.py [--size 256] [--solver pk] [--repeats 5]

The instance is the top load step of the paper-sweep surface at N = 256.

* bare    : in this process, one warm-up solve, then ``repeats`` timed ``solver.solve`` calls.
* harness : the runner on the same instance (``harness.job.JobDriver``: a forked isolated worker that
            builds the instance, an untimed warm-up, ``repeats`` timed solves each followed
            by the KKT check, the reference/analytic comparison and a fsync'ed row).

Reported:
  overhead per solve  = (job wall - build - warm-up - sum of timed solves) / sum of timed solves
                        (worker start, pipe round trips, KKT check, row writing)
  KKT check share     = one kkt_check on the instance / median bare solve
  solve-time ratio    = median harness solve_time_s / median bare solve time (isolation must
                        not slow the solver itself)
  whole-run overhead  = the same with run_benchmark's fixed costs (plan, meta.json, parquet/csv)

``--seal-only``: the seal's own cost at ``--size`` (outside the solve's clock, paid around
every solve): ``ProblemSeal.of`` on the problem a solver is handed and the judge's copy,
then ``broken`` after a product, in seconds.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from dataclasses import replace

import numpy as np

from contactbench.harness.judging import ProblemSeal
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.kkt import kkt_check
from contactbench.harness.profiles import PROFILES
from contactbench.harness.run.job import JobDriver
from contactbench.harness.run.plan import RunConfig, plan_run
from contactbench.harness import run_benchmark
from contactbench.harness.table.store import ResultStore, load_table
from contactbench.problems.scenes import LoadSequence, SceneConfig, register_scene
from contactbench.problems.scenes.core import PaperSweep
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver


@register_scene
class TopStep(PaperSweep):
    """paper-sweep reduced to its top load step (one instance-step)."""

    name = "overhead-top-step"

    def build(self, spec):  # type: ignore[no-untyped-def]
        seq = super().build(spec)
        last = len(seq) - 1
        return LoadSequence(seq.instance, [seq.deltas[last]], lambda k: seq.at(last), surface=seq.surface)


def seal_seconds(inst: ContactInstance) -> tuple[float, float]:
    """(seconds of ``ProblemSeal.of``, seconds of ``broken``) on a solver's copy of ``inst``'s
    problem with the judge's beside it, as the worker seals a solve; the seal must hold."""
    qp = QP(inst.qp.H, inst.qp.ubar.copy(), inst.qp.geometry, inst.qp.constraints)
    qp.H.matvec(np.ones(qp.n))  # (the caches a product builds, as after a warm-up)
    t0 = time.perf_counter()
    seal = ProblemSeal.of(qp, [inst.qp])
    t_of = time.perf_counter() - t0
    qp.H.matvec(np.ones(qp.n))
    t0 = time.perf_counter()
    broken = seal.broken(qp)
    t_broken = time.perf_counter() - t0
    assert not broken, broken
    return t_of, t_broken


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--solver", default="pk")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--profile", default="default")
    ap.add_argument("--seal-only", action="store_true", help="only the seal's cost at --size (module doc)")
    args = ap.parse_args()

    cfg = SceneConfig(size=args.size, steps=args.steps, seeds=(0,))
    scene = TopStep()
    spec = scene.instances(scene.config(cfg))[0]
    inst = scene.build(spec).at(0)
    if args.seal_only:
        t_of, t_broken = seal_seconds(inst)
        print(f"paper-sweep top step, N = {args.size}, n = {inst.n}: seal {t_of:.3f} s, check {t_broken:.3f} s")
        return
    solver = get_solver(args.solver)
    settings = SolverSettings(tol=PROFILES[args.profile].tol, time_limit=600)
    solver.solve(inst.qp, settings, None)  # warm-up
    bare = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        res = solver.solve(inst.qp, settings, None)
        bare.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    kkt_check(inst, np.asarray(res.p))
    t_kkt = time.perf_counter() - t0

    run = RunConfig(profiles=(args.profile,), repeats=args.repeats, timeout=600, reference="none", warm=False,
                    progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        job = plan_run([scene.name], cfg, [args.solver], run).jobs[0]
        store = ResultStore(tmp)
        t0 = time.perf_counter()
        JobDriver(job, run, {}, store.cache_dir, store.append).run()
        t_job = time.perf_counter() - t0
        table = store.finalize()
        with tempfile.TemporaryDirectory() as tmp2:
            t0 = time.perf_counter()
            run_benchmark([scene.name], cfg, [args.solver], replace(run, warmup=False), tmp2, command=["bench"])
            t_run = time.perf_counter() - t0
            whole = load_table(tmp2)
    solves = table["solve_time_s"].to_numpy()
    build = float(table["build_time_s"].iloc[0])
    warmup = float(np.median(solves))  # the untimed warm-up costs about one solve
    overhead = (t_job - build - warmup - solves.sum()) / solves.sum()
    whole_over = (t_run - float(whole["build_time_s"].iloc[0]) - whole["solve_time_s"].sum()) / whole["solve_time_s"].sum()
    print(f"instance: paper-sweep top step, N = {args.size}, n = {inst.n}; solver {args.solver}, profile {args.profile}")
    print(f"status {set(table['status'])}, kkt_error {table['kkt_error'].max():.2e}")
    print(f"bare solve         median {statistics.median(bare):.4f} s  min {min(bare):.4f} s")
    print(f"harness solve_time median {np.median(solves):.4f} s  min {solves.min():.4f} s"
          f"  (ratio {np.median(solves) / statistics.median(bare):.3f})")
    print(f"build (in worker)  {build:.3f} s;  job wall {t_job:.3f} s for {len(solves)} timed solves + warm-up")
    print(f"KKT check          {t_kkt * 1e3:.2f} ms = {100 * t_kkt / statistics.median(bare):.2f} % of a solve")
    print(f"overhead per solve {100 * overhead:.2f} % (worker start, pipe, KKT check, rows)")
    print(f"whole-run overhead {100 * whole_over:.2f} % (adds plan, meta.json with git, parquet/csv; no warm-up)")


if __name__ == "__main__":
    main()
