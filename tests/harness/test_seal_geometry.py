"""What a solver reaches through ``QP.geometry`` is the problem too: the surface's heights
(its coarse levels' too) and the unknowns' indices are read-only at the source, so no write
changes the steps built from them after, and the seal reads the geometry (the indices, the
far field, the surface and its levels), so a write that gets past is caught -- by ``run``,
whose later solves get the problem as built, and by ``validate``."""

from __future__ import annotations

import gc
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.harness.judging import ProblemSeal
from contactbench.problems.instances import QP, InstanceBuilder
from contactbench.problems.lcp import exact_solution
from contactbench.problems.scenes.base import LoadSequence
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver

HERE = __name__  # the import path of the solvers below


def surface_problem() -> QP:
    """A QP on a 16 x 16 RMD surface with coarse levels; its geometry's indices its own
    array (not the operator's), so that a write into them is the geometry's alone."""
    surface = rmd_surface_n(16, 0.7, family="periodic", length=1e-4, rms_height=1e-6, seed=0)
    assert surface.levels
    qp = InstanceBuilder(surface, 1e9, "bcc").build(0.3 * (surface.z_max - surface.z_mean)).qp
    assert qp.geometry is not None
    return replace(qp, geometry=replace(qp.geometry, indices=qp.geometry.indices.copy()))


def test_no_write_through_numpy_reaches_a_surface_s_heights() -> None:
    """Neither the heights nor a coarse level's can be made writeable (nor a view of them,
    nor their base), and the surface holds a copy of the array it was given."""
    given = np.random.default_rng(0).normal(size=(8, 8))
    surface = Surface(given, 1e-6)
    given[0, 0] = 1e3
    assert surface.heights[0, 0] != 1e3
    rough = rmd_surface_n(16, 0.7, family="periodic", seed=0)
    for heights in (surface.heights, surface.heights[::2], rough.levels[0].heights, rough.heights.ravel()):
        assert not heights.flags.writeable
        with pytest.raises(ValueError):
            heights.flags.writeable = True
        base = heights.base
        while isinstance(base, np.ndarray):
            with pytest.raises(ValueError):
                base.flags.writeable = True
            base = base.base
        with pytest.raises(ValueError):
            heights *= 3.0


def test_no_write_through_numpy_reaches_a_trial_set() -> None:
    """A geometry's indices are read-only, its integer type kept, and a copy of the array
    it was given; ``dataclasses.replace`` keeps them so."""
    qp = surface_problem()
    given = np.arange(qp.n, dtype=np.int32)
    geometry = replace(qp.geometry, indices=given)
    given[0] = 5
    for idx in (geometry.indices, geometry.indices[1:], replace(geometry, far_field=0.0).indices):
        assert idx.dtype == np.int32 and not idx.flags.writeable
        with pytest.raises(ValueError):
            idx.flags.writeable = True
    assert geometry.indices[0] == 0
    with pytest.raises(ValueError):
        geometry.indices[...] = 0


def _swap_heights(qp: QP) -> None:
    object.__setattr__(qp.geometry.surface, "heights", qp.geometry.surface.heights * 3.0)


def _swap_level(qp: QP) -> None:
    level = qp.geometry.surface.levels[0]
    object.__setattr__(level, "heights", level.heights * 3.0)


def _swap_indices(qp: QP) -> None:
    object.__setattr__(qp.geometry, "indices", np.zeros_like(qp.geometry.indices))


def _far_field(qp: QP) -> None:
    object.__setattr__(qp.geometry, "far_field", 0.0)


def _surface_meta(qp: QP) -> None:
    qp.geometry.surface.meta["seed"] = 7


WRITES: dict[str, tuple[Callable[[QP], None], str]] = {
    "heights": (_swap_heights, "geometry.surface.heights"),
    "level": (_swap_level, "geometry.surface.levels[0].heights"),
    "indices": (_swap_indices, "geometry.indices"),
    "far-field": (_far_field, "geometry.far_field"),
    "surface-meta": (_surface_meta, "geometry.surface.meta"),
}


@pytest.mark.parametrize("kind", sorted(WRITES))
def test_the_seal_names_a_write_into_the_geometry(kind: str) -> None:
    qp = surface_problem()
    seal = ProblemSeal.of(qp)
    qp.H.matvec(np.ones(qp.n))  # an honest product leaves it whole
    assert seal.broken(qp) == ""
    write, where = WRITES[kind]
    write(qp)
    broken = seal.broken(qp)
    assert "wrote into the problem" in broken and where in broken, broken


def test_the_seal_reads_a_surface_shared_with_the_problems_held_once() -> None:
    """The judge's problems held beside the solver's share its surface: read under the
    solver's problem's name, a write named once."""
    qp = surface_problem()
    held = replace(qp, ubar=qp.ubar.copy())
    seal = ProblemSeal.of(qp, [held])
    _swap_heights(qp)
    broken = seal.broken(qp)
    assert "geometry.surface.heights" in broken and "held[0].geometry.surface.heights" not in broken, broken


def _exact(ctx: SolveContext) -> np.ndarray:
    return exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar, dtype=np.float64)).p


