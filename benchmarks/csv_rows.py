"""The benchmark scripts' rows: one solve's row from a child process that prints
``RESULT <json>``, and the CSV tables of dataclass rows (append one row; read the latest row
of each key back as the dataclass, int and float fields converted); ``cell`` formats a
number for their Markdown tables ("-" where there is none)."""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import subprocess
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any, Callable, TypeVar

Row = TypeVar("Row")


def cell(value: float, spec: str) -> str:
    """``value`` in format ``spec`` for a Markdown table, "-" where it is not a finite
    number (nothing measured: a reader is never shown "nan")."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "-"
    return format(x, spec) if math.isfinite(x) else "-"


def cpu_model() -> str:
    """The processor's model name (Linux's /proc/cpuinfo), or the platform's word for it."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def refuse_bad_grid_sizes(ap: argparse.ArgumentParser, flag: str, sizes: list[int]) -> None:
    """Exit 2 in one line unless every size is a power of two >= 16 (the RMD recipes the
    benchmarks pose need N = 2^k)."""
    if any(N < 16 or N & (N - 1) for N in sizes):
        shown = sizes if len(sizes) > 1 else sizes[0]
        ap.error(f"{flag} must be a power of two >= 16 (the RMD surfaces need N = 2^k), got {shown}")


def refuse_missing_device(ap: argparse.ArgumentParser, operator: str) -> None:
    """Exit 2 with the reason in one line when ``operator`` is "gpu" and CuPy or a CUDA
    device is missing, before any solve (not once per child)."""
    if operator != "gpu":
        return
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.instances import check_operator_kind

    try:
        check_operator_kind("gpu")
    except ProblemInputError as exc:
        ap.error(str(exc))


def host_name() -> str:
    """What the rows' ``host`` column says of the machine: env CONTACTBENCH_HOST when set
    (e.g. the accelerator's name), else the node's name with its processor and cores."""
    named = os.environ.get("CONTACTBENCH_HOST", "").strip()
    return named or f"{platform.node()} ({cpu_model()}, {os.cpu_count()} cores)"


def child_result(cmd: list[str], env: dict[str, str] | None, limit_s: float) -> tuple[dict[str, Any] | None, str, str]:
    """Run ``cmd`` for at most ``limit_s`` seconds: (its last ``RESULT`` JSON, "", "") when it
    printed one, else (None, "failed" | "timeout", the reason in one line)."""
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=limit_s, check=False)
    except subprocess.TimeoutExpired:
        return None, "timeout", f"killed after {limit_s:.0f} s"
    found = [ln[7:] for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if found:
        return json.loads(found[-1]), "", ""
    return None, "failed", (proc.stderr.strip().splitlines() or ["(no output)"])[-1]


def append_row(path: Path, row: Any) -> None:
    """Append ``row`` (a dataclass) to the CSV at ``path``, with a header when it is new."""
    new = not path.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=[f.name for f in fields(row)])
        if new:
            w.writeheader()
        w.writerow(asdict(row))


def read_latest(path: Path, cls: type[Row], key: Callable[[Row], tuple], order: Callable[[Row], tuple]) -> list[Row]:
    """The rows of ``path`` as ``cls``, the latest of each ``key``, sorted by ``order``."""
    types = {f.name: f.type for f in fields(cls)}
    latest: dict[tuple, Row] = {}
    with open(path, newline="") as fh:
        for raw in csv.DictReader(fh):
            conv = {k: (int(float(v)) if types[k] == "int" else float(v) if types[k] == "float" else v)
                    for k, v in raw.items()}
            row = cls(**conv)
            latest[key(row)] = row
    return sorted(latest.values(), key=order)
