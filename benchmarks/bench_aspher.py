"""ASPHER against our fast solver and the field's codes, side by side in one run on the
same problems: seconds, iterations, matvecs, kkt by our judge and peak memory, one cold
solve per (problem, entry), the same thread count for all.

Problems (``problems_of``): the surfaces of benchmarks/bench_surface_population.py -- the
paper's (``saupe``) and the held-out families (``periodic``, ``fourier``, ``measured``),
its Hurst / rms-slope cells and seeds -- under *load control* at
P / (E* A) = ``LOAD_PER_SLOPE`` x the member's rms slope (a partial contact), in two
boundaries:

* ``nonperiodic`` -- the Love kernel on the finite patch, every family;
* ``periodic``    -- the periodic half-space, 2/(E*|q|) (our ``spectral`` kernel: ASPHER's,
  Tamaas' and ContactMechanics' periodic operator; none of them has a periodic real-space
  Love kernel), on the periodic families (``periodic``, ``fourier``).

Entries (``ENTRIES``), each a registered solver with fixed parameters, judged by
harness/judging.py at profile "high" (tol 1e-9, check 1e-8):

* ASPHER: ``aspher-pcg``, ``aspher-nested``, ``aspher-nested-f32``, ``aspher-active-f32``
  (solvers/peer_aspher.py);
* ours: ``fast-dual-pccg`` (its defaults: under load control the |q| preconditioner,
  solvers/_preconditioners.LOAD_FOURIER), ``fast-dual-pccg[precondition=fourier]``
  (Vollebregt's |q| preconditioner: the idea ASPHER's preconditioner is built on, named),
  ``fast-dual-pccg[precondition=islands]`` (the island blocks instead),
  ``fast-dual-pccg[precision=mixed]`` (float32 rounds at every size) and
  ``fast-dual-pccg[whole-double]`` (no screening, float64: every point carried in double,
  what screening and the float32 rounds save);
* the field: ``cm-pk-ccg``, ``tamaas-pkr`` (both pose load control), ``cm-dual-ccg``;
* the *displacement twin* (``posing = "twin"``): the displacement-controlled problem at the
  approach Delta of ``fast-dual-pccg``'s load-controlled answer -- the same solution, posed
  as ContactMechanics' dual CCG takes it (it needs an approach, not a load), and our solver
  from zero and from the coarse grids at that approach:
  ``fast-dual-pccg[first_guess=zero]``, ``fast-dual-pccg[first_guess=coarse]``,
  ``cm-dual-ccg``.  A twin row says so in its ``posing`` column.

An entry that cannot pose a problem gets a ``skipped`` row with its own reason
(``Solver.skip``); one whose package is missing an ``unavailable`` row with the hint.

Each solve runs in its own process (``child_result``) with ``SolverSettings(time_limit=
--timeout)``; rows are appended to ``OUT/aspher.csv`` as they finish (host, date, commit,
threads, and ``smoke`` = 1 for a run below ``TIMED_MIN_N``: those rows check the script, they
are not timings).  ``OUT/aspher.md`` is rebuilt from the CSV (latest row per problem and entry).

Usage:
  python benchmarks/bench_aspher.py [--sizes 512 1024 2048 4096] [--families saupe,...]
      [--boundaries nonperiodic,periodic] [--seeds 512:3,...] [--cells 0.7:0.3,...] [--entries aspher-pcg,...]
      [--threads 2] [--timeout 900] [--out results/peers] [--fresh] [--table-only]
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
from bench_surface_population import (FAMILIES, THREAD_VARS, Member, check_choices, check_population_args, code_commit,
                                      parse_seeds, plan, surface_of)
from csv_rows import append_row, cell, child_result, read_latest, host_name

#: The load, P / (E* A), per unit of the member's rms slope.
LOAD_PER_SLOPE = 0.05
#: boundary -> (kernel, periodic, the families posed in it).
BOUNDARIES: dict[str, tuple[str, bool, tuple[str, ...]]] = {
    "nonperiodic": ("love", False, FAMILIES),
    "periodic": ("spectral", True, ("periodic", "fourier")),
}
#: Rows of a run below this size check the script; they are not timings.
TIMED_MIN_N = 512
DEFAULT_SIZES = (512, 1024, 2048, 4096)
KILL_MARGIN_S = 120.0
PROFILE = "high"


@dataclass(frozen=True)
class Entry:
    """One column of the comparison: a registered solver with fixed parameters, posed
    under load control or as the displacement twin (module doc)."""

    label: str
    solver: str
    params: tuple[tuple[str, str], ...] = ()
    posing: str = "load"  # "load" or "twin"


ENTRIES: tuple[Entry, ...] = (
    Entry("aspher-pcg", "aspher-pcg"),
    Entry("aspher-nested", "aspher-nested"),
    Entry("aspher-nested-f32", "aspher-nested-f32"),
    Entry("aspher-active-f32", "aspher-active-f32"),
    Entry("fast-dual-pccg", "fast-dual-pccg"),
    Entry("fast-dual-pccg[fourier]", "fast-dual-pccg", (("precondition", "fourier"),)),
    Entry("fast-dual-pccg[islands]", "fast-dual-pccg", (("precondition", "islands"),)),
    Entry("fast-dual-pccg[mixed]", "fast-dual-pccg", (("precision", "mixed"),)),
    # every point carried in float64: what screening and the float32 rounds save
    Entry("fast-dual-pccg[whole-double]", "fast-dual-pccg", (("precision", "double"), ("screening", "none"))),
    Entry("cm-pk-ccg", "cm-pk-ccg"),
    Entry("tamaas-pkr", "tamaas-pkr"),
    Entry("cm-dual-ccg", "cm-dual-ccg"),
    Entry("twin:fast-dual-pccg", "fast-dual-pccg", (("first_guess", "zero"),), "twin"),
    Entry("twin:fast-dual-pccg[coarse]", "fast-dual-pccg", (("first_guess", "coarse"),), "twin"),
    Entry("twin:cm-dual-ccg", "cm-dual-ccg", posing="twin"),
)
BY_LABEL = {e.label: e for e in ENTRIES}
#: The load-controlled answer whose approach poses the twins.
TWIN_SOURCE = "fast-dual-pccg"


@dataclass(frozen=True)
class Problem:
    """One surface of the population in one boundary, under load control."""

    member: Member
    boundary: str

    @property
    def key(self) -> str:
        return f"{self.boundary}@{self.member.key}"

    @classmethod
    def parse(cls, key: str) -> Problem:
        boundary, member = key.split("@")
        return cls(Member.parse(member), boundary)


@dataclass
class AspherRow:
    """One cold solve of one problem by one entry."""

    boundary: str
    kernel: str
    family: str
    N: int
    hurst: float
    rms_slope: float
    seed: int
    surface: str
    n: int
    load_over_EA: float
    entry: str
    solver: str
    params: str
    posing: str
    status: str  # the judge's status, or skipped / unavailable / failed / timeout
    reading: str  # the judge's reading (pass / wrong / unconverged), "" where not judged
    claimed: int
    iterations: int
    matvecs: int
    seconds: float
    kkt: float
    load_N: float
    delta_m: float  # the approach: the load-control multiplier, or the twin's Delta
    peak_rss_mib: float
    peer_claim: str  # the code's own certified figures (ASPHER: fw_error, penetration_error, status)
    note: str  # the skip / failure reason, or the solver's message
    threads: int
    smoke: int
    host: str
    commit: str
    timestamp: str


def problems_of(sizes: list[int], families: list[str], boundaries: list[str], seeds: dict[int, int],
                cells: list[tuple[float, float]] | None = None) -> list[Problem]:
    """The problems, smallest sizes first (module doc); ``cells`` restricts the (Hurst, rms
    slope) cells (None: bench_surface_population's)."""
    out = []
    for m in plan(sizes, families, seeds):
        if cells is None or (m.hurst, m.rms_slope) in cells:
            out += [Problem(m, b) for b in boundaries if m.family in BOUNDARIES[b][2]]
    return out


def parse_cells(text: str) -> list[tuple[float, float]] | None:
    """``"0.7:0.3,0.3:1"`` as (Hurst, rms slope) pairs; "" -> None (every cell)."""
    if not text:
        return None
    return [(float(h), float(s)) for h, s in (c.split(":") for c in text.split(","))]


def builder_of(pr: Problem):
    from contactbench.problems.instances import InstanceBuilder
    from contactbench.problems.scenes.core import PAPER_E

    kernel, periodic, _ = BOUNDARIES[pr.boundary]
    s = surface_of(pr.member)
    return InstanceBuilder(s, PAPER_E, kernel, periodic=periodic), s.name


def load_over_EA(pr: Problem) -> float:
    return LOAD_PER_SLOPE * pr.member.rms_slope


def instance_of(pr: Problem, entry: Entry, delta: float | None):
    """The load-controlled instance, or its displacement twin at ``delta``."""
    b, name = builder_of(pr)
    if entry.posing == "twin":
        return b.build(float(delta)), name
    return b.build_load(b.load_force(load_over_EA(pr))), name


def peer_claim(info: dict) -> str:
    keys = ("peer_status", "fw_error", "penetration_error", "load_error", "peer_error", "stages", "backend",
            "precision", "active_set")
    return json.dumps({k: info[k] for k in keys if k in info}, sort_keys=True, default=str)


def row_of(pr: Problem, entry: Entry, name: str, n: int, status: str, note: str, commit: str, **kw) -> AspherRow:
    from contactbench.problems.operators import fft_workers

    kernel = BOUNDARIES[pr.boundary][0]
    m = pr.member
    base = dict(reading="", claimed=0, iterations=0, matvecs=0, seconds=math.nan, kkt=math.nan, load_N=math.nan,
                delta_m=math.nan, peak_rss_mib=round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
                peer_claim="")
    base.update(kw)
    return AspherRow(pr.boundary, kernel, m.family, m.N, m.hurst, m.rms_slope, m.seed, name, n, load_over_EA(pr),
                     entry.label, entry.solver, json.dumps(dict(entry.params), sort_keys=True), entry.posing, status,
                     note=note[:300], threads=fft_workers(), smoke=int(m.N < TIMED_MIN_N), host=host_name(),
                     commit=commit, timestamp=time.strftime("%Y-%m-%dT%H:%M:%S"), **base)


def solve_entry(pr: Problem, entry: Entry, delta: float | None, timeout: float, commit: str) -> AspherRow:
    """One cold solve in this process (module doc); a skip or an unavailable package is a row."""
    from contactbench.harness import get_profile, solve_sequence
    from contactbench.harness.run.worker import problem_traits
    from contactbench.solvers import get_solver
    from contactbench.solvers.base import SolverSettings

    solver = get_solver(entry.solver)
    ok, why = solver.availability()
    if entry.posing == "twin" and (delta is None or not math.isfinite(delta)):
        return row_of(pr, entry, "", 0, "skipped", f"no approach: {TWIN_SOURCE} gave no load-controlled answer",
                      commit)
    inst, name = instance_of(pr, entry, delta)
    if not ok:
        return row_of(pr, entry, name, inst.n, "unavailable", why, commit)
    skip = solver.skip(problem_traits(inst))
    if skip:
        return row_of(pr, entry, name, inst.n, "skipped", skip, commit)
    profile = get_profile(PROFILE)
    settings = SolverSettings(tol=profile.tol, time_limit=timeout, params=dict(entry.params))
    (step,) = solve_sequence(solver, [inst], settings, warm=False, check_tol=profile.check_tol)
    res, v = step.result, step.verdict
    if res is None or v is None:
        return row_of(pr, entry, name, inst.n, "failed", step.error or "no result", commit, seconds=step.seconds)
    approach = res.multiplier if entry.posing == "load" else float(delta)  # type: ignore[arg-type]
    return row_of(pr, entry, name, inst.n, v.status, res.message or "", commit, reading=v.reading,
                  claimed=int(res.converged), iterations=int(res.iterations), matvecs=int(res.matvecs),
                  seconds=round(step.seconds, 3), kkt=float(f"{step.kkt_error:.3e}"),
                  load_N=float(f"{inst.load(res.p):.10e}"), delta_m=math.nan if approach is None else float(approach),
                  peer_claim=peer_claim(res.info))


def run_child(pr: Problem, entry: Entry, delta: float | None, args: argparse.Namespace, commit: str) -> AspherRow:
    """The row of one solve in a child process; a "timeout"/"failed" row when it gives none."""
    cmd = [sys.executable, __file__, "--child", f"{pr.key}#{entry.label}", "--timeout", str(args.timeout),
           "--commit", commit, "--load-per-slope", repr(args.load_per_slope)] + \
        (["--delta", repr(delta)] if delta is not None else [])
    env = dict(os.environ)
    if args.threads:
        env.update({v: str(args.threads) for v in THREAD_VARS})
    result, status, detail = child_result(cmd, env, args.timeout + KILL_MARGIN_S)
    if result is not None:
        return AspherRow(**result)
    print(f"  {pr.key} {entry.label}: {status}: {detail}", file=sys.stderr, flush=True)
    row = row_of(pr, entry, "", 0, status, detail, commit)
    row.threads, row.peak_rss_mib = int(args.threads or 0), math.nan
    return row


def read_rows(path: Path) -> list[AspherRow]:
    """The CSV's rows, the latest of each (problem, entry)."""
    return read_latest(path, AspherRow,
                       key=lambda r: (r.boundary, r.family, r.N, r.hurst, r.rms_slope, r.seed, r.entry),
                       order=lambda r: (r.boundary, r.N, r.family, r.hurst, r.seed, list(BY_LABEL).index(r.entry)
                                        if r.entry in BY_LABEL else 99))


# ---------------------------------------------------------------------------
# The report
# ---------------------------------------------------------------------------


def _cell(r: AspherRow | None) -> str:
    """seconds / matvecs (iterations) / kkt of one row, or its status."""
    if r is None:
        return "-"
    if r.status in ("skipped", "unavailable", "failed", "timeout"):
        return r.status
    flag = "" if r.reading == "pass" else f" **{r.reading or r.status}**"
    return f"{r.seconds:.3g} s, {r.matvecs} mv ({r.iterations} it), kkt {r.kkt:.1e}{flag}"


def problem_of(r: AspherRow) -> tuple:
    return (r.boundary, r.N, r.family, r.hurst, r.rms_slope, r.seed)


def side_by_side(rows: list[AspherRow], entries: list[str]) -> list[str]:
    """One line per problem: every entry's seconds, matvecs (iterations) and kkt."""
    by = {(problem_of(r), r.entry): r for r in rows}
    lines = ["| boundary | N | family | H | slope | seed | " + " | ".join(entries) + " |",
             "|" + "---|" * (6 + len(entries))]
    for key in sorted({problem_of(r) for r in rows}):
        b, N, fam, H, s, seed = key
        cells = [_cell(by.get((key, e))) for e in entries]
        lines.append(f"| {b} | {N} | {fam} | {H:g} | {s:g} | {seed} | " + " | ".join(cells) + " |")
    return lines


def median_of(rows: list[AspherRow], field: str) -> float:
    return float(np.median([getattr(r, field) for r in rows])) if rows else math.nan


def medians(rows: list[AspherRow], entries: list[str]) -> list[str]:
    """Per boundary and size: each entry's median seconds, matvecs and peak RSS over the
    problems it passed, and how many it passed of those it ran."""
    lines = ["| boundary | N | entry | passed / ran | median s | median matvecs | median iterations | "
             "worst kkt | median peak RSS MiB |", "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for b, N in sorted({(r.boundary, r.N) for r in rows}):
        for e in entries:
            ran = [r for r in rows if r.boundary == b and r.N == N and r.entry == e
                   and r.status not in ("skipped", "unavailable")]
            if not ran:
                continue
            ok = [r for r in ran if r.reading == "pass"]
            worst = max((r.kkt for r in ran if math.isfinite(r.kkt)), default=math.nan)
            lines.append(f"| {b} | {N} | {e} | {len(ok)}/{len(ran)} | {cell(median_of(ok, 'seconds'), '.3g')} | "
                         f"{cell(median_of(ok, 'matvecs'), '.0f')} | {cell(median_of(ok, 'iterations'), '.0f')} | "
                         f"{cell(worst, '.1e')} | {cell(median_of(ok, 'peak_rss_mib'), '.0f')} |")
    return lines


#: ASPHER's load-controlled entries: its fastest per problem is the race's reference.
ASPHER_ENTRIES = ("aspher-pcg", "aspher-nested", "aspher-nested-f32", "aspher-active-f32")
#: Our entry in the race: the fast solver with its defaults.
OURS = "fast-dual-pccg"


def race(rows: list[AspherRow]) -> list[str]:
    """Per boundary and size, over the problems where ``OURS`` and an ASPHER entry passed:
    our seconds over ASPHER's nested solve's and over its fastest passing entry's, median
    and worst (the largest ratio), and the problems behind them; a line saying so where
    no problem has both."""
    lines = ["| boundary | N | problems | ours / ASPHER nested: median | worst | ours / ASPHER's fastest: median | "
             "worst |", "|---|---:|---:|---:|---:|---:|---:|"]
    by = {(problem_of(r), r.entry): r for r in rows if r.reading == "pass"}
    for b, N in sorted({(r.boundary, r.N) for r in rows}):
        keys = sorted({problem_of(r) for r in rows if r.boundary == b and r.N == N})
        fastest, nested = [], []
        for k in keys:
            theirs = [by[(k, e)].seconds for e in ASPHER_ENTRIES if (k, e) in by]
            if (k, OURS) not in by or not theirs:
                continue
            ours = by[(k, OURS)].seconds
            fastest.append(ours / min(theirs))
            if (k, "aspher-nested") in by:
                nested.append(ours / by[(k, "aspher-nested")].seconds)
        if fastest:
            lines.append(f"| {b} | {N} | {len(fastest)} | {median_and_worst(nested)} | {median_and_worst(fastest)} |")
    return lines if len(lines) > 2 else [f"No problem has both {OURS} and an ASPHER entry passing."]


def median_and_worst(ratios: list[float]) -> str:
    """Two table cells: the median and the largest of ``ratios`` ("-" when there are none)."""
    return f"{np.median(ratios):.2f} | {max(ratios):.2f}" if ratios else "- | -"


#: The two published ideas, each as (ASPHER's entry, our entry with the idea, our entry without).
IDEAS = (("\\|q\\| preconditioner", "aspher-pcg", "fast-dual-pccg[fourier]", "fast-dual-pccg[islands]"),
         ("coarse-grid start", "aspher-nested", "twin:fast-dual-pccg[coarse]", "twin:fast-dual-pccg"))


def ideas(rows: list[AspherRow]) -> list[str]:
    """Per boundary and size: median matvecs over the problems all three entries of an idea
    passed (ASPHER's count includes its coarse levels' products; ours the coarse solves')."""
    lines = ["| idea | boundary | N | problems | ASPHER | ours with it | ours without |", "|---|---|---:|---:|---|---|---|"]
    by = {(problem_of(r), r.entry): r for r in rows if r.reading == "pass"}
    for idea, theirs, with_, without in IDEAS:
        for b, N in sorted({(r.boundary, r.N) for r in rows}):
            keys = [k for k in {problem_of(r) for r in rows if r.boundary == b and r.N == N}
                    if all((k, e) in by for e in (theirs, with_, without))]
            if not keys:
                continue
            cells = [f"`{e}` {float(np.median([by[(k, e)].matvecs for k in keys])):.0f} mv" for e in (theirs, with_, without)]
            lines.append(f"| {idea} | {b} | {N} | {len(keys)} | " + " | ".join(cells) + " |")
    return lines


def left_out(rows: list[AspherRow]) -> list[str]:
    """Each entry's skipped / unavailable reasons, once each."""
    seen: dict[tuple[str, str, str], int] = {}
    for r in rows:
        if r.status in ("skipped", "unavailable"):
            k = (r.entry, r.status, r.note)
            seen[k] = seen.get(k, 0) + 1
    return [f"- `{e}` {st} on {k} problem(s): {note}" for (e, st, note), k in sorted(seen.items())]


def write_markdown(rows: list[AspherRow], path: Path) -> None:
    entries = [e.label for e in ENTRIES if any(r.entry == e.label for r in rows)]
    hosts = sorted({r.host for r in rows})
    commits = sorted({r.commit for r in rows})
    threads = sorted({r.threads for r in rows})
    times = sorted(r.timestamp for r in rows)
    smoke = any(r.smoke for r in rows)
    lines = [
        "# ASPHER beside our fast solver, ContactMechanics and Tamaas: one cold load-controlled solve per problem",
        "",
        "Written by `benchmarks/bench_aspher.py` from `aspher.csv` (latest row per problem and entry; its module",
        "doc defines the problems, the entries and the displacement twins).  Judged by our judge at profile",
        f"`{PROFILE}` on our operator; `mv` = matvecs as each code counts them (ASPHER: every level of a nested solve).",
        f"Host(s): {', '.join(hosts)}; commit(s): {', '.join(commits)}; threads for every entry: "
        f"{', '.join(map(str, threads))}; rows from {times[0]} to {times[-1]}.",
        "",
    ]
    if smoke:
        lines += [f"**Smoke run**: rows below {TIMED_MIN_N}^2 (`smoke` = 1) check the script on a shared, loaded "
                  "machine; their seconds are not timings and nothing here is a finding about speed.", ""]
    lines += ["## The race: our default against ASPHER, problem by problem", "", *race(rows), "",
              "## Per entry", "", *medians(rows, entries), "",
              "## The published ideas: median matvecs where all three passed", "", *ideas(rows), "",
              "## Side by side", "",
              *side_by_side(rows, entries), "", "## Left out, with the reason", "", *(left_out(rows) or ["- none"])]
    path.write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------------------
# The run
# ---------------------------------------------------------------------------


def check_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """One-line errors for bad input, before anything runs."""
    check_population_args(ap, args)
    check_choices(ap, "boundary", args.boundaries, list(BOUNDARIES))
    check_choices(ap, "entry", args.entries, list(BY_LABEL))
    try:
        parse_cells(args.cells)
    except ValueError:
        ap.error(f"--cells must look like 0.7:0.3,0.3:1 (Hurst:rms slope), got {args.cells!r}")
    if not (args.timeout > 0):
        ap.error(f"--timeout must be > 0 s, got {args.timeout}")
    if args.threads is not None and args.threads < 1:
        ap.error(f"--threads must be >= 1, got {args.threads}")


def twin_delta(rows: list[AspherRow], pr: Problem) -> float | None:
    """The approach of ``TWIN_SOURCE``'s passed load-controlled answer on ``pr`` (None: none)."""
    m = pr.member
    for r in rows:
        if (r.entry == TWIN_SOURCE and r.boundary == pr.boundary and problem_of(r)[1:] ==
                (m.N, m.family, m.hurst, m.rms_slope, m.seed) and r.reading == "pass"):
            return r.delta_m
    return None


def run(args: argparse.Namespace) -> None:
    out = Path(args.out)
    csv_path = out / "aspher.csv"
    if args.fresh and csv_path.exists():
        csv_path.unlink()
    commit = code_commit()
    entries = [BY_LABEL[e] for e in args.entries.split(",")]
    entries.sort(key=lambda e: e.posing == "twin")  # the twins need the load answers' approach
    problems = problems_of(args.sizes, args.families.split(","), args.boundaries.split(","), parse_seeds(args.seeds),
                           parse_cells(args.cells))
    print(f"{len(problems)} problems x {len(entries)} entries, threads {args.threads or 'all cores'}", flush=True)
    for pr in problems:
        done: list[AspherRow] = []
        for e in entries:
            delta = twin_delta(done, pr) if e.posing == "twin" else None
            row = run_child(pr, e, delta, args, commit)
            append_row(csv_path, row)
            done.append(row)
            print(f"  {pr.key} {e.label}: {row.status} {row.reading} {row.seconds} s, {row.matvecs} mv, "
                  f"kkt {row.kkt:.1e}", flush=True)
    write_markdown(read_rows(csv_path), out / "aspher.md")


def child(args: argparse.Namespace) -> None:
    key, label = args.child.split("#")
    row = solve_entry(Problem.parse(key), BY_LABEL[label], args.delta, args.timeout, args.commit)
    print("RESULT " + json.dumps(asdict(row)), flush=True)


def main() -> None:
    global LOAD_PER_SLOPE
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(DEFAULT_SIZES))
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--boundaries", default=",".join(BOUNDARIES))
    ap.add_argument("--seeds", default="", help="seeds per size, e.g. 512:3,2048:1 (default: "
                    "bench_surface_population's)")
    ap.add_argument("--cells", default="", help="Hurst:rms-slope cells, e.g. 0.7:0.3 (default: "
                    "bench_surface_population's)")
    ap.add_argument("--entries", default=",".join(BY_LABEL))
    ap.add_argument("--timeout", type=float, default=900.0, help="time limit of one solve (s)")
    ap.add_argument("--load-per-slope", type=float, default=LOAD_PER_SLOPE,
                    help=f"P / (E* A) per unit of rms slope (default {LOAD_PER_SLOPE})")
    ap.add_argument("--threads", type=int, default=None, help="OpenMP/BLAS/FFT threads of every entry "
                    "(default: all cores)")
    ap.add_argument("--out", default="results/peers")
    ap.add_argument("--fresh", action="store_true", help="start a new CSV (default: append)")
    ap.add_argument("--table-only", action="store_true", help="rebuild aspher.md from the CSV, run nothing")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--delta", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--commit", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    LOAD_PER_SLOPE = args.load_per_slope  # the problems' load, in this process and each child's
    if args.child:
        child(args)
        return
    check_args(ap, args)
    if args.table_only:
        write_markdown(read_rows(Path(args.out) / "aspher.csv"), Path(args.out) / "aspher.md")
        return
    run(args)


if __name__ == "__main__":
    main()
