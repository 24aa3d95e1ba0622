"""``contactbench validate``: the command line of the conformance battery (argument
parsing, the solvers it names, the exit status, the optional CSV and report).

Exit status (``VerdictTable.exit_code``, combined over the solvers by ``_combined_exit``):
0 conforms, 1 wrong (with ``--strict`` also crashes, timeouts, flagged rows), 2 bad input,
3 incomplete, 4 untested (no answer of any solver's own judged, or its own skip left a group untried).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
import os
import sys
from pathlib import Path
from typing import Any, Sequence

from contactbench.problems.atomic_files import names_nothing
from contactbench.problems.errors import ProblemInputError
from contactbench.solvers.base import ParamError, Solver
from contactbench.solvers.registry import (NamedVariant, SolverSpecError, all_solvers, check_late_sources,
                                           expand_solver_spec, is_import_path, load_solver, refuse_same_variants,
                                           split_solver_spec)
from contactbench.solvers.registry import load_named_solver as load_import_path

from ..arguments import EXIT_BAD_INPUT, Parser, time_limit
from ..arguments import check_out_dir as check_writable_dir
from ..run.plan import probe_import, refuse_name_clash
from ..run.skips import checked_availability
from ..table.files import begins_with, replace_atomically
from .declared import LoadFailed, OneLine, in_a_child, names_user_code
from .cases import KILL_GRACE
from .battery import BATTERY_GROUPS, conformance_cases, left_out_lines, record_columns, validate
from .report import check_report_folder, write_conformance_report


# ---------------------------------------------------------------------------
# Command line: contactbench validate
# ---------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(
        prog="contactbench validate",
        description="Run solvers through the conformance battery and judge every answer with the harness's "
                    "judge (the scaled KKT check of `contactbench run`).",
        epilog="exit status: 0 conforms (every case solved to the solver's promise, or skipped for a declared "
               "capability); 1 wrong: an answer claimed as converged that fails, or a solver that wrote into its "
               "problem (with --strict also crashes, timeouts, flagged rows); 2 bad input, refused before anything "
               "runs (unknown solver, import path that does not load, no case selected, solver not available, a "
               "bad --timeout, a --csv or --out that cannot be written or holds what validate did not write, a "
               "solver declaration that cannot be used); "
               "3 incomplete: cases left unsolved; 4 untested: "
               "no answer of any solver's own was judged (every case skipped for a declared capability, refused "
               "where refusing is allowed, or answered without calling the solver), or its own skip left a whole "
               "group of the selection untried "
               "(docs/verdicts.md).")
    ap.add_argument("solvers", nargs="*", metavar="SOLVER",
                    help="registry name, or import path module:NAME (the current directory is importable); "
                         "NAME[k=v,...] validates that variant, NAME[grid] each point of its declared grid")
    ap.add_argument("--all", action="store_true", help="every available registered solver")
    ap.add_argument("--full", action="store_true", help="the full battery (default: the fast subset)")
    ap.add_argument("--group", action="append", choices=BATTERY_GROUPS, help="only these groups (repeatable)")
    ap.add_argument("--cases", metavar="GLOB", type=case_glob,
                    help="only cases whose name or group matches, e.g. 'edge/*'")
    ap.add_argument("--timeout", type=time_limit, help="seconds per solve, finite and > 0 (default: 20 fast, "
                                                            "60 full): the solver's time limit; a solve still "
                                                            f"running {KILL_GRACE[0]:g} s + {KILL_GRACE[1]:g} x "
                                                            "the limit later is killed, a timeout")
    ap.add_argument("--strict", action="store_true", help="also fail on crashes, timeouts and flagged rows")
    ap.add_argument("--no-isolate", action="store_true",
                    help="solve in-process, for debugging: no time limit, no protection against a solver that "
                         "ends the process itself (os._exit, a fatal signal ends validate; sys.exit is a crash row), "
                         "and the solver's code runs where the judge does (docs/verdicts.md)")
    ap.add_argument("--list", action="store_true", help="list the selected cases and exit (the solvers named, "
                                                        "their --params, --csv and --out are checked first)")
    ap.add_argument("--csv", metavar="PATH", type=path_text,
                    help="also write the verdict rows as CSV (a new file in an existing folder, or a CSV file "
                         "validate wrote; never a link)")
    ap.add_argument("--out", metavar="DIR", type=path_text,
                    help="write the conformance report: DIR/verdicts.csv and DIR/conformance.md (the exit status is "
                         "the same); DIR is new, empty or a report folder of validate")
    ap.add_argument("--command", metavar="'CMD {problem} {solution}'",
                    help="validate an outside program over the file protocol (docs/external-solvers.md)")
    ap.add_argument("--inputs", choices=("dense", "kernel"), default=None,
                    help="with --command: what the program reads, the dense H (default) or the kernel table")
    ap.add_argument("--quiet", action="store_true", help="print only the summary line per solver")
    ap.add_argument("--params", type=json_object, default=None, metavar="JSON",
                    help='solver parameters for every solve, e.g. \'{"precision": "mixed"}\' (checked against the '
                         "solver's declared parameters: `contactbench list solvers --params`)")
    return ap


def case_glob(text: str) -> str:
    """``--cases``: a non-empty glob (an empty one would select every case)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r} names no case; give a glob such as 'edge/*'")
    return text


