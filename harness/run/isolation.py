"""Process isolation for solves: a long-lived worker process with a hard wall-clock limit.

A solver runs inside a child process that the harness (the parent) can kill.  The
parent sends one message at a time over a pipe and waits at most ``timeout`` seconds
for the answer; then

* an answer            -> ``ChildReply(kind="ok")`` (or ``"error"`` if the handler raised),
* no answer in time    -> the child is killed (SIGKILL) -> ``ChildReply(kind="timeout")``,
  whose detail names where the worker was, read just before (``stacks.where_it_was``),
* the child died       -> ``ChildReply(kind="crashed")`` with its signal / exit code
  (a segfault or ``os.abort`` in a solver costs only the message that caused it).

The worker is restarted lazily on the next call, with a fresh handler (all worker
state -- built instances, warm starts -- is lost; callers track a ``generation``
counter to know).  The child:

* ignores SIGINT, so Ctrl-C reaches only the parent, which stops cleanly;
* leads a process group of its own, which the parent kills whenever the worker ends, so
  the processes a solver started do not outlive it (``kill_process_group``);
* adopts the orphans among its descendants (Linux, ``PR_SET_CHILD_SUBREAPER``:
  ``contactbench.solvers._processes``), so that a process a solver started stays its
  descendant even after leaving that group (``setsid``) and its parent exiting; after each
  message it kills every descendant left (what a solve started ends with the solve), and
  the parent kills the worker's descendants, found by their parent links, before the
  worker itself;
* runs under a keeper where orphans can be adopted: the child the parent starts adopts
  orphans too and forks the worker, its one child, so that what the worker started is
  still the keeper's descendant when the worker dies on its own (``os._exit``, a signal)
  -- the worker's orphans are re-parented to the keeper, and to no process that is not
  the worker's.  When the worker exits the keeper kills every process left, collects
  them, and ends as the worker did (its exit code, its signal: ``describe_exit`` names the
  worker's).  In the worker, ``os.getppid()`` is the keeper's pid.  Elsewhere
  (``SUBREAPER_MISSING``) the child is the worker, and a process that leaves its group and
  whose parent exits is out of reach.  Out of reach as well: what a solve started and moved
  out of its group when the solve itself kills its keeper (SIGKILL) -- a solver that does so
  is not one ``run`` trusts (docs/verdicts.md);
* asks the kernel to signal it when the parent dies (``PR_SET_PDEATHSIG``): the worker
  SIGKILL, the keeper SIGTERM, on which it kills what it keeps (``_end_kept_tree``) -- so a
  ``kill -9`` of the runner leaves no orphan writing rows, nor one a solve started;
* optionally limits BLAS (threadpoolctl) and FFT (``CONTACTBENCH_FFT_WORKERS``) threads,
  so J workers do not oversubscribe the cores.
* keeps its temporary files, and those of the programs it runs (``TMPDIR``), in a folder
  of its own, which the parent removes whenever the worker ends -- killed at a time limit
  or an interrupt included;
* optionally (``capture_output``) writes what the handler prints -- file descriptors 1
  and 2, so C libraries' output too -- to a file in that folder instead of the parent's
  terminal; a reply of a worker that died, timed out or failed quotes its last lines.

Workers are started with the ``fork`` method on Linux: a child inherits everything
registered in the parent (solvers registered by a test or given as ``module:NAME``).  A fork
soon after another first lets the threads that fork started reach their wait
(``forks.settle_after_fork``): a library pool's stop before a fork misses a thread still on
its way there, and the fork waits for it for ever.
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import math
import os
import resource
import shutil
import signal
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Callable, Iterator, Literal, NoReturn

from contactbench.problems.output_streams import output_to_fd
from contactbench.solvers._loading import exception_message as exception_message
from contactbench.solvers._loading import exception_text as exception_text
from contactbench.solvers._processes import REAP_WAIT_S, become_subreaper, end_descendants, end_own_descendants

from ..table.files import pid_exists
from .forks import process_context, settle_after_fork, settle_every_fork
from .stacks import dump_stacks_on_signal, pass_stack_signal_to, short_path, where_it_was

Handler = Callable[[Any], Any]
HandlerFactory = Callable[[], Handler]
ChildReplyKind = Literal["ok", "error", "timeout", "crashed"]


#: What a solver may raise inside a worker, each recorded as the row's error: anything.
#: The worker ignores SIGINT (the parent handles Ctrl-C), so a ``KeyboardInterrupt``,
#: ``SystemExit`` or ``GeneratorExit`` there is the solver's own doing, not the user's.
SOLVER_RAISES: tuple[type[BaseException], ...] = (BaseException,)

#: What a solver's code may raise where Ctrl-C is not ignored (the parent's skip decisions,
#: an in-process ``validate``), each recorded as the solver's fault: anything but a
#: ``KeyboardInterrupt``, which there is the user's and stops the run.
SOLVER_FAULTS: tuple[type[BaseException], ...] = (Exception, SystemExit, GeneratorExit)


def raised_at(exc: BaseException, frames: int = 2) -> str:
    """Where ``exc`` was raised: its innermost ``frames`` frames, innermost first, each as
    ``path:line in function`` with the path cut below ``site-packages`` (a peer's own
    module) or to its file name -- so a row tells a solver's bug from a dependency's."""
    stack = traceback.extract_tb(exc.__traceback__)[-frames:]
    return " <- ".join(f"{short_path(f.filename)}:{f.lineno} in {f.name}" for f in reversed(stack))


def error_text(exc: BaseException) -> str:
    """One line for a row: the exception, its message and where it was raised."""
    where = raised_at(exc)
    return exception_text(exc) + (f" [at {where}]" if where else "")


@dataclass
class ChildReply:
    """What came back from one message: the handler's value, or why nothing did."""

    kind: ChildReplyKind
    value: Any = None
    elapsed: float = 0.0
    detail: str = ""
    exitcode: int | None = None  # kind "crashed": the worker's exit code (minus its signal), None if unread

    @property
    def ok(self) -> bool:
        return self.kind == "ok"


