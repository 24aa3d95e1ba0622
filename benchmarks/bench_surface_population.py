"""The fast default solver over a population of surface families: matvecs, iterations,
seconds, peak memory and kkt of one cold top step per member, the default solver against
the same solver in float64 with the island blocks alone.

Population (``plan``): four surface families (``FAMILIES``) x Hurst/rms-slope cells
(``CELLS``; ``LARGE_CELLS`` from 4096^2 up) x seeds (``--seeds N:k``, default ``SEEDS``)
x sizes (``--sizes``), L = 100 um:

* ``saupe``    -- Saupe's non-periodic RMD (problems/surfaces.py ``rmd_surface_n``, the paper's);
* ``periodic`` -- the wrap-around RMD (diamond-square) of the same module;
* ``fourier``  -- Fourier synthesis with a roll-off and a short cutoff (``fourier_synthesis``);
* ``measured`` -- a Fourier-synthesis surface as an instrument delivers it: a tilt of one rms
  height across L left in, ``MISSING_FRACTION`` of the points missing in small holes, filled by
  problems/io.py's "fill-nearest" rule (``measured_like_heights``, ``fill_missing``).

Every surface is scaled to its cell's rms slope (``with_rms_slope``).  Instance: the
paper's, BCC kernel, non-periodic, E = the paper's, top step Delta = (z_max - z_mean)/2,
cold start, tol 1e-9 (profile "high", judged by harness/judging.py).  Variants (``VARIANTS``):
"default" -- ``fast-dual-pccg`` with its defaults -- and "double-islands" --
``precision=double, precondition=islands``; "fourier" is the wave-number preconditioner,
what "auto" is on a device (solvers/_device.py), so its matvecs there are these; "farfield"
the island blocks with the far-field coupling at every size (``FAR_FIELD_GRID_POINTS``'s
evidence: results/perf/farfield-1024).

Each solve runs in its own process (``--in-process`` runs them in this one: matvec counts
only, no per-solve peak memory) with ``SolverSettings(time_limit=--timeout)`` and a hard
kill later; rows are appended to ``OUT/surface-population.csv`` as they finish, with the
host, the time and the code's commit.  ``OUT/surface-population.md`` is rebuilt from the
CSV (latest row per member and variant): median and worst matvecs and seconds per size and
family, and the two checks -- no default solve above ``STALL_FACTOR`` x the median matvecs of
its size, and none slower than the double-islands variant by more than ``SLOWER_LIMIT``.

Usage:
  python benchmarks/bench_surface_population.py [--sizes 512 1024 2048 4096] [--families saupe,...]
      [--seeds 512:3,1024:3,2048:2,4096:1] [--first-seed 0] [--variants default,double-islands] [--threads 2]
      [--timeout 900] [--out results/perf] [--fresh] [--in-process] [--table-only]
The scale check (one cold top step at 8192^2 per RMD family, ``LARGE_CELLS``):
  python benchmarks/bench_surface_population.py --fresh --sizes 8192 --families saupe,periodic
      --variants default --threads 2 --timeout 1800 --out results/perf/scale-8192
The quiet-machine commands of results/perf: results/perf/README.md, "Surface population".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time
from typing import Sequence
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from device_warmup import warm_up_device
from csv_rows import append_row, child_result, host_name, read_latest, refuse_bad_grid_sizes, refuse_missing_device

FAMILIES = ("saupe", "periodic", "fourier", "measured")
#: (Hurst exponent, rms slope) cells below 4096^2 ...
CELLS = ((0.3, 1.0), (0.5, 0.05), (0.7, 0.3), (0.9, 0.1))
#: ... and from 4096^2 up.
LARGE_CELLS = ((0.7, 0.3),)
LARGE_N = 4096
SEEDS = {512: 3, 1024: 3, 2048: 2, 4096: 1}
DEFAULT_SIZES = (512, 1024, 2048, 4096)
LENGTH = 100e-6
MISSING_FRACTION = 0.03
SOLVER = "fast-dual-pccg"
VARIANTS: dict[str, dict[str, str]] = {
    "default": {},
    "double-islands": {"precision": "double", "precondition": "islands"},
    "double": {"precision": "double"},
    "islands": {"precondition": "islands"},
    "auto": {"precision": "auto"},
    "fourier": {"precondition": "fourier"},
    "farfield": {"precondition": "farfield"},
    "mixed": {"precision": "mixed"},
}
#: A default solve may need at most this many times the median matvecs of its size ...
STALL_FACTOR = 2.0
#: ... and be at most this much slower than the double-islands variant on the same member.
SLOWER_LIMIT = 0.10
KILL_MARGIN_S = 120.0
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "CONTACTBENCH_FFT_WORKERS")


@dataclass(frozen=True)
class Member:
    """One surface of the population."""

    family: str
    N: int
    hurst: float
    rms_slope: float
    seed: int

    @property
    def key(self) -> str:
        return f"{self.family}:{self.N}:{self.hurst:g}:{self.rms_slope:g}:{self.seed}"

    @classmethod
    def parse(cls, key: str) -> Member:
        fam, N, H, s, seed = key.split(":")
        return cls(fam, int(N), float(H), float(s), int(seed))


@dataclass
class PopulationRow:
    """One cold top-step solve of one member in one variant."""

    family: str
    N: int
    hurst: float
    rms_slope: float
    seed: int
    surface: str
    n: int
    variant: str
    params: str
    status: str
    iterations: int
    matvecs: int
    matvecs_float32: int
    matvecs_float64: int
    preconditioner_builds: int
    seconds: float
    kkt: float
    load_N: float
    peak_rss_mib: float
    threads: int
    host: str
    commit: str
    timestamp: str
    repeats: int = 1
    operator: str = "fft"  # the instance's operator ("gpu": the device-resident solve)


def plan(sizes: list[int], families: list[str], seeds: dict[int, int], first_seed: int = 0) -> list[Member]:
    """The population, smallest sizes first: seeds ``first_seed``, ``first_seed + 1``, ... (a
    held-out population is the same cells on seeds the committed tables did not use)."""
    out = []
    for N in sizes:
        for H, slope in (LARGE_CELLS if N >= LARGE_N else CELLS):
            for fam in families:
                out += [Member(fam, N, H, slope, s) for s in range(first_seed, first_seed + seeds.get(N, 1))]
    return out


def surface_of(m: Member):
    """The member's surface (module doc)."""
    from contactbench.problems.io import fill_missing
    from contactbench.problems.surfaces import (
        Surface,
        fourier_synthesis,
        measured_like_heights,
        rmd_surface_n,
        with_rms_slope,
    )

    if m.family in ("saupe", "periodic"):
        return with_rms_slope(rmd_surface_n(m.N, m.hurst, m.family, length=LENGTH, seed=m.seed), m.rms_slope)
    base = fourier_synthesis(m.N, m.hurst, m.rms_slope, length=LENGTH, seed=m.seed)
    if m.family == "fourier":
        return base
    raw = measured_like_heights(base, base.rms_height / LENGTH, MISSING_FRACTION, seed=m.seed + 1000)
    name = f"measured-H{m.hurst:g}-N{m.N}-s{m.seed}"
    meta = {"family": "measured", "hurst": m.hurst, "rms_slope": m.rms_slope, "seed": m.seed, "base": base.name}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        z = fill_missing(raw, "fill-nearest", name, meta)
    return Surface(z, base.delta, name=name, periodic=False, meta=meta)


