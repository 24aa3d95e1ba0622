"""Run metadata (OUT/meta.json): what ran, where, with what.

Package versions, Python, CPU model and core counts, thread settings (environment and
threadpoolctl's view of the BLAS libraries), date, git commit (and whether the tree was
dirty), the command line, the run configuration, the scenes' warnings and, for every
instance on a measured map, what was done to the map (``surface_preprocessing``:
"<scene>/<instance>" -> ``problems.preprocessing.MapPreprocessing.as_dict()``; its
warnings also join ``warnings``).  A resumed
(or, with ``--append``, an added) run keeps the first record's ``date`` and ``command``,
appends itself to ``invocations`` and lists its command in ``commands`` (every distinct
command that wrote to the folder, in order: ``commands_of``).
"""

from __future__ import annotations

import json
import math
import os
import platform
import socket
import subprocess
import sys
from dataclasses import fields
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any, Iterable

import pandas as pd

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import InstanceSpec, SceneConfig
from contactbench.problems.scenes.core import surface_from_params

from .files import write_text_atomic
from .schema import CELL_COLUMNS, as_text

META_FILE = "meta.json"


class MetaError(ProblemInputError):
    """OUT/meta.json that is not a JSON object (the run's record): named, never replaced."""


PACKAGES = (
    "contactbench", "numpy", "scipy", "pandas", "pyarrow", "qpsolvers", "osqp", "clarabel", "proxsuite", "piqp",
    "cvxpy", "scs", "ecos", "highspy", "matplotlib", "threadpoolctl", "psutil", "dask", "distributed",
    "pytest-benchmark", "numba", "ducc0",
)
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "CONTACTBENCH_FFT_WORKERS",
              "CONTACTBENCH_FFT_BACKEND", "CONTACTBENCH_MEMORY_BUDGET_GB")


def package_versions(names: tuple[str, ...] = PACKAGES) -> dict[str, str]:
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def physical_cores() -> int | None:
    try:
        import psutil

        return psutil.cpu_count(logical=False)
    except Exception:
        return None


def thread_settings() -> dict[str, Any]:
    env = {k: os.environ.get(k) for k in THREAD_ENV}
    pools: list[dict[str, Any]] = []
    try:
        from threadpoolctl import threadpool_info

        pools = [
            {k: p.get(k) for k in ("user_api", "internal_api", "num_threads", "version")} for p in threadpool_info()
        ]
    except Exception:
        pass
    try:
        from contactbench.problems.operators import fft_backend, fft_workers

        fft, backend = fft_workers(), fft_backend()
    except Exception:
        fft, backend = None, None
    return {"env": env, "threadpools": pools, "fft_workers": fft, "fft_backend": backend}


def git_state(cwd: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """Commit and dirty flag of the source tree (read-only git commands)."""
    root = cwd or Path(__file__).resolve().parent.parent

    def git(*args: str) -> str | None:
        try:
            r = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10)
        except (OSError, subprocess.SubprocessError):
            return None
        return r.stdout.strip() if r.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "dirty": bool(status) if status is not None else None}


def machine_record() -> dict[str, Any]:
    return {
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu": cpu_model(),
        "logical_cores": os.cpu_count(),
        "physical_cores": physical_cores(),
    }


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def surface_preprocessing(specs: Iterable[InstanceSpec]) -> dict[str, dict[str, Any]]:
    """meta.json's ``surface_preprocessing``: "<scene>/<instance>" -> the
    ``MapPreprocessing`` record (``as_dict``) of every recipe on a measured map (its
    ``params["surface_path"]``), as the scene's loader prepares it."""
    out: dict[str, dict[str, Any]] = {}
    for spec in specs:
        if spec.params.get("surface_path"):
            record = surface_from_params(spec.params).preprocessing
            if record is not None:
                out[f"{spec.scene}/{spec.instance}"] = record.as_dict()
    return out


