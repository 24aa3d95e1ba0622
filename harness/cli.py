"""The ``contactbench`` command line.

    contactbench list scenes|solvers|options [--params]
    contactbench run SCENE [SCENE...] [--solvers a,b[k=v,...]|all] [--profile p[,q]] [--size N] [--steps K]
                     [--seeds 0-9|0,3,5] [--surface PATH [--length L] [--channel C]] [--E E] [--kernel bcc|love]
                     [--surface-family saupe|periodic] [--periodic] [--repeats R] [--timeout S] [--out DIR]
                     [--jobs J] [--cold] ...
    contactbench export SCENE [scene options of run] --format problem-dir|hdf5|qpbenchmark --out DIR
    contactbench report DIR
    contactbench validate ...       (every argument goes to harness/conformance/battery.py)
    contactbench --version

The scene options' flags come from their records (``problems.scenes.options``; ``list
options`` prints the table and the scenes that read each); their rules are the plan's.
``run`` plans first (``harness.run.plan``: every scene option, solver, profile and
reference name is checked before anything runs; bad input exits 2 with one line, its
problems joined by "; ", and writes nothing), then writes DIR/rows.jsonl (the resumable journal),
DIR/results.parquet, DIR/results.csv and DIR/meta.json; running the same command
again completes only the missing cells.

Exit status (docs/harness.md, "Exit status"):

* 0 -- done (``run``: at least one row was judged, solved or inaccurate);
* 1 -- ``run`` wrote its table but the judge could read no row: every one failed,
  timed out, crashed or was skipped (the summary line and the table say why); or the
  run stopped once it ran -- a ``--jobs`` process killed, a write that failed (a full
  disk) -- its rows kept (one line);
* 2 -- bad input, refused before anything runs, in one line (its problems joined by
  "; ") and no traceback: an unknown name (with the closest known ones), an empty or repeated item of
  a comma list (``--solvers pk,,nnls``, ``--profile low,low``), an option the scene would
  ignore, a configuration that cannot run (``--kernel spectral`` without
  ``--periodic``, an implausible ``--E``), or a path that cannot be read or written;
* 130 -- interrupted by Ctrl-C, 143 -- stopped by SIGTERM (``Terminated``): the same stop,
  the rows so far kept, the table written from them and the folder's lock released;
* 141 -- the reader of the output went away (``contactbench list solvers | head``), silently.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import warnings
from contextlib import contextmanager
import contactbench
from pathlib import Path
from typing import Any, Iterator, Sequence

from contactbench.problems.atomic_files import names_nothing
from contactbench.problems.operators import fft_backend, fft_workers, memory_budget_scope
from contactbench.problems.scenes import all_scenes
from contactbench.problems.scenes.options import CONFIG_FIELDS, OPTIONS, OptionRecord

from contactbench.stops import EXIT_INTERRUPTED, EXIT_TERMINATED, STARTING_TEXT
from contactbench.plugins import did_you_mean

from .held_warnings import INPUT_ERRORS, HeldWarnings, held_warnings
from .arguments import (EXIT_BAD_INPUT, InputError, Parser, check_out_dir, check_utf8_path, comma_items, os_error_line,
                        positive_float, time_limit, positive_number, plain_number)

#: Exit status of a run whose rows the judge could not read at all (module doc).
EXIT_NOTHING_JUDGED = 1
#: ... and of a run stopped once it ran -- a lost ``--jobs`` process, a write that failed (a
#: full disk) -- its rows kept (module doc).
EXIT_RUN_STOPPED = 1
#: Exit status when the reader of the output closed it (128 + SIGPIPE, as a shell reports it).
EXIT_BROKEN_PIPE = 141


class Terminated(KeyboardInterrupt):
    """SIGTERM (a batch scheduler's, ``kill``'s), raised where Ctrl-C raises
    ``KeyboardInterrupt``: the command stops as it does on Ctrl-C, its rows and the
    folder's lock dealt with the same way (``terminate_as_interrupt``)."""


