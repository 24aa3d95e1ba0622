"""The one place a table row is built (column meanings: ``harness.table.schema``).

``RowFactory.row`` gives every row its identity (scene, instance, step, variant,
profile, repeat, cell_id, ...) and the step's facts (n, delta, E, kernel, ...; the grid,
the elastic layer and a measured map's preparation from ``ContactInstance.problem_columns``);
``answer_columns`` turns a worker's ``SolveReply`` into the answer's columns (status,
figures, the solver's account, the judge's reading in ``verdict``).  Skipped, failed,
timed-out, crashed and lost rows are the same row with a status and a reason.
"""

from __future__ import annotations

import socket
from dataclasses import asdict
from typing import Any

from contactbench.problems.constraints import CONTROLS
from contactbench.solvers.registry import load_solver

from ..table.files import canonical_json
from ..table.meta import now_iso
from .plan import InstanceJob, RunConfig, make_cell_id
from ..profiles import get_profile
from ..table.schema import ALL_COLUMNS, HISTORIES
from .studies import SolverVariant
from .worker import SolveReply, StepInfo


def blank_row() -> dict[str, Any]:
    row: dict[str, Any] = {c: None for c in ALL_COLUMNS}
    row.update(skip_reason="", error="", trace="", reference_solver="", solver_message="", solver_status="",
               verdict="")
    return row


def answer_columns(reply: SolveReply, time_limit: float) -> dict[str, Any]:
    """The columns of one timed solve: "failed" when the solver raised or returned an
    unusable p; else the judge's status, or "timeout" when it finished past the limit."""
    out: dict[str, Any] = {"solve_time_s": reply.elapsed, "warm_start": reply.warm_start}
    if reply.facts is not None:
        out["peak_mem_mb"] = reply.peak_mem_mb
        out.update(asdict(reply.facts))
    if reply.verdict is None:
        out.update(status=reply.aborted or "failed", error=reply.error)
        return out
    verdict = reply.verdict
    out.update(verdict.figures, status=verdict.status, verdict=verdict.reading)
    if time_limit and reply.elapsed > time_limit:
        out.update(status="timeout", error=f"finished after {reply.elapsed:.3g} s, beyond the {time_limit:.3g} s limit")
    out["correct_claim"] = bool(verdict.claimed) == (out["status"] == "solved")
    return out


class RowFactory:
    """Rows of one job's cells."""

    def __init__(self, job: InstanceJob, run: RunConfig) -> None:
        self.job = job
        self.run = run
        self.host = socket.gethostname()
        self.families: dict[str, str] = {}

    def cell_id(self, k: int, v: SolverVariant, profile: str, r: int) -> str:
        return make_cell_id(self.job.spec, k, v, profile, r, self.run.warm)

    def family(self, base: str) -> str:
        if base not in self.families:
            try:
                self.families[base] = load_solver(base).family
            except Exception:
                self.families[base] = ""
        return self.families[base]

    def row(self, info: StepInfo | None, k: int, v: SolverVariant, profile: str, r: int, *,
            reference_solver: str = "", build_time_s: float | None = None, **values: Any) -> dict[str, Any]:
        """One row: identity, the step's facts (when it was built), then ``values``."""
        row = blank_row()
        spec = self.job.spec
        row.update(
            scene=spec.scene, instance=spec.instance, step=k, delta=info.delta if info else float("nan"),
            n=info.n if info else None, solver=v.name, base_solver=v.base, params=canonical_json(v.params),
            family=self.family(v.base), profile=profile, repeat=r, warm_start=False,
            check_tol=get_profile(profile).check_tol, time_limit_s=self.run.timeout,
            E=info.E if info else None, nominal_area=info.nominal_area if info else None,
            N=info.N if info else None, kernel=info.kernel if info else "",
            periodic=info.periodic if info else None, reference_solver=reference_solver,
            analytic_load=info.analytic.get("load") if info else None, build_time_s=build_time_s,
            host=self.host, timestamp=now_iso(), cell_id=self.cell_id(k, v, profile, r),
            history=HISTORIES[0] if self.run.warm else HISTORIES[1], **instance_columns(spec.params),
        )
        row.update(info.columns if info else recipe_columns(spec.params))
        row.update(values)
        return row


def recipe_columns(params: dict[str, Any]) -> dict[str, Any]:
    """What a row of a step that was not built (its build failed or timed out) knows of it
    from the recipe alone: E, kernel and periodic where the recipe names them, and N where it
    generates a square grid of ``size`` points a side (not a measured map, whose side the
    file tells).  n is the built problem's and stays unknown."""
    out: dict[str, Any] = {}
    if isinstance(params.get("E"), (int, float)) and not isinstance(params.get("E"), bool):
        out["E"] = float(params["E"])
    if isinstance(params.get("kernel"), str):
        out["kernel"] = params["kernel"]
    if isinstance(params.get("periodic"), bool):
        out["periodic"] = params["periodic"]
    size = params.get("size")
    if isinstance(size, int) and not isinstance(size, bool) and not params.get("surface_path"):
        out["N"] = size
    return out


def instance_columns(params: dict[str, Any]) -> dict[str, Any]:
    """The recipe's surface family, Hurst exponent, seed, control, hardness and variant
    (``InstanceSpec.params`` keys ``family``, ``hurst``, ``seed``, ``control``, ``hardness``,
    ``variant``)
    as table columns; N, kernel and periodic come from the built instance (``StepInfo``).
    A recipe on a measured map (``surface_path``) has no Hurst exponent and no seed (NaN,
    <NA>), whatever its scene's defaults put in its params."""
    measured = bool(params.get("surface_path"))
    hurst = None if measured else params.get("hurst")
    seed = None if measured else params.get("seed")
    hardness = params.get("hardness")
    return {"surface_family": str(params.get("family") or ""),
            "hurst": float(hurst) if hurst is not None else float("nan"),
            "seed": int(seed) if seed is not None else None,
            "control": str(params.get("control") or CONTROLS[0]),
            "hardness": float(hardness) if hardness is not None else float("nan"),
            "variant": str(params.get("variant") or "")}