class SwapsTheHeights(Solver):
    """Answers right, claimed, after putting heights three times as high in the surface it
    reaches through its problem's geometry (past the read-only array)."""

    name = "test-swaps-the-heights"
    family = "test"
    capabilities = Capabilities(needs_dense=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        g = ctx.qp.geometry
        if g is not None and g.surface is not None:
            object.__setattr__(g.surface, "heights", g.surface.heights * 3.0)
        return Outcome(_exact(ctx), 1, True)


class ScalesTheHeights(Solver):
    """Tries to scale its surface's heights in place (read-only: the attempt raises)."""

    name = "test-scales-the-heights"
    family = "test"
    capabilities = Capabilities(needs_dense=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        g = ctx.qp.geometry
        if g is not None and g.surface is not None:
            heights = g.surface.heights
            try:
                heights.flags.writeable = True
            except ValueError:
                pass
            heights *= 3.0
        return Outcome(_exact(ctx), 1, True)


def _pk(table: Any) -> list[tuple[int, int, float]]:
    rows = table[table["solver"] == "pk"].sort_values("step")
    return [(int(r.step), int(r.n), float(r.load)) for r in rows.itertuples()]


def test_run_fails_a_geometry_writer_and_solves_the_steps_after_as_built(run_harness, tmp_path: Any) -> None:
    """Each of the writer's rows fails, wrong, naming the heights; the in-place writer's
    rows fail (its write raised); pk after them in the same worker solves every step as a
    run of pk alone does (the same trial sets and loads, not those of a surface 3x higher)."""
    options: dict[str, Any] = dict(size=16, steps=3, seeds=(0,), profiles=("mid",), warmup=False, timeout=60.0)
    alone = _pk(run_harness(["paper-sweep"], solvers=["pk"], out=tmp_path / "alone", **options))
    table = run_harness(["paper-sweep"], solvers=[f"{HERE}:SwapsTheHeights", f"{HERE}:ScalesTheHeights", "pk"],
                        out=tmp_path / "after", **options)
    swaps = table[table["solver"] == SwapsTheHeights.name]
    assert len(swaps) == 3 and set(zip(swaps["status"], swaps["verdict"])) == {("failed", "wrong")}
    assert swaps["error"].str.contains("wrote into the problem it was handed").all()
    assert swaps["error"].str.contains("geometry.surface.heights").all(), swaps["error"].tolist()
    scales = table[table["solver"] == ScalesTheHeights.name]
    assert len(scales) == 3 and (scales["status"] == "failed").all()
    assert scales["error"].str.contains("read-only").all(), scales["error"].tolist()
    after = _pk(table)
    assert [(k, n) for k, n, _ in after] == [(k, n) for k, n, _ in alone]
    assert np.allclose([x for *_, x in after], [x for *_, x in alone], rtol=1e-9, atol=0.0)


def test_validate_finds_a_geometry_writer_wrong() -> None:
    cases = cf.conformance_cases("fast", pattern="units/unit-systems-N16")
    assert cases
    table = cf.validate(SwapsTheHeights(), cases, isolate=False)
    judged = [r for r in table.rows if r.step >= 0]
    assert judged and all(r.status == "WRONG" for r in judged), table.format()
    assert all("geometry.surface.heights" in r.message for r in judged), table.format()
    assert table.outcome() == "wrong", table.headline()


class ChangesTheRecipe(Solver):
    """Answers right, claimed, after doubling E in the instance builder that its worker's
    load sequence builds the later steps from (reached through ``gc`` and the step
    factory's closure: no attribute of its own problem)."""

    name = "test-changes-the-recipe"
    family = "test"
    capabilities = Capabilities(needs_dense=False)

    def iterate(self, ctx: SolveContext) -> Outcome:
        for obj in gc.get_objects():
            if isinstance(obj, LoadSequence):
                for cell in getattr(obj.factory, "__closure__", None) or ():
                    if isinstance(cell.cell_contents, InstanceBuilder):
                        cell.cell_contents.E *= 2.0
        return Outcome(_exact(ctx), 1, True)


def test_a_solver_changing_what_later_steps_are_built_from_is_caught_and_they_are_built_right(
        run_harness: Callable[..., Any], tmp_path: Path) -> None:
    def loads(table: Any) -> list[float]:
        return [float(x) for x in table[table["solver"] == "pk"].sort_values("step")["load"]]

    kw = {"size": 16, "steps": 3, "profiles": ("mid",), "reference": "none", "warmup": False, "timeout": 60.0}
    alone = run_harness(["paper-sweep"], solvers=["pk"], out=tmp_path / "alone", **kw)
    both = run_harness(["paper-sweep"], solvers=[f"{HERE}:ChangesTheRecipe", "pk"], out=tmp_path / "both", **kw)
    mine = both[both["solver"] == "test-changes-the-recipe"]
    assert (mine["status"] == "failed").all() and mine["error"].str.contains("wrote into the problem").all(), \
        mine[["step", "status", "error"]].to_string()
    np.testing.assert_allclose(loads(both), loads(alone), rtol=1e-9)