def map_warnings(surfaces: dict[str, dict[str, Any]]) -> list[str]:
    """The loader's warnings of each measured map, "<scene>: <warning>" as the scenes'
    own warnings read."""
    found = [f"{key.split('/', 1)[0]}: {w}" for key, rec in surfaces.items() for w in rec.get("warnings") or ()]
    return list(dict.fromkeys(found))


def build_meta(command: list[str] | None = None, config: dict[str, Any] | None = None,
               warnings: list[str] | None = None, extra: dict[str, Any] | None = None,
               surfaces: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The run's record (module doc); ``surfaces`` (``surface_preprocessing``) is stored
    under ``surface_preprocessing`` and its maps' warnings join ``warnings``."""
    return {
        "date": now_iso(),
        "command": list(command if command is not None else sys.argv),
        "git": git_state(),
        "machine": machine_record(),
        "threads": thread_settings(),
        "packages": package_versions(),
        "config": config or {},
        "warnings": list(dict.fromkeys([*(warnings or []), *map_warnings(surfaces or {})])),
        "surface_preprocessing": dict(surfaces or {}),
        **(extra or {}),
    }


def write_meta(out_dir: str | os.PathLike[str], record: dict[str, Any]) -> Path:
    """Write OUT/meta.json; a resumed run keeps the first record and lists itself under
    ``invocations``; the maps' records (``surface_preprocessing``) and the warnings of the
    runs before it stay beside its own (a map's rows outlive the run that read it).  A
    record that cannot be read is not replaced (``read_meta``'s ``MetaError``)."""
    path = Path(out_dir) / META_FILE
    previous = read_meta(out_dir)
    invocations = list(listed(previous.get("invocations")))
    invocations.append({k: record.get(k) for k in ("date", "command", "git", "config")})
    merged = {**record, **{k: v for k, v in previous.items() if k in ("date", "command")}}
    merged["invocations"] = invocations
    merged["commands"] = commands_of(merged)
    merged["warnings"] = sorted({str(w) for w in [*listed(previous.get("warnings")), *record.get("warnings", [])]})
    earlier = previous.get("surface_preprocessing")
    merged["surface_preprocessing"] = {**(earlier if isinstance(earlier, dict) else {}),
                                       **(record.get("surface_preprocessing") or {})}
    write_text_atomic(path, json.dumps(merged, indent=2, default=str))
    return path


def command_text(command: Any) -> str:
    return " ".join(str(a) for a in command) if isinstance(command, (list, tuple)) else str(command or "")


def listed(value: Any) -> list[Any]:
    """A meta.json field that is a list (``invocations``, ``warnings``) as that list; anything
    else (absent, or a hand-edited number or text) as no entry."""
    return value if isinstance(value, list) else []


def commands_of(meta: dict[str, Any]) -> list[str]:
    """Every distinct command that wrote to the run folder, first first: ``command`` and
    those of ``invocations`` (meta.json of any age)."""
    found = [command_text(meta.get("command"))]
    found += [command_text(inv.get("command")) for inv in listed(meta.get("invocations")) if isinstance(inv, dict)]
    return [c for c in dict.fromkeys(found) if c]


def planned_cells(config: Any) -> int | None:
    """How many cells a run's plan has (its meta.json ``config.cells``, written by the
    runner); None for a folder written before it was recorded, or a count that is not one."""
    cells = (config if isinstance(config, dict) else {}).get("cells")
    ok = isinstance(cells, (int, float)) and not isinstance(cells, bool) and math.isfinite(cells) and cells >= 1
    return int(cells) if ok else None


def planned_runs(meta: dict[str, Any]) -> list[int]:
    """The cells of each distinct plan that wrote to the folder (``invocations``' configs; a
    resume of a plan is the same plan), or of ``config`` alone in a record without them.  A
    plan is its run's configuration as the folder's marker pins it (``config.fingerprint``,
    written by the runner: warm or cold, repeats and the limits included); in a record
    without it, its scenes, scene options, solvers, profiles and cells."""
    configs = [inv.get("config") for inv in listed(meta.get("invocations")) if isinstance(inv, dict)]
    plans: dict[str, int] = {}
    for config in configs or [meta.get("config")]:
        cells = planned_cells(config)
        if cells is not None:
            key = config.get("fingerprint")
            what = key if isinstance(key, str) and key else \
                {k: config.get(k) for k in ("scenes", "scene_config", "solvers", "profiles", "cells")}
            plans.setdefault(json.dumps(what, sort_keys=True, default=str), cells)
    return list(plans.values())


def cells_text(meta: dict[str, Any], t: pd.DataFrame) -> str | None:
    """The report header's "Cells" line: the cells with a row against the plans', and
    "partial run" when fewer (an interrupted run, or one still to be resumed); None without
    a recorded plan.  A cell is a distinct ``cell_id`` (``schema.CELL_COLUMNS`` where the
    table carries none).  A folder added to with ``--append`` holds the cells of several
    plans, which may share cells: it is complete when its cells reach the plans' sum,
    partial when they fall short of the largest plan (its missing cells then bounded from
    below, not counted: rows are not told apart by plan), and otherwise not decided here."""
    plans = planned_runs(meta)
    if not plans:
        return None
    ids = t["cell_id"].map(as_text) if "cell_id" in t.columns else pd.Series("", index=t.index)
    keys = [c for c in CELL_COLUMNS if c in t.columns]
    done = int(ids[ids != ""].nunique()) if (ids != "").any() else len(t.drop_duplicates(keys) if keys else t)
    largest, total = max(plans), sum(plans)
    if done < largest and len(plans) == 1:
        return (f"PARTIAL RUN: {done} of {largest} planned cells have a row ({largest - done} missing: the run "
                "was interrupted or has not finished; run the same command again to resume it)")
    if done < largest:  # (the rows of the several plans are not told apart: a bound, not a count)
        return (f"PARTIAL RUN: {done} cells have a row over {len(plans)} runs added with --append, which planned "
                f"{' + '.join(map(str, plans))} cells: at least {largest - done} of the largest run's are missing "
                "(interrupted or not finished; resume each run with its own command)")
    if len(plans) == 1 and done > largest:
        return (f"{done} cells with a row, {largest} planned: {done - largest} more than the plan has (rows not of "
                "this run's plan), so whether each planned cell has one is not decided here")
    if len(plans) == 1:
        return f"{done} of {largest} planned cells (complete)"
    if done >= total:
        return f"{done} of {total} planned cells over {len(plans)} runs added with --append (complete)"
    return (f"{done} cells with a row; {len(plans)} runs added with --append planned {' + '.join(map(str, plans))} "
            "cells, some of them perhaps the same: complete only if every run finished (resume one with its own "
            "command)")


def references_asked(meta: dict[str, Any]) -> bool | None:
    """Whether any run that wrote to the folder asked for reference solutions (its
    ``config.run.reference`` is not "none"); None where no record says."""
    configs = [inv.get("config") for inv in listed(meta.get("invocations")) if isinstance(inv, dict)]
    asked = [c["run"].get("reference") for c in configs or [meta.get("config")]
             if isinstance(c, dict) and isinstance(c.get("run"), dict) and "reference" in c["run"]]
    return any(str(a) != "none" for a in asked) if asked else None


def read_meta(out_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """OUT/meta.json ({} where there is none); ``MetaError`` naming the file where it is not
    a JSON object."""
    path = Path(out_dir) / META_FILE
    if not path.exists():
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MetaError(f"{path} is not valid JSON ({exc}); repair or remove it") from None
    if not isinstance(meta, dict):
        raise MetaError(f"{path} holds a JSON {type(meta).__name__}, not a run's record (an object); "
                        "repair or remove it")
    return meta


def scene_config_from_meta(meta: dict[str, Any]) -> SceneConfig:
    """The SceneConfig a run used (OUT/meta.json), or the default one."""
    raw = dict((meta.get("config") or {}).get("scene_config") or {})
    names = {f.name for f in fields(SceneConfig)}
    kw = {k: v for k, v in raw.items() if k in names}
    if kw.get("seeds") is not None:
        kw["seeds"] = tuple(int(s) for s in kw["seeds"])
    return SceneConfig(**kw)