def set_parent_death_signal(sig: int = signal.SIGKILL) -> None:
    """Linux: have the kernel send ``sig`` to this process when its parent dies."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, int(sig), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except OSError:  # pragma: no cover - no libc (musl, ...): best effort
        pass


def limit_threads(threads: int | None) -> Any:
    """Limit BLAS/OpenMP threads (threadpoolctl) and FFT workers in this process.

    Returns the threadpoolctl controller (keep a reference for the limit to hold)."""
    if not threads:
        return None
    n = str(int(threads))
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "CONTACTBENCH_FFT_WORKERS"):
        os.environ[var] = n
    try:
        from threadpoolctl import threadpool_limits

        return threadpool_limits(limits=int(threads))
    except Exception:  # pragma: no cover - threadpoolctl missing
        return None


#: The file, in a worker's temporary folder, that holds what its handler printed
#: (``ChildProcess(capture_output=True)``), one message's worth at a time.
OUTPUT_NAME = "handler-output.txt"
#: How many of its last lines a reply of a worker that died, timed out or failed quotes.
OUTPUT_TAIL_LINES = 5
#: How much of the end of that file is read for them (bytes).
OUTPUT_TAIL_BYTES = 4096
#: The disk space (bytes) one message's output file may take while the parent waits for the
#: reply: past it the parent drops all but the first ``KEPT_HEAD_BYTES`` (``bound_output``),
#: so a solver printing without end cannot fill the disk before its time limit.
OUTPUT_FILE_CAP = 64 * 1024 * 1024
#: The head of a message's output that is kept (the run's log keeps no more of an entry).
KEPT_HEAD_BYTES = 64 * 1024
#: How often (seconds) a waiting parent checks the output files' size.
OUTPUT_CHECK_S = 0.1


def bound_output(path: str, cap: int = OUTPUT_FILE_CAP, head: int = KEPT_HEAD_BYTES) -> None:
    """Cut the output file ``path`` back to its first ``head`` bytes when it takes more than
    ``cap`` bytes of disk.  The writer keeps its offset (the file is not opened to append),
    so what it writes next lands past a hole: the file's size still counts every byte
    printed, its blocks hold only the head and what came since; nothing when it is gone."""
    with contextlib.suppress(OSError):
        st = os.stat(path)
        if st.st_blocks * 512 > cap:
            os.truncate(path, head)


@contextlib.contextmanager
def output_to(path: str) -> Iterator[None]:
    """File descriptors 1 and 2 (stdout and stderr, of Python and of C libraries alike)
    point at ``path`` (truncated; the null device where it cannot be opened) for the
    block, and ``sys.stdout``/``sys.stderr`` write there too (``output_to_fd``); then all
    is put back."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    except OSError:  # the folder is gone (a solver emptied its TMPDIR): the output is dropped
        fd = os.open(os.devnull, os.O_WRONLY)
    try:
        with output_to_fd(fd):
            yield
    finally:
        os.close(fd)


