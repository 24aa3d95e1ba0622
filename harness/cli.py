"""The ``contactbench`` command line.

    contactbench list scenes|solvers [--params]
    contactbench run SCENE [SCENE...] [--solvers a,b|all] [--profile p[,q]] [--size N] [--steps K]
                     [--seeds 0-9|0,3,5] [--surface PATH [--length L] [--channel C]] [--E E] [--kernel bcc|love]
                     [--surface-family saupe|periodic] [--periodic] [--repeats R] [--timeout S] [--out DIR]
                     [--jobs J] [--cold] ...
    contactbench export SCENE [scene options of run] --format problem-dir|hdf5|qpbenchmark --out DIR
    contactbench report DIR
    contactbench validate ...       (every argument goes to harness/conformance.py)

``run`` plans first (``harness.plan``: every scene option, solver, profile and
reference name is checked before anything runs; bad input exits 2 with one line per
problem and writes nothing), then writes DIR/rows.jsonl (the resumable journal),
DIR/results.parquet, DIR/results.csv and DIR/meta.json; running the same command
again completes only the missing cells.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Any, Sequence

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import OPERATOR_KINDS
from contactbench.problems.surfaces import RMD_FAMILIES


def parse_seeds(text: str) -> Sequence[int]:
    """'0-9' -> 0..9, '0,3,5' -> (0, 3, 5), '0-2,7' -> (0, 1, 2, 7).  One range stays a
    lazy ``range`` (the plan bounds its size before anything expands it)."""
    parts: list[range] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        try:
            a, b = part.split("-", 1) if "-" in part else (part, part)
            lo, hi = int(a), int(b)
            if hi < lo or lo < 0:
                raise ValueError
        except ValueError:
            raise argparse.ArgumentTypeError(f"bad seed list {text!r}: use e.g. 0-9 or 0,3,5") from None
        parts.append(range(lo, hi + 1))
    if not parts:
        raise argparse.ArgumentTypeError(f"empty seed list {text!r}")
    if len(parts) == 1:
        return parts[0]
    most = 10**6  # a list of several parts is expanded here (one range is not: the plan bounds it)
    if sum(len(r) for r in parts) > most:
        raise argparse.ArgumentTypeError(f"seed list {text!r} has over {most:,} seeds; give one range (e.g. 0-99)")
    return tuple(dict.fromkeys(s for r in parts for s in r))


def parse_profiles(text: str) -> tuple[str, ...]:
    from .profiles import PROFILES

    names = tuple(p.strip() for p in text.split(",") if p.strip())
    bad = [p for p in names if p not in PROFILES]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"unknown profile {', '.join(bad) or text!r}; choose from {', '.join(PROFILES)}")
    return names


def positive_number(text: str, kind: type, what: str) -> Any:
    """``text`` as a number of ``kind`` that is > 0, else an argparse error naming it."""
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not {what}: {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return v


def positive_float(text: str) -> float:
    return float(positive_number(text, float, "a number"))


def positive_int(text: str) -> int:
    return int(positive_number(text, int, "an integer"))


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="contactbench", description="Benchmark harness for BEM rough-surface contact QPs")
    ap.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = ap.add_subparsers(dest="command", required=True)

    ls = sub.add_parser("list", help="list scenes or solvers")
    ls.add_argument("what", choices=("scenes", "solvers"))
    ls.add_argument("--params", action="store_true", help="with solvers: each solver's declared parameters and grid")

    run = sub.add_parser("run", help="run scenes and write a tidy table")
    run.add_argument("scenes", nargs="+", metavar="SCENE")
    run.add_argument("--solvers", default=None, help="comma list of registry names or MODULE:NAME, or 'all'")
    run.add_argument("--profile", type=parse_profiles, default=None, help="profile(s): default, low, mid, high (comma list)")
    add_scene_options(run)
    run.add_argument("--repeats", type=positive_int, default=1, help="timed solves per cell (min and median reported)")
    run.add_argument("--timeout", type=positive_float, default=60.0, help="hard limit per solve, seconds")
    run.add_argument("--out", default=None, help="output directory (default results/<scenes>)")
    run.add_argument("--jobs", type=positive_int, default=1, help="instances run concurrently")
    run.add_argument("--cold", action="store_true", help="no warm starts along load histories")
    run.add_argument("--no-warmup", action="store_true", help="skip the untimed warm-up solve")
    run.add_argument("--reference", default="auto", help="reference solver: auto (default), none, or a name")
    run.add_argument("--reference-timeout", type=positive_float, default=None, help="limit for a reference solve (default 5 x timeout)")
    run.add_argument("--memory-budget-gb", type=positive_float, default=None,
                     help="memory a solve, and an instance, may use (GiB)")
    run.add_argument("--max-cells", type=positive_int, default=None, help="most cells a plan may have (default 100000)")
    run.add_argument("--append", action="store_true",
                     help="add this run to a results folder that holds a run of another configuration")
    run.add_argument("--threads", type=positive_int, default=None, help="BLAS/FFT threads per worker")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--report", action="store_true", help="build the report after the run")
    run.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="send the cells to a running Dask scheduler (tcp://host:8786); see docs/distributed.md")

    exp = sub.add_parser("export", help="write every (instance, step) QP of a scene to files (problems/export.py)")
    exp.add_argument("scene", metavar="SCENE")
    add_scene_options(exp)
    exp.add_argument("--format", dest="fmt", choices=("problem-dir", "hdf5", "qpbenchmark"), required=True)
    exp.add_argument("--out", required=True, help="output directory")
    exp.add_argument("--dense-limit", type=positive_int, default=None, help="largest n whose dense H is written")

    rep = sub.add_parser("report", help="build the report of a run directory (solves nothing)")
    rep.add_argument("dir")

    sub.add_parser("validate", help="run a solver through the conformance battery (contactbench validate --help)",
                   add_help=False)
    return ap


def cmd_list(what: str, params: bool = False) -> int:
    if what == "scenes":
        from contactbench.problems.scenes import scene_import_errors

        from .studies import catalogue

        for name, description in catalogue().items():
            print(f"{name:24s} {description}")
        for mod, err in scene_import_errors().items():
            print(f"[import error] {mod}: {err.strip().splitlines()[-1]}")
        return 0
    from contactbench.solvers.registry import all_solvers, import_errors

    rows = []
    for name, solver in all_solvers().items():
        ok, why = solver.availability()
        rows.append((name, solver.family, "yes" if ok else f"no ({why})", solver.capabilities.describe()))
    w0 = max([len(r[0]) for r in rows] + [6])
    w1 = max([len(r[1]) for r in rows] + [6])
    pad = " " * (w0 + w1 + 4)
    print(f"{'solver':{w0}s}  {'family':{w1}s}  available / capabilities")
    for name, fam, avail, caps in rows:
        print(f"{name:{w0}s}  {fam:{w1}s}  {avail}\n{pad}{caps}")
        if params:
            print("\n".join(f"{pad}{line}" for line in solver_parameter_lines(all_solvers()[name])))
    for mod, err in import_errors().items():
        print(f"[import error] {mod}: {err.strip().splitlines()[-1]}")
    return 0


def solver_parameter_lines(solver: object) -> list[str]:
    """``list solvers --params``: each declared parameter (``Param.describe``) and the grid."""
    declared = tuple(getattr(solver, "params", ()) or ())
    lines = [f"param {p.describe()}" for p in declared] or ["params: none declared"]
    grid = dict(getattr(solver, "grid", {}) or {})
    lines += [f"grid  {key} = {', '.join(map(str, values))}" for key, values in grid.items()]
    return lines


def scene_config(args: argparse.Namespace) -> Any:
    """The SceneConfig of ``run``/``export``'s scene options.  --length may be omitted for
    a surface file that states its lateral size (problems/io.py checks it at planning)."""
    from contactbench.problems.scenes import SceneConfig

    if args.channel is not None and not args.surface:
        raise ProblemInputError("--channel picks a channel of a --surface file; no --surface was given")
    extra = {} if args.channel is None else {"channel": args.channel}
    if args.height_unit is not None or args.allow_steep:  # problems/units.py: the plausibility check
        if not args.surface:
            raise ProblemInputError("--height-unit and --allow-steep apply to a --surface file; no --surface was given")
        extra.update({k: v for k, v in (("height_unit", args.height_unit), ("allow_steep", args.allow_steep)) if v})
    if args.surface_family is not None:
        if args.surface:
            raise ProblemInputError("--surface-family picks the generated RMD surfaces; a --surface file was given")
        extra["family"] = args.surface_family
    return SceneConfig(size=args.size, steps=args.steps, seeds=args.seeds, surface_path=args.surface,
                       length=args.length, E=args.E, kernel=args.kernel, periodic=args.periodic,
                       operator=args.operator, extra=extra)


def add_scene_options(p: argparse.ArgumentParser) -> None:
    """The scene options shared by ``run`` and ``export``."""
    p.add_argument("--size", type=positive_int, default=None, help="grid points per side N")
    p.add_argument("--steps", type=positive_int, default=None, help="number of load steps K")
    p.add_argument("--seeds", type=parse_seeds, default=None, help="e.g. 0-9 or 0,3,5")
    p.add_argument("--surface", default=None,
                   help="measured height map: .npy/.csv/.txt or any SurfaceTopography format (.x3p, .gwy, .nc, .mat, ...)")
    p.add_argument("--channel", default=None, help="channel (index or name) of a multi-channel --surface file")
    p.add_argument("--length", type=positive_float, default=None,
                   help="side length L in metres (optional when the surface file states its size)")
    p.add_argument("--height-unit", choices=("m", "mm", "um", "nm"), default=None,
                   help="unit of the heights of a --surface file that states none (default m)")
    p.add_argument("--allow-steep", action="store_true",
                   help="run a --surface beyond the small-slope range (rms slope > 1 or heights > side length)")
    p.add_argument("--surface-family", choices=RMD_FAMILIES, default=None,
                   help="RMD surface family of the generated surfaces: saupe (non-periodic MidPointFM2D, the "
                        "paper's; default of non-periodic scenes) or periodic (wrap-around diamond-square)")
    p.add_argument("--E", type=positive_float, default=None, help="composite modulus E* in Pa")
    p.add_argument("--kernel", choices=("bcc", "love", "spectral"), default=None)
    p.add_argument("--periodic", action="store_true", default=None, help="periodic domain")
    p.add_argument("--operator", choices=OPERATOR_KINDS, default=None,
                   help="operator the instance is built with (gpu: the optional CuPy backend, extra `gpu`)")


def cmd_run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from .runner import RunConfig, run_benchmark

    cfg = scene_config(args)
    kw = {}
    if args.memory_budget_gb:
        kw["memory_budget"] = args.memory_budget_gb * 2**30
    if args.max_cells:
        kw["max_cells"] = args.max_cells
    run_cfg = RunConfig(profiles=args.profile, repeats=args.repeats, timeout=args.timeout, warm=not args.cold,
                        warmup=not args.no_warmup, jobs=args.jobs, reference=args.reference,
                        reference_timeout=args.reference_timeout, threads_per_worker=args.threads,
                        progress=False if args.no_progress else None, **kw)
    out = args.out or "results/" + "-".join(args.scenes)
    # run_benchmark plans, checks the folder, then holds its lock (harness/store.py) while it writes
    if args.scheduler:
        from .distributed import run_benchmark_on_dask

        summary = run_benchmark_on_dask(args.scenes, cfg, args.solvers, run_cfg, out, args.scheduler,
                                        command=["contactbench", *argv], append=args.append)
    else:
        summary = run_benchmark(args.scenes, cfg, args.solvers, run_cfg, out, command=["contactbench", *argv],
                                append=args.append)
    for w in summary.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(summary.line())
    if args.report:
        return cmd_report(out)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from contactbench.problems.export import export_scene

    summary = export_scene(args.scene, scene_config(args), args.fmt, args.out, dense_limit=args.dense_limit)
    print(summary.line())
    return 0


def cmd_report(out_dir: str) -> int:
    try:
        from . import report
    except ImportError as exc:
        if "contactbench.harness.report" in str(exc) or "report" in str(getattr(exc, "name", "")):
            print("contactbench report: the report module (harness/report.py) is not installed in this checkout; "
                  f"the tidy table is in {out_dir}/results.parquet", file=sys.stderr)
            return 2
        raise
    path = report.build_report(out_dir)
    if path is not None:
        print(f"report: {path}")
    return 0


def cmd_validate(args: Sequence[str]) -> int:
    try:
        from . import conformance
    except ImportError as exc:
        if "conformance" in str(exc):
            print("contactbench validate: the conformance battery (harness/conformance.py) is not in this checkout",
                  file=sys.stderr)
            return 2
        raise
    return int(conformance.main(list(args)) or 0)


def forwarded_validate(argv: list[str]) -> list[str] | None:
    """The arguments after ``validate`` when it is the command (they belong to
    harness/conformance.py, options included), else None."""
    for i, a in enumerate(argv):
        if a == "validate":
            return argv[i + 1:]
        if not a.startswith("-"):
            return None
    return None


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    forwarded = forwarded_validate(argv)
    verbose = any(a in ("-v", "--verbose") for a in argv[: len(argv) - len(forwarded or [])])
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, format="%(message)s", stream=sys.stderr)
    if forwarded is not None:
        return cmd_validate(forwarded)
    args = build_parser().parse_args(argv)
    try:
        if args.command == "list":
            return cmd_list(args.what, args.params)
        if args.command == "run":
            return cmd_run(args, argv)
        if args.command == "report":
            return cmd_report(args.dir)
        if args.command == "export":
            return cmd_export(args)
    except KeyboardInterrupt:
        print("interrupted: rows so far are kept; run the same command again to finish", file=sys.stderr)
        return 130
    except (ProblemInputError, KeyError, ValueError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        for line in str(msg).splitlines() or [""]:
            print(f"contactbench: error: {line}", file=sys.stderr)
        return 2
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
