"""Side-by-side benchmark: our fast solvers against the field's FFT contact codes.

Solves the IDENTICAL problem with every code in the same run: the paper-sweep surface
(RMD H = 0.7, L = 100 um, N x N, the paper-sweep seed 55), the load ramp Delta_k = (k/K)(z_max - z_mean)/2,
k = 1..K, and

* ``nonperiodic-bcc``   the paper's problem: BCC influence coefficients on a finite
  patch (2N x 2N circulant embedding).  ContactMechanics solves it through a
  FreeFFTElasticHalfSpace whose Green's function is replaced by our BCC table
  (times the pixel area: CM's ``evaluate_disp`` takes forces, divides by the area).
* ``periodic-spectral`` the periodic problem with the continuum kernel 2/(E*|q|),
  q = 0 removed -- CM's PeriodicFFTElasticHalfSpace with ``stiffness_q0=0`` and Tamaas'
  basic_2d model (contact modulus E* = E with nu = 0).  With the mean mode removed the
  surface rises away from the contacts, so points *outside* the trial set
  {z >= z_max - Delta} can touch: the periodic QP here is posed on the whole grid
  (ubar = Delta - z_max + z everywhere, may be negative).  Under displacement control
  the mean displacement is zero, so Tamaas' target mean gap is -mean(ubar).

Conventions: p is the force per element (N); CM's "dual" variable is the same pixel
force with gradient = gap = Hp - z - offset, offset = Delta - z_max.  The peers stop on
max|projected gap| <= gtol: we hand them gtol = tol * max(ubar) (the harness's scaled
dual residual) and judge *every* answer, ours and theirs, by the harness's ``judge``.
Our solvers run the load ramp through ``harness.sequence.solve_sequence`` (warm starts
mapped by grid index).
Peers run single-threaded; ours run at 1 FFT thread and at the default.

Each (case, solver, threads) runs in its own subprocess, so the peak RSS is its own.

Usage: python benchmarks/bench_peers.py [--size 512] [--steps 10] [--tol 1e-8]
       [--solvers fast-ccg,fast-dual-ccg] [--cases nonperiodic-bcc,periodic-spectral]
       [--backends ducc,scipy] [--out results/perf/peers]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

E_STAR = 1.0e9
LENGTH = 100e-6
CASES = ("nonperiodic-bcc", "periodic-spectral")
PEERS = ("cm-dual-ccg", "tamaas-pkr")


@dataclass
class StepRecord:
    step: int
    load: float
    contact_fraction: float
    kkt: float
    seconds: float
    iterations: int


@dataclass
class RunRecord:
    case: str
    solver: str
    threads: str
    N: int
    fft_backend: str = ""
    total_seconds: float = float("nan")
    matvecs: int = 0
    ffts: int = 0
    peak_rss_mb: float = float("nan")
    max_kkt: float = float("nan")
    status: str = "ok"
    message: str = ""
    steps: list[StepRecord] = field(default_factory=list)


# ---------------------------------------------------------------------------
# Problem construction (identical for every code)
# ---------------------------------------------------------------------------


def scene(N: int, steps: int):
    from contactbench.problems.instances import load_ramp, paper_max_displacement
    from contactbench.problems.scenes.core import PAPER_SEED
    from contactbench.problems.surfaces import rmd_surface_n

    surf = rmd_surface_n(N, 0.7, length=LENGTH, seed=PAPER_SEED)
    return surf, load_ramp(paper_max_displacement(surf), steps)


def our_instances(case: str, surf, deltas):
    """ContactInstances, one per step, all sharing one kernel transform."""
    from contactbench.problems.instances import QP, ContactInstance, Geometry, InstanceBuilder
    from contactbench.problems.operators import FFTOperator

    if case == "nonperiodic-bcc":
        b = InstanceBuilder(surf, E_STAR, "bcc", periodic=False)
        return b.transform, [b.build(float(d)) for d in deltas]
    b = InstanceBuilder(surf, E_STAR, "spectral", periodic=True)
    idx = np.arange(surf.heights.size)
    out = []
    for d in deltas:
        ubar = float(d) - float(surf.heights.max()) + surf.heights.ravel()
        geom = Geometry(surf.shape, surf.delta, idx, surface=surf, far_field=float(d), E=E_STAR,
                        kernel="spectral", periodic=True)
        qp = QP(FFTOperator(b.transform, idx), ubar, geom)
        out.append(ContactInstance(qp, float(d), E_STAR, "spectral", True, surf, {}))
    return b.transform, out


def figures(inst, p_on_set: np.ndarray) -> tuple[float, float, float]:
    """(load, contact fraction, scaled KKT error) of an answer, by the harness's judge."""
    from contactbench.harness.judge import judge

    kkt = judge(inst, p_on_set, True, float("inf")).kkt_error
    return inst.load(p_on_set), inst.contact_fraction(p_on_set), kkt