def kill_process_group(pgid: int) -> None:
    """SIGKILL every process of group ``pgid`` (a worker's: the worker and what it started);
    nothing when the group is gone."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


#: In a worker: the pid of the process that started it, on the harness's side (its parent,
#: or its keeper's parent where a keeper holds its tree); None elsewhere.
STARTED_BY: int | None = None


def _worker_main(conn: Connection, factory: HandlerFactory, threads: int | None, scratch: str | None = None,
                 capture_output: bool = False, other_end: Connection | None = None) -> None:
    global STARTED_BY
    STARTED_BY = os.getppid()
    if other_end is not None:  # (the parent's end, inherited by a fork: held here, the parent's close is no EOF)
        other_end.close()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # (the command's own handler is its process's)
    with contextlib.suppress(OSError):  # a group of its own, killed with it (``kill_process_group``)
        os.setpgid(0, 0)
    if scratch is not None:  # the worker's temporary files (and its programs'), removed by the parent
        tempfile.tempdir = os.environ["TMPDIR"] = scratch
        dump_stacks_on_signal(scratch)  # (read at a timeout, before the kill: ``where_it_was``)
    set_parent_death_signal()
    if become_subreaper():  # this process keeps the worker's tree (``keep_worker_tree``); the worker is its child
        signal.signal(signal.SIGTERM, _end_kept_tree)
        set_parent_death_signal(signal.SIGTERM)  # (the keeper's: what it keeps ends with it)
        keeper = os.getpid()
        settle_after_fork()  # the pool threads the fork that made this process started are waiting (``forks``)
        worker = os.fork()
        if worker:
            conn.close()  # (the worker's end of the pipe is the worker's alone: its death reads as EOF)
            pass_stack_signal_to(worker)
            keep_worker_tree(worker)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        set_parent_death_signal()
        if os.getppid() != keeper:  # pragma: no cover - the keeper died before the line above
            os._exit(1)
        become_subreaper()  # the orphans of what a solver starts stay this worker's descendants
    settle_every_fork()  # a solver's own fork, too (``forks``)
    if not os.environ.get("CONTACTBENCH_FAULTHANDLER"):
        faulthandler.disable()  # a crashing solver is reported as a row, not a stack dump
    _limits = limit_threads(threads)  # noqa: F841 - held for the process lifetime
    output = os.path.join(scratch, OUTPUT_NAME) if scratch is not None else os.devnull
    serve(conn, factory(), output if capture_output else None)


def serve(conn: Connection, handler: Handler, output: str | None) -> None:
    """The worker's loop: each message's reply, what it printed to ``output`` (None: where
    the process's output goes), and what it started ended before the reply is sent."""
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        try:
            with output_to(output) if output is not None else contextlib.nullcontext():
                reply: tuple[str, Any] = ("ok", handler(msg))
        except Exception as exc:  # the handler's own failure; solver errors are rows
            reply = ("error", f"{exception_text(exc)}\n{traceback.format_exc(limit=6)}")
        end_own_descendants()  # what the message started ends with it, before its reply
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return
        except Exception as exc:  # a reply that cannot be pickled: the handler's failure, said so
            try:
                conn.send(("error", f"the handler's reply cannot be sent to the parent: {exception_text(exc)}"))
            except (BrokenPipeError, OSError):
                return


def keep_worker_tree(worker: int) -> NoReturn:
    """The keeper's life (module doc): collect the orphans it adopts until its one child, the
    worker, exits; then kill every process left -- each a descendant of the worker, however
    it ended (``os._exit``, a signal) -- and end as the worker did, so that the parent reads
    the worker's own exit."""
    while True:
        pid, status = os.waitpid(-1, 0)
        if pid == worker:
            break
    end_own_descendants()
    exit_as(os.waitstatus_to_exitcode(status))


def _end_kept_tree(signum: int, frame: Any) -> NoReturn:
    """The keeper's SIGTERM -- its death signal, sent when the process that started it dies
    (a ``kill -9`` of the runner): every process it keeps is killed before it ends."""
    end_own_descendants()
    os._exit(128 + signum)


def exit_as(code: int) -> NoReturn:
    """End this process with exit code ``code``, or by signal ``-code`` where it is negative
    (no core dump of its own: the process that took the signal dumped one if any)."""
    if code < 0:
        sig = -code
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        with contextlib.suppress(ValueError, OSError):
            signal.signal(sig, signal.SIG_DFL)
        with contextlib.suppress(ValueError, OSError):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {sig})
        os.kill(os.getpid(), sig)
        code = 128 + sig  # (a signal that does not end a process: its number, as a shell says it)
    os._exit(code)