@contextmanager
def terminate_as_interrupt() -> Iterator[list[int]]:
    """SIGTERM raises ``Terminated`` in the main thread for the block (elsewhere: nothing
    changes); the handler before is put back after.  The list yielded gets the signal's
    number each time the handler runs (``main``: a ``Terminated`` that Python swallowed, in
    a weakref callback, still ends the command as terminated).  The processes this one
    starts set SIGTERM back to its default (harness/run/executors.py, harness/run/isolation.py)."""
    fired: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield fired
        return

    def raise_terminated(signum: int, frame: Any) -> None:
        fired.append(signum)
        raise Terminated()

    before = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield fired
    finally:
        signal.signal(signal.SIGTERM, before)


def interrupt_in_chain(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C or SIGTERM (``Terminated``) that ``exc`` carries in its ``__cause__`` /
    ``__context__`` chain, ``exc`` itself included (an interrupt that landed inside code that
    wraps what it raises: ``__set_name__``'s RuntimeError), else None."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return None


def output_reader_gone() -> int:
    """``EXIT_BROKEN_PIPE``, with stdout pointed at the null device so that nothing more is
    flushed at exit (`contactbench list solvers | head`)."""
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return EXIT_BROKEN_PIPE


def stopped(exc: KeyboardInterrupt, what: str) -> int:
    """The line and exit status of a command stopped by Ctrl-C or SIGTERM (``Terminated``)."""
    word, code = ("terminated", EXIT_TERMINATED) if isinstance(exc, Terminated) else ("interrupted", EXIT_INTERRUPTED)
    print(f"{word}: {what}", file=sys.stderr)
    return code


def parse_seeds(text: str) -> Sequence[int]:
    """'0-9' -> 0..9, '0,3,5' -> (0, 3, 5), '0-2,7' -> (0, 1, 2, 7).  One range stays a
    lazy ``range`` (the plan bounds its size before anything expands it).  An empty item
    or an item given twice is refused (``comma_items``); ranges that overlap give each
    seed once."""
    parts: list[range] = []
    for part in comma_items(text):
        try:
            a, b = part.split("-", 1) if "-" in part else (part, part)
            lo, hi = plain_number(a, int), plain_number(b, int)
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
    if sum(r.stop - r.start for r in parts) > most:
        raise argparse.ArgumentTypeError(f"seed list {text!r} has over {most:,} seeds; give one range (e.g. 0-99)")
    return tuple(dict.fromkeys(s for r in parts for s in r))


def parse_profiles(text: str) -> tuple[str, ...]:
    """``--profile``: profile names, each once (``comma_items``), each a known profile."""
    from .profiles import PROFILES

    names = tuple(comma_items(text))
    bad = [p for p in names if p not in PROFILES]
    if bad or not names:
        hint = did_you_mean(bad[0], PROFILES) if bad else ""
        raise argparse.ArgumentTypeError(f"unknown profile {', '.join(bad) or text!r}{hint}; "
                                         f"choose from {', '.join(PROFILES)}")
    return names


def number_list(text: str) -> tuple[float, ...]:
    """A comma list of numbers (``--loads``, ``--length``) with no empty item
    (``comma_items``); a value may repeat (L0,L1 of a square), and every other rule on
    them (``--loads`` increasing) is the plan's."""
    try:
        values = tuple(plain_number(t, float) for t in comma_items(text, repeats=True))
    except ValueError:
        values = ()
    if not values:
        raise argparse.ArgumentTypeError(f"takes numbers separated by commas, got {text!r}")
    return values


def solver_list(text: str) -> str:
    """``--solvers``: the list as given, once no item of it is empty or given twice
    (``comma_items``, split as ``solvers.registry.split_solver_list`` splits it).  The
    plan resolves it, and refuses a list that names no solver or has an unbalanced
    bracket."""
    from contactbench.solvers.registry import SolverSpecError, split_solver_list

    try:
        comma_items(text, split=split_solver_list)
    except SolverSpecError:  # (the plan names it)
        pass
    return text


def length_value(text: str) -> float | tuple[float, ...]:
    """``--length``: L0, or L0,L1 as a tuple (how many, and their rules, are the plan's)."""
    values = number_list(text)
    return values[0] if len(values) == 1 else values


def number(text: str) -> float:
    """A number written plainly (``arguments.plain_number``: "1_0" is none)."""
    try:
        return plain_number(text, float)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def integer(text: str) -> int:
    """An integer written plainly (``arguments.plain_number``: "1_000" is none)."""
    try:
        return plain_number(text, int)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


#: The text -> value parser of each option kind (``problems.scenes.options.OptionRecord.kind``):
#: the type only; every rule on the value is checked by the plan, as for the API.
PARSERS: dict[str, Any] = {"int": integer, "float": number, "floats": number_list, "length": length_value,
                           "seeds": parse_seeds, "text": str}


def positive_int(text: str) -> int:
    return int(positive_number(text, int, "an integer"))


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="contactbench", description="Benchmark harness for BEM rough-surface contact QPs")
    ap.add_argument("--version", action="version", version=f"contactbench {contactbench.__version__}")
    ap.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND",
                            parser_class=Parser)

    ls = sub.add_parser("list", help="list scenes, solvers or the scene options")
    ls.add_argument("what", choices=("scenes", "solvers", "options"))
    ls.add_argument("--params", action="store_true", help="with solvers: each solver's declared parameters and grid")

    run = sub.add_parser("run", help="run scenes and write a tidy table")
    run.add_argument("scenes", nargs="+", metavar="SCENE", help="scene or mix name (contactbench list scenes)")
    run.add_argument("--solvers", type=solver_list, default=None, metavar="LIST",
                     help="comma list of registry names or MODULE:NAME, each optionally with parameters "
                          "NAME[key=value,...] (contactbench list solvers --params) or NAME[grid] (one variant "
                          "per point of the solver's declared grid; NAME[grid,key=value] fixes key), or 'all' "
                          "(default: the scene's study, else every available solver)")
    run.add_argument("--profile", type=parse_profiles, default=None,
                     help="profile(s): default, low, mid, high (comma list; default: the scene's study)")
    add_scene_options(run)
    run.add_argument("--repeats", type=positive_int, default=1, help="timed solves per cell (min and median reported)")
    run.add_argument("--timeout", type=time_limit, default=60.0, help="hard limit per solve, seconds")
    run.add_argument("--out", default=None, metavar="DIR", help="output directory (default: results/<scenes>)")
    run.add_argument("--jobs", type=positive_int, default=1, help="instances run concurrently")
    run.add_argument("--cold", action="store_true", help="no warm starts along load histories")
    run.add_argument("--no-warmup", action="store_true", help="skip the untimed warm-up solve")
    run.add_argument("--reference", default="auto", help="reference solver: auto, none, or a name")
    run.add_argument("--reference-timeout", type=time_limit, default=None,
                     help="limit for a reference solve (default: 5 x timeout)")
    run.add_argument("--memory-budget-gb", type=positive_float, default=None,
                     help="memory a solve, and an instance, may use, GiB (default: the harness's budget)")
    run.add_argument("--max-cells", type=positive_int, default=None, help="most cells a plan may have (default: 100000)")
    run.add_argument("--append", action="store_true",
                     help="add this run to a results folder that holds a run of another configuration")
    run.add_argument("--threads", type=positive_int, default=None,
                     help="BLAS/FFT threads per worker (default: cores / jobs)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--report", action="store_true", help="build the report after the run")
    run.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="send the cells to a running Dask scheduler (tcp://host:8786); see docs/distributed.md")

    exp = sub.add_parser("export", help="write every (instance, step) QP of a scene to files (problems/export.py)")
    exp.add_argument("scene", metavar="SCENE", help="scene name (contactbench list scenes)")
    add_scene_options(exp)
    exp.add_argument("--format", dest="fmt", choices=("problem-dir", "hdf5", "qpbenchmark"), required=True,
                     help="problem-dir: one folder per QP in the external-solver format (docs/external-solvers.md); "
                          "hdf5: one problems.h5; qpbenchmark: one <scene>.parquet in qpbenchmark's ProblemList")
    exp.add_argument("--out", required=True, metavar="DIR", help="output directory")
    exp.add_argument("--dense-limit", type=positive_int, default=None,
                     help="largest n whose dense H is written (default: problems/export.py's)")
    exp.add_argument("--max-qps", type=positive_int, default=None,
                     help="most QPs (instances x steps) one export may write (default: problems/export.py's MAX_QPS)")

    rep = sub.add_parser("report", help="build the report of a run directory (solves nothing)")
    rep.add_argument("dir", help="a run's --out folder (its results table and meta.json), or a folder holding a "
                                 "results.csv or results.parquet")

    sub.add_parser("validate", help="run a solver through the conformance battery (contactbench validate --help)",
                   add_help=False)
    return ap


