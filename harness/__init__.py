"""The harness's public API: run a benchmark, judge an answer, read the table, write the
report, validate a solver.  Everything else lives in the sub-packages by concern
(docs/architecture.md): ``table`` (the stored table and its files), ``run`` (plans,
jobs, workers, executors), ``report`` (report.md and report.html) and ``conformance``
(``contactbench validate``).

The names are resolved on first access (PEP 562), so importing one sub-module (the
isolated worker imports ``harness.run.worker``) does not import the report.
"""

from __future__ import annotations

import importlib
from typing import Any

#: Public name -> the module that defines it.
_PUBLIC: dict[str, str] = {
    "run_benchmark": "contactbench.harness.run.runner",
    "RunConfig": "contactbench.harness.run.plan",
    "RunSummary": "contactbench.harness.run.runner",
    "Study": "contactbench.harness.run.studies",
    "solve_sequence": "contactbench.harness.run.sequence",
    "load_table": "contactbench.harness.table.store",
    "build_report": "contactbench.harness.report.build",
    "judge": "contactbench.harness.judging",
    "Verdict": "contactbench.harness.judging",
    "get_profile": "contactbench.harness.profiles",
    "validate": "contactbench.harness.conformance.battery",
    "assert_conforms": "contactbench.harness.conformance.battery",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str) -> Any:
    if name not in _PUBLIC:
        raise AttributeError(f"module 'contactbench.harness' has no attribute {name!r}")
    return getattr(importlib.import_module(_PUBLIC[name]), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