# ---------------------------------------------------------------------------
# Runners (each returns a RunRecord; called in a child process)
# ---------------------------------------------------------------------------


def run_ours(case: str, solver_name: str, N: int, steps: int, tol: float) -> RunRecord:
    from contactbench.harness.sequence import solve_sequence
    from contactbench.problems.operators import fft_backend
    from contactbench.solvers.base import SolverSettings

    surf, deltas = scene(N, steps)
    transform, insts = our_instances(case, surf, deltas)
    rec = RunRecord(case, solver_name, os.environ.get("CONTACTBENCH_FFT_WORKERS", "default"), N,
                    fft_backend=fft_backend())
    f0 = transform.fft_count
    for s in solve_sequence(solver_name, insts, SolverSettings(tol=tol / 10)):
        assert s.result is not None and s.verdict is not None, s.error
        rec.matvecs += s.result.matvecs
        p = s.result.p
        rec.steps.append(StepRecord(s.step + 1, s.inst.load(p), s.inst.contact_fraction(p), s.kkt_error, s.seconds,
                                    s.result.iterations))
    rec.ffts = transform.fft_count - f0 - 2 * len(insts)  # minus the judge's own matvecs
    return finish(rec)


class _Unavailable(Exception):
    pass


def _cm_substrate(case: str, surf):
    try:
        from ContactMechanics import FreeFFTElasticHalfSpace, PeriodicFFTElasticHalfSpace
    except ImportError as e:  # optional extra "peers"
        raise _Unavailable(f"contactmechanics not installed ({e})") from None
    from contactbench.problems.kernels import kernel_table

    N1, N2 = surf.shape
    size = (surf.delta * N1, surf.delta * N2)
    if case == "periodic-spectral":
        return PeriodicFFTElasticHalfSpace((N1, N2), E_STAR, physical_sizes=size, stiffness_q0=0.0)

    class BCCFreeHalfSpace(FreeFFTElasticHalfSpace):
        """CM's free half-space with our BCC influence coefficients as Green's function."""

        def __init__(self) -> None:
            self._comp_nb_grid_pts = (2 * N1, 2 * N2)
            super().__init__((N1, N2), E_STAR, physical_sizes=size)

        def _compute_greens_function(self):
            tab = kernel_table("bcc", (N1, N2), surf.delta, E_STAR, periodic=False)
            self.real_buffer.p[...] = tab * self.area_per_pt  # force kernel -> pressure kernel
            self.fftengine.fft(self.real_buffer, self.fourier_buffer)
            return self.fourier_buffer.p.copy()

    return BCCFreeHalfSpace()


def run_cm(case: str, variant: str, N: int, steps: int, tol: float) -> RunRecord:
    """ContactMechanics' dual CCG (Bugnicourt et al. 2018 on the pixel forces), warm-started
    with the previous step's forces."""
    surf, deltas = scene(N, steps)
    _, insts = our_instances(case, surf, deltas)
    rec = RunRecord(case, variant, "1", N)
    sub = _cm_substrate(case, surf)
    from ContactMechanics.Systems import NonSmoothContactSystem
    from SurfaceTopography import Topography

    topo = Topography(surf.heights, physical_sizes=sub.physical_sizes, periodic=(case != "nonperiodic-bcc"))
    system = NonSmoothContactSystem(sub, topo)
    force = np.zeros(surf.shape)
    zmax = float(surf.heights.max())
    for k, inst in enumerate(insts):
        gtol = tol * float(np.max(inst.qp.ubar))
        t = time.perf_counter()
        res = system.dual_minimize_proxy(inst.delta - zmax, init_force=force, gtol=gtol, maxiter=100000)
        force = np.asarray(res.x).reshape(surf.shape)
        dt = time.perf_counter() - t
        load, area, kkt = figures(inst, force.ravel()[inst.geometry.indices])
        rec.steps.append(StepRecord(k + 1, load, area, kkt, dt, int(res.nit)))
    rec.matvecs = -1
    return finish(rec)


