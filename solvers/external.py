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
``./contactbench-solvers.toml`` when it exists.  Each entry becomes a registered solver
of family "external": listed by ``contactbench list solvers``, runnable in every scene,
judged like any other.  A command runs in the folder of the manifest that declares it.

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

1. write the problem directory into a temporary folder (set-up time, ``setup_time_s``);
2. run the command -- split by ``shlex`` and run without a shell, the placeholders
   replaced inside each word -- in its own process group, timed from outside;
3. at the time limit (``ctx.deadline``) kill the program, its descendants and its whole process
   group: ``SolveAborted("timeout")``; once it has exited, its group (a child it left behind;
   one that left the group, ``setsid``, ends with the harness's isolated worker, which adopts
   it: ``harness.run.isolation``);
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
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.kernels import KERNELS
from contactbench.problems.qpfile import (DENSE_LIMIT, SolutionFile, SolutionFileError, read_solution_dir,
                                         write_problem_dir)

from ._processes import end_descendants
from .base import (Capabilities, Outcome, ProblemTraits, Promise, SolveAborted, SolveContext, Solver, Status,
                   check_promise)
from .registry import all_solvers, register

#: Environment variable naming manifest files (os.pathsep-separated).
MANIFEST_ENV = "CONTACTBENCH_EXTERNAL_SOLVERS"
#: The manifest read from the current directory when present.
LOCAL_MANIFEST = "contactbench-solvers.toml"
#: Characters of stdout/stderr kept with a row.
TAIL_CHARS = 2000
#: Seconds a process group gets between SIGTERM and SIGKILL at the time limit.
TERM_GRACE = 0.5
#: Exit codes a shell reports for a child killed by these signals (128 + signal).
SIGNAL_EXITS = {128 + s: s.name for s in (signal.SIGSEGV, signal.SIGABRT, signal.SIGBUS, signal.SIGILL,
                                          signal.SIGFPE, signal.SIGKILL)}
INPUTS = ("dense", "kernel")
_KEYS = {"name", "command", "inputs", "warm_start", "version", "description", "exact", "promise", "load_control",
         "bounds"}
#: The manifest's true/false keys.
_FLAGS = ("warm_start", "exact", "load_control", "bounds")


class ExternalSolverError(RuntimeError):
    """The external program exited with a non-zero code (the row's status "failed")."""


# ---------------------------------------------------------------------------
# The manifest
# ---------------------------------------------------------------------------


#: What an external solver's name may be: it is a row's label, a ``--solvers`` entry (where
#: ',', '[' and ':' have meanings) and part of a folder's name (no '/').
SOLVER_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*")


@dataclass(frozen=True)
class ExternalSpec:
    """One manifest entry (module doc)."""

    name: str
    command: str
    inputs: str = "dense"
    warm_start: bool = False
    version: str | None = None
    description: str = ""
    exact: bool = False
    promise: Promise = "exact"
    load_control: bool = False  # it poses the load equality and may report its multiplier
    bounds: bool = False  # it honours the upper bounds
    workdir: str | None = None  # the folder the command runs in (None: the current one)
    source: str = ""  # the manifest it came from

    def __post_init__(self) -> None:
        where = f" ({self.source})" if self.source else ""
        if not SOLVER_NAME.fullmatch(self.name):
            raise ProblemInputError(f"external solver name {self.name!r}{where} must be letters, digits and "
                                    "'.', '_', '+', '-', starting with a letter or digit (it names rows, "
                                    "--solvers entries and folders)")
        if self.inputs not in INPUTS:
            raise ProblemInputError(f"external solver {self.name!r}{where}: inputs must be 'dense' or 'kernel', "
                                    f"got {self.inputs!r}")
        words = split_command(self.command, self.name)
        if "{solution}" not in self.command or "{problem}" not in self.command:
            raise ProblemInputError(f"external solver {self.name!r}{where}: the command must contain {{problem}} "
                                    f"and {{solution}}, got {self.command!r}")
        if not words:
            raise ProblemInputError(f"external solver {self.name!r}{where}: empty command")


def split_command(template: str, name: str = "command") -> list[str]:
    """The command template split into words as a POSIX shell would (no shell runs it)."""
    try:
        return shlex.split(str(template))
    except ValueError as exc:
        raise ProblemInputError(f"external solver {name!r}: cannot parse command {template!r}: {exc}") from None


def _load_toml(path: Path) -> dict[str, Any]:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ModuleNotFoundError:
            raise ProblemInputError(f"reading {path} needs Python >= 3.11 (tomllib) or the tomli package") from None
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ProblemInputError(f"external solver manifest {path} does not exist") from None
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ProblemInputError(f"external solver manifest {path} is unreadable: {exc}") from None


