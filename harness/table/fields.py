"""Contact fields on the grid, kept for the report's pictures of the field: the height
map, the contact pressure with the contact area, and the gap.

The worker (harness/run/worker.py) calls ``save_field`` after every judged solve; it keeps
the first *solved* answer of the top step of each instance (every step when the
environment variable ``CONTACTBENCH_FIELD_STEPS=all``) as

    OUT/arrays/field-<scene>-<instance>-k<step>.npz      (numpy.savez_compressed, no pickles)
      heights   float32 (m, m)  surface heights xi (the instance's length unit)
      pressure  float32 (m, m)  mean contact pressure p_ij / delta^2 (0 off contact)
      gap       float32 (m, m)  gap g = u - (Delta - xi_max + xi) (NaN where unknown; without a
                                surface, as for Example 1, w = Hp - ubar on the trial set)
      contact   bool    (m, m)  p_ij > 1e-6 p_s (ContactInstance.contact_mask at its default tolerance)
      scalars   N, N1 (grid points along axes 0 and 1), spacing, spacing1 (the stored maps'
                spacing along axes 0 and 1), E, far_field (Delta: under load control the
                answer's approach, ``answer_approach``; NaN without a surface), load,
                dim_load (P / (E A0)), contact_fraction (A/A0, full grid), rms_slope
                (h'_rms of the full surface), step, steps, solver, unit, periodic

Disk budget.  Maps are block-averaged to at most ``FIELD_MAX_SIDE`` points per side
(contact: any point of the block), so one file holds at most 3 float32 maps of 512^2
(3 MiB before compression, about 2 MiB after); no new file is written once the field
files of a run directory total ``FIELD_BUDGET_MB``.  Instances without a grid geometry
(the counterexample) keep nothing.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from contactbench.problems.constraints import fit_multiplier

from .files import safe_name, write_npz_atomic

#: Stored maps have at most this many points per side (block averages beyond).
FIELD_MAX_SIDE = 512
#: No new field file once a run directory's field files total this many MiB.
FIELD_BUDGET_MB = 64.0
#: Environment variable: "top" (default) keeps the top step of each instance, "all" every step.
FIELD_STEPS_ENV = "CONTACTBENCH_FIELD_STEPS"
FIELD_PREFIX = "field-"
FIELD_RE = re.compile(r"^field-(.+)-k(\d+)\.npz$")


def _safe(text: str) -> str:
    return safe_name(text)[:160]


def field_name(scene: str, instance: str, step: int) -> str:
    return f"{FIELD_PREFIX}{_safe(f'{scene}-{instance}')}-k{int(step)}.npz"


def wants_step(step: int, steps: int) -> bool:
    """Whether the field of ``step`` is kept (the top step, or all when asked)."""
    return os.environ.get(FIELD_STEPS_ENV, "top").strip().lower() == "all" or step == steps - 1


def field_files_mb(arrays_dir: Path) -> float:
    if not arrays_dir.is_dir():
        return 0.0
    return sum(p.stat().st_size for p in arrays_dir.glob(f"{FIELD_PREFIX}*.npz")) / 2**20


def block_reduce(a: np.ndarray, side: int = FIELD_MAX_SIDE, how: str = "mean") -> np.ndarray:
    """``a`` (m x m) averaged (or any-ed, for ``how="any"``) over square blocks so that
    it has at most ``side`` points per side (rows/columns beyond a whole block dropped)."""
    f = math.ceil(a.shape[0] / side)
    if f <= 1:
        return a
    m0, m1 = (a.shape[0] // f) * f, (a.shape[1] // f) * f
    b = a[:m0, :m1].reshape(m0 // f, f, m1 // f, f)
    return b.any(axis=(1, 3)) if how == "any" else np.nanmean(b, axis=(1, 3))


def answer_approach(inst: Any, p: np.ndarray) -> float:
    """The far-field displacement Delta of the answer: the instance's own under
    displacement control; under load control the load equality's multiplier that p
    implies (``problems.constraints.fit_multiplier``, as ``ContactInstance.gap`` fits it)."""
    c = inst.qp.constraints
    if not c.load_control:
        return float(inst.delta)
    q = np.asarray(p, dtype=float)
    return fit_multiplier(np.asarray(inst.qp.H.matvec(q), dtype=float) - np.asarray(inst.qp.ubar, dtype=float),
                          q, c.upper)


def gap_field(inst: Any, p: np.ndarray, approach: float) -> np.ndarray:
    """The gap on the whole grid, u - (Delta - xi_max + xi) with Delta = ``approach``, from
    the scene's matrix-free operator; else w = Hp - ubar - Delta (``ContactInstance.gap``)
    on the trial set only (NaN elsewhere) -- the operator cannot give the displacement off
    the set, or the instance has no surface (Example 1: ubar is drawn)."""
    g = inst.geometry
    H = inst.qp.H
    if g.has_surface and hasattr(H, "displacement_field"):
        h = np.asarray(inst.surface.heights, dtype=float)
        u = np.asarray(H.displacement_field(p), dtype=float).reshape(g.grid_shape)
        return u - (approach - float(h.max()) + h)
    out = np.full(g.grid_shape, np.nan)
    out.ravel()[g.indices] = inst.gap(p, approach if inst.qp.constraints.load_control else None)
    return out


def save_field(arrays_path: str | None, scene: str, instance: str, inst: Any, p: np.ndarray, step: int, steps: int,
               solver: str, status: str) -> Path | None:
    """Keep this solve's field when it is solved, on a grid, at a kept step, the first
    for its (instance, step), and within the disk budget.  Never raises: a field is a
    picture, not a result."""
    try:
        if not arrays_path or status != "solved" or not wants_step(step, steps):
            return None
        if inst.geometry is None or inst.surface is None:
            return None
        d = Path(arrays_path).parent
        path = d / field_name(scene, instance, step)
        if path.exists() or field_files_mb(d) >= FIELD_BUDGET_MB:
            return None
        d.mkdir(parents=True, exist_ok=True)
        g = inst.geometry
        pressure = inst.pressure_field(p)
        contact = np.zeros(g.grid_shape, dtype=bool)
        contact.ravel()[g.indices] = inst.contact_mask(p)
        heights = np.asarray(inst.surface.heights, dtype=float)
        f = math.ceil(g.grid_shape[0] / FIELD_MAX_SIDE)
        approach = answer_approach(inst, p)
        arrays = dict(
            heights=block_reduce(heights).astype(np.float32),
            pressure=block_reduce(pressure).astype(np.float32),
            gap=block_reduce(gap_field(inst, p, approach)).astype(np.float32),
            contact=block_reduce(contact, how="any"),
            N=np.int64(g.grid_shape[0]), N1=np.int64(g.grid_shape[1]), spacing=np.float64(g.spacing[0] * f),
            spacing1=np.float64(g.spacing[1] * f), E=np.float64(inst.E),
            far_field=np.float64(approach), load=np.float64(inst.load(p)),
            dim_load=np.float64(inst.dimensionless_load(p)), contact_fraction=np.float64(inst.contact_fraction(p)),
            rms_slope=np.float64(inst.surface.rms_slope()), step=np.int64(step), steps=np.int64(steps),
            solver=np.str_(solver), unit=np.str_(getattr(inst.surface, "unit", "m")),
            periodic=np.bool_(bool(inst.periodic)))
        write_npz_atomic(path, compressed=True, **arrays)
        return path
    except Exception:  # noqa: BLE001 - never lose a row for a picture
        return None


@dataclass
class ContactField:
    """A stored field (see the module docstring)."""

    scene: str
    instance: str
    step: int
    steps: int
    solver: str
    heights: np.ndarray
    pressure: np.ndarray
    gap: np.ndarray
    contact: np.ndarray
    N: int
    spacing: float
    E: float
    far_field: float
    load: float
    dim_load: float
    contact_fraction: float
    rms_slope: float
    unit: str
    periodic: bool
    N1: int = 0  # points along axis 1 (files written before it: 0, read as N)
    spacing1: float = 0.0  # spacing along axis 1 (0: read as spacing)

    @property
    def extent(self) -> tuple[float, float]:
        """The stored maps' physical sizes along axes 0 and 1."""
        m0, m1 = self.heights.shape
        return m0 * self.spacing, m1 * (self.spacing1 or self.spacing)


