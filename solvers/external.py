"""External solvers: any program that speaks the file protocol of ``problems/qpfile.py``.

An external solver is declared in a TOML manifest (docs/external-solvers.md)::

    [[solver]]
    name = "pgs-c"                                  # registry name
    command = "./pgs {problem} {solution}"          # {problem}, {solution}: directories
    inputs = "dense"                                # "dense" (reads H) or "kernel" (kernel_table)
    warm_start = false                              # it reads p0.f64 when given
    version = "./pgs --version"                     # optional: recorded with each answer
    description = "projected Gauss-Seidel in C"     # optional
    exact = false                                   # optional: finite termination (exact answers)
    promise = "exact"                               # optional: "exact" or a scaled KKT floor (validate)
    load_control = false                            # optional: it poses sum(p) = P, reports the multiplier
    bounds = false                                  # optional: it honours upper bounds (a hardness)

Manifests are read from the files named by the environment variable
``CONTACTBENCH_EXTERNAL_SOLVERS`` (one or more paths separated by ``os.pathsep``) and from
``./contactbench-solvers.toml`` when anything has that name.  Each entry becomes a registered
solver of family "external": listed by ``contactbench list solvers``, runnable in every scene,
judged like any other.  A command runs in the folder of the manifest that declares it.
Reading and checking a manifest -- its keys, the name (at most ``NAME_MAX_CHARS``
characters), the command template and its placeholders (``{problem}``, ``{solution}``; a
literal brace written ``{{`` or ``}}``), the version command -- is
``solvers/_external_manifest.py``'s: a manifest that cannot be read or has a bad entry is
refused whole, in one line naming the file, before anything runs.

The version command is run once in a process, when its ``availability()`` is asked -- as
the harness does before it runs a solver (``run``'s plan, ``validate``, ``list solvers``) --
under its own limit (``VERSION_LIMIT_S``), never inside a solve: a solve records the text
asked (``info["external_version"]``, and in its message, the row's ``solver_message``) --
its worker, forked from the process that asked, holds it -- or, where it was not asked,
``VERSION_NOT_ASKED``.  A command that fails, or gives no answer in time, gives a text in
parentheses saying so, and never fails or times a solve.

Constrained problems (``problems.constraints``) are written in format 2: ``upper.f64``
and ``"load"`` in problem.json.  A program is handed them only when its manifest
declares it can pose them (``load_control = true``: the equality sum(p) = P, whose
multiplier, the approach Delta, it may report as ``"multiplier"`` in solution.json;
``bounds = true``: 0 <= p <= upper); an entry that declares neither is skipped on such a
problem with the reason (``base.constraint_skip``), as before.
(The registration is done by ``solvers/external_manifests.py``, a late source of the
registry: the manifests are read when external solvers are resolved -- a name that is
not built in, or the list of every solver -- not on import, so that a broken manifest is
reported as that source's error and this module stays importable, e.g. for
``validate --command``.)

One solve (``ExternalSolver.iterate``):

1. write the problem directory -- with the tolerance, the time left and the iteration
   limit (``ctx.max_iter``, null where the program keeps its own) -- into a temporary
   folder (set-up time, ``setup_time_s``), named
   after at most ``TEMP_NAME_CHARS`` characters of the solver's name; a removal of that
   folder that fails afterwards is no failure of the row;
2. run the command -- split by ``shlex`` and run without a shell, the placeholders
   replaced inside each word -- in its own process group, timed from outside;
3. at the time limit (``ctx.deadline``) kill the program, its descendants and its whole process
   group: ``SolveAborted("timeout")``.  However it ends, every process it started has
   ended before its answer is read (``run_program``): what it left running in its group,
   and what left the group (``setsid``) and was adopted by the solving process
   (``_processes.ends_what_it_starts``; that process's other children are left alone);
   death by a signal (a segfault): ``SolveAborted("crashed")``; a non-zero exit:
   ``ExternalSolverError`` (the row's status "failed"), with the tail of stderr/stdout;
4. read the solution directory (``read_solution_dir``, ``as_written``): a missing or
   unreadable p.f64, or a status outside the protocol's words, is a ``SolutionFileError``
   naming what is wrong; a p of the wrong length or with NaN, inf or negative entries
   goes to the judge as written (no answer, or an inaccurate one: wrong when claimed);
5. the claim (``SolutionFile.claims_converged``): the statuses "converged", "solved" and
   "optimal" claim convergence, and so does a missing status; "not_converged",
   "max_iter", "time_limit", "stalled" and "failed" claim nothing.  The harness judges p
   with its KKT check.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.kernels import KERNELS
from contactbench.problems.qpfile import (DENSE_LIMIT, SolutionFile, SolutionFileError, read_solution_dir,
                                         write_problem_dir)

from ._external_manifest import LOCAL_MANIFEST as LOCAL_MANIFEST  # (its callers read both names here)
from ._external_manifest import MANIFEST_ENV as MANIFEST_ENV
from ._external_manifest import ExternalSpec, filled_words, load_manifest, manifest_paths, split_command
from ._processes import end_descendants, ends_what_it_starts
from .base import Capabilities, Outcome, ProblemTraits, SolveAborted, SolveContext, Solver, Status
from .registry import all_solvers, register

#: Characters of stdout/stderr kept with a row.
TAIL_CHARS = 2000
#: Seconds a process group gets between SIGTERM and SIGKILL at the time limit.
TERM_GRACE = 0.5
#: Exit codes a shell reports for a child killed by these signals (128 + signal).
SIGNAL_EXITS = {128 + s: s.name for s in (signal.SIGSEGV, signal.SIGABRT, signal.SIGBUS, signal.SIGILL,
                                          signal.SIGFPE, signal.SIGKILL)}
#: Seconds the version command of a manifest may run (``ExternalSolver.version``).
VERSION_LIMIT_S = 10.0
#: Characters of the version command's first line that are recorded.
VERSION_CHARS = 200
#: The version text of a solve in a process that did not ask the version (``ExternalSolver.version``).
VERSION_NOT_ASKED = "(version command not run in this process: its availability() was not asked)"
#: Characters of a solver's name in the name of its solve's temporary folder.
TEMP_NAME_CHARS = 32


class ExternalSolverError(RuntimeError):
    """The external program exited with a non-zero code (the row's status "failed")."""


# ---------------------------------------------------------------------------
# Running the program
# ---------------------------------------------------------------------------


@dataclass
class ProcessResult:
    """One run of the external program."""

    returncode: int | None  # None: killed at the time limit
    elapsed: float
    stdout: str
    stderr: str
    timed_out: bool = False

    def tail(self, chars: int = TAIL_CHARS) -> str:
        """The last ``chars`` characters of stderr and stdout (labelled)."""
        parts = [(k, v.strip()) for k, v in (("stderr", self.stderr), ("stdout", self.stdout)) if v.strip()]
        return "\n".join(f"[{k}] {v[-chars:]}" for k, v in parts)


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM to the process group, SIGKILL after TERM_GRACE seconds; and SIGKILL, first,
    to the program's descendants that left its group (``setsid``): found while it runs."""
    end_descendants(proc.pid, except_group=proc.pid)
    for sig, wait in ((signal.SIGTERM, TERM_GRACE), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=wait)
            if sig == signal.SIGTERM:  # the leader is gone; make sure its children are too
                os.killpg(proc.pid, signal.SIGKILL)
            break
        except subprocess.TimeoutExpired:
            continue
        except ProcessLookupError:
            break
    try:
        proc.wait(timeout=5.0)
    except subprocess.TimeoutExpired:  # pragma: no cover - an unkillable process
        pass


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: the program gets SIGKILL if the solving process dies (no orphan survives a
    harness worker killed at its hard limit)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except Exception:
        pass


def _read_text(path: Path) -> str:
    try:
        with open(path, "rb") as fh:
            size = fh.seek(0, os.SEEK_END)
            fh.seek(max(0, size - 4 * TAIL_CHARS))
            return fh.read().decode("utf-8", errors="replace")
    except OSError:
        return ""


def run_program(argv: Sequence[str], workdir: str | None, timeout: float | None, scratch: Path) -> ProcessResult:
    """Run ``argv`` in its own process group with stdout/stderr to files in ``scratch``;
    kill the group after ``timeout`` seconds (None: no limit).  However it ends, every
    process it started has ended when this returns (``ends_what_it_starts``): what it left
    running in its group, and what left the group (``setsid``) and was adopted by this
    process; this process's other children are left alone."""
    out_path, err_path = scratch / "stdout.txt", scratch / "stderr.txt"
    with open(out_path, "wb") as out, open(err_path, "wb") as err, ends_what_it_starts():
        t0 = time.perf_counter()
        try:
            proc = subprocess.Popen(list(argv), cwd=workdir, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                    start_new_session=True,
                                    preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None)
        except OSError as exc:
            raise ExternalSolverError(f"cannot start {argv[0]!r}: {exc}") from None
        try:
            rc: int | None = proc.wait(timeout=timeout)
            timed_out = False
            elapsed = time.perf_counter() - t0
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)  # what it left running in its group: its solve is over
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            rc, timed_out = None, True
            elapsed = time.perf_counter() - t0
        except BaseException:  # KeyboardInterrupt: leave nothing running behind
            _kill_group(proc)
            raise
    return ProcessResult(rc, elapsed, _read_text(out_path), _read_text(err_path), timed_out)