def run_tamaas(case: str, N: int, steps: int, tol: float) -> RunRecord:
    rec = RunRecord(case, "tamaas-pkr", "1", N)
    if case != "periodic-spectral":
        raise _Unavailable("Tamaas has no exact free-boundary (finite patch) operator for this kernel; "
                           "a zero-padded periodic cell would be a different problem")
    try:
        import tamaas as tm
    except ImportError as e:
        raise _Unavailable(f"tamaas not installed ({e})") from None
    surf, deltas = scene(N, steps)
    _, insts = our_instances(case, surf, deltas)
    tm.set_log_level(tm.LogLevel.error)
    L = surf.delta * surf.shape[0]
    model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [L, L], list(surf.shape))
    model.E, model.nu = E_STAR, 0.0
    heights = np.ascontiguousarray(surf.heights)
    for k, inst in enumerate(insts):
        solver = tm.PolonskyKeerRey(model, heights, tol, tm.PolonskyKeerRey.gap, tm.PolonskyKeerRey.gap)
        t = time.perf_counter()
        solver.solve(-float(np.mean(inst.qp.ubar)))  # mean displacement is zero: mean gap = -mean(ubar)
        dt = time.perf_counter() - t
        force = np.array(model.traction).reshape(surf.shape) * surf.delta**2
        load, area, kkt = figures(inst, force.ravel()[inst.geometry.indices])
        rec.steps.append(StepRecord(k + 1, load, area, kkt, dt, -1))
    rec.matvecs = -1
    return finish(rec)


def finish(rec: RunRecord) -> RunRecord:
    rec.total_seconds = float(sum(s.seconds for s in rec.steps))
    rec.max_kkt = float(max((s.kkt for s in rec.steps), default=float("nan")))
    rec.peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return rec


def child_main(args: argparse.Namespace) -> None:
    case, solver = args.child.split(":")
    try:
        if solver.startswith("cm-"):
            rec = run_cm(case, solver, args.size, args.steps, args.tol)
        elif solver == "tamaas-pkr":
            rec = run_tamaas(case, args.size, args.steps, args.tol)
        else:
            rec = run_ours(case, solver, args.size, args.steps, args.tol)
    except _Unavailable as e:
        rec = RunRecord(case, solver, "1", args.size, status="skipped", message=str(e))
    print("RESULT " + json.dumps(asdict(rec)))


# ---------------------------------------------------------------------------
# Parent: orchestrate, compare, write the table
# ---------------------------------------------------------------------------


def spawn(case: str, solver: str, threads: str | None, args: argparse.Namespace, backend: str = "") -> RunRecord:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if backend:
        env["CONTACTBENCH_FFT_BACKEND"] = backend
    if threads is None:
        env.pop("CONTACTBENCH_FFT_WORKERS", None)
    else:
        env["CONTACTBENCH_FFT_WORKERS"] = threads
    cmd = [sys.executable, __file__, "--child", f"{case}:{solver}", "--size", str(args.size),
           "--steps", str(args.steps), "--tol", str(args.tol)]
    try:
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return RunRecord(case, solver, threads or "default", args.size, status="timeout",
                         message=f"over {args.timeout} s")
    for line in out.stdout.splitlines():
        if line.startswith("RESULT "):
            d = json.loads(line[7:])
            d["steps"] = [StepRecord(**s) for s in d["steps"]]
            rec = RunRecord(**d)
            if threads is None and not solver.startswith(("cm-", "tamaas")):
                rec.threads = f"default({os.cpu_count()})"
            return rec
    return RunRecord(case, solver, threads or "default", args.size, status="error",
                     message=(out.stderr or out.stdout)[-500:])


def fft_floor_seconds(case: str, N: int, threads: str | None, backend: str = "", reps: int = 20) -> float:
    """Seconds for one forward+inverse transform pair of the operator (the matvec's floor)."""
    if backend:
        os.environ["CONTACTBENCH_FFT_BACKEND"] = backend
    if threads is not None:
        os.environ["CONTACTBENCH_FFT_WORKERS"] = threads
    else:
        os.environ.pop("CONTACTBENCH_FFT_WORKERS", None)
    surf, deltas = scene(N, 1)
    transform, insts = our_instances(case, surf, deltas)
    # The path a matvec takes (scatter on the top step's trial set, pruned pair, gather).
    pidx = insts[-1].qp.H.pidx
    x = np.random.default_rng(0).random(pidx.size)
    transform.apply_on_set(pidx, x)
    t = time.perf_counter()
    for _ in range(reps):
        transform.apply_on_set(pidx, x)
    return (time.perf_counter() - t) / reps


