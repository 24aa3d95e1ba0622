"""Cascade multi-resolution (solvers/cmr.py) and its scenes (problems/scenes/cmr.py)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import scipy.linalg as sl
from scipy.optimize import nnls

from contactbench.problems.kkt import kkt_check
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, InstanceBuilder, paper_max_displacement
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.surfaces import rmd_surface_n, spectral_surface
from contactbench.solvers.base import Capabilities, SolveResult, Solver, SolverSettings, WarmStart
from contactbench.solvers.cmr import CMRSolver, cascade_surfaces, within_radius
from contactbench.solvers.registry import all_solvers, register, unregister

BASE = "test-cmr-exact"


class ExactBase(Solver):
    """Exact test base: H = L L', then NNLS on ||L' p - L^-1 ubar|| (Lawson-Hanson)."""

    name = BASE
    family = "test"
    capabilities = Capabilities(warm_start="primal", exact=True)
    calls: list[tuple[int, bool]] = []

    def solve(self, qp: QP, settings: SolverSettings, warm: WarmStart | None = None) -> SolveResult:
        ExactBase.calls.append((qp.n, warm is not None))
        L = np.linalg.cholesky(qp.H.to_dense())
        p, _ = nnls(L.T, sl.solve_triangular(L, qp.ubar, lower=True), maxiter=50 * qp.n)
        return SolveResult(p=p, converged=True, status="optimal", iterations=1, warm_started=warm is not None)


@pytest.fixture(autouse=True)
def exact_base() -> Iterator[None]:
    register(ExactBase, replace=True)
    ExactBase.calls = []
    yield
    unregister(BASE)


def direct(inst) -> np.ndarray:
    return ExactBase().solve(inst.qp, SolverSettings()).p


def rmd_instance(N: int = 64, H: float = 0.7, periodic: bool = False, seed: int = 0):
    s = rmd_surface_n(N, H, seed=seed)
    return InstanceBuilder(s, 1e9, "bcc", periodic=periodic).build(paper_max_displacement(s))


@pytest.mark.parametrize("periodic", [False, True])
def test_large_h_reproduces_the_direct_solution(periodic: bool) -> None:
    inst = rmd_instance(periodic=periodic)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4, "coarsest": 8}))
    p_ref = direct(inst)
    np.testing.assert_allclose(r.p, p_ref, rtol=1e-8, atol=1e-12 * p_ref.max())
    assert [lv["N"] for lv in r.info["levels"]] == [8, 16, 32, 64]
    assert r.info["levels"][-1]["n_p"] == inst.n  # nothing pruned
    assert kkt_check(inst, r.p).kkt_error < 1e-8


def test_large_h_on_a_block_averaged_cascade() -> None:
    s = spectral_surface(64, 0.7, seed=5)
    inst = InstanceBuilder(s, 1e9, "bcc").build(0.5 * (s.z_max - s.z_mean))
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4}))
    assert [lv["N"] for lv in r.info["levels"]] == [16, 32, 64]
    np.testing.assert_allclose(r.p, direct(inst), rtol=1e-8, atol=1e-20)


def test_small_h_prunes_and_returns_p_on_the_full_trial_set() -> None:
    inst = rmd_instance(N=64, H=0.5, seed=2)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.0, "coarsest": 16}))
    fine = r.info["levels"][-1]
    assert r.p.shape == (inst.n,)
    assert fine["n"] == inst.n and fine["n_p"] < inst.n
    assert np.count_nonzero(r.p) <= fine["n_p"]
    assert fine["n_p_over_n"] == pytest.approx(fine["n_p"] / inst.n)
    assert fine["load"] == pytest.approx(r.p.sum())
    # base solves: the coarsest level whole, every later level on its projected set
    assert [n for n, _ in ExactBase.calls] == [lv["n_p"] for lv in r.info["levels"]]
    assert r.info["levels"][0]["n_p"] == r.info["levels"][0]["n"]
    for lv in r.info["levels"]:
        assert lv["time"] >= 0 and 0 <= lv["contact_fraction"] <= 1


def test_projected_set_grows_with_h() -> None:
    inst = rmd_instance(N=64, H=0.7, seed=1)
    ratios = [CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": h})).info["n_p_over_n"]
              for h in (1.0, 2.0, 4.0)]
    assert ratios[0] <= ratios[1] <= ratios[2] <= 1.0


def test_warm_start_is_restricted_to_the_projected_set() -> None:
    inst = rmd_instance(N=32, H=0.7)
    p0 = direct(inst)
    ExactBase.calls = []
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 2.0, "coarsest": 8}), WarmStart(p=p0))
    assert r.warm_started
    assert [w for _, w in ExactBase.calls] == [False] * (len(ExactBase.calls) - 1) + [True]


def test_explicit_levels_and_unknown_levels() -> None:
    inst = rmd_instance(N=64)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"levels": [16, 32]}))
    assert r.info["cascade"] == [16, 32, 64]
    with pytest.raises(ProblemInputError, match="not available"):
        CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"levels": [24]}))


def test_needs_geometry_context_and_valid_h() -> None:
    qp = QP(DenseOperator(np.eye(2)), np.ones(2))
    with pytest.raises(ProblemInputError, match="geometry"):
        CMRSolver(BASE).solve(qp, SolverSettings())
    with pytest.raises(ProblemInputError, match="h must be"):
        CMRSolver(BASE).solve(rmd_instance(N=16).qp, SolverSettings(params={"h": 0.5}))


def test_availability_names_a_missing_base() -> None:
    ok, why = CMRSolver("no-such-base").availability()
    assert not ok and "no-such-base" in why
    assert CMRSolver(BASE).availability()[0]
    assert {"cmr+nnls", "cmr+scipy-nnls"} <= set(all_solvers())


def test_within_radius_minimum_image() -> None:
    centres = np.array([[0.5, 0.5]])
    pts = np.array([[9.8, 0.5], [5.0, 5.0], [0.5, 2.4]])
    np.testing.assert_array_equal(within_radius(pts, centres, 1.0, period=10.0), [True, False, False])
    np.testing.assert_array_equal(within_radius(pts, centres, 1.0, period=None), [False, False, False])
    np.testing.assert_array_equal(within_radius(pts, centres, 2.0, period=None), [False, False, True])
    assert not within_radius(pts, np.zeros((0, 2)), 1.0, None).any()


def test_cascade_surfaces_rmd_levels_are_subsamples() -> None:
    s = rmd_surface_n(64, 0.7)
    lv = cascade_surfaces(s, 16)
    assert [x.N for x in lv] == [16, 32]
    np.testing.assert_array_equal(lv[0].heights, s.heights[::4, ::4])


def test_solver_warns_on_a_rolloff_surface() -> None:
    s = spectral_surface(128, 0.6, seed=0, rolloff_wavelength=100e-6 / 32)
    inst = InstanceBuilder(s, 1e9, "bcc").build(0.2 * (s.z_max - s.z_mean))
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.5, "coarsest": 32}))
    assert r.info["psd_power_law"] is False and "NOT a power law" in r.info["warnings"][0]
    clean = CMRSolver(BASE).solve(rmd_instance(N=64).qp, SolverSettings())
    assert clean.info["psd_power_law"] is True and "warnings" not in clean.info


# --- scenes -----------------------------------------------------------------------------


def test_cmr_scene_recipes_and_variants() -> None:
    sc = get_scene("cmr")
    cfg = sc.config(SceneConfig(size=32, steps=2))
    specs = sc.instances(cfg)
    assert [sp.params["hurst"] for sp in specs] == [0.3, 0.5, 0.7]
    seq = specs[0].build()
    assert len(seq) == 2 and seq.deltas[-1] == pytest.approx(paper_max_displacement(seq.surface))
    assert [x.N for x in seq.surface.levels][-1] == 16
    v = sc.variants(cfg, ["nnls", "cmr+nnls"])
    assert [x.name for x in v] == ["nnls", "cmr+nnls"] and v[1].params["h"] == 2.0
    assert sc.warnings(cfg) == []


def test_h_sweep_variants_cover_paper_range() -> None:
    sc = get_scene("cmr-h-sweep")
    v = sc.variants(sc.config(None), ["nnls", "cmr+nnls"])
    hs = [x.params["h"] for x in v if x.base == "cmr+nnls"]
    assert hs[0] == 1.25 and hs[-1] == 3.0 and len({x.name for x in v}) == len(v)


def test_cutoff_scene_warns_only_on_the_rolloff_surface() -> None:
    sc = get_scene("cmr-cutoff")
    cfg = sc.config(None)
    names = [sp.instance for sp in sc.instances(cfg)]
    warns = sc.warnings(cfg)
    assert len(warns) == 1 and "rolloff" in warns[0] and "NOT a power law" in warns[0]
    assert any(n.startswith("power-law") for n in names)


def test_cutoff_scene_cmr_fails_on_rolloff_and_works_on_power_law() -> None:
    sc = get_scene("cmr-cutoff")
    cfg = sc.config(SceneConfig(size=128, extra={"coarsest": 32}))
    errs = {}
    for spec in sc.instances(cfg):
        inst = spec.build().at(0)
        r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.5, "coarsest": 32}))
        ref = direct(inst).sum()
        errs[spec.params["surface"]] = abs(r.p.sum() - ref) / ref
    assert errs["power-law"] < 0.05
    assert errs["rolloff"] > 4 * errs["power-law"]


def test_repair_makes_a_pruning_cascade_exact() -> None:
    inst = rmd_instance(N=64, H=0.5, seed=2)
    plain = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.0, "coarsest": 16}))
    assert kkt_check(inst, plain.p).kkt_error > 1e-6  # h = 1 prunes real contacts here
    fixed = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.0, "coarsest": 16, "repair": True}))
    assert fixed.info["repair_rounds"] >= 1
    assert fixed.info["levels"][-1]["n_p"] < inst.n  # still solved on a reduced set
    p_ref = direct(inst)
    np.testing.assert_allclose(fixed.p, p_ref, rtol=1e-8, atol=1e-12 * p_ref.max())
    assert kkt_check(inst, fixed.p).kkt_error < 1e-8