def command_words(template: str, problem: Path, solution: Path) -> list[str]:
    """The template's words with {problem} and {solution} replaced by the directories (and
    each doubled brace by one: ``solvers._external_manifest``)."""
    return filled_words(template, {"problem": str(problem), "solution": str(solution)})


def version_text(proc: ProcessResult) -> str:
    """What a run of a version command says: the first line it printed (stdout, else
    stderr), or, when it did not exit 0, a text in parentheses saying so."""
    said = proc.stdout.strip() or proc.stderr.strip()
    first = said.splitlines()[0][:VERSION_CHARS] if said else ""
    if proc.timed_out:
        return f"(version command gave no answer within {VERSION_LIMIT_S:g} s)"
    if proc.returncode != 0:
        return f"(version command exited {proc.returncode}{': ' + first if first else ''})"
    return first or "(version command printed nothing)"


def ask_version(command: str, workdir: str | None) -> str:
    """The version text (``version_text``) of a version command (checked by ``ExternalSpec``),
    run once in ``workdir`` under ``VERSION_LIMIT_S``; one that cannot start gives a text
    saying so."""
    with tempfile.TemporaryDirectory(prefix="contactbench-version-", ignore_cleanup_errors=True) as tmp:
        try:
            proc = run_program(split_command(command, what="version command"), workdir, VERSION_LIMIT_S, Path(tmp))
        except ExternalSolverError as exc:
            return f"(version command failed: {exc})"
    return version_text(proc)