def top_step(m: Member, operator: str = "fft"):
    """The paper's instance on the member's surface at its top step (its products by
    ``operator``), and the surface's name."""
    from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
    from contactbench.problems.scenes.core import PAPER_E

    s = surface_of(m)
    return InstanceBuilder(s, PAPER_E, "bcc", periodic=False, operator=operator).build(paper_max_displacement(s)), s.name


def code_commit() -> str:
    """HEAD of the repository this script runs from, "+dirty" when it has uncommitted changes."""
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def solve_member(m: Member, variant: str, timeout: float, commit: str, repeats: int = 1,
                 operator: str = "fft") -> PopulationRow:
    """One cold solve by ``operator``, in this process, ``repeats`` times, each on a freshly built instance
    (no operator cache carries over): the row of the first, with the fastest of the repeats'
    seconds (the iterates, and so the counts, are the same each time; checked)."""
    from contactbench.harness import get_profile
    from contactbench.harness import solve_sequence
    from contactbench.problems.operators import fft_workers
    from contactbench.solvers.base import SolverSettings

    profile = get_profile("high")
    warm_up_device(SOLVER, VARIANTS[variant], operator, lambda: top_step(m, operator)[0].qp)
    inst, name = top_step(m, operator)
    params = VARIANTS[variant]
    settings = SolverSettings(tol=profile.tol, time_limit=timeout, params=dict(params))
    (step,) = solve_sequence(SOLVER, [inst], settings, warm=False, check_tol=profile.check_tol)
    res = step.result
    seconds = step.seconds
    for _ in range(repeats - 1):  # a fresh instance each time: no operator cache carries over
        (again,) = solve_sequence(SOLVER, [top_step(m, operator)[0]], settings, warm=False, check_tol=profile.check_tol)
        if res is not None and (again.result is None or again.result.matvecs != res.matvecs):
            raise RuntimeError(f"{name} {variant}: a repeat took another path ({again.result and again.result.matvecs} "
                               f"matvecs against {res.matvecs})")
        seconds = min(seconds, again.seconds)
    info = res.info if res is not None else {}
    return PopulationRow(
        family=m.family, N=m.N, hurst=m.hurst, rms_slope=m.rms_slope, seed=m.seed, surface=name, n=inst.n,
        variant=variant, params=json.dumps(params, sort_keys=True),
        status=step.verdict.status if step.verdict is not None else "failed",
        iterations=int(res.iterations) if res is not None else 0, matvecs=int(res.matvecs) if res is not None else 0,
        matvecs_float32=int(info.get("matvecs_float32", 0)), matvecs_float64=int(info.get("matvecs_float64", 0)),
        preconditioner_builds=int(info.get("preconditioner_builds", 0)), seconds=round(seconds, 3),
        kkt=float(f"{step.kkt_error:.3e}"), load_N=float(f"{inst.load(res.p):.10e}") if res is not None else math.nan,
        peak_rss_mib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1), threads=fft_workers(),
        host=host_name(), commit=commit, timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"), repeats=repeats,
        operator=operator)


