"""Benchmark of the generic QP adapters (qp-*, cvxpy) against the scipy-nnls reference.

Part 1 (``table``): every available adapter on 32^2, 64^2 and 128^2 RMD instances
(H = 0.7, E = 1e9 Pa, SI units, BCC kernel, the paper's top displacement) at the four
profiles: wall time, build time, scaled KKT error, relative error in p and in the load
against scipy-nnls, and the backend's own status.

Part 2 (``sweep``): the ``high`` profile on one 256^2 surface at displacements chosen
so that the trial set has n ~ 500, 1000, 2000, 4000 elements; each adapter stops at the
first size it takes more than --cap seconds for, or that the power law t = a n^b fitted
to its last two points predicts past 60 s.  That fit estimates the largest n it solves
in 60 s (an extrapolation, labelled as such).

Run:  OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_qp_backends.py [--quick] [--out FILE]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np

from contactbench.problems.kkt import kkt_check, relative_error, relative_load_error
from contactbench.problems.instances import ContactInstance, InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.harness.profiles import PROFILES
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import all_solvers, get_solver


@dataclass
class Row:
    instance: str
    n: int
    solver: str
    profile: str
    wall: float
    build: float
    kkt: float
    p_err: float
    load_err: float
    status: str
    converged: bool


def adapters() -> list[str]:
    return [n for n, s in all_solvers().items() if (n.startswith("qp-") or n == "cvxpy") and s.availability()[0]]


def top_step(N: int, seed: int = 1) -> ContactInstance:
    surf = rmd_surface_n(N, 0.7, seed=seed)
    return InstanceBuilder(surf, 1e9, operator="dense").build(paper_max_displacement(surf), meta={"N": N})


def instance_with_n(surf: Surface, n_target: int) -> ContactInstance:
    """The load step of ``surf`` whose trial set has (about) n_target elements."""
    z = np.sort(surf.heights.ravel())[::-1]
    delta = float(z[0] - z[min(n_target, z.size) - 1])
    return InstanceBuilder(surf, 1e9, operator="dense").build(delta)


def run_one(name: str, inst: ContactInstance, label: str, profile: str, p_ref: np.ndarray,
            time_limit: float | None = None) -> Row:
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = get_solver(name).solve(inst.qp, SolverSettings(tol=PROFILES[profile].tol, time_limit=time_limit))
    wall = time.perf_counter() - t0
    kkt = kkt_check(inst, res.p).kkt_error
    return Row(label, inst.n, name, profile, wall, res.setup_time, kkt, relative_error(res.p, p_ref),
               relative_load_error(inst.load(res.p), inst.load(p_ref)), res.info.get("backend_status", res.status), res.converged)


def reference(inst: ContactInstance) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    res = get_solver("scipy-nnls").solve(inst.qp, SolverSettings(1e-9))
    return res.p, time.perf_counter() - t0


def fmt(rows: list[Row]) -> str:
    out = ["| instance | n | solver | profile | time s | build s | kkt | err p | err load | status |",
           "|---|---:|---|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        out.append(f"| {r.instance} | {r.n} | {r.solver} | {r.profile} | {r.wall:.3g} | {r.build:.2g} | "
                   f"{r.kkt:.1e} | {r.p_err:.1e} | {r.load_err:.1e} | {r.status[:24]} |")
    return "\n".join(out)


def table(sizes: list[int], emit) -> list[Row]:
    rows = []
    for N in sizes:
        inst = top_step(N)
        p_ref, t_ref = reference(inst)
        emit(f"\n## {N}^2 top step: n = {inst.n}, scipy-nnls reference {t_ref:.3g} s, "
             f"kkt {kkt_check(inst, p_ref).kkt_error:.1e}\n")
        block = [run_one(name, inst, f"{N}^2", prof, p_ref) for name in adapters() for prof in PROFILES]
        emit(fmt(block))
        rows += block
    return rows


def fit_n_at(points: list[tuple[int, float]], seconds: float = 60.0) -> tuple[float, str]:
    """Largest n solved in ``seconds``, interpolated or extrapolated from (n, t) points."""
    (n1, t1), (n2, t2) = points[-2], points[-1]
    b = math.log(max(t2, 1e-6) / max(t1, 1e-6)) / math.log(n2 / n1) if n2 != n1 else 3.0
    b = min(max(b, 1.0), 4.0)
    n60 = n2 * (seconds / max(t2, 1e-6)) ** (1.0 / b)
    kind = "measured bracket" if t2 >= seconds else "extrapolated"
    return n60, f"{kind}, t ~ n^{b:.2f}"


def sweep(targets: list[int], cap: float, emit) -> None:
    surf = rmd_surface_n(256, 0.7, seed=2)
    insts = [instance_with_n(surf, n) for n in targets]
    refs = [reference(i) for i in insts]
    emit("\n## size sweep, profile high (256^2 surface, displacement chosen for n)\n")
    emit("reference scipy-nnls: " + ", ".join(f"n={i.n}: {t:.3g} s" for i, (_, t) in zip(insts, refs)))
    rows: list[Row] = []
    summary = ["| solver | largest n measured | its time s | kkt there | err p there | est. n in 60 s |",
               "|---|---:|---:|---:|---:|---|"]
    for name in adapters() + ["scipy-nnls"]:
        pts: list[tuple[int, float]] = []
        last: Row | None = None
        for inst, (p_ref, t_ref) in zip(insts, refs):
            est = get_solver(name).time_estimate(inst.n, "dense")
            if len(pts) >= 2 and fit_n_at(pts)[0] < inst.n:
                break  # predicted past 60 s: extrapolate instead of attempting it
            last = run_one(name, inst, "sweep", "high", p_ref, time_limit=4 * cap)
            rows.append(last)
            pts.append((inst.n, last.wall))
            emit(f"  {name:20s} n={inst.n:5d} t={last.wall:8.3g} s (model {est:.3g}) kkt={last.kkt:.1e} "
                 f"err={last.p_err:.1e} status={last.status[:30]}")
            if last.wall > cap:
                break
        if last is None:
            continue
        n60, how = fit_n_at(pts) if len(pts) >= 2 else (float("nan"), "one point")
        summary.append(f"| {name} | {last.n} | {last.wall:.3g} | {last.kkt:.1e} | {last.p_err:.1e} | "
                       f"~{n60:.0f} ({how}) |")
    emit("\n" + fmt(rows))
    emit("\n" + "\n".join(summary))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="32^2 only, no sweep")
    ap.add_argument("--no-sweep", action="store_true")
    ap.add_argument("--sweep-only", action="store_true")
    ap.add_argument("--cap", type=float, default=30.0, help="stop a solver's sweep past this many seconds")
    ap.add_argument("--out", default=None, help="also write the markdown here")
    args = ap.parse_args(argv)
    lines: list[str] = []

    def emit(s: str) -> None:
        print(s, flush=True)
        lines.append(s)

    if not args.sweep_only:
        table([32] if args.quick else [32, 64, 128], emit)
    if not (args.quick or args.no_sweep):
        sweep([500, 1000, 2000, 4000], args.cap, emit)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