def option_lines() -> list[str]:
    """``list options``: each record of ``problems.scenes.options.OPTIONS`` -- flag, kind,
    unit, ranges, what it requires or excludes -- and the scenes that read it (their
    ``Scene.options``)."""
    scenes = all_scenes()
    lines = []
    for rec in OPTIONS:
        facts = [rec.kind + (f" [{rec.unit}]" if rec.unit else ""),
                 f"valid {rec.valid.text()}" if rec.valid else "",
                 f"plausible {rec.plausible.text()[3:]}" if rec.plausible else "",
                 f"choices {','.join(rec.choices)}" if rec.choices else "",
                 *(f"needs {' or '.join(req.keys)}" + (f" when {req.when}" if req.when else "") for req in rec.requires),
                 *(f"excludes {other}" for other in rec.excludes),
                 "not with --surface" if rec.generated_only else "",
                 "in the instance name" if rec.suffix else ""]
        readers = "every scene" if rec.universal else ", ".join(n for n, sc in scenes.items() if rec.name in sc.options)
        lines.append(f"{rec.flag:20s} {'; '.join(f for f in facts if f)}\n{'':20s} read by: {readers or 'none'}")
    return lines


def cmd_list(what: str, params: bool = False) -> int:
    if params and what != "solvers":
        raise InputError(f"--params lists the solvers' parameters: `contactbench list solvers --params`, not "
                         f"`list {what}`")
    if what == "options":
        print("\n".join(option_lines()))
        return 0
    if what == "scenes":
        from contactbench.problems.scenes import scene_import_errors

        from .run.studies import catalogue

        for name, description in catalogue().items():
            print(f"{name:24s} {description}")
        for mod, err in scene_import_errors().items():
            print(f"[import error] {mod}: {err.strip().splitlines()[-1]}")
        return 0
    from contactbench.solvers.registry import all_solvers, import_errors

    from .run.skips import checked_availability

    rows = []
    for name, solver in all_solvers().items():
        ok, why, _ = checked_availability(solver)
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
    """The SceneConfig of ``run``/``export``'s scene options (``problems.scenes.options``):
    each record's value, as a field or a key of ``extra``, where given.  Every rule on
    them is the plan's (``harness.run.plan.plan_run``), the same for the API."""
    from contactbench.problems.scenes import SceneConfig

    given = {rec.name: getattr(args, rec.name) for rec in OPTIONS if getattr(args, rec.name, None) is not None}
    fields = {k: v for k, v in given.items() if k in CONFIG_FIELDS}
    return SceneConfig(**fields, extra={k: v for k, v in given.items() if k not in CONFIG_FIELDS})