def failed_row(m: Member, variant: str, status: str, commit: str, threads: int, operator: str = "fft") -> PopulationRow:
    return PopulationRow(m.family, m.N, m.hurst, m.rms_slope, m.seed, "", 0, variant,
                         json.dumps(VARIANTS[variant], sort_keys=True), status, 0, 0, 0, 0, 0, math.nan, math.nan,
                         math.nan, math.nan, threads, host_name(), commit, time.strftime("%Y-%m-%dT%H:%M:%S"),
                         operator=operator)


def run_child(m: Member, variant: str, args: argparse.Namespace, commit: str) -> PopulationRow:
    """The row of one solve in a child process; a "timeout"/"failed" row when it gives none."""
    cmd = [sys.executable, __file__, "--child", f"{m.key}@{variant}", "--timeout", str(args.timeout),
           "--commit", commit, "--repeats", str(repeats_of(m, args.repeats)),
           "--operator", args.operator]
    env = dict(os.environ)
    if args.threads:
        env.update({v: str(args.threads) for v in THREAD_VARS})
    result, status, detail = child_result(cmd, env, args.timeout + KILL_MARGIN_S)
    if result is not None:
        return PopulationRow(**result)
    print(f"  {m.key} {variant}: {status}: {detail}", file=sys.stderr, flush=True)
    return failed_row(m, variant, status, commit, int(args.threads or 0), args.operator)


