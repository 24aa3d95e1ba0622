"""The resumable result store: one JSON line per finished solve, then a tidy table.

Layout of a run directory ``OUT/``::

    rows.jsonl        the journal: one JSON object per row, appended and fsync'ed as
                      each solve finishes (the source of truth)
    results.parquet   the tidy table (harness/table/schema.py), regenerated from the journal;
                      read it with ``schema.load_table`` (also importable from here)
    results.csv       the same table as CSV
    meta.json         run metadata (harness/table/meta.py)
    _cache/           reference solutions, one file per instance-step, and the answers a next
                      step starts from (removed once the job is done)
    run.lock          while a run is writing: its PID, host and start time (``RunLock``)
    .contactbench-run.json
                      the marker: this is a contactbench run folder (format version, and
                      the configuration of each run that wrote to it; ``RunFolder``)
    arrays/           contact fields and wrong answers kept for the report's pictures
                      (harness/table/fields.py)

(and what the solvers printed, harness/run/output_log.py).  A run never reads or writes
through a link, and keeps each of these entries as the kind the layout gives it:
``check_run_entries`` refuses a folder where one is a link, a folder where a file
belongs or a file where a folder belongs (``entry_problem``: the one rule), before
anything is written or locked.

A results folder is safe to point at (``read_run_folder`` and ``refuse_unrecorded``, before anything is written or
locked): a missing or empty folder is a new run; a marked folder accepts a run whose
configuration it records (a resume), and a run with another configuration only when
asked to add to it (``append``; the differences are named otherwise); a folder written
by contactbench before the marker existed (its meta.json has contactbench's ``command``
and ``config`` keys, and it has rows.jsonl) counts as marked with the configuration its
meta.json records; any other non-empty folder is refused and left as it is.

One writer per results folder: ``contactbench run`` holds ``RunLock`` on OUT for the
whole run (an exclusive ``flock`` on OUT/run.lock, whose text names the holder).  A
second run into a live folder is refused (``FolderInUseError``, exit 2, naming the
holder's PID and host); a lock left by a process that is gone (same host, PID no longer
running, or running a later process under a reused PID) is taken over with a warning.
The lock is taken and let go with SIGINT and SIGTERM held back, so a signal never leaves it.
``report`` and ``load_table`` read without the lock: the table files are written to a
unique temporary file in OUT and renamed over the old ones (``os.replace``), so a
reader sees the old table or the new one, never half of one.

Crash safety: a row is appended with one ``write`` under an exclusive ``flock`` and
fsync'ed, so concurrent writers (``--jobs``, Dask workers on a shared file system) do not
interleave.  A ``kill -9`` can leave at most a partial last line; it is cut off when
the store is next opened.  Rows are identified by ``cell_id``; reading keeps the first row
of each cell (journal: ``first_of_each_cell``; ``load_table``: ``reading.first_rows``, where a
row without a cell id is of the cell its cell columns name), so a cell is never counted
twice; a folder's results.parquet is read only while it holds the journal's cells.  The
journal is read checked (``checked_journal``, harness/table/journal.py): a line that is not
a JSON object is ignored; a row without ``cell_id`` or against the table contract is a
``JournalError``.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import logging
import os
import socket
import sys
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterable

from contactbench.problems.atomic_files import literal_path, names_nothing
from contactbench.stops import signals_deferred
from contactbench.problems.errors import ProblemInputError

import pandas as pd

from .files import canonical_json, pid_exists, replace_atomically
from .meta import META_FILE
from .journal import JournalError as JournalError, checked_journal, encode_row as encode_row
from .journal import read_journal as read_journal, repair_journal
from .reading import check_cell_ids, first_rows, journal_cell_ids, journal_stamp, parquet_stamp, read_csv, write_parquet
from .schema import CELL_COLUMNS, MissingTableError, TableError, apply_schema, check_table, text_values

ROWS_FILE = "rows.jsonl"
PARQUET_FILE = "results.parquet"
CSV_FILE = "results.csv"
LOCK_FILE = "run.lock"
MARKER_FILE = ".contactbench-run.json"
CACHE_DIR = "_cache"
ARRAYS_DIR = "arrays"
#: The entries of a results folder (module doc): name -> whether it is a folder.
RUN_ENTRIES: dict[str, bool] = {ROWS_FILE: False, PARQUET_FILE: False, CSV_FILE: False, META_FILE: False,
                                LOCK_FILE: False, MARKER_FILE: False, CACHE_DIR: True, ARRAYS_DIR: True}
#: Version of the marker's format (``RunFolder``).
MARKER_FORMAT = 1

log = logging.getLogger("contactbench")

#: Columns that identify a group of repeats: a cell (schema.CELL_COLUMNS).
GROUP_COLUMNS = CELL_COLUMNS  # (the schema names what identifies a cell)


class ResultStore:
    """Append-only journal of rows with the set of finished cells; its rows are read
    checked (``checked_journal``), so ``load`` refuses a journal against the contract."""

    def __init__(self, out_dir: str | os.PathLike[str], load: bool = True) -> None:
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self.path = self.out / ROWS_FILE
        if load:
            repair_journal(self.path)
        self._status = {r["cell_id"]: str(r.get("status", "")) for r in (self.rows() if load else ())}

    @property
    def cache_dir(self) -> Path:
        d = self.out / CACHE_DIR
        d.mkdir(parents=True, exist_ok=True)
        return d

    def done(self) -> set[str]:
        return set(self._status)

    def done_statuses(self) -> dict[str, str]:
        """cell_id -> status of every stored row."""
        return dict(self._status)

    def status_of(self, cell_id: str) -> str | None:
        return self._status.get(cell_id)

    def __contains__(self, cell_id: str) -> bool:
        return cell_id in self._status

    def __len__(self) -> int:
        return len(self._status)

    def append(self, row: dict[str, Any]) -> None:
        """Write one row durably (flock + whole line + fsync), or not at all: a write that
        fails part-way (a full disk) is cut back to the journal as it was, so no torn line
        joins the next row, and the ``OSError`` names the journal."""
        line = encode_row(row).encode("utf-8")
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            size = os.fstat(fd).st_size
            try:
                written = 0
                while written < len(line):
                    written += os.write(fd, line[written:])
                os.fsync(fd)
            except OSError as exc:
                with contextlib.suppress(OSError):
                    os.ftruncate(fd, size)
                raise OSError(exc.errno, exc.strerror, str(self.path)) from None
            finally:
                fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)
        self._status[str(row["cell_id"])] = str(row.get("status", ""))

    def count_lines(self) -> int:
        """Rows in the journal right now (cheap; used for progress across processes)."""
        if not self.path.exists():
            return 0
        with open(self.path, "rb") as fh:
            return sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 20), b""))

    def rows(self) -> list[dict[str, Any]]:
        """The journal's rows (``checked_journal``)."""
        return checked_journal(self.path)

    def finalize(self) -> pd.DataFrame:
        """Regenerate results.parquet and results.csv from the checked journal (or neither),
        the parquet stamped with the journal as it was before it was read
        (``reading.journal_stamp``: a row appended meanwhile makes the stamp stale)."""
        stamp = journal_stamp(self.path) if self.path.exists() else None
        table = tidy_table(self.rows())
        write_table(table, self.out, stamp)
        return table