def how_it_ended(exitcode: int | None) -> str:
    """How a process whose exit code (``multiprocessing``'s: minus the signal that killed
    it, None while it runs) is ``exitcode`` ended: 'killed by signal SIGABRT' / 'exited
    with code 3' / 'did not exit'."""
    if exitcode is None:
        return "did not exit"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = str(-exitcode)
        return f"killed by signal {name}"
    return f"exited with code {exitcode}"


def describe_exit(exitcode: int | None) -> str:
    """'worker killed by signal SIGABRT' / 'worker exited with code 3' / 'worker did not
    exit' (``how_it_ended``)."""
    return f"worker {how_it_ended(exitcode)}"


#: Seconds the parent waits at most, once a worker's pipe is closed, for its process to end
#: (``ChildReply.exitcode``): a keeper first kills and collects what it keeps, which takes up
#: to ``REAP_WAIT_S`` and longer on a loaded machine.  A wait for the kernel, which returns as
#: soon as the process ends, not a claim on speed.
DIED_WAIT_S = REAP_WAIT_S + 25.0

#: How often (seconds) a parent waiting on a worker's pipe checks that its keeper lives
#: (``ChildProcess._answered_within``): a process the solver started and left running may
#: hold the pipe open after the worker and its keeper died, so no end of file comes.
KEEPER_CHECK_S = 0.25

#: A worker's temporary folder is ``<tmp>/<prefix><owner's pid>-<random>``.
SCRATCH_PREFIX = "contactbench-worker-"


def pid_space() -> str:
    """This process's pid namespace (the inode of /proc/self/ns/pid; "0" where unreadable)."""
    try:
        return str(os.stat("/proc/self/ns/pid").st_ino)
    except OSError:
        return "0"


def scratch_owner(pid: int | None = None) -> str:
    """The owner tag of a worker's temporary folder: "<pid namespace>.<pid>" of the process
    that starts the worker (default: this one), so that only a process of the same pid
    namespace -- not another container sharing the temporary folder -- reads the pid."""
    return f"{pid_space()}.{os.getpid() if pid is None else pid}"


def remove_orphan_scratch() -> None:
    """Remove the workers' temporary folders whose owner -- the process that started the
    worker, in this pid namespace (``scratch_owner``) -- is no longer alive (it was killed
    before it could remove them)."""
    space = pid_space()
    for d in Path(tempfile.gettempdir()).glob(f"{SCRATCH_PREFIX}*-*"):
        owner_space, _, pid = d.name[len(SCRATCH_PREFIX):].split("-", 1)[0].rpartition(".")
        if owner_space == space and pid.isdigit() and not pid_exists(int(pid)) and d.is_dir() and not d.is_symlink():
            shutil.rmtree(d, ignore_errors=True)