def repeats_of(m: Member, spec: dict[int, int]) -> int:
    """How many times member ``m`` is solved (``--repeats``: per size, default 1)."""
    return spec.get(m.N, 1)


def read_rows(path: Path) -> list[PopulationRow]:
    """The CSV's rows, the latest of each (member, variant)."""
    return read_latest(path, PopulationRow, key=lambda r: (r.family, r.N, r.hurst, r.rms_slope, r.seed, r.variant, r.operator),
                       order=lambda r: (r.N, r.family, r.hurst, r.seed, r.variant))


@dataclass(frozen=True)
class Flag:
    """A default solve that breaks one of the two checks (module doc)."""

    row: PopulationRow
    why: str


def member_of(r: PopulationRow) -> tuple:
    return (r.family, r.N, r.hurst, r.rms_slope, r.seed)


def double_islands_below() -> int:
    """The grid points below which the default's ``auto`` choices are the double-islands
    configuration itself: the far field from ``FAR_FIELD_GRID_POINTS``, float32 from
    ``MIXED_GRID_POINTS``."""
    from contactbench.solvers._preconditioners import FAR_FIELD_GRID_POINTS, MIXED_GRID_POINTS

    return min(FAR_FIELD_GRID_POINTS, MIXED_GRID_POINTS)


def same_configuration(r: PopulationRow) -> bool:
    """Whether the default ran the double-islands configuration itself on ``r``'s grid."""
    return r.N * r.N < double_islands_below()


def checks(rows: list[PopulationRow], metric: str = "matvecs") -> list[Flag]:
    """Default solves above STALL_FACTOR x the median matvecs of their size (over every
    family; seconds also grow with the member's n), or above (1 + SLOWER_LIMIT) x the double-islands variant on their member where
    the two configurations differ (where they are the same, ``noise_lines`` reports the
    ratio: the machine's spread on identical work)."""
    flags = []
    default = [r for r in rows if r.variant == "default" and r.status == "solved"]
    ref = {member_of(r): r for r in rows if r.variant == "double-islands" and r.status == "solved"}
    for r in rows:
        if r.variant == "default" and r.status != "solved":
            flags.append(Flag(r, f"status {r.status}"))
    for N in sorted({r.N for r in default}) if metric == "matvecs" else ():  # a stall is counted in matvecs
        med = float(np.median([getattr(r, metric) for r in default if r.N == N]))
        flags += [Flag(r, f"{metric} {getattr(r, metric):g} > {STALL_FACTOR:g} x median {med:g}")
                  for r in default if r.N == N and getattr(r, metric) > STALL_FACTOR * med]
    for r in default:
        b = ref.get(member_of(r))
        if b is not None and not same_configuration(r) and getattr(r, metric) > (1.0 + SLOWER_LIMIT) * getattr(b, metric):
            flags.append(Flag(r, f"{metric} {getattr(r, metric):g} > {1 + SLOWER_LIMIT:g} x double-islands "
                                 f"{getattr(b, metric):g}"))
    return flags


def noise_lines(rows: list[PopulationRow]) -> list[str]:
    """Per size where the default is the double-islands configuration: the matvecs (the same
    iterates must give the same counts) and the range of the seconds ratio."""
    ref = {member_of(r): r for r in rows if r.variant == "double-islands" and r.status == "solved"}
    out = []
    for N in sorted({r.N for r in rows}):
        pairs = [(r, ref[member_of(r)]) for r in rows if r.N == N and r.variant == "default" and r.status == "solved"
                 and same_configuration(r) and member_of(r) in ref]
        if not pairs:
            continue
        same_mv = sum(a.matvecs == b.matvecs for a, b in pairs)
        ratios = [a.seconds / b.seconds for a, b in pairs if b.seconds > 0]
        out.append(f"- N = {N}: the default is `precision=double, precondition=islands` here (`auto` below "
                   f"{int(np.sqrt(double_islands_below()))}^2 grid points); {same_mv} of {len(pairs)} members with the same matvecs; seconds ratio "
                   f"{min(ratios):.2f}-{max(ratios):.2f} (median {np.median(ratios):.2f}): the machine's spread on "
                   f"identical work")
    return out