def load_field(path: Path, scene: str, instance: str) -> ContactField:
    with np.load(path, allow_pickle=False) as z:
        v = {k: z[k] for k in z.files}
    return ContactField(scene, instance, int(v["step"]), int(v["steps"]), str(v["solver"]),
                        np.asarray(v["heights"], float), np.asarray(v["pressure"], float), np.asarray(v["gap"], float),
                        np.asarray(v["contact"], bool), int(v["N"]), float(v["spacing"]), float(v["E"]),
                        float(v["far_field"]), float(v["load"]), float(v["dim_load"]), float(v["contact_fraction"]),
                        float(v["rms_slope"]), str(v["unit"]), bool(v["periodic"]),
                        int(v.get("N1", v["N"])), float(v.get("spacing1", v["spacing"])))


def find_fields(out_dir: Path, keys: set[tuple[str, str]]) -> dict[tuple[str, str, int], Path]:
    """(scene, instance, step) -> field file under OUT/arrays/, for the (scene, instance)
    pairs of ``keys`` (file names are sanitised, so they are matched by name)."""
    d = Path(out_dir) / "arrays"
    if not d.is_dir():
        return {}
    by_name = {_safe(f"{sc}-{inst}"): (sc, inst) for sc, inst in keys}
    out: dict[tuple[str, str, int], Path] = {}
    for p in sorted(d.glob(f"{FIELD_PREFIX}*.npz")):
        m = FIELD_RE.match(p.name)
        if m and m.group(1) in by_name:
            out[(*by_name[m.group(1)], int(m.group(2)))] = p
    return out
