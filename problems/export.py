"""Writing a scene's QPs out: every (instance, step) of a scene, for outside QP tools.

Three formats (``contactbench export SCENE ... --format F --out DIR``):

* ``problem-dir`` -- one directory per QP in the external-solver problem format
  (``problems/qpfile.py``, ``contactbench-qp/1``), written by its ``write_problem_dir``:
  ``DIR/<name>/problem.json`` + raw arrays.
* ``hdf5`` -- ``DIR/problems.h5`` (needs h5py): one group per QP holding exactly the
  arrays of its problem directory (``ubar``, ``index``, ``H``, ``kernel_table``) as
  datasets and its ``problem.json`` as the group attribute ``problem_json``.  Both are
  built by ``qpfile.problem_payload``, so there is one writer of the format.
* ``qpbenchmark`` -- ``DIR/<scene>.parquet`` in qpbenchmark's ``ProblemList`` layout
  (columns P, q, G, h, A, b, lb, ub, name; matrices flattened row-major, absent
  entries null), with P = H (dense), q = -ubar, lb = 0 and no other constraint, so
  ``qpbenchmark.ParquetTestSet`` reads it as is.  The file is written one QP (one row
  group) at a time (``QPBenchmarkWriter``), so an export holds one QP's P at a time.

Arrays are written in the dtype the instance holds them in where the format allows it
(``data_dtype``: ubar is float64 or float32, a float32 stress case keeps float32): in
hdf5 the ``ubar`` dataset has that dtype (and its ``problem_json`` says so); in
qpbenchmark q and lb have it (a column holds one dtype: the widest of its QPs, float32
widened exactly to float64 when the file mixes both) and the file's key-value metadata
``PARQUET_DTYPES_KEY`` maps every QP to its dtype.  The problem-dir format is float64
only (``qpfile``), so there a float32 ubar is written widened, exactly.  The manifest
records each QP's dtype.

Every QP is named ``<instance>-step<k>`` (characters other than letters, digits and
``._-`` replaced by ``_``).  The dense H is written only for n <= ``dense_limit``
(default ``qpfile.DENSE_LIMIT``, 4096: 128 MiB per matrix); above it problem-dir and
hdf5 keep the FFT kernel table only and qpbenchmark (which needs P) skips the QP.  A
dense H within the dense limit but over the process's memory budget for dense matrices
(``operators.memory_budget``) is refused with a one-line ``ProblemInputError`` before
anything is written (``check_dense_fits``).
``DIR/manifest.json`` lists every QP -- name, scene, instance, step, n, far-field
displacement, objective-free facts, and for a measured map the sha256 of its heights as
read (``surface_sha256``) -- and every skip with its reason, with the scene options used
(``scene_options``, the scene's defaults filled in) and the ``contactbench_version``; the
summary line says what was skipped.  A step with no unknown (n = 0) is skipped too.

``DIR`` follows the rule of a run's results folder: a missing or empty folder is new, a
folder an export wrote (its manifest.json names the tool) is written over, and any other
non-empty folder is refused and left as it is (``check_export_folder``; an empty
``--out`` too).  The scene options are checked first by the same rules as a run's
(``scenes.options.check_config``), and the count of QPs (instances x steps) is bounded
by ``MAX_QPS`` before any recipe of the whole range is made (``check_scene``).  Every
refusal of a single QP -- its name, its dense H, its build, its kernel table, the entry
of ``DIR`` it would be written to -- is raised in a pass over all of them before the
first is written (``export_plan.plan_export``, then ``check_targets``), so a refused
export leaves ``DIR`` as it was (a new one is not made).  The whole export holds an
exclusive lock on ``DIR`` (``atomic_files.folder_lock``): a second export into it
meanwhile is refused and touches nothing.  An export never writes through
a symbolic link, nor over an entry of ``DIR`` that the manifest does not list as an
export's: either is refused, naming it (``check_target``); ``problems.h5`` and the
Parquet file are written whole or not at all (``atomic_files.replace_atomically``).

The manifest is written before anything else, marked ``"complete": false`` and listing
what of the folder is an export's (``owned_folders``: problem directories, each added
before it is written; ``owned_files``: ``problems.h5`` or a Parquet file), so a folder
whose export was interrupted is still an export's folder and the same command can be
run again into it.  At the end the manifest is rewritten with ``"complete": true`` and
the QP list; before that, whatever an earlier export wrote there and this one does not
is removed (``remove_owned``): the files of the problem directory format
(``qpfile.PROBLEM_DIR_FILES``) in each of its problem directories, and the directory
itself when nothing else is left in it, and its ``problems.h5`` or Parquet file.  Nothing
else in the folder is touched: a file of another name in such a directory stays, and so
does the directory that holds it (no longer listed as an export's).  A problem directory
that is written again holds only the new QP's files (``qpfile.write_problem_dir``).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .atomic_files import (FolderLockedError, folder_lock, literal_path, names_nothing, replace_atomically,
                           write_text_atomic)
from .errors import ProblemInputError
from .export_plan import (
    MAX_QPS,
    ExportPlan,
    PlannedQP,
    check_dense_fits,
    check_scene,
    file_safe,
    package_version,
    plan_export,
    problem_name,
    scene_steps,
)
from .instances import ContactInstance
from .operators import PRECISIONS
from .qpfile import (
    DENSE_LIMIT,
    PROBLEM_DIR_FILES,
    PROBLEM_JSON,
    payload_nbytes,
    problem_json,
    problem_payload,
    read_problem_dir,
    write_problem_dir,
)

FORMATS = ("problem-dir", "hdf5", "qpbenchmark")
#: The manifest's ``tool``: what marks a folder as an export's (``check_export_folder``).
EXPORT_TOOL = "contactbench export"
MANIFEST_FILE = "manifest.json"
#: The file of the hdf5 format.
HDF5_FILE = "problems.h5"
#: qpbenchmark's ProblemList columns, in its order.
QPBENCHMARK_KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub", "name")
#: The array columns of those (each a list of floats; ``name`` is a string).
QPBENCHMARK_ARRAYS = QPBENCHMARK_KEYS[:-1]
#: The key of the qpbenchmark file's key-value metadata that maps every QP to the dtype
#: of its data (JSON: name -> dtype name, ``data_dtype``).
PARQUET_DTYPES_KEY = "contactbench.dtypes"


@dataclass
class ExportedQP:
    """One manifest entry."""

    name: str
    scene: str
    instance: str
    step: int
    n: int
    delta: float | None
    dense_H: bool
    #: The dtype of the QP's data as the instance holds it (``data_dtype``), e.g. float32.
    dtype: str
    #: The sha256 of the measured map's heights as read (None: a generated surface).
    surface_sha256: str | None = None


@dataclass
class ExportSummary:
    """What an export wrote and skipped."""

    scene: str
    fmt: str
    out: str
    dense_limit: int
    written: list[ExportedQP] = field(default_factory=list)
    skipped: list[dict[str, Any]] = field(default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)  # the scene options used (``options_record``)
    version: str = ""  # the contactbench version that wrote it

    def line(self) -> str:
        no_dense = sum(1 for q in self.written if not q.dense_H)
        text = f"exported {len(self.written)} QPs of {self.scene} as {self.fmt} to {self.out}"
        if no_dense:
            text += f"; dense H left out of {no_dense} (n > {self.dense_limit}: kernel table only)"
        if self.skipped:
            text += f"; skipped {len(self.skipped)} (" + "; ".join(sorted({s['reason'] for s in self.skipped})) + ")"
        return text


class ExportStopped(RuntimeError):
    """An export that stopped once it was writing (a write that failed: a full disk), its
    manifest saying it is incomplete (``cli``: one line, exit 1)."""


def export_scene(scene_name: str, cfg: Any, fmt: str, out: str | Path, *, dense_limit: int | None = None,
                 tol: float | None = None, max_qps: int = MAX_QPS) -> ExportSummary:
    """Write every (instance, step) QP of a scene in ``fmt`` under ``out`` (module doc).

    Bad input is a one-line ``ProblemInputError`` before anything is written: the format,
    the folder (``check_export_folder``), the scene's options and inputs and its count of
    QPs (at most ``max_qps``, ``check_scene``), and every refusal of a single QP
    (``export_plan.plan_export``).  The whole export holds the folder's lock
    (``atomic_files.folder_lock``): a second export into the folder meanwhile is a
    ``ProblemInputError`` and touches nothing.  A target that is a symbolic link, or an
    entry of the folder that the export would write and that its manifest does not list
    as an export's, is a ``ProblemInputError`` naming it (``check_targets``), before
    anything is written."""
    if fmt not in FORMATS:
        raise ProblemInputError(f"export format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    limit = DENSE_LIMIT if dense_limit is None else int(dense_limit)
    if fmt == "hdf5":
        require_h5py()
    out_dir = check_export_folder(out)
    plan = plan_export(scene_name, cfg, limit, tables=fmt != "qpbenchmark", tol=tol, max_qps=max_qps)
    steps = plan.built(lambda qp: qp.n > 0 and (fmt != "qpbenchmark" or qp.n <= limit))
    first = next(steps, None)  # the first QP is built before the folder is made
    out_dir.mkdir(parents=True, exist_ok=True)
    qps = itertools.chain([] if first is None else [first], steps)
    try:
        with folder_lock(out_dir):
            check_export_folder(out_dir)  # again, now that no other export can change it
            return _export_locked(plan, scene_name, qps, fmt, out_dir, limit, tol)
    except FolderLockedError:  # (raised by folder_lock alone)
        raise ProblemInputError(f"export folder {out_dir} is in use by another export; wait for it to finish or "
                                "choose another --out") from None
    except OSError as exc:  # a write that failed once the export was writing: no bad input
        lines = str(exc).splitlines()
        raise ExportStopped(f"the export into {out_dir} stopped: {lines[0] if lines else type(exc).__name__}; "
                            "what it wrote is listed as incomplete in its manifest, and the same command "
                            "finishes it") from None


def _export_locked(plan: ExportPlan, scene_name: str, qps: Iterator[tuple[PlannedQP, ContactInstance | None]],
                   fmt: str, out_dir: Path, limit: int, tol: float | None) -> ExportSummary:
    """``export_scene``'s writing of the checked ``plan``'s QPs (``qps``: each built where
    it is written), with the folder's lock held: the folder's entries are checked
    (``check_targets``) before anything is written."""
    summary = ExportSummary(scene_name, fmt, str(out_dir), limit, options=plan.options, version=package_version())
    folders, files = owned_paths(out_dir)
    format_file = _format_file(fmt, scene_name)
    check_targets(out_dir, plan, format_file, folders, files)
    if format_file is not None:
        files.add(format_file)
    write_progress(summary, folders, files)

    def write_all(sink: Any) -> None:
        for qp, inst in qps:
            name = qp.name
            if qp.n == 0:
                summary.skipped.append({"name": name, "n": 0, "reason": "no unknown (n = 0)"})
                continue
            if inst is None:  # (qpbenchmark: n over the dense limit)
                summary.skipped.append({"name": name, "n": qp.n, "reason": f"n > dense limit {limit} (P must be dense)"})
                continue
            check_room(out_dir, payload_nbytes(inst, limit), name)
            record = inst.preprocessing
            entry = ExportedQP(name, scene_name, qp.instance, qp.step, inst.n, _finite(inst.delta), inst.n <= limit,
                               data_dtype(inst).name, None if record is None else record.raw_sha256)
            if fmt == "problem-dir":
                check_target(out_dir, name, folders, directory=True)  # (again: only exports are locked out)
                if name not in folders:  # listed before it exists, so an interrupted export still owns it
                    folders.add(name)
                    write_progress(summary, folders, files)
                write_problem_dir(inst, out_dir / name, tol=tol, time_limit=None, dense_limit=limit)
            elif fmt == "hdf5":
                write_hdf5_group(sink, name, inst, tol=tol, dense_limit=limit)
            else:
                sink.write(qpbenchmark_row(name, inst))
            summary.written.append(entry)

    if fmt == "hdf5":
        replace_atomically(out_dir / HDF5_FILE, _in_hdf5(write_all))
    elif fmt == "qpbenchmark":
        replace_atomically(out_dir / str(format_file), _in_parquet(write_all))
    else:
        write_all(None)
    written = {q.name for q in summary.written} if fmt == "problem-dir" else set()
    remove_owned(out_dir, folders - written, files - {format_file})
    write_manifest(summary, out_dir / MANIFEST_FILE)
    return summary


def _in_hdf5(write: Callable[[Any], None]) -> Callable[[str], None]:
    """A writer of a new HDF5 file at a path: ``write`` given the open file."""
    def to(path: str) -> None:
        with require_h5py().File(path, "w") as h5:
            write(h5)
    return to


def _in_parquet(write: Callable[[Any], None]) -> Callable[[str], None]:
    """A writer of a new qpbenchmark Parquet file at a path: ``write`` given its
    ``QPBenchmarkWriter``."""
    def to(path: str) -> None:
        sink = QPBenchmarkWriter(path)
        try:
            write(sink)
        except BaseException:
            with contextlib.suppress(Exception):  # the file is discarded: its first error is the one raised
                sink.close()
            raise
        sink.close()
    return to


#: The disk space (bytes) an export leaves free beyond what it writes (``check_room``).
DISK_RESERVE_BYTES = 256 * 1024 * 1024


def check_room(out_dir: Path, nbytes: int, name: str) -> None:
    """A one-line ``ProblemInputError`` naming QP ``name`` unless its ``nbytes`` and
    ``DISK_RESERVE_BYTES`` fit the free space of the disk that holds ``out_dir``, checked
    before the QP is written: an export never fills a disk (what it wrote of a single file
    is removed, ``replace_atomically``)."""
    free = shutil.disk_usage(out_dir).free
    if nbytes + DISK_RESERVE_BYTES > free:
        raise ProblemInputError(f"{name}: writing it takes about {nbytes / 1e9:.3g} GB and the disk of {out_dir} "
                                f"has {free / 1e9:.3g} GB free; free some space, choose another --out or a smaller "
                                "scene")


def data_dtype(inst: ContactInstance) -> np.dtype:
    """The dtype an export writes a QP's data (ubar, and qpbenchmark's q and lb) in where
    the format allows it: the dtype the instance holds ubar in when it is one of the
    operator precisions (``operators.PRECISIONS``: float64, float32), else float64."""
    dt = np.asarray(inst.qp.ubar).dtype
    return dt if any(dt == p for p in PRECISIONS) else np.dtype(np.float64)


def check_targets(out_dir: Path, plan: ExportPlan, format_file: str | None, folders: set[str],
                  files: set[str]) -> None:
    """``check_target`` of everything of ``out_dir`` the export of ``plan`` would write:
    its format's file (``format_file``, None for problem-dir, which is checked against
    ``files``), else the problem directory of every QP with an unknown (against
    ``folders``), in the plan's order; the first refusal is raised.  Touches nothing."""
    if format_file is not None:
        check_target(out_dir, format_file, files, directory=False)
        return
    for qp in plan.qps:
        if qp.n > 0:
            check_target(out_dir, qp.name, folders, directory=True)