def summary_lines(rows: list[PopulationRow], metric: str) -> list[str]:
    """Median / worst ``metric`` per size and family, for each variant present."""
    variants = [v for v in VARIANTS if any(r.variant == v for r in rows)]
    head = "| N | family | members | " + " | ".join(f"{v} median | {v} worst" for v in variants) + " |"
    lines = [head, "|" + "---|" * (3 + 2 * len(variants))]
    for N in sorted({r.N for r in rows}):
        for fam in [f for f in FAMILIES if any(r.family == f and r.N == N for r in rows)] + ["all"]:
            sel = [r for r in rows if r.N == N and (fam == "all" or r.family == fam) and r.status == "solved"]
            cells = []
            for v in variants:
                vals = [getattr(r, metric) for r in sel if r.variant == v]
                cells += [f"{np.median(vals):.4g}", f"{max(vals):.4g}"] if vals else ["-", "-"]
            members = len({member_of(r) for r in sel})
            lines.append(f"| {N} | {fam} | {members} | " + " | ".join(cells) + " |")
    return lines


def write_markdown(rows: list[PopulationRow], path: Path) -> None:
    hosts = sorted({r.host for r in rows})
    commits = sorted({r.commit for r in rows})
    times = sorted(r.timestamp for r in rows)
    lines = [
        "# fast-dual-pccg over a surface population: one cold top step per member",
        "",
        "Written by `benchmarks/bench_surface_population.py` from `surface-population.csv` (latest row per",
        "member and variant; the module doc defines the population and the two checks).",
        f"Host(s): {', '.join(hosts)}; commit(s): {', '.join(commits)}; rows from {times[0]} to {times[-1]}.",
        "",
        "## Matvecs",
        "",
        *summary_lines(rows, "matvecs"),
        "",
        "## Seconds",
        "",
        *summary_lines(rows, "seconds"),
        "",
        "## Peak RSS (MiB)",
        "",
        *summary_lines(rows, "peak_rss_mib"),
        "",
        f"## Checks: default matvecs <= {STALL_FACTOR:g} x the median of its size; matvecs and seconds "
        f"<= {1 + SLOWER_LIMIT:g} x double-islands",
        "",
    ]
    for metric in ("matvecs", "seconds"):
        flags = checks(rows, metric)
        lines.append(f"- {metric}: " + ("none broken" if not flags else f"{len(flags)} broken"))
        lines += [f"  - {f.row.surface or f.row.family} (N = {f.row.N}): {f.why}" for f in flags]
    noise = noise_lines(rows)
    if noise:  # only with both variants on a member
        lines += ["", "Where the two configurations are the same:", "", *noise]
    path.write_text("\n".join(lines) + "\n")


def parse_sizes_map(text: str, base: dict[int, int]) -> dict[int, int]:
    """``"512:3,2048:1"`` over ``base``."""
    out = dict(base)
    for item in filter(None, text.split(",")):
        N, k = item.split(":")
        out[int(N)] = int(k)
    return out


def parse_seeds(text: str) -> dict[int, int]:
    return parse_sizes_map(text, SEEDS)


def check_choices(ap: argparse.ArgumentParser, what: str, text: str, allowed: Sequence[str]) -> None:
    """A one-line error naming the first of the comma-separated ``text`` not in ``allowed``."""
    bad = [x for x in text.split(",") if x not in allowed]
    if bad:
        ap.error(f"unknown {what} {bad[0]!r}: choose from {', '.join(allowed)}")


def check_population_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """The checks every population benchmark shares: --families, --sizes, --seeds."""
    check_choices(ap, "family", args.families, FAMILIES)
    refuse_bad_grid_sizes(ap, "--sizes", args.sizes)
    try:
        seeds = parse_seeds(args.seeds)
    except ValueError:
        ap.error(f"--seeds must look like 512:3,1024:2, got {args.seeds!r}")
    if any(k < 1 for k in seeds.values()):
        ap.error("--seeds: at least one seed per size")