class ChildProcess:
    """One child process running ``factory()``'s handler on each message sent to it."""

    def __init__(self, factory: HandlerFactory, threads: int | None = None, start_method: str | None = None,
                 capture_output: bool = False, output_files: tuple[str, ...] = (),
                 output_cap: int = OUTPUT_FILE_CAP) -> None:
        self.factory = factory
        self.threads = threads
        self.capture_output = capture_output  # the handler's stdout/stderr to a file (module doc)
        self.output_files = output_files  # other files the handler prints to (bounded as its own)
        self.output_cap = output_cap
        self.ctx = process_context(start_method)  # (its fork waits for the threads of a recent fork: ``forks``)
        self.proc: Any = None
        self.conn: Connection | None = None
        self.scratch: str | None = None  # the live worker's temporary folder (``start``)
        self.generation = 0  # bumped at every (re)start: worker state does not survive it

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.is_alive()

    def start(self) -> None:
        parent, child = self.ctx.Pipe(duplex=True)
        remove_orphan_scratch()
        self.scratch = tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{scratch_owner()}-")
        proc = self.ctx.Process(target=_worker_main, daemon=True,
                                args=(child, self.factory, self.threads, self.scratch, self.capture_output, parent))
        proc.start()
        with contextlib.suppress(OSError):  # as the worker does: its group exists before any kill
            os.setpgid(proc.pid, proc.pid)
        child.close()
        self.proc, self.conn = proc, parent
        self.generation += 1

    def ensure_started(self) -> None:
        if not self.alive:
            self.kill()
            self.start()

    def call(self, message: Any, timeout: float | None) -> ChildReply:
        """Send ``message``; wait at most ``timeout`` s (None: forever) for the reply."""
        self.ensure_started()
        assert self.conn is not None
        t0 = time.perf_counter()
        try:
            self.conn.send(message)
        except (BrokenPipeError, OSError):
            return self._crashed(t0)
        if not self._answered_within(timeout):
            if self._keeper_ended():  # (dead, its pipe held open by what the solver left running)
                return self._crashed(t0)
            elapsed = time.perf_counter() - t0
            where = where_it_was(self.proc.pid, self.scratch) if self.scratch is not None else ""
            detail = f"no answer within the hard limit of {timeout:.3g} s; worker killed{where}" + self.output_tail()
            self.kill()
            return ChildReply("timeout", elapsed=elapsed, detail=detail)
        try:
            kind, value = self.conn.recv()
        except (EOFError, OSError):
            return self._crashed(t0)
        elapsed = time.perf_counter() - t0
        if kind == "error":
            return ChildReply("error", elapsed=elapsed, detail=str(value) + self.output_tail())
        return ChildReply("ok", value=value, elapsed=elapsed)

    def _answered_within(self, timeout: float | None) -> bool:
        """Whether the reply arrives within ``timeout`` s (None: waits for it), in waits of at
        most ``KEEPER_CHECK_S``, or of ``OUTPUT_CHECK_S`` where the handler's output goes to
        files, each cut back after each wait (``bound_output``); False at once when the
        keeper has ended with no reply sent (``_keeper_ended``)."""
        assert self.conn is not None
        files = self.bounded_files()
        chunk = OUTPUT_CHECK_S if files else KEEPER_CHECK_S  # (the former the shorter)
        end = math.inf if timeout is None else time.monotonic() + timeout
        while (left := end - time.monotonic()) > 0:
            if self.conn.poll(min(left, chunk)):
                return True
            for path in files:
                bound_output(path, self.output_cap)
            if self._keeper_ended():
                break
        return bool(self.conn.poll(0))

    def _keeper_ended(self) -> bool:
        """Whether the worker's keeper (``proc``) has ended: then no reply can come, the
        worker ending with it (``set_parent_death_signal``)."""
        return self.proc is not None and self.proc.exitcode is not None

    def bounded_files(self) -> tuple[str, ...]:
        """The files the handler's output goes to, which a wait keeps under ``output_cap``."""
        own = (os.path.join(self.scratch, OUTPUT_NAME),) if self.capture_output and self.scratch else ()
        return own + self.output_files

    def _crashed(self, t0: float) -> ChildReply:
        elapsed = time.perf_counter() - t0
        code = None
        if self.proc is not None:
            self.proc.join(DIED_WAIT_S)
            code = self.proc.exitcode
        detail = describe_exit(code) + self.output_tail()
        self.kill()
        return ChildReply("crashed", elapsed=elapsed, detail=detail, exitcode=code)

    def output_tail(self) -> str:
        """The last ``OUTPUT_TAIL_LINES`` lines the handler printed during the latest message,
        as lines to append to a reply's detail ("" when it printed nothing or the output is
        not captured)."""
        if not self.capture_output or self.scratch is None:
            return ""
        try:
            with open(os.path.join(self.scratch, OUTPUT_NAME), "rb") as fh:
                fh.seek(max(0, fh.seek(0, os.SEEK_END) - OUTPUT_TAIL_BYTES))
                tail_bytes = fh.read(OUTPUT_TAIL_BYTES)  # (a live writer may grow the file meanwhile)
                lines = tail_bytes.replace(b"\0", b"").decode("utf-8", errors="replace").strip().splitlines()
        except OSError:
            return ""
        tail = lines[-OUTPUT_TAIL_LINES:]
        return "\n[last output]\n" + "\n".join(tail) if tail else ""

    def kill(self) -> None:
        """Stop the child, every descendant of it and every process of its group (SIGKILL),
        release the pipe and remove its temporary folder (what a killed solver, or a program
        it ran, left there).  A live child's group -- the keeper, the worker and what stayed
        in it -- is stopped first (SIGSTOP), so that it starts nothing more while the
        descendants are found and killed."""
        if self.proc is not None:
            if self.proc.pid is not None and self.proc.exitcode is None:  # alive and not reaped: its pid is ours
                for stop in (os.kill, os.killpg):  # (the child itself, should its group not be made)
                    with contextlib.suppress(ProcessLookupError, PermissionError):
                        stop(self.proc.pid, signal.SIGSTOP)
                end_descendants(self.proc.pid)
            if self.proc.pid is not None:  # before the worker is reaped: its group id is still its own
                kill_process_group(self.proc.pid)
            if self.proc.is_alive():
                self.proc.kill()
            self.proc.join(5.0)
        if self.conn is not None:
            self.conn.close()
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)
        self.proc, self.conn, self.scratch = None, None, None

    def close(self) -> None:
        """Ask the child to exit, then make sure it has.  Its group is continued first
        (SIGCONT): a keeper or worker a solve stopped ends on its own, not at the wait's end."""
        if self.conn is not None and self.alive:
            try:
                self.conn.send(None)
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(self.proc.pid, signal.SIGCONT)
                self.proc.join(2.0)
            except (BrokenPipeError, OSError):
                pass
        self.kill()

    def __enter__(self) -> "ChildProcess":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# ---------------------------------------------------------------------------
# Peak memory of one solve
# ---------------------------------------------------------------------------


def _proc_status_kb(field: str) -> float | None:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return float(line.split()[1])
    except OSError:
        return None
    return None


class PeakMemory:
    """Peak resident-memory growth of this process during a block, in MiB.

    Linux: the kernel's high-water mark (VmHWM) is reset before the block by writing
    "5" to /proc/self/clear_refs, so the figure is exact and costs nothing during the
    solve.  Elsewhere: ru_maxrss growth (a lower bound in a long-lived process)."""

    def __init__(self) -> None:
        self.before_kb: float = 0.0
        self.exact = False
        self.mb = float("nan")

    def __enter__(self) -> "PeakMemory":
        rss = _proc_status_kb("VmRSS")
        try:
            with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
                fh.write("5")
            self.exact = rss is not None
        except OSError:
            self.exact = False
        if self.exact:
            self.before_kb = float(rss or 0.0)
        else:
            self.before_kb = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.exact:
            peak = _proc_status_kb("VmHWM")
            self.mb = max(0.0, ((peak or 0.0) - self.before_kb) / 1024.0)
        else:
            self.mb = max(0.0, (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - self.before_kb) / 1024.0)