def add_option(p: argparse.ArgumentParser, rec: OptionRecord) -> None:
    """One scene option's flag, from its record (``dest`` is the option's name)."""
    text = rec.help + (f" [{rec.unit}]" if rec.unit and f" {rec.unit}" not in rec.help else "")
    if rec.valid is not None or rec.plausible is not None:
        ranges = [f"valid {rec.valid.text()}" if rec.valid else "",
                  f"plausible {rec.plausible.text()[3:]}{' ' + rec.unit if rec.unit else ''}" if rec.plausible else ""]
        text += f" ({'; '.join(r for r in ranges if r)})"
    text = text.replace("%", "%%")
    if rec.kind == "switch":
        p.add_argument(rec.flag, dest=rec.name, action="store_true", default=None, help=text)
    elif rec.kind == "choice":
        p.add_argument(rec.flag, dest=rec.name, choices=rec.choices, default=None, help=text)
    else:
        metavar = rec.flag.lstrip("-").replace("-", "_").upper()
        p.add_argument(rec.flag, dest=rec.name, type=PARSERS[rec.kind], default=None, metavar=metavar, help=text)


def add_scene_options(p: argparse.ArgumentParser) -> None:
    """The scene options shared by ``run`` and ``export``, one flag per record of
    ``problems.scenes.options.OPTIONS`` (None: the scene's default)."""
    for rec in OPTIONS:
        add_option(p, rec)