def program_outcome(proc: ProcessResult, name: str, limit: float | None) -> None:
    """Raise for a run without an answer (module doc, step 3); return when it exited 0."""
    tail = proc.tail()
    suffix = f"\n{tail}" if tail else ""
    if proc.timed_out:
        raise SolveAborted("timeout", f"external solver {name!r} killed at its time limit of {limit:.3g} s"
                                      f"{suffix}")
    rc = int(proc.returncode or 0)
    if rc < 0:
        try:
            sig = signal.Signals(-rc).name
        except ValueError:
            sig = str(-rc)
        raise SolveAborted("crashed", f"external solver {name!r} died by signal {sig}{suffix}")
    if rc in SIGNAL_EXITS:
        raise SolveAborted("crashed", f"external solver {name!r} exited {rc} (a child killed by "
                                      f"{SIGNAL_EXITS[rc]}){suffix}")
    if rc != 0:
        raise ExternalSolverError(f"external solver {name!r} exited with code {rc}{suffix}")


def solution_of(proc: ProcessResult, solution: Path, n: int) -> SolutionFile:
    """The answer a program that exited 0 wrote (``read_solution_dir``, p as written); a
    ``SolutionFileError`` that says what is wrong with it carries the program's output tail,
    as a failed exit does."""
    try:
        return read_solution_dir(solution, n, as_written=True)
    except SolutionFileError as exc:
        tail = proc.tail()
        if not tail:
            raise
        raise SolutionFileError(f"{exc}\n{tail}") from None