def check_target(out_dir: Path, name: str, owned: set[str], *, directory: bool) -> None:
    """A one-line ``ProblemInputError`` naming ``out_dir/name`` unless an export may write
    it: absent, or one of ``owned`` (the entries the folder's manifest lists as an
    export's) that is a folder (``directory``) or a regular file, never a symbolic link."""
    path = out_dir / name
    if path.is_symlink():
        raise ProblemInputError(f"{path} is a symbolic link; an export never writes through one: remove it or "
                                "choose another --out")
    if not path.exists():
        return
    if name not in owned:
        raise ProblemInputError(f"{path} exists and is not an export's (its folder's {MANIFEST_FILE} does not list "
                                "it); move it away or choose another --out")
    if path.is_dir() != directory or not (path.is_dir() or path.is_file()):
        raise ProblemInputError(f"{path} is not a {'folder' if directory else 'regular file'}, as an export writes "
                                "it; move it away or choose another --out")


def _format_file(fmt: str, scene_name: str) -> str | None:
    """The one file a format writes in the folder (None: problem-dir writes folders)."""
    return {"hdf5": HDF5_FILE, "qpbenchmark": f"{file_safe(scene_name)}.parquet"}.get(fmt)


def _own_name(name: Any) -> bool:
    """Whether ``name`` can be the name of something an export wrote in its folder (a plain
    file-safe name: never a path, ``.`` or ``..``)."""
    return isinstance(name, str) and name not in ("", ".", "..") and file_safe(name) == name