def path_text(text: str) -> str:
    """``--csv`` and ``--out``: a path with something in it (an empty one names nothing)."""
    if names_nothing(text):
        raise argparse.ArgumentTypeError(f"{text!r} names no file or folder; give a path")
    return text


def json_object(text: str) -> dict[str, Any]:
    """A JSON object from the command line (argparse reports anything else as a usage error)."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object such as '{{\"precision\": \"mixed\"}}', got {text!r}")
    return value


class CommandLineError(OneLine):
    """Bad command-line input found before anything runs (one line)."""


class SolverLoadError(CommandLineError):
    """A solver named on the command line that cannot be loaded or run here."""


def load_named_solver(name: str) -> Solver:
    """The solver called ``name`` (registry name or ``module:NAME``), or a
    ``SolverLoadError`` that says what is wrong in one line: an unknown registry name, or
    what ``registry.load_named_solver`` says of an import path that does not load (a file
    path where a module name goes, a module not found, a missing attribute, a declaration
    the registry refuses, whatever importing it or building the solver raised, a registered
    solver's name: ``plan.refuse_name_clash``) -- never the end of ``validate``."""
    if not is_import_path(name):
        try:
            return load_solver(name)
        except KeyError as exc:
            raise SolverLoadError(f"{exc.args[0] if exc.args else exc} (or give an import path module:NAME)") from None
    try:
        solver = load_import_path(name)
    except ProblemInputError as exc:  # (the registry's SolverLoadError: one line)
        raise SolverLoadError(str(exc)) from None
    refuse_name_clash(name.strip(), solver)  # as run refuses it: its verdict would read as that one's
    return solver


def command_solver_of(command: str | None, inputs: str | None) -> list[Solver]:
    """The solver of ``--command`` (an unregistered external solver), checked up front."""
    if command is None:
        if inputs is not None:
            raise SolverLoadError("--inputs goes with --command")
        return []
    from contactbench.solvers.external import command_solver

    return [command_solver(command, inputs or "dense")]


def availability(solver: Solver) -> tuple[bool, str]:
    """``solver.availability()``, or a ``SolverLoadError`` naming the solver when it fails."""
    ok, why, failed = checked_availability(solver)
    if failed:
        raise SolverLoadError(f"solver {solver.name!r}: {why}")
    return ok, why


@dataclass(frozen=True)
class Candidate:
    """One solver to validate: ``load``, the text ``load_solver`` reads it by (or the
    ``--command`` solver itself), its ``name``, the parameters of the variant named
    (``NAME[k=v]``, each point of ``NAME[grid]``; None: ``--params``) and its label."""

    load: Solver | str
    name: str
    params: dict[str, Any] | None = None
    label: str | None = None


def named_candidates(name: str) -> list[tuple[Candidate, Solver]]:
    """The candidates one SOLVER argument names, each with its solver: the solver, or with
    brackets each variant it stands for (``solvers.registry.expand_solver_spec``: checked
    parameters, a grid's points), each labelled as ``run`` labels it."""
    if "[" not in name:
        solver = load_named_solver(name)
        return [(Candidate(name, solver.name), solver)]
    try:
        base = split_solver_spec(name).name
        load_named_solver(base)  # (its one-line load errors first)
        specs, solver = expand_solver_spec(name)
    except SolverSpecError as exc:
        raise CommandLineError(str(exc)) from None
    return [(Candidate(base, solver.name, dict(spec.params), spec.label), solver) for spec in specs]


def selected_solvers(names: Sequence[str], every: bool, extra: Sequence[Solver] = (), required: bool = True,
                     params: dict[str, Any] | None = None) -> list[Candidate]:
    """The solvers named (a variant each, ``named_candidates``), the ``--command`` one and
    with ``every`` each available registered one, checked: each available, its parameters
    (a variant's own, else ``params``: ``--params``) taken by its declaration, no variant
    named twice (``refuse_same_variants``); none at all is an error when ``required``.
    ``validate`` runs it in a child where a solver is named by import path
    (``declared.in_a_child``, ``names_user_code``): it loads the solvers."""
    chosen = [pair for n in names for pair in named_candidates(n)]
    chosen += [(Candidate(s, s.name), s) for s in extra]
    for c, solver in chosen:
        ok, why = availability(solver)
        if not ok:
            raise SolverLoadError(f"solver {solver.name!r} is not available here: {why}")
    if every:
        seen = {solver.name for _, solver in chosen}
        chosen += [(Candidate(n, s.name), s) for n, s in all_solvers().items() if n not in seen and availability(s)[0]]
    if not chosen and required:
        raise SolverLoadError("name a solver (registry name or module:NAME), pass --all, or give --command")
    if params is not None and any(c.params is not None for c, _ in chosen):
        raise CommandLineError("--params goes with plain solver names; a NAME[k=v] or NAME[grid] names its own")
    for c, solver in chosen:
        solver.resolve_params(c.params if c.params is not None else params)
    refuse_same_variants([NamedVariant(c.label or solver.name, solver, c.params if c.params is not None else params)
                          for c, solver in chosen], "the command line")
    return [c for c, _ in chosen]


def _combined_exit(codes: Sequence[int]) -> int:
    """Wrong answers first (1), then incomplete solvers (3); 4 when every solver is
    untested (no answer of any one's own judged); else 0 (solvers the selection left
    untested are named in their lines, but others were judged)."""
    first = next((c for c in (1, 3) if c in codes), 0)
    return first or (4 if codes and all(c == 4 for c in codes) else 0)


def main(argv: Sequence[str] | None = None) -> int:
    """``contactbench validate`` (module doc for the exit status).  Every input -- the
    options, the cases, the solvers and their parameters, the --csv and --out paths --
    is checked before anything runs: bad input is one line on stderr and exit 2 (two
    SOLVER arguments that name one variant among them: ``refuse_same_variants``)."""
    arguments = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(arguments)
    except SystemExit as exc:  # --help (0) or a usage error (2), as a return value
        return exc.code if isinstance(exc.code, int) else EXIT_BAD_INPUT
    mode = "full" if args.full else "fast"
    try:
        check_late_sources()  # (a bad external manifest: refused whichever solvers are named)
        cases = conformance_cases(mode, args.group, args.cases)  # (a pattern that matches nothing: refused there)
        command_solvers = command_solver_of(args.command, args.inputs)
        choose = (args.solvers, args.all, command_solvers, not args.list, args.params)
        in_child = not args.no_isolate and any(names_user_code(name) for name in args.solvers)
        if in_child:  # a module whose import ends or hangs its process: named, as ``run`` names it
            for name in args.solvers:
                if names_user_code(name):
                    probe_import(name.split("[", 1)[0])
        solvers = in_a_child(selected_solvers, *choose) if in_child else selected_solvers(*choose)
        if args.csv is not None:
            check_csv_path(args.csv)
        if args.out is not None:
            check_out_dir(args.out)
    except (OneLine, ProblemInputError, ParamError, SolverSpecError) as exc:
        print(f"contactbench validate: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.list:
        width = max([len(c.name) for c in cases] + [4])
        for c in cases:
            print(f"{c.name:{width}s}  group={c.group:14s} profile={c.profile}")
        return 0
    codes, tables = [], []
    for c in solvers:
        try:
            table = validate(c.load, cases, mode=mode, timeout=args.timeout, isolate=not args.no_isolate,
                             params=c.params if c.params is not None else args.params, label=c.label)
        except LoadFailed as exc:  # (it loaded a moment ago, in another child)
            print(f"contactbench validate: error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        print(table.summary(args.strict) if args.quiet else table.format(args.strict) + "\n", flush=True)
        left = left_out_lines(table) if not args.quiet or not isinstance(c.load, str) else []
        if left:
            print("\n".join(left) + "\n", flush=True)
        codes.append(table.exit_code(args.strict))
        tables.append(table)
    try:
        if args.out:
            path = write_conformance_report(tables, args.out, strict=args.strict, command=arguments)
            print(f"conformance report: {path}")
        if args.csv and tables:
            write_verdict_csv(tables, args.csv, args.strict)
    except (OSError, ProblemInputError) as exc:  # the folder changed while the battery ran
        where = f"{exc.filename}: " if isinstance(exc, OSError) and exc.filename else ""
        text = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        print(f"contactbench validate: error: cannot write {where}{text}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return _combined_exit(codes)


def csv_header() -> str:
    """The first line of every CSV file validate writes (``--csv``; the report's
    verdicts.csv too): the verdict record's columns (``battery.record_columns``)."""
    return ",".join(record_columns())


def is_verdict_csv(path: Path) -> bool:
    """Whether ``path`` is a CSV file validate wrote: a plain file, not a link, that begins
    with ``csv_header`` on a line of its own (``table.files.begins_with``)."""
    return any(begins_with(path, f"{csv_header()}{end}".encode()) for end in ("\n", "\r\n"))


def write_verdict_csv(tables: Sequence[Any], path: str, strict: bool) -> None:
    """The verdict rows of ``tables`` as CSV at ``path``, written whole and renamed into
    place (never through a link)."""
    import pandas as pd

    frame = pd.concat([t.to_frame(strict) for t in tables], ignore_index=True)
    replace_atomically(path, lambda tmp: frame.to_csv(tmp, index=False))


def check_csv_path(path: str) -> None:
    """``--csv PATH`` must name a file that can be written, in a folder that exists, and
    that is new or a CSV file validate wrote (``is_verdict_csv``): a link, a folder or any
    other file there is refused and left as it is (checked before anything runs; a file
    where a folder of the path goes is named)."""
    p = Path(path)
    if p.is_symlink():
        raise CommandLineError(f"--csv {path!r}: is a symbolic link; validate never writes through one: "
                               "give the path of a file")
    if p.is_dir():
        raise CommandLineError(f"--csv {path!r}: is a folder; give the name of a file")
    folder = p.parent
    if not folder.is_dir():
        probe = folder
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if probe.exists() and not probe.is_dir():
            raise CommandLineError(f"--csv {path!r}: {str(probe)!r} is a file, not a folder")
        raise CommandLineError(f"--csv {path!r}: no such folder {str(folder)!r}")
    if not os.access(folder, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise CommandLineError(f"--csv {path!r}: cannot write it (permission denied)")
    if os.path.lexists(p) and not is_verdict_csv(p):
        raise CommandLineError(f"--csv {path!r}: the file there was not written by validate (its first line is "
                               "not the verdict table's header) and would be written over; move it away or give "
                               "a new path")


def check_out_dir(path: str) -> None:
    """``--out DIR`` must be a folder that can be written (``arguments.check_out_dir``) and
    that is new, empty or a conformance report folder (``report.check_report_folder``);
    checked before anything runs."""
    check_report_folder(path)
    check_writable_dir(path)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