def tidy_table(rows: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """The tidy table: every column of the schema with its dtype, repeat min/median filled."""
    df = apply_schema(pd.DataFrame(list(rows)))
    if len(df):
        fill_repeat_statistics(df)
        df = df.sort_values(["scene", "instance", "step", "solver", "profile", "repeat"], kind="stable")
        df = df.reset_index(drop=True)
    return df


def fill_repeat_statistics(df: pd.DataFrame) -> None:
    """solve_time_min_s / solve_time_median_s over the repeats of each group (rows
    that ran to an answer only: solved or inaccurate)."""
    ran = df["status"].isin(["solved", "inaccurate"]) & df["solve_time_s"].notna()
    keys = [df[c].astype("string").fillna("") for c in GROUP_COLUMNS]
    grouped = df["solve_time_s"].where(ran).groupby(keys, dropna=False)
    df["solve_time_min_s"] = grouped.transform("min")
    df["solve_time_median_s"] = grouped.transform("median")


def write_table(table: pd.DataFrame, out_dir: str | os.PathLike[str], stamp: str | None = None) -> None:
    """results.parquet (with the ``stamp`` of the journal it was made from) and results.csv,
    each written to a unique temporary file in ``out_dir`` and then renamed over the old
    one (a reader never sees half a table, and two writers never share a temporary name)."""
    out = Path(out_dir)
    replace_atomically(out / PARQUET_FILE, lambda tmp: write_parquet(table, tmp, stamp))
    replace_atomically(out / CSV_FILE, lambda tmp: table.to_csv(tmp, index=False))


# --- What a results folder is (the marker) ---


class RunFolderError(ProblemInputError):
    """The results folder is not one this run may write to (the command line exits 2)."""


def canonical(identity: dict[str, Any]) -> dict[str, Any]:
    """``identity`` as JSON reads it back (tuples -> lists, keys sorted)."""
    return json.loads(canonical_json(identity))


def fingerprint(identity: dict[str, Any]) -> str:
    """A short hash of a run configuration (``canonical`` JSON)."""
    return hashlib.sha256(json.dumps(canonical(identity), sort_keys=True).encode("utf-8")).hexdigest()[:16]


def flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts as dotted keys ("run.timeout")."""
    if not isinstance(d, dict):
        return {prefix: d}
    return {key: x for k, v in d.items() for key, x in flatten(v, f"{prefix}.{k}" if prefix else str(k)).items()}


def differences(recorded: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """One phrase per setting that differs: "run.timeout: 60.0 in the folder, 5.0 in this run";
    two lists by what only one holds: "solvers: only in the folder "a", "b"; only in this run
    "c"" (a list of 50 solvers that differs by one is named by that one)."""
    a, b = flatten(canonical(recorded)), flatten(canonical(wanted))
    out = []
    for key in sorted(set(a) | set(b)):
        x, y = a.get(key, "(unset)"), b.get(key, "(unset)")
        if x == y:
            continue
        if isinstance(x, list) and isinstance(y, list):
            sides = [f"only {where} {', '.join(json.dumps(v) for v in only)}" for where, only in
                     (("in the folder", [v for v in x if v not in y]), ("in this run", [v for v in y if v not in x]))
                     if only]
            out.append(f"{key}: {'; '.join(sides) or 'the same entries in another order'}")
        else:
            out.append(f"{key}: {json.dumps(x)} in the folder, {json.dumps(y)} in this run")
    return out


@dataclass
class RunFolder:
    """What a results folder holds (module doc): ``kind`` is "new" (missing or empty but
    for a lock file), "marked" or "legacy" (written before the marker); ``runs`` are the
    recorded configurations, each ``{"fingerprint": ..., "config": ...}``."""

    out: Path
    kind: str
    runs: list[dict[str, Any]] = field(default_factory=list)

    def records(self, identity: dict[str, Any]) -> bool:
        fp = fingerprint(identity)
        return any(r.get("fingerprint") == fp for r in self.runs)

    def closest(self, identity: dict[str, Any]) -> list[str]:
        """The differences to the recorded configuration closest to ``identity``."""
        diffs = [differences(r.get("config") or {}, identity) for r in self.runs]
        return min(diffs, key=len) if diffs else []


def entry_problem(path: Path, folder: bool) -> str | None:
    """What makes ``path`` unfit as a results folder's entry that is a folder (``folder``)
    or a plain file -- a link (the run never reads or writes through one), or the other
    kind (a special file counts as neither) -- or None when it is fit or absent."""
    if path.is_symlink():
        return "is a symbolic link; a run never reads or writes through one"
    if not path.exists() or (path.is_dir() if folder else path.is_file()):
        return None
    return "is not a folder, where a run keeps one" if folder else "is not a plain file, where a run keeps one"


def check_run_entries(out_dir: str | os.PathLike[str], entries: dict[str, bool] | None = None) -> None:
    """``RunFolderError`` (one line naming the first) when an entry of ``out_dir`` among
    ``entries`` (name -> whether it is a folder; default ``RUN_ENTRIES``) is unfit
    (``entry_problem``); reads only."""
    out = Path(out_dir)
    for name, folder in (RUN_ENTRIES if entries is None else entries).items():
        problem = entry_problem(out / name, folder)
        if problem is not None:
            raise RunFolderError(f"results folder {out}: {out / name} {problem}; move it away or choose another "
                                 "--out (nothing was written)")


def legacy_config(out: Path) -> dict[str, Any] | None:
    """The ``config`` of a folder written by contactbench before the marker: meta.json
    with contactbench's ``command`` (a list) and ``config`` (a dict), and a rows.jsonl."""
    if not (out / ROWS_FILE).is_file():
        return None
    try:
        meta = json.loads((out / META_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if isinstance(meta, dict) and isinstance(meta.get("command"), list) and isinstance(meta.get("config"), dict):
        return meta["config"]
    return None


Identity = Callable[[dict[str, Any]], dict[str, Any]]  # a meta.json ``config`` -> a run's configuration


def read_run_folder(out_dir: str | os.PathLike[str], identity_of: Identity) -> RunFolder:
    """Inspect ``out_dir`` without touching it; raise ``RunFolderError`` for an empty or
    blank name (the rule of an export's folder, ``problems.export.check_export_folder``),
    a path that is not a folder, an entry that is a link or of the wrong kind
    (``check_run_entries``), a foreign non-empty folder or an unreadable marker
    (``JournalError`` for a journal against the contract, ``checked_journal``).  ``identity_of`` turns a
    legacy meta.json ``config``, and each configuration the marker records, into a run
    configuration as this version reads one."""
    if names_nothing(out_dir):
        raise RunFolderError(f"the results folder (--out) must be named, got {os.fspath(out_dir)!r}")
    out = Path(out_dir)
    if not out.exists():
        return RunFolder(out, "new")
    if not out.is_dir():
        raise RunFolderError(f"results folder {out} is not a folder; choose another --out")
    check_run_entries(out)
    held = live_lock_error(out)
    if held is not None:  # a live run may not have written its marker yet: its lock is the reason
        raise held
    marker = out / MARKER_FILE
    if marker.exists():
        try:
            data = json.loads(marker.read_text(encoding="utf-8"))
            fmt, runs = int(data["format"]), data["runs"]
            if not (isinstance(runs, list) and all(isinstance(r, dict) for r in runs)):
                raise TypeError("runs")
        except (OSError, ValueError, KeyError, TypeError):
            raise RunFolderError(f"results folder {out}: its marker {marker.name} cannot be read; "
                                 "choose another --out") from None
        if fmt > MARKER_FORMAT:
            raise RunFolderError(f"results folder {out} was written by a newer contactbench (marker format {fmt}); "
                                 "choose another --out")
        checked_journal(out / ROWS_FILE)
        configs = [identity_of(r.get("config") or {}) for r in runs]  # (read as this version reads a run)
        return RunFolder(out, "marked", [{"fingerprint": fingerprint(c), "config": c} for c in configs])
    if not [p for p in out.iterdir() if p.name != LOCK_FILE]:
        return RunFolder(out, "new")
    config = legacy_config(out)
    if config is None:
        raise RunFolderError(f"results folder {out} is not empty and is not a contactbench run folder "
                             f"(no {MARKER_FILE}); choose an empty or new --out")
    checked_journal(out / ROWS_FILE)
    identity = identity_of(config)
    return RunFolder(out, "legacy", [{"fingerprint": fingerprint(identity), "config": canonical(identity)}])


def refuse_unrecorded(folder: RunFolder, identity: dict[str, Any], append: bool) -> RunFolder:
    """``folder``, unless it does not record the run's configuration ``identity`` and the run
    does not ``append``: then a ``RunFolderError`` naming the differences."""
    if folder.kind == "new" or append or folder.records(identity):
        return folder
    diffs = folder.closest(identity)
    raise RunFolderError(f"results folder {folder.out} holds a run with another configuration "
                         f"({'; '.join(diffs) or 'differs'}); resume it with the same options, choose another "
                         "--out, or add to it with --append")


def record_run(folder: RunFolder, identity: dict[str, Any]) -> Path:
    """Write the marker with ``identity`` among its runs (atomically)."""
    runs = list(folder.runs)
    if not folder.records(identity):
        runs.append({"fingerprint": fingerprint(identity), "config": canonical(identity)})
    folder.out.mkdir(parents=True, exist_ok=True)
    path = folder.out / MARKER_FILE
    text = json.dumps({"format": MARKER_FORMAT, "tool": "contactbench", "runs": runs}, indent=2, sort_keys=True)
    replace_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    folder.runs, folder.kind = runs, "marked"
    return path


# --- One writer per results folder ---


class FolderInUseError(ProblemInputError):
    """Another live run holds the results folder's lock (the command line exits 2)."""


@dataclass(frozen=True)
class LockHolder:
    """What run.lock says of the run that holds (or held) it."""

    pid: int
    host: str
    started: str
    started_epoch: float = 0.0
    command: str = ""

    def describe(self) -> str:
        return f"PID {self.pid} on host {self.host} (started {self.started or 'at an unknown time'})"

    @classmethod
    def me(cls) -> "LockHolder":
        now = time.time()
        started = datetime.fromtimestamp(now, timezone.utc).isoformat(timespec="seconds")
        return cls(os.getpid(), socket.gethostname(), started, now, " ".join(sys.argv)[:500])

    @classmethod
    def parse(cls, text: str) -> "LockHolder | None":
        try:
            d = json.loads(text)
            return cls(int(d["pid"]), str(d["host"]), str(d.get("started", "")), float(d.get("started_epoch", 0.0)),
                       str(d.get("command", "")))
        except (ValueError, KeyError, TypeError):
            return None


def process_state(holder: LockHolder) -> str:
    """"running", "gone" (no such process, or a process started after the lock: a reused
    PID) or "unknown" (another host: its processes cannot be seen from here)."""
    if holder.host != socket.gethostname():
        return "unknown"
    if not pid_exists(holder.pid):
        return "gone"
    try:
        import psutil

        if holder.started_epoch and psutil.Process(holder.pid).create_time() > holder.started_epoch + 2.0:
            return "gone"  # that PID now names a process started after the lock was written
    except Exception:
        pass
    return "running"


class RunLock:
    """The lock of one results folder (module doc): ``with RunLock(out): ...``.

    Held as an exclusive, non-blocking ``flock`` on OUT/run.lock for the whole run (the
    kernel drops it when the process dies, however it dies), with the holder's PID, host
    and start time written in the file for the message a second run gets.  Released by
    removing the file; a folder the lock itself created and that stayed empty is removed
    too (a run refused at planning leaves nothing behind).  A run.lock that is neither
    empty nor a lock record is not ours: ``RunFolderError``, the file left as it is."""

    def __init__(self, out_dir: str | os.PathLike[str]) -> None:
        self.out = Path(out_dir)
        self.path = self.out / LOCK_FILE
        self.fd: int | None = None
        self.created_dir = False
        self.took_over: LockHolder | None = None

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc: Any) -> None:
        self.release()

    def acquire(self) -> "RunLock":
        """Take the lock (class doc) with SIGINT and SIGTERM held back (``signals_deferred``),
        so that no signal leaves run.lock naming this process half-way: one that came
        meanwhile is acted on once the lock is taken, and the lock is then released."""
        if self.fd is not None:
            return self
        try:
            with signals_deferred():
                self._acquire()
        except BaseException:
            self.release()
            raise
        return self

    def _acquire(self) -> None:
        self.created_dir = not self.out.exists()
        self.out.mkdir(parents=True, exist_ok=True)
        try:
            for _ in range(20):  # another process may remove or replace the file between open and flock
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
                try:
                    if self._claim(fd):
                        self.fd = fd
                        _HELD.add(fd)
                        _HELD_PATHS[str(self.out.resolve())] = self
                        return
                except BaseException:
                    os.close(fd)
                    raise
                os.close(fd)
            raise FolderInUseError(f"results folder {self.out} is in use: its lock file {self.path} keeps changing")
        except BaseException:
            self._remove_empty_dir()
            raise

    def _claim(self, fd: int) -> bool:
        """Lock ``fd``, judge any previous holder, write ourselves; False: retry."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            raise self.in_use(LockHolder.parse(os.pread(fd, 65536, 0).decode("utf-8", "replace"))) from None
        if not self._is_current(fd):
            return False
        text = os.pread(fd, 65536, 0).decode("utf-8", "replace")
        previous = LockHolder.parse(text)
        if previous is None and text.strip():
            raise RunFolderError(f"results folder {self.out} holds a file {LOCK_FILE} that is not a contactbench "
                                 "lock; it is left as it is: move it, or choose another --out")
        if previous is not None:
            state = process_state(previous)
            if state != "gone":
                raise self.in_use(previous, state)
            log.warning("warning: taking over the lock of results folder %s left by %s, which is no longer running",
                        self.out, previous.describe())
            self.took_over = previous
        data = json.dumps(asdict(LockHolder.me())).encode("utf-8")
        os.ftruncate(fd, 0)
        os.pwrite(fd, data, 0)
        os.fsync(fd)
        return True

    def _is_current(self, fd: int) -> bool:
        try:
            return os.fstat(fd).st_ino == os.stat(self.path).st_ino
        except FileNotFoundError:
            return False

    def in_use(self, holder: LockHolder | None, state: str = "running") -> FolderInUseError:
        who = holder.describe() if holder is not None else "another process"
        if state == "unknown":
            hint = (f"its processes cannot be checked from this host; if that run is gone, delete {self.path}, "
                    "or choose another --out")
        else:
            hint = "wait for it to finish or choose another --out"
        return FolderInUseError(f"results folder {self.out} is in use by another run: {who}; {hint}")

    def release(self) -> None:
        """Remove run.lock (when it is still ours) and let go of it, with SIGINT and SIGTERM
        held back (``signals_deferred``): a signal never leaves the file behind."""
        if self.fd is None:
            return
        with signals_deferred():
            try:
                if self._is_current(self.fd):
                    os.unlink(self.path)
            except OSError:
                pass
            finally:
                _HELD.discard(self.fd)
                if _HELD_PATHS.get(str(self.out.resolve())) is self:
                    del _HELD_PATHS[str(self.out.resolve())]
                os.close(self.fd)
                self.fd = None
            self._remove_empty_dir()

    def _remove_empty_dir(self) -> None:
        if self.created_dir:
            with contextlib.suppress(OSError):
                self.out.rmdir()  # only succeeds when empty


def live_lock_error(out: Path) -> FolderInUseError | None:
    """The error a run gets for ``out`` while another process holds its lock, found without
    writing anything (a shared ``flock`` probe on a read-only descriptor); None when the
    lock is free, absent, or held by this process."""
    path = out / LOCK_FILE
    if str(out.resolve()) in _HELD_PATHS:
        return None
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return None
        return RunLock(out).in_use(LockHolder.parse(os.pread(fd, 65536, 0).decode("utf-8", "replace")))
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


@contextlib.contextmanager
def holding_lock(out_dir: str | os.PathLike[str]) -> Any:
    """Hold the lock of ``out_dir`` for the block, unless this process already holds it
    (a caller that wrapped the run in ``RunLock``)."""
    key = str(Path(out_dir).resolve())
    if key in _HELD_PATHS:
        yield _HELD_PATHS[key]
        return
    with RunLock(out_dir) as lock:
        yield lock


#: Lock descriptors held by this process: a forked child (an isolated worker, a pool
#: process) closes its copies, so the lock lives and dies with the run itself.
_HELD: set[int] = set()
#: Resolved folder -> the RunLock this process holds on it.
_HELD_PATHS: dict[str, "RunLock"] = {}


def _close_held_in_child() -> None:
    for fd in list(_HELD):
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELD.clear()
    _HELD_PATHS.clear()


os.register_at_fork(after_in_child=_close_held_in_child)


# --- The one reader of a stored table ---


def _read_run_dir(out: Path) -> pd.DataFrame:
    """A run directory's table, read without writing anything.  The journal is the source
    of truth where there is one: results.parquet is read when it was made from the journal
    as it is now (its stamp, ``reading.journal_stamp``: a table copied from another run or
    older than its journal is not); a table without a stamp when it holds exactly the
    cells the journal names (``reading.journal_cell_ids``) and the journal was not changed
    after it (by its file time: a time may send the reader to the journal, never away from
    it); else the journal itself (a run that stopped before writing its table, a table
    older than its journal whatever the files' times say).  Without a journal:
    results.parquet, else results.csv."""
    pq, csv, journal = out / PARQUET_FILE, out / CSV_FILE, out / ROWS_FILE
    if not journal.is_file():
        if pq.is_file():
            return pd.read_parquet(literal_path(pq))
        if csv.is_file():
            return read_csv(csv)
        raise MissingTableError(f"no results table in {out}: expected {PARQUET_FILE}, {CSV_FILE} or {ROWS_FILE}")
    stamp = parquet_stamp(pq) if pq.is_file() else None
    if stamp is not None and stamp == journal_stamp(journal):  # (made from this journal as it is)
        return pd.read_parquet(literal_path(pq))
    if stamp is None and pq.is_file() and journal.stat().st_mtime <= pq.stat().st_mtime:  # (an unstamped table)
        try:
            table = pd.read_parquet(literal_path(pq))
        except (OSError, ValueError):  # (an unreadable table: the journal it is made from is read)
            table = None
        if table is not None and "cell_id" in table.columns:
            if set(text_values(table["cell_id"])) == journal_cell_ids(journal):
                return table
    return tidy_table(checked_journal(journal))


def load_table(path: str | os.PathLike[str]) -> pd.DataFrame:
    """The one reader of a stored tidy table, with the schema checked and applied.

    ``path`` is a run directory (see ``_read_run_dir``) or a ``.parquet`` / ``.csv``
    file; the first row of each cell is kept (``reading.first_rows``: a row without a
    cell id is of the cell its cell columns and ``repeat`` name).  Reading never writes."""
    p = Path(path)
    if p.is_dir():
        df = _read_run_dir(p)
    elif p.suffix == ".parquet" and p.is_file():
        df = pd.read_parquet(literal_path(p))
    elif p.suffix == ".csv" and p.is_file():
        df = read_csv(p)
    elif not p.exists():
        raise MissingTableError(f"no results table in {p}: the path does not exist")
    else:
        raise TableError(f"{p} is not a stored table (a run directory, .parquet or .csv)")
    check_table(df, p)
    df = apply_schema(df)
    check_cell_ids(df, p)
    return df[first_rows(df)].reset_index(drop=True)
