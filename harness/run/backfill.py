"""Re-solve the top step of each grid instance of a stored run to add the field files
its report pictures (``arrays/field-*.npz``; harness/table/fields.py) -- for a run stored
before fields were kept.  This solves; ``contactbench report`` never does.

    python -m contactbench.harness.run.backfill OUT [SOLVER]

A run on a measured map (``--surface``) is rebuilt from the map's path as the run
resolved it (meta.json ``surface_preprocessing``), so it may be backfilled from another
folder; an instance its recipe no longer gives (the map changed since, or the code that
names it) is not rebuilt, and is named.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import load_solver

from ..arguments import EXIT_BAD_INPUT
from ..judging import judge
from ..table.fields import save_field
from ..table.meta import read_meta, scene_config_from_meta
from ..table.store import load_table
from .studies import expand


@dataclass
class Backfill:
    """The field files written, and the "<scene>/<instance>" of the table the recipes no
    longer gave."""

    written: list[Path] = field(default_factory=list)
    not_rebuilt: list[str] = field(default_factory=list)


def recorded_surface(user: SceneConfig, meta: dict) -> SceneConfig:
    """``user`` with its ``surface_path`` as the run resolved it (the path typed may be
    relative to another folder)."""
    records = meta.get("surface_preprocessing") or {}
    paths = {str(r.get("path")) for r in records.values() if isinstance(r, dict) and r.get("path")}
    if user.surface_path and len(paths) == 1:
        return replace(user, surface_path=paths.pop())
    return user


def backfill_fields(out_dir: str | os.PathLike[str], solver: str = "fast-dual-pccg", tol: float = 1e-10,
                    time_limit: float = 600.0) -> Backfill:
    """For a run stored before fields were kept: rebuild the top step of each grid
    instance of OUT's table from its scene recipe (the configuration in OUT/meta.json),
    solve it with ``solver``, judge it, and keep its field (module doc)."""
    out = Path(out_dir)
    table = load_table(out)
    meta = read_meta(out)
    user = recorded_surface(scene_config_from_meta(meta), meta)
    grid = table[table["N"].notna() & table["delta"].notna()]  # surfaces on a grid (not the counterexample)
    wanted = set(zip(grid["scene"], grid["instance"]))
    done = Backfill()
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
                    done.written.append(path)
    done.not_rebuilt = sorted(f"{s}/{i}" for s, i in wanted)
    return done


def main(argv: list[str]) -> int:
    """The command (module doc): the files written on stdout, what was not rebuilt and any
    bad input on stderr in one line each; exit 2 for bad input, 1 when an instance was not
    rebuilt."""
    if not 1 <= len(argv) <= 2:
        print("usage: python -m contactbench.harness.run.backfill OUT [SOLVER]", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        done = backfill_fields(*argv)
    except (ProblemInputError, KeyError, ValueError, OSError) as exc:
        print(f"backfill: error: {exc.args[0] if isinstance(exc, KeyError) and exc.args else exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    for f in done.written:
        print(f)
    for name in done.not_rebuilt:
        print(f"backfill: not rebuilt: {name} (its recipe no longer gives this instance: the map or the code that "
              "names it changed since the run)", file=sys.stderr)
    return 1 if done.not_rebuilt else 0


if __name__ == "__main__":  # pragma: no cover - a maintenance command
    sys.exit(main(sys.argv[1:]))
