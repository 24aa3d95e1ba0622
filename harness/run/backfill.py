"""Re-solve the top step of each grid instance of a stored run to add the field files
its report pictures (``arrays/field-*.npz``; harness/table/fields.py) -- for a run stored
before fields were kept.  This solves; ``contactbench report`` never does.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from contactbench.problems.scenes import get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import load_solver

from ..judging import judge
from ..table.fields import save_field
from ..table.meta import read_meta, scene_config_from_meta
from ..table.store import load_table
from .studies import expand


def backfill_fields(out_dir: str | os.PathLike[str], solver: str = "fast-dual-pccg", tol: float = 1e-10,
                    time_limit: float = 600.0) -> list[Path]:
    """For a run stored before fields were kept: rebuild the top step of each grid
    instance of OUT's table from its scene recipe (the configuration in OUT/meta.json),
    solve it with ``solver``, judge it, and keep its field.  Returns the files written.
    This solves; ``contactbench report`` never does.  Usage:
    ``python -m contactbench.harness.run.backfill OUT [SOLVER]``."""
    out = Path(out_dir)
    table = load_table(out)
    meta = read_meta(out) or {}
    user = scene_config_from_meta(meta)
    grid = table[table["N"].notna() & table["delta"].notna()]  # surfaces on a grid (not the counterexample)
    wanted = set(zip(grid["scene"], grid["instance"]))
    written: list[Path] = []
    for name in (meta.get("config") or {}).get("scenes") or sorted(set(grid["scene"])):
        for study, cfg in expand(name, user):
            scene = get_scene(study.scene)
            for spec in scene.instances(scene.config(cfg)):
                if (study.scene, spec.instance) not in wanted:
                    continue
                wanted.discard((study.scene, spec.instance))
                seq = spec.build()
                k = len(seq) - 1
                inst = seq.at(k)
                res = load_solver(solver).solve(inst.qp, SolverSettings(tol=tol, time_limit=time_limit), None)
                p = np.asarray(res.p, dtype=np.float64).reshape(-1)
                status = judge(inst, p, bool(res.converged), 1e-8).status
                path = save_field(str(out / "arrays" / "x.npz"), study.scene, spec.instance, inst, p, k, len(seq),
                                  solver, status)
                if path is not None:
                    written.append(path)
    return written


if __name__ == "__main__":  # pragma: no cover - a maintenance command
    import sys

    for f in backfill_fields(sys.argv[1], *sys.argv[2:3]):
        print(f)