def cmd_run(args: argparse.Namespace, argv: Sequence[str], held: HeldWarnings | None = None) -> int:
    """``run``: plan, check the folder, run; ``held``: the command's held warnings, shown
    once every check has passed (``run_benchmark``'s ``ready``; a Dask run's when it ends)."""
    from .run.executors import RunStopped
    from .run.runner import RunConfig, run_benchmark

    cfg = scene_config(args)
    fft_workers(), fft_backend()  # the threads and the FFT library of every product: refused here, not in a worker
    kw = {}
    if args.memory_budget_gb:
        kw["memory_budget"] = args.memory_budget_gb * 2**30
    if args.max_cells:
        kw["max_cells"] = args.max_cells
    run_cfg = RunConfig(profiles=args.profile, repeats=args.repeats, timeout=args.timeout, warm=not args.cold,
                        warmup=not args.no_warmup, jobs=args.jobs, reference=args.reference,
                        reference_timeout=args.reference_timeout, threads_per_worker=args.threads,
                        progress=False if args.no_progress else None, **kw)
    out = run_out(args)
    check_out_dir(out)
    if args.report:  # a page the report would refuse is refused before the solves, not after them
        from .report.build import check_pages

        check_pages(out)
    # run_benchmark plans, checks the folder, then holds its lock (harness/table/store.py) while it writes
    with memory_budget_scope(kw.get("memory_budget")):  # the run's skips and builds read it too
        if args.scheduler is not None:  # (an empty address is refused, not read as a local run)
            from .run.distributed import run_benchmark_on_dask

            summary = run_benchmark_on_dask(args.scenes, cfg, args.solvers, run_cfg, out, args.scheduler,
                                            command=["contactbench", *argv], append=args.append)
        else:
            try:
                summary = run_benchmark(args.scenes, cfg, args.solvers, run_cfg, out, command=["contactbench", *argv],
                                        append=args.append, ready=None if held is None else held.release)
            except RunStopped as exc:
                print(f"contactbench: error: {exc}", file=sys.stderr)
                return EXIT_RUN_STOPPED
    if held is not None:
        held.release()
    print(summary.line())  # (the plan's warnings: logged by run_benchmark as it starts)
    status = 0
    if summary.judged == 0:
        print(f"contactbench: error: no row could be judged ({summary.rows} rows, none solved or inaccurate)"
              f"{common_reason(out)}; see the 'error' and 'skip_reason' columns of {out}/results.csv",
              file=sys.stderr)
        status = EXIT_NOTHING_JUDGED
    if args.report:
        return cmd_report(out) or status
    return status


def common_reason(out: str) -> str:
    """"; most common reason: ..." -- the first line of the commonest ``error`` or
    ``skip_reason`` of the table in ``out`` -- or "" when there is none."""
    from .table.store import load_table

    table = load_table(out)
    reasons = [str(v).strip().splitlines()[0][:200] for col in ("error", "skip_reason") if col in table
               for v in table[col].dropna() if str(v).strip()]
    if not reasons:
        return ""
    top = max(dict.fromkeys(reasons), key=reasons.count)
    return f"; most common reason ({reasons.count(top)} of {len(table)}): {top}"


