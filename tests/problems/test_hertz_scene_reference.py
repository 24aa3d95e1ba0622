"""The hertz scene's closed-form reference is Hertz at the approach from the paraboloid's
apex: an even N puts the apex between nodes, d^2 / (4R) above the highest one, where the
step's Delta is measured from."""

from __future__ import annotations

import numpy as np
import pytest
from contactbench.problems.instances import hertz_solution
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers import SolverSettings, get_solver


def _hertz_step(kernel: str, size: int):
    scene = get_scene("hertz")
    (spec,) = scene.instances(scene.config(SceneConfig(size=size, kernel=kernel)))
    seq = spec.build()
    inst = seq.at(0)
    res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-10))
    assert res.converged
    return spec, seq, float(np.sum(res.p))


def test_the_love_load_at_n16_is_within_one_percent_of_the_reference() -> None:
    """Was +2.95e-2 against Hertz at the Delta from the highest node; +5.9e-3 from the apex."""
    _, seq, load = _hertz_step("love", 16)
    ref = seq.analytic(0)["load"]
    assert abs(load / ref - 1.0) < 1e-2


def test_the_reference_is_taken_d2_over_4r_past_the_step() -> None:
    spec, seq, _ = _hertz_step("love", 16)
    R, E = float(spec.params["radius"]), float(spec.params["E"])
    d = float(spec.params["length"]) / 16
    want = hertz_solution(R, E, seq.deltas[0] + d * d / (4.0 * R))
    got = seq.analytic(0)
    assert got["load"] == pytest.approx(want.load, rel=1e-12)
    assert got["contact_radius"] == pytest.approx(want.contact_radius, rel=1e-12)
    assert got["peak_pressure"] == pytest.approx(want.peak_pressure, rel=1e-12)