def _spec_of(entry: Any, path: Path, k: int) -> ExternalSpec:
    where = f"{path} entry {k + 1}"
    if not isinstance(entry, dict):
        raise ProblemInputError(f"{where}: each [[solver]] must be a table")
    unknown = sorted(set(entry) - _KEYS)
    if unknown:
        raise ProblemInputError(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(_KEYS))}")
    for key in ("name", "command"):
        if not isinstance(entry.get(key), str):
            raise ProblemInputError(f"{where}: {key!r} is required and must be a string")
    for key in _FLAGS:
        if key in entry and not isinstance(entry[key], bool):
            raise ProblemInputError(f"{where}: {key!r} must be true or false, got {entry[key]!r}")
    try:
        promise = check_promise(entry.get("promise", "exact"))
    except ValueError as exc:
        raise ProblemInputError(f"{where}: {exc}") from None
    return ExternalSpec(name=entry["name"], command=entry["command"], inputs=str(entry.get("inputs", "dense")),
                        warm_start=bool(entry.get("warm_start", False)), version=entry.get("version"),
                        description=str(entry.get("description", "")), exact=bool(entry.get("exact", False)),
                        promise=promise, load_control=bool(entry.get("load_control", False)),
                        bounds=bool(entry.get("bounds", False)), workdir=str(path.resolve().parent), source=str(path))


def load_manifest(path: str | os.PathLike[str]) -> list[ExternalSpec]:
    """The entries of one manifest (``[[solver]]`` tables); bad content is a
    ``ProblemInputError`` naming the file, the entry and the key."""
    p = Path(path)
    doc = _load_toml(p)
    entries = doc.get("solver", [])
    if not isinstance(entries, list):
        raise ProblemInputError(f"{p}: 'solver' must be an array of tables ([[solver]])")
    specs = [_spec_of(e, p, k) for k, e in enumerate(entries)]
    names = [s.name for s in specs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ProblemInputError(f"{p}: solver name(s) {', '.join(dup)} declared twice")
    return specs


def manifest_paths(environ: dict[str, str] | None = None, cwd: str | None = None) -> list[Path]:
    """The manifests to read: those of ``CONTACTBENCH_EXTERNAL_SOLVERS``, then
    ./contactbench-solvers.toml when it exists (each once)."""
    env = os.environ if environ is None else environ
    paths = [Path(s) for s in env.get(MANIFEST_ENV, "").split(os.pathsep) if s.strip()]
    local = Path(cwd or os.getcwd()) / LOCAL_MANIFEST
    if local.is_file():
        paths.append(local)
    seen: dict[Path, Path] = {}
    for p in paths:
        seen.setdefault(p.resolve(), p)
    return list(seen.values())


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
    kill the group after ``timeout`` seconds (None: no limit), and once the program has
    exited (a child it left behind, still running)."""
    out_path, err_path = scratch / "stdout.txt", scratch / "stderr.txt"
    with open(out_path, "wb") as out, open(err_path, "wb") as err:
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
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)  # what it left running in its group: its solve is over
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            rc, timed_out = None, True
        except BaseException:  # KeyboardInterrupt: leave nothing running behind
            _kill_group(proc)
            raise
        elapsed = time.perf_counter() - t0
    return ProcessResult(rc, elapsed, _read_text(out_path), _read_text(err_path), timed_out)


def command_words(template: str, problem: Path, solution: Path) -> list[str]:
    """The template's words with {problem} and {solution} replaced by the directories."""
    return [w.replace("{problem}", str(problem)).replace("{solution}", str(solution))
            for w in split_command(template)]


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
        return split_command(self.spec.command, self.name)[0]

    def availability(self) -> tuple[bool, str]:
        exe = self.executable()
        if os.sep in exe or (os.altsep and os.altsep in exe):
            path = Path(self.spec.workdir or ".") / exe
            ok = path.is_file() and os.access(path, os.X_OK)
            return (True, "available") if ok else (False, f"{path} is not an executable file")
        if shutil.which(exe) is None:
            return False, f"{exe!r} is not on PATH"
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
        """The output of the manifest's version command (once per process; "" without one)."""
        if self._version is None:
            self._version = ""
            if self.spec.version:
                try:
                    res = subprocess.run(split_command(self.spec.version, self.name), cwd=self.spec.workdir,
                                         capture_output=True, text=True, timeout=10.0, stdin=subprocess.DEVNULL)
                    said = res.stdout.strip() or res.stderr.strip()
                    self._version = said.splitlines()[0][:200] if said else f"(exit {res.returncode})"
                except (OSError, subprocess.TimeoutExpired) as exc:
                    self._version = f"(version command failed: {exc})"
        return self._version

    # -- the solve ------------------------------------------------------------
    def iterate(self, ctx: SolveContext) -> Outcome:
        with tempfile.TemporaryDirectory(prefix=f"contactbench-{self.name}-") as tmp:
            root = Path(tmp)
            problem, solution = root / "problem", root / "solution"
            solution.mkdir()
            write_problem_dir(ctx.qp, problem, tol=ctx.tol, time_limit=ctx.deadline.remaining(), p0=ctx.p0)
            ctx.mark_setup_done()
            limit = ctx.deadline.remaining()
            proc = run_program(command_words(self.spec.command, problem, solution), self.spec.workdir, limit, root)
            info = {"external_command": self.spec.command, "external_time_s": proc.elapsed,
                    "external_returncode": proc.returncode, "external_output_tail": proc.tail()}
            if self.spec.version:
                info["external_version"] = self.version()
            ctx.info.update(info)
            program_outcome(proc, self.name, limit)
            sol = solution_of(proc, solution, ctx.n)
        claimed, status, note = solution_status(sol)
        ctx.info.update({"external_status": sol.status, "external_time_reported_s": sol.time_s})
        message = f"external: exit 0 in {proc.elapsed:.3g} s, status {sol.status or 'none'}"
        if note:
            message += f" ({note})"
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