def cmd_export(args: argparse.Namespace, held: HeldWarnings | None = None) -> int:
    """``export``: check, then write every QP; ``held``: the command's held warnings, shown
    once the export is written (its checks come first, ``export_scene``)."""
    from contactbench.problems.export import ExportStopped, export_scene

    from .run.studies import COMPOSITES

    composite = COMPOSITES.get(args.scene)
    if composite is not None:  # `list scenes` lists it: say what it is, not "unknown scene"
        scenes = ", ".join(dict.fromkeys(p.study.scene for p in composite.parts))
        raise InputError(f"export {args.scene}: a composite of the scenes {scenes}; export one scene at a time")
    cfg = scene_config(args)
    check_out_dir(args.out)
    # export_scene checks the options (the plan's rules), the scene's inputs and the folder before writing
    cap = {} if args.max_qps is None else {"max_qps": args.max_qps}
    try:
        summary = export_scene(args.scene, cfg, args.fmt, args.out, dense_limit=args.dense_limit, **cap)
    except ExportStopped as exc:
        print(f"contactbench: error: {exc}", file=sys.stderr)
        return EXIT_RUN_STOPPED
    if held is not None:
        held.release()
    print(summary.line())
    if summary.skipped:  # exit 0 says every QP is written
        total = len(summary.written) + len(summary.skipped)
        print(f"contactbench export: {len(summary.skipped)} of {total} QPs not written (the line above says why)",
              file=sys.stderr)
        return 1
    return 0


def cmd_report(out_dir: str) -> int:
    if names_nothing(out_dir):  # ("" would read the current folder)
        raise InputError(f"report: the folder must be named, got {out_dir!r}")
    check_utf8_path(out_dir, "report")
    if Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise InputError(f"report {out_dir}: a file, not a run folder (give the --out folder of a run, which holds "
                         "its results table)")
    if not Path(out_dir).is_dir():
        raise InputError(f"report {out_dir}: no such folder (give the --out folder of a run)")
    from .report.build import ReportWriteError, build_report
    from .report.sections.claims import write_claims_report

    claims = write_claims_report(out_dir)  # a claims folder: claims.csv -> claims.md first
    if claims is not None:
        print(f"claims: {claims}")
        if not has_results_table(out_dir):
            return 0
    try:
        path = build_report(out_dir)
    except ReportWriteError as exc:
        print(f"contactbench: error: {exc}", file=sys.stderr)
        return EXIT_RUN_STOPPED
    if path is not None:
        print(f"report: {path}")
    return 0


def interrupted_text(args: argparse.Namespace) -> str:
    """What a command stopped by Ctrl-C or SIGTERM leaves behind, for the line it prints."""
    if args.command == "export":
        from contactbench.problems.export import MANIFEST_FILE

        if not (Path(args.out) / MANIFEST_FILE).is_file():
            return f"nothing was exported to {args.out}"
        return (f"the export in {args.out} is incomplete (its {MANIFEST_FILE} says so); run the same command "
                "again to finish it")
    if args.command == "report":
        return "no report was written; the last one and its figures are as they were"
    if args.command == "run" and not has_rows(run_out(args)):
        return f"no row was written to {run_out(args)} yet; run the same command again to start"
    return "rows so far are kept; run the same command again to finish"


def run_out(args: argparse.Namespace) -> str:
    """The results folder of ``contactbench run``: ``--out``, else results/<scene names>
    (an empty ``--out`` is refused, not read as the default)."""
    return args.out if args.out is not None else "results/" + "-".join(args.scenes)


def has_results_table(out_dir: str) -> bool:
    """Whether a folder holds a stored results table (not only a claims ledger)."""
    from .table.store import CSV_FILE, PARQUET_FILE, ROWS_FILE

    return any((Path(out_dir) / name).is_file() for name in (PARQUET_FILE, CSV_FILE, ROWS_FILE))


def has_rows(out_dir: str) -> bool:
    """Whether a folder holds a row of results: a line of its journal, or a row of its table
    (a table of only its header, as an interrupt before the first row leaves, holds none).
    True where a file is there but cannot be read (its rows are not said to be absent)."""
    from .table.store import CSV_FILE, PARQUET_FILE, ROWS_FILE

    out = Path(out_dir)
    try:
        if (out / ROWS_FILE).is_file():
            with open(out / ROWS_FILE, "rb") as fh:
                if any(line.strip() for line in fh):
                    return True
        if (out / PARQUET_FILE).is_file():
            import pyarrow.parquet as pq

            if pq.ParquetFile(out / PARQUET_FILE).metadata.num_rows > 0:
                return True
        if (out / CSV_FILE).is_file():
            with open(out / CSV_FILE, "rb") as fh:
                return sum(1 for line in fh if line.strip()) > 1  # (the header, then a row)
    except Exception:  # (a file that cannot be read: not "no row")
        return True
    return False