def print_steps(case: str, recs: list[RunRecord]) -> None:
    ok = [r for r in recs if r.status == "ok"]
    if not ok:
        return
    print(f"\n== {case}: load P (N) / contact fraction A/A0 / kkt per step ==")
    print("step " + " ".join(f"{(r.solver + '@' + r.threads + r.fft_backend)[:30]:>32s}" for r in ok))
    for k in range(len(ok[0].steps)):
        cells = [f"{r.steps[k].load:.8e}/{r.steps[k].contact_fraction:.5f}/{r.steps[k].kkt:.0e}" for r in ok]
        print(f"{k + 1:4d} " + " ".join(f"{c:>32s}" for c in cells))
    ref = ok[0]
    for r in ok[1:]:
        dl = max(abs(a.load - b.load) / abs(b.load) for a, b in zip(r.steps, ref.steps))
        da = max(abs(a.contact_fraction - b.contact_fraction) for a, b in zip(r.steps, ref.steps))
        print(f"  {r.solver}@{r.threads} vs {ref.solver}@{ref.threads}: max rel load diff {dl:.2e}, "
              f"max |dA/A0| {da:.2e}")


def write_tables(rows: list[dict], out: Path) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--solvers", default="fast-ccg,fast-dual-ccg,fast-pdas")
    ap.add_argument("--peers", default=",".join(PEERS))
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--threads", default="1,default", help="FFT threads for ours: comma list, 'default' = all")
    ap.add_argument("--backends", default="", help="FFT libraries for ours: comma list of ducc,scipy "
                    "(default: the operator's default only)")
    ap.add_argument("--timeout", type=float, default=900.0)
    ap.add_argument("--out", default="results/perf/peers")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child_main(args)
        return
    rows: list[dict] = []
    for case in args.cases.split(","):
        recs: list[RunRecord] = []
        for peer in filter(None, args.peers.split(",")):
            recs.append(spawn(case, peer, "1", args))
            print(f"[{case}] {peer}: {recs[-1].status} {recs[-1].total_seconds:.2f} s {recs[-1].message}", flush=True)
        backends = args.backends.split(",") if args.backends else [""]
        for solver in filter(None, args.solvers.split(",")):
            for th in args.threads.split(","):
                for backend in backends:
                    recs.append(spawn(case, solver, None if th == "default" else th, args, backend))
                    r = recs[-1]
                    print(f"[{case}] {solver}@{r.threads} {r.fft_backend}: {r.status} {r.total_seconds:.2f} s, "
                          f"{r.matvecs} matvecs, max kkt {r.max_kkt:.1e} {r.message}", flush=True)
        print_steps(case, recs)
        peers_ok = [r.total_seconds for r in recs if r.status == "ok" and r.solver in PEERS
                    and r.max_kkt <= 10 * args.tol]
        best_peer = min(peers_ok) if peers_ok else float("nan")
        floors = {(th, b): fft_floor_seconds(case, args.size, None if th == "default" else th, b)
                  for th in args.threads.split(",") for b in backends}
        for r in recs:
            th_key = "default" if r.threads.startswith("default") else r.threads
            b_key = r.fft_backend if r.fft_backend in backends else backends[0]
            floor = floors.get((th_key, b_key), float("nan"))
            per_mv = r.total_seconds / r.matvecs if r.matvecs > 0 else float("nan")
            outside = 1.0 - (r.ffts / 2) * floor / r.total_seconds if r.ffts > 0 else float("nan")
            rows.append({
                "case": case, "N": r.N, "solver": r.solver, "threads": r.threads, "fft": r.fft_backend,
                "status": r.status,
                "total_s": round(r.total_seconds, 3), "matvecs": r.matvecs, "ffts": r.ffts,
                "peak_rss_mb": round(r.peak_rss_mb, 1), "max_kkt": f"{r.max_kkt:.2e}",
                "ratio_to_best_peer": round(r.total_seconds / best_peer, 3) if best_peer == best_peer else "",
                "ms_per_matvec": round(1e3 * per_mv, 2) if per_mv == per_mv else "",
                "fft_pair_ms": round(1e3 * floor, 2) if r.ffts > 0 else "",
                "frac_outside_fft": round(outside, 3) if outside == outside else "",
                "note": r.message[:120],
            })
        print(f"[{case}] best peer (kkt <= {10 * args.tol:g}): {best_peer:.2f} s; FFT pair floor: "
              + ", ".join(f"{k[0]} thr {k[1] or 'default'} {1e3 * v:.2f} ms" for k, v in floors.items()), flush=True)
    write_tables(rows, Path(args.out))
    print(f"\nwrote {args.out}.csv and .md")


if __name__ == "__main__":
    main()