def solution_status(sol: SolutionFile) -> tuple[bool, Status, str]:
    """(claims convergence, Status, note) of an outside program's report (its status is
    one of the protocol's words: ``read_solution_dir`` refuses any other)."""
    if sol.status is None:
        return True, Status.CONVERGED, "no status given: read as a claim of convergence"
    if sol.claims_converged:
        return True, Status.CONVERGED, "" if sol.status == "converged" else f"{sol.status!r}: a claim of convergence"
    if sol.status == "not_converged":
        return False, Status.STALLED, ""
    return False, Status(sol.status), ""


# ---------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------


class ExternalSolver(Solver):
    """A registered solver that runs an outside program (module doc)."""

    family = "external"

    def __init__(self, spec: ExternalSpec) -> None:
        self.spec = spec
        self.name = spec.name  # type: ignore[misc]
        self.description = spec.description or f"external program: {spec.command}"  # type: ignore[misc]
        dense = spec.inputs == "dense"
        self.capabilities = Capabilities(  # type: ignore[misc]
            operators=frozenset({"dense"}) if dense else frozenset({"fft"}), needs_dense=dense,
            warm_start="primal" if spec.warm_start else "none", exact=spec.exact, promise=spec.promise,
            input_format="dense" if dense else "kernel-table", load_control=spec.load_control, bounds=spec.bounds)
        self._version: str | None = None

    # -- what the harness asks ----------------------------------------------
    def executable(self) -> str:
        return split_command(self.spec.command, f"external solver {self.name!r}")[0]

    def pinned_source(self) -> bytes:
        """The manifest entry (its command, inputs, workdir and version command) and the
        bytes of every file its command names that exists -- the program, and a script an
        interpreter runs (``python3 solve.py ...``): an edited program is another solver
        to a results folder (``registry.source_digest``)."""
        entry = json.dumps({k: v for k, v in asdict(self.spec).items() if k != "source"}, sort_keys=True)
        return entry.encode("utf-8") + b"".join(p.read_bytes() for p in self.command_files())

    def command_files(self) -> list[Path]:
        """The regular files the command's words name: the first word on PATH or under the
        workdir, the others under the workdir (placeholders and options name none)."""
        words = split_command(self.spec.command, f"external solver {self.name!r}")
        base = Path(self.spec.workdir or ".")
        found = [base / w for w in words if "{" not in w and (base / w).is_file()]
        on_path = shutil.which(words[0]) if words and os.sep not in words[0] else None
        return ([Path(on_path)] if on_path and (base / words[0]) not in found else []) + found

    def availability(self) -> tuple[bool, str]:
        exe = self.executable()
        if os.sep in exe or (os.altsep and os.altsep in exe):
            path = Path(self.spec.workdir or ".") / exe
            if not (path.is_file() and os.access(path, os.X_OK)):
                return False, f"{path} is not an executable file"
        elif shutil.which(exe) is None:
            return False, f"{exe!r} is not on PATH"
        self.version()  # (module doc: before any solve)
        return True, "available"

    def skip(self, traits: ProblemTraits) -> str | None:
        if self.spec.inputs == "dense" and traits.n > DENSE_LIMIT:
            return (f"{self.name} reads the dense H, which the file protocol writes only up to n = {DENSE_LIMIT} "
                    f"(CONTACTBENCH_QPFILE_DENSE_LIMIT); this problem has n = {traits.n}")
        if self.spec.inputs == "kernel" and traits.kernel not in KERNELS:
            return (f"{self.name} reads the kernel table; this problem's H ({traits.kernel or 'a matrix'}) "
                    "is not a grid kernel")
        return super().skip(traits)

    def default_max_iter(self, n: int) -> int | None:
        return None  # the program keeps its own

    def version(self) -> str:
        """The version text of the manifest's version command (``ask_version``), asked once
        in this process ("" without one).  ``availability`` asks it, so that it runs before
        any solve and outside its time; a solve only records what was asked."""
        if self._version is None:
            self._version = ask_version(self.spec.version, self.spec.workdir) if self.spec.version else ""
        return self._version

    # -- the solve ------------------------------------------------------------
    def iterate(self, ctx: SolveContext) -> Outcome:
        with tempfile.TemporaryDirectory(prefix=f"contactbench-{self.name[:TEMP_NAME_CHARS]}-",
                                         ignore_cleanup_errors=True) as tmp:  # (a removal that fails: not the row's)
            root = Path(tmp)
            problem, solution = root / "problem", root / "solution"
            solution.mkdir()
            write_problem_dir(ctx.qp, problem, tol=ctx.tol, time_limit=ctx.deadline.remaining(), p0=ctx.p0,
                              max_iter=ctx.max_iter)
            ctx.mark_setup_done()
            limit = ctx.deadline.remaining()
            proc = run_program(command_words(self.spec.command, problem, solution), self.spec.workdir, limit, root)
            info = {"external_command": self.spec.command, "external_time_s": proc.elapsed,
                    "external_returncode": proc.returncode, "external_output_tail": proc.tail()}
            if self.spec.version:
                info["external_version"] = self._version if self._version is not None else VERSION_NOT_ASKED
            ctx.info.update(info)
            program_outcome(proc, self.name, limit)
            sol = solution_of(proc, solution, ctx.n)
        claimed, status, note = solution_status(sol)
        ctx.info.update({"external_status": sol.status, "external_time_reported_s": sol.time_s})
        message = f"external: exit 0 in {proc.elapsed:.3g} s, status {sol.status or 'none'}"
        if note:
            message += f" ({note})"
        if "external_version" in ctx.info:
            message += f"; version {ctx.info['external_version']}"
        tail = proc.tail(300).replace("\n", " | ")
        if tail:
            message += f"; {tail}"
        multiplier = sol.multiplier if ctx.constraints.load_control else None
        return Outcome(np.asarray(sol.p), int(sol.iterations or 0), claimed, message[:500], w=None,
                       status=status, info={}, multiplier=multiplier)