def owned_paths(out_dir: Path) -> tuple[set[str], set[str]]:
    """(problem directory names, file names) in ``out_dir`` that the export whose manifest
    is there wrote (module doc): the lists of an incomplete manifest, else the QPs of a
    problem-dir export or the file of an hdf5 or qpbenchmark one; empty sets without an
    export's manifest."""
    try:
        doc = json.loads((out_dir / MANIFEST_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set(), set()
    if not isinstance(doc, dict) or doc.get("tool") != EXPORT_TOOL:
        return set(), set()
    if doc.get("complete") is False:
        folders, files = doc.get("owned_folders"), doc.get("owned_files")
    else:
        qps = doc.get("qps") if doc.get("format") == "problem-dir" else None
        folders = [q.get("name") for q in qps if isinstance(q, dict)] if isinstance(qps, list) else []
        files = [_format_file(str(doc.get("format")), str(doc.get("scene")))]
    return ({n for n in folders if _own_name(n)} if isinstance(folders, list) else set(),
            {n for n in files if _own_name(n)} if isinstance(files, list) else set())


def remove_owned(out_dir: Path, folders: set[str], files: set[str]) -> None:
    """Remove what an earlier export wrote in ``out_dir`` and this one does not: from each
    problem directory of ``folders`` (a folder, not a symbolic link) its regular files of
    the problem directory format (``qpfile.PROBLEM_DIR_FILES``; ``problem.json`` first, so
    a folder whose removal stops part-way is no problem directory), then the folder itself
    when nothing else is left in it -- a user's file there and the folder that holds it
    stay as they are; and the regular files ``files``.  Nothing else is touched."""
    for name in sorted(folders):
        d = out_dir / name
        if not d.is_dir() or d.is_symlink():
            continue
        for file in [PROBLEM_JSON, *sorted(PROBLEM_DIR_FILES - {PROBLEM_JSON})]:
            path = d / file
            if path.is_file() and not path.is_symlink():
                path.unlink()
        if not any(d.iterdir()):
            d.rmdir()
    for name in sorted(files):
        f = out_dir / name
        if f.is_file() and not f.is_symlink():
            f.unlink()


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def require_h5py() -> Any:
    try:
        import h5py
    except ImportError:
        raise ProblemInputError("--format hdf5 needs h5py, which is not installed (pip install h5py); "
                                "problem-dir needs nothing") from None
    return h5py


def write_hdf5_group(h5: Any, name: str, inst: ContactInstance, *, tol: float | None, dense_limit: int) -> None:
    """One QP as an HDF5 group: its problem directory's arrays and problem.json
    (``qpfile.problem_payload``, the builder of the directory itself), with ``ubar`` in
    the dtype the instance holds it in (``data_dtype``; ``problem_json`` lists it)."""
    doc, arrays = problem_payload(inst, tol=tol, time_limit=None, dense_limit=dense_limit)
    held = data_dtype(inst)
    if held != arrays["ubar"].dtype:  # the payload holds the problem directory's float64
        arrays["ubar"] = np.ascontiguousarray(inst.qp.ubar, dtype=held.newbyteorder("<"))
        doc["arrays"]["ubar"]["dtype"] = arrays["ubar"].dtype.str
    g = h5.create_group(name)
    g.attrs["problem_json"] = problem_json(doc)
    for key, a in arrays.items():
        g.create_dataset(key, data=a)


def read_hdf5_problem(path: str | Path, name: str) -> Any:
    """A QP group of ``problems.h5`` back as a ``qpfile.ProblemFile`` (unpacked to a
    temporary problem directory and read by ``read_problem_dir``; a float32 dataset is
    widened, exactly, to the directory format's float64: read the dataset itself for the
    dtype it holds)."""
    h5py = require_h5py()
    with h5py.File(path, "r") as h5, tempfile.TemporaryDirectory() as tmp:
        if name not in h5:
            raise ProblemInputError(f"{path}: no QP named {name!r}")
        g = h5[name]
        doc = json.loads(g.attrs["problem_json"])
        d = Path(tmp)
        for key, entry in doc["arrays"].items():
            stored = np.dtype(entry["dtype"])
            entry["dtype"] = (np.dtype("<f8") if stored.kind == "f" else stored).str
            np.asarray(g[key][...], dtype=np.dtype(entry["dtype"])).tofile(d / entry["file"])
        (d / "problem.json").write_text(json.dumps(doc))
        return read_problem_dir(d)


def qpbenchmark_row(name: str, inst: ContactInstance) -> dict[str, Any]:
    """min 1/2 p'Hp - ubar'p, p >= 0 as qpbenchmark's row: P = H (float64, flattened; the
    one dense copy, checked against the memory budget by ``to_dense``), q = -ubar and
    lb = 0 in ``data_dtype``; with bounds ub = the upper bounds, with a load equality
    A = 1' (one row, stored flat like P) and b = [P] (``problems.constraints``)."""
    held = data_dtype(inst)
    ubar = np.asarray(inst.qp.ubar, dtype=held)
    c = inst.qp.constraints
    return {"P": inst.qp.H.to_dense().ravel(), "q": -ubar, "G": None, "h": None,
            "A": None if c.load is None else np.ones(ubar.size), "b": None if c.load is None else np.array([c.load]),
            "lb": np.zeros(ubar.size, dtype=held), "ub": c.upper_or_inf(ubar.size) if c.bounded else None,
            "name": name}


def append_qpbenchmark_row(rows: dict[str, list[Any]], name: str, inst: ContactInstance) -> None:
    """``qpbenchmark_row`` appended to ``rows`` (column -> list of cells, ``write_parquet``)."""
    row = qpbenchmark_row(name, inst)
    for key in QPBENCHMARK_KEYS:
        rows[key].append(row[key])


class QPBenchmarkWriter:
    """qpbenchmark's Parquet file at ``path`` (written new), one row group per QP.

    Each array column is a list of the widest dtype of the arrays written to it (float64
    while it holds none): a float32 q stays float32 while every QP's is; when a wider QP
    comes, the QPs written so far are copied once, a row group at a time, into the wider
    type (exact).  ``close`` records each QP's data dtype (its q's) under
    ``PARQUET_DTYPES_KEY`` and ends the file; a writer with no QP leaves a file of no
    rows.  It holds one row at a time (and, while widening, one row group read back)."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        self.seen: dict[str, np.dtype | None] = {k: None for k in QPBENCHMARK_ARRAYS}
        self.dtypes: dict[str, str] = {}
        self._schema: Any = None
        self._writer: Any = None

    def schema(self) -> Any:
        """The file's Arrow schema for the dtypes seen so far."""
        import pyarrow as pa

        return pa.schema([(k, pa.list_(pa.from_numpy_dtype(self.seen[k] or np.dtype(np.float64))))
                          for k in QPBENCHMARK_ARRAYS] + [("name", pa.string())])

    def write(self, row: dict[str, Any]) -> None:
        """One QP (a ``qpbenchmark_row``) as the next row group."""
        import pyarrow as pa

        for k in QPBENCHMARK_ARRAYS:
            if row[k] is not None:
                dt = np.asarray(row[k]).dtype
                self.seen[k] = dt if self.seen[k] is None else np.result_type(self.seen[k], dt)
        self._open(self.schema())
        cells = [_list_cell(row[k], self._schema.field(k).type) for k in QPBENCHMARK_ARRAYS]
        self._writer.write_table(pa.Table.from_arrays(cells + [pa.array([row["name"]], pa.string())],
                                                      schema=self._schema))
        self.dtypes[str(row["name"])] = np.asarray(row["q"]).dtype.name

    def close(self) -> None:
        """Record the QPs' dtypes and end the file."""
        self._open(self.schema())
        self._writer.add_key_value_metadata({PARQUET_DTYPES_KEY: json.dumps(self.dtypes)})
        self._writer.close()

    def _open(self, schema: Any) -> None:
        """The writer of ``schema``: the one open, or a new file holding the rows written so
        far cast to it."""
        import pyarrow.parquet as pq

        if self._writer is not None and schema.equals(self._schema):
            return
        self._schema = schema
        if self._writer is None:
            self._writer = pq.ParquetWriter(self.path, schema)
            return
        self._writer.close()
        narrow = f"{self.path}.narrow"
        os.replace(self.path, narrow)
        try:
            self._writer = pq.ParquetWriter(self.path, schema)
            with pq.ParquetFile(narrow) as source:
                for i in range(source.num_row_groups):
                    self._writer.write_table(source.read_row_group(i).cast(schema))
        finally:
            os.unlink(narrow)


def _list_cell(a: np.ndarray | None, list_type: Any) -> Any:
    """``a`` (None: null) as a one-cell Arrow list array of ``list_type``; the values are
    not copied when ``a`` is contiguous and of the list's value type."""
    import pyarrow as pa

    if a is None:
        return pa.nulls(1, list_type)
    values = pa.array(np.ravel(np.asarray(a, dtype=list_type.value_type.to_pandas_dtype())))
    return pa.ListArray.from_arrays(pa.array([0, len(values)], pa.int32()), values, type=list_type)


def write_parquet(rows: dict[str, list[Any]], path: Path) -> Path:
    """The rows as qpbenchmark's Parquet file ``path`` (``QPBenchmarkWriter``), whole or
    not at all (``replace_atomically``: a link at ``path`` is replaced, never followed)."""
    def write(sink: QPBenchmarkWriter) -> None:
        for i in range(len(rows["name"])):
            sink.write({k: rows[k][i] for k in QPBENCHMARK_KEYS})

    replace_atomically(path, _in_parquet(write))
    return path


def read_qpbenchmark_dtypes(path: str | Path) -> dict[str, str]:
    """name -> data dtype of every QP of an exported Parquet file (``PARQUET_DTYPES_KEY``)."""
    import pyarrow.parquet as pq

    meta = pq.read_metadata(path).metadata or {}
    raw = meta.get(PARQUET_DTYPES_KEY.encode())
    if raw is None:
        raise ProblemInputError(f"{path}: no {PARQUET_DTYPES_KEY} metadata (not a contactbench export)")
    return dict(json.loads(raw))


def _qpbenchmark_cells(path: str | Path, name: str) -> Any:
    """The row of problem ``name``, read as qpbenchmark's ParquetTestSet reads it."""
    import pandas as pd

    df = pd.read_parquet(literal_path(path), engine="pyarrow")
    hit = df[df["name"] == name]
    if len(hit) != 1:
        raise ProblemInputError(f"{path}: no problem named {name!r}")
    return hit.iloc[0]


def read_qpbenchmark_row(path: str | Path, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, q, lb) of one exported problem, read as qpbenchmark's ParquetTestSet does (in
    the dtypes stored)."""
    row = _qpbenchmark_cells(path, name)
    q = np.asarray(row["q"])
    return np.asarray(row["P"]).reshape(q.size, q.size), q, np.asarray(row["lb"])


def read_qpbenchmark_constraints(path: str | Path, name: str) -> tuple[np.ndarray | None, np.ndarray | None,
                                                                       np.ndarray | None]:
    """(ub, A, b) of one exported problem (None where it has none); A as a 1 x n matrix."""
    row = _qpbenchmark_cells(path, name)

    def arr(key: str) -> np.ndarray | None:
        v = row[key]
        return None if v is None else np.asarray(v)

    A = arr("A")
    return arr("ub"), None if A is None else A.reshape(1, -1), arr("b")


def check_export_folder(out: str | Path) -> Path:
    """``out`` as a Path if an export may write there: missing, empty, or written by an
    export before (its manifest names ``EXPORT_TOOL``); else a ``ProblemInputError``
    naming it (the rule of a run's results folder; an empty name and a folder whose
    manifest is a symbolic link are refused too).  Touches nothing."""
    if names_nothing(out):
        raise ProblemInputError(f"the export folder (--out) must be named, got {str(out)!r}")
    out_dir = Path(out)
    if not out_dir.exists():
        return out_dir
    if not out_dir.is_dir():
        raise ProblemInputError(f"export folder {out_dir} is not a folder; choose another --out")
    if (out_dir / MANIFEST_FILE).is_symlink():
        raise ProblemInputError(f"{out_dir / MANIFEST_FILE} is a symbolic link; an export never writes through one: "
                                "remove it or choose another --out")
    if not any(out_dir.iterdir()) or is_export_folder(out_dir):
        return out_dir
    raise ProblemInputError(f"export folder {out_dir} is not empty and is not a contactbench export folder "
                            f"(no {MANIFEST_FILE} of an export); choose an empty or new --out")


def is_export_folder(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds the manifest of an export (``EXPORT_TOOL``), complete or
    not (module doc)."""
    try:
        doc = json.loads((out_dir / MANIFEST_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("tool") == EXPORT_TOOL


def write_manifest(summary: ExportSummary, path: Path) -> Path:
    """The complete manifest of a finished export (module doc)."""
    doc = {"tool": EXPORT_TOOL, "complete": True, "scene": summary.scene, "format": summary.fmt,
           "dense_limit": summary.dense_limit, "contactbench_version": summary.version,
           "scene_options": summary.options, "qps": [asdict(q) for q in summary.written],
           "skipped": summary.skipped}
    return _write_json(path, doc)


def write_progress(summary: ExportSummary, folders: set[str], files: set[str]) -> Path:
    """The manifest of an export under way (module doc): ``"complete": false`` and what of
    the folder is an export's."""
    doc = {"tool": EXPORT_TOOL, "complete": False, "scene": summary.scene, "format": summary.fmt,
           "dense_limit": summary.dense_limit, "owned_folders": sorted(folders), "owned_files": sorted(files)}
    return _write_json(Path(summary.out) / MANIFEST_FILE, doc)


def _write_json(path: Path, doc: dict[str, Any]) -> Path:
    """``doc`` into ``path`` whole or not at all (``write_text_atomic``)."""
    write_text_atomic(path, json.dumps(doc, indent=2) + "\n")
    return path


__all__ = [
    "FORMATS",
    "ExportSummary",
    "ExportedQP",
    "ExportStopped",
    "MAX_QPS",
    "PARQUET_DTYPES_KEY",
    "QPBenchmarkWriter",
    "check_dense_fits",
    "check_export_folder",
    "check_scene",
    "check_target",
    "data_dtype",
    "export_scene",
    "problem_name",
    "read_hdf5_problem",
    "read_qpbenchmark_constraints",
    "read_qpbenchmark_dtypes",
    "read_qpbenchmark_row",
    "scene_steps",
]


def qpbenchmark_test_set(parquet_path: str | Path, title: str = "contactbench",
                         description: str = "contactbench export") -> Any:
    """The exported Parquet file as a qpbenchmark ``TestSet`` (needs the optional
    ``qpbenchmark`` extra; its abstract TestSet asks for these three properties)."""
    from qpbenchmark.parquet_test_set import ParquetTestSet

    class Exported(ParquetTestSet):
        @property
        def description(self) -> str:
            return description

        @property
        def sparse_only(self) -> bool:
            return False

        @property
        def title(self) -> str:
            return title

    return Exported(Path(parquet_path))