def check_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """One-line errors for bad input, before anything runs."""
    check_population_args(ap, args)
    check_choices(ap, "variant", args.variants, VARIANTS)
    try:
        repeats = parse_sizes_map(args.repeats, {})
    except ValueError:
        ap.error(f"--repeats must look like 512:3,1024:2, got {args.repeats!r}")
    if any(k < 1 for k in repeats.values()):
        ap.error("--repeats: at least one solve per member")
    if args.first_seed < 0:
        ap.error(f"--first-seed must be >= 0, got {args.first_seed}")
    if not (args.timeout > 0):
        ap.error(f"--timeout must be > 0 s, got {args.timeout}")
    refuse_missing_device(ap, args.operator)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(DEFAULT_SIZES))
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--seeds", default="", help="seeds per size, e.g. 512:3,2048:1 (default: " +
                    ",".join(f"{k}:{v}" for k, v in SEEDS.items()) + ")")
    ap.add_argument("--first-seed", type=int, default=0, help="the first seed of every member "
                    "(default 0; a held-out population starts past the seeds of the committed tables)")
    ap.add_argument("--variants", default="default,double-islands")
    ap.add_argument("--repeats", default="", help="solves per member by size, the fastest recorded, "
                    "e.g. 512:3,1024:2 (default: 1)")
    ap.add_argument("--timeout", type=float, default=900.0, help="time limit of one solve (s)")
    ap.add_argument("--threads", type=int, default=None, help="BLAS/OpenMP/FFT threads (default: all cores)")
    ap.add_argument("--out", default="results/perf")
    ap.add_argument("--fresh", action="store_true", help="start a new CSV (the old one is renamed to .csv.old)")
    ap.add_argument("--in-process", action="store_true", help="solve in this process (no per-solve peak RSS)")
    ap.add_argument("--table-only", action="store_true", help="rebuild the table from the CSV")
    ap.add_argument("--operator", default="fft", choices=("fft", "gpu"),
                    help="the instances' operator (gpu: CuPy on a CUDA device, the solve resident there)")
    ap.add_argument("--commit", default=None, help="the commit the rows record (default: HEAD of this checkout)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        from contactbench.harness.run.isolation import set_parent_death_signal

        set_parent_death_signal()  # a killed run takes its solve with it
        key, variant = args.child.split("@")
        row = solve_member(Member.parse(key), variant, args.timeout, args.commit or code_commit(),
                           int(args.repeats or 1), args.operator)
        print("RESULT " + json.dumps(asdict(row)), flush=True)
        return
    check_args(ap, args)
    args.repeats = parse_sizes_map(args.repeats, {})
    out = Path(args.out)
    csv_path = out / "surface-population.csv"
    if args.fresh and csv_path.exists():
        csv_path.replace(out / "surface-population.csv.old")
    if not args.table_only:
        commit = args.commit or code_commit()
        if args.in_process and args.threads:
            os.environ.update({v: str(args.threads) for v in THREAD_VARS})
        for m in plan(args.sizes, args.families.split(","), parse_seeds(args.seeds), args.first_seed):
            for variant in args.variants.split(","):
                row = (solve_member(m, variant, args.timeout, commit, repeats_of(m, args.repeats), args.operator)
                       if args.in_process
                       else run_child(m, variant, args, commit))
                append_row(csv_path, row)
                print(f"{m.key} {variant}: {row.status} n={row.n} it={row.iterations} mv={row.matvecs} "
                      f"{row.seconds:.2f} s kkt={row.kkt:.1e} rss={row.peak_rss_mib:.0f} MiB", flush=True)
    if not csv_path.exists():
        sys.exit(f"bench_surface_population: error: no table at {csv_path}")
    write_markdown(read_rows(csv_path), out / "surface-population.md")
    print(f"wrote {out / 'surface-population.md'}")


if __name__ == "__main__":
    main()