def command_solver(command: str, inputs: str = "dense", name: str = "command", *, warm_start: bool = False,
                   workdir: str | None = None, load_control: bool = False, bounds: bool = False) -> ExternalSolver:
    """An unregistered external solver for ``contactbench validate --command``."""
    return ExternalSolver(ExternalSpec(name=name, command=command, inputs=inputs, warm_start=warm_start,
                                       description=f"command: {command}", load_control=load_control, bounds=bounds,
                                       workdir=workdir, source="--command"))


# ---------------------------------------------------------------------------
# Registration
# ---------------------------------------------------------------------------


def register_manifest(path: str | os.PathLike[str], replace: bool = False) -> list[ExternalSolver]:
    """Register every entry of one manifest.  A name that is already registered is an
    error naming both, unless ``replace`` and the registered one is external too."""
    solvers = [ExternalSolver(s) for s in load_manifest(path)]
    known = all_solvers()
    for s in solvers:
        old = known.get(s.name)
        if old is not None and not (replace and isinstance(old, ExternalSolver)):
            where = old.spec.source if isinstance(old, ExternalSolver) else f"family {old.family!r}"
            raise ProblemInputError(f"{path}: external solver name {s.name!r} is already registered ({where})")
    for s in solvers:
        register(s, replace=True)
    return solvers


def _import_builtin_solvers() -> None:
    """Import the other solver modules first, so that a manifest entry that reuses a
    built-in name is refused here rather than breaking the built-in (a module that fails
    to import is left for the registry's discovery to record)."""
    import pkgutil

    package = __name__.rsplit(".", 1)[0]
    pkg = importlib.import_module(package)
    for m in sorted(pkgutil.walk_packages(pkg.__path__, prefix=f"{package}."), key=lambda m: m.name):
        short = m.name.rsplit(".", 1)[-1]
        if short.startswith("_") or short in ("base", "registry", "external", "external_manifests"):
            continue
        try:
            importlib.import_module(m.name)
        except Exception:  # recorded by the registry's discovery
            pass


def register_manifests(paths: Sequence[Path] | None = None) -> list[ExternalSolver]:
    """Register the entries of every manifest (``manifest_paths()`` by default); every
    good manifest is registered before the errors of the bad ones are raised together."""
    done: list[ExternalSolver] = []
    errors: list[str] = []
    paths = manifest_paths() if paths is None else list(paths)
    if paths:
        _import_builtin_solvers()
    for p in paths:
        try:
            done += register_manifest(p, replace=False)
        except (ProblemInputError, ValueError) as exc:
            errors.append(str(exc))
    if errors:
        raise ProblemInputError("; ".join(errors))
    return done