def cmd_validate(args: Sequence[str]) -> int:
    """``contactbench validate``: harness/conformance/command.py's ``main``, with the exit
    statuses of the other commands for an interrupt (``stopped``) and for a reader of the output
    that went away (``EXIT_BROKEN_PIPE``, silently, as ``_main`` does)."""
    from .conformance.command import main as validate_main

    try:
        return int(validate_main(list(args)) or 0)
    except KeyboardInterrupt as exc:
        return stopped(exc, "no conformance report was written")
    except BrokenPipeError:  # `contactbench validate --list | head`
        return output_reader_gone()


def forwarded_validate(argv: list[str]) -> list[str] | None:
    """The arguments after ``validate`` when it is the command (they belong to
    harness/conformance/command.py, options included), else None."""
    for i, a in enumerate(argv):
        if a == "validate":
            return argv[i + 1:]
        if not a.startswith("-"):
            return None
    return None


def show_warning_on_one_line(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                             file: Any = None, line: str | None = None) -> None:
    """A warning as one ``contactbench: warning:`` line on stderr (not Python's two, with
    the source line that raised it)."""
    print(f"contactbench: warning: {message}", file=sys.stderr if file is None else file)


#: The line's text of a SIGTERM that reached the handler but whose ``Terminated`` Python
#: swallowed (raised in a weakref callback: "Exception ignored"), the command run on to its end.
SWALLOWED_TEXT = "the signal arrived where Python could not stop the command, which ran on to its end"


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module doc); its exit status.  An exception whose cause or context
    holds a Ctrl-C or SIGTERM is that interrupt (``interrupt_in_chain``); a SIGTERM whose
    ``Terminated`` was swallowed still ends it with ``EXIT_TERMINATED``."""
    fired: list[int] = []
    try:
        with warnings.catch_warnings(), terminate_as_interrupt() as fired:
            warnings.showwarning = show_warning_on_one_line
            code = _main(list(sys.argv[1:] if argv is None else argv))
    except Exception as exc:  # (stopped before a command ran: while its arguments and modules were read)
        interrupt = interrupt_in_chain(exc)
        if interrupt is None:
            raise
        return stopped(interrupt, STARTING_TEXT)
    except KeyboardInterrupt as exc:
        return stopped(exc, STARTING_TEXT)
    if fired and code not in (EXIT_INTERRUPTED, EXIT_TERMINATED):
        return stopped(Terminated(), SWALLOWED_TEXT)
    return code


def _main(argv: list[str]) -> int:
    forwarded = forwarded_validate(argv)
    verbose = any(a in ("-v", "--verbose") for a in argv[: len(argv) - len(forwarded or [])])
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO, format="%(message)s", stream=sys.stderr)
    if forwarded is not None:
        return cmd_validate(forwarded)
    args = build_parser().parse_args(argv)
    try:
        try:
            return run_command(args, argv)
        except Exception as exc:  # an interrupt wrapped by the code it landed in is that interrupt
            interrupt = interrupt_in_chain(exc)
            if interrupt is None:
                raise
            raise interrupt from None
    except KeyboardInterrupt as exc:
        return stopped(exc, interrupted_text(args))
    except INPUT_ERRORS as exc:  # one line: the problems joined by "; "
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"contactbench: error: {one_line(str(msg))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader of our output has gone (`contactbench list solvers | head`)
        return output_reader_gone()
    except OSError as exc:  # a path that cannot be read or written: one line naming it
        print(f"contactbench: error: {os_error_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT


def run_command(args: argparse.Namespace, argv: list[str]) -> int:
    """Run the command ``args`` names (``list``, ``run``, ``report``, ``export``)."""
    if args.command == "list":
        return cmd_list(args.what, args.params)
    if args.command == "run":
        with held_warnings() as held:
            return cmd_run(args, argv, held)
    if args.command == "report":
        return cmd_report(args.dir)
    if args.command == "export":
        with held_warnings() as held:
            return cmd_export(args, held)
    return 1


def one_line(text: str) -> str:
    """``text`` on one line: its non-blank lines, stripped, joined by "; "."""
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
