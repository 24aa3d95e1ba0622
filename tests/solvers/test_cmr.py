"""Cascade multi-resolution (solvers/cmr.py) and its scenes (problems/scenes/cmr.py)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sl
from scipy.optimize import nnls

from contactbench.problems.kkt import kkt_check
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP, InstanceBuilder, counterexample, paper_max_displacement
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.surfaces import rmd_surface_n, spectral_surface
from contactbench.solvers import (
    Capabilities,
    Outcome,
    ParamError,
    ProblemTraits,
    SolveContext,
    Solver,
    SolverSettings,
    WarmStart,
)
from contactbench.solvers.cmr import CMR_BASES, CMRSolver, within_radius
from contactbench.solvers.registry import all_solvers, register, unregister

BASE = "test-cmr-exact"


class ExactBase(Solver):
    """Exact test base: H = L L', then NNLS on ||L' p - L^-1 ubar|| (Lawson-Hanson).
    ``calls`` records (n, warm started, time limit) of every solve."""

    name = BASE
    family = "test"
    capabilities = Capabilities(warm_start="primal", exact=True)
    calls: list[tuple[int, bool, float | None]] = []

    def iterate(self, ctx: SolveContext) -> Outcome:
        ExactBase.calls.append((ctx.n, ctx.warm_started, ctx.deadline.remaining()))
        L = np.linalg.cholesky(ctx.qp.H.to_dense())
        p, _ = nnls(L.T, sl.solve_triangular(L, ctx.qp.ubar, lower=True), maxiter=50 * ctx.n)
        return Outcome(p, 1, True)


class SlowBase(ExactBase):
    """ExactBase after SLOW_SECONDS of work (or its time limit, whichever comes first);
    unconverged when its time ran out."""

    name = "test-cmr-slow"

    def iterate(self, ctx: SolveContext) -> Outcome:
        t_end = time.perf_counter() + SLOW_SECONDS
        while time.perf_counter() < t_end and not ctx.expired():
            time.sleep(0.01)
        out = super().iterate(ctx)
        return Outcome(out.p, 1, not ctx.expired())


SLOW_SECONDS = 0.3


@pytest.fixture(autouse=True)
def exact_base() -> Iterator[None]:
    register(ExactBase, replace=True)
    register(SlowBase, replace=True)
    ExactBase.calls = []
    yield
    unregister(BASE)
    unregister(SlowBase.name)


def direct(inst) -> np.ndarray:
    return ExactBase().solve(inst.qp, SolverSettings()).p


def rmd_instance(N: int = 64, H: float = 0.7, periodic: bool = False, seed: int = 0):
    s = rmd_surface_n(N, H, seed=seed)
    return InstanceBuilder(s, 1e9, "bcc", periodic=periodic).build(paper_max_displacement(s))


@pytest.mark.parametrize("periodic", [False, True])
def test_large_h_reproduces_the_direct_solution(periodic: bool) -> None:
    inst = rmd_instance(N=32, periodic=periodic)  # (periodic: the whole 32^2 grid is the trial set)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4, "coarsest": 4}))
    p_ref = direct(inst)
    np.testing.assert_allclose(r.p, p_ref, rtol=1e-8, atol=1e-12 * p_ref.max())
    assert [lv["N"] for lv in r.info["levels"]] == [4, 8, 16, 32]
    assert r.info["levels"][-1]["n_p"] == inst.n  # nothing pruned
    assert kkt_check(inst, r.p).kkt_error < 1e-8


def test_levels_a_layer_cannot_be_posed_on_are_left_out_and_named() -> None:
    """A layer thicker than the fine spacing but thinner than a coarse level's: that level
    cannot be posed ('love' needs T >= the spacing), and the solve had failed on it.  The
    cascade leaves such levels out, says which, and still answers exactly (large h)."""
    from contactbench.problems.layers import Layer

    s = rmd_surface_n(32, 0.7, seed=0)
    inst = InstanceBuilder(s, 1e9, "love", layer=Layer(3.0 * s.delta, 0.3)).build(paper_max_displacement(s))
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4, "coarsest": 4}))
    assert [lv["N"] for lv in r.info["levels"]] == [16, 32]  # 4 and 8 have spacings of 8 and 4 deltas
    assert r.info["levels_not_posed"] == [4, 8] and "levels [4, 8] not posed" in r.message
    np.testing.assert_allclose(r.p, direct(inst), rtol=1e-8, atol=1e-12 * float(np.max(r.p)))


@pytest.mark.parametrize("coarse", ["subsample", "mean"])
def test_large_h_on_a_surface_without_generator_stages(coarse: str) -> None:
    s = spectral_surface(64, 0.7, seed=5)
    inst = InstanceBuilder(s, 1e9, "bcc").build(0.5 * (s.z_max - s.z_mean))
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4, "coarse": coarse}))
    assert [lv["N"] for lv in r.info["levels"]] == [16, 32, 64] and r.info["coarse"] == coarse
    np.testing.assert_allclose(r.p, direct(inst), rtol=1e-8, atol=1e-20)


def test_coarse_kind_changes_the_coarse_levels_only() -> None:
    """coarse=mean and coarse=subsample pose different coarse QPs (different coarse loads)
    on the same fine problem; with no pruning both return the direct solution."""
    inst = rmd_instance(N=64, H=0.7, seed=3)
    runs = {c: CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1e4, "coarse": c}))
            for c in ("subsample", "mean")}
    sub, mean = ([lv["load"] for lv in runs[c].info["levels"]] for c in ("subsample", "mean"))
    assert sub[:-1] != pytest.approx(mean[:-1], rel=1e-3)
    assert sub[-1] == pytest.approx(mean[-1], rel=1e-10) == pytest.approx(direct(inst).sum(), rel=1e-10)


#: Saupe RMD, 256^2, H = 0.7, h = 2, top step, coarsest 16, coarse=mean
#: (benchmarks/check_cmr_families.py): seed 0 misses -1.74 % of the direct load, seed 1
#: -2.62 % (the worst of seeds 0-19; median -0.30 %, 90 % of seeds under 2 %).
CMR_MEAN_SEED_WITHIN, CMR_MEAN_SEED_BEYOND, CLAIM = 0, 1, 0.02


def cmr_h_sweep_top(seed: int):
    sc = get_scene("cmr-h-sweep")
    (spec,) = sc.instances(sc.config(SceneConfig(seeds=(seed,))))
    return spec.build().at(0)


def test_cmr_mean_matches_the_direct_load_on_a_fixed_seed() -> None:
    """On the paper's surface (saupe, 256^2, H = 0.7, h = 2, top step), CMR with
    coarse=mean is within the paper's 2 % of the direct solve's load on seed 0."""
    inst = cmr_h_sweep_top(CMR_MEAN_SEED_WITHIN)
    assert inst.surface.meta["family"] == "saupe" and inst.surface.N == 256
    P = all_solvers()["fast-dual-pccg"].solve(inst.qp, SolverSettings()).p.sum()
    r = all_solvers()["cmr+fast-dual-pccg"].solve(inst.qp, SolverSettings(params={"coarse": "mean"}))
    err = (r.p.sum() - P) / P
    assert -CLAIM < err < 0  # measured -1.74 %: the cascade misses a little load, never adds
    assert r.info["cascade"] == [16, 32, 64, 128, 256]


def test_cmr_mean_beyond_the_claim_is_judged_inaccurate() -> None:
    """Where coarse=mean misses more than 2 % (seed 1: -2.62 %), the harness's judge does
    not pass the answer: its recomputed KKT error fails even the loosest profile."""
    from contactbench.harness.judging import judge
    from contactbench.harness.profiles import PROFILES

    inst = cmr_h_sweep_top(CMR_MEAN_SEED_BEYOND)
    P = all_solvers()["fast-dual-pccg"].solve(inst.qp, SolverSettings()).p.sum()
    r = all_solvers()["cmr+fast-dual-pccg"].solve(inst.qp, SolverSettings(params={"coarse": "mean"}))
    assert (r.p.sum() - P) / P < -CLAIM
    loosest = max(p.check_tol for p in PROFILES.values())
    v = judge(inst, r.p, r.converged, loosest)
    assert v.status == "inaccurate" and v.kkt_error > 0.1 and not r.converged  # nor did CMR claim it
    assert r.status == "stalled" and "full problem's scaled KKT error" in r.message


def test_coarse_params_are_checked() -> None:
    qp = rmd_instance(N=64).qp
    with pytest.raises(ParamError, match="'coarse' must be one of 'subsample', 'mean'"):
        CMRSolver(BASE).solve(qp, SolverSettings(params={"coarse": "median"}))
    with pytest.raises(ProblemInputError, match="coarsest level 12 is not available on the 64 x 64 surface"):
        CMRSolver(BASE).solve(qp, SolverSettings(params={"coarsest": 12}))
    r = CMRSolver(BASE).solve(qp, SolverSettings(params={"coarsest": 32, "coarse": "mean"}))
    assert r.info["cascade"] == [32, 64]


@pytest.mark.parametrize("base", ["scipy-nnls", "fast-dual-pccg"])
def test_the_papers_dense_base_and_our_fast_base_run_under_cmr(base: str) -> None:
    """cmr+scipy-nnls (the paper's dense Cholesky + NNLS base) and cmr+fast-dual-pccg are
    registered and give the exact answer when nothing is pruned."""
    inst = rmd_instance(N=32, H=0.7, seed=2)
    r = all_solvers()[f"cmr+{base}"].solve(inst.qp, SolverSettings(params={"h": 1e4, "coarsest": 8,
                                                                             "coarse": "mean"}))
    p_ref = direct(inst)
    np.testing.assert_allclose(r.p.sum(), p_ref.sum(), rtol=1e-6)
    assert kkt_check(inst, r.p).kkt_error < 1e-5


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
    assert [n for n, _, _ in ExactBase.calls] == [lv["n_p"] for lv in r.info["levels"]]
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
    assert [w for _, w, _ in ExactBase.calls] == [False] * (len(ExactBase.calls) - 1) + [True]


def test_explicit_levels_and_unknown_levels() -> None:
    inst = rmd_instance(N=64)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"levels": [16, 32]}))
    assert r.info["cascade"] == [16, 32, 64]
    with pytest.raises(ProblemInputError, match="not available"):
        CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"levels": [24]}))


def test_needs_geometry_context_and_valid_params() -> None:
    qp = QP(DenseOperator(np.eye(2)), np.ones(2))
    with pytest.raises(ProblemInputError, match="geometry"):
        CMRSolver(BASE).solve(qp, SolverSettings())
    qp32 = rmd_instance(N=32).qp
    with pytest.raises(ParamError, match="'h'"):
        CMRSolver(BASE).solve(qp32, SolverSettings(params={"h": 0.5}))
    with pytest.raises(ParamError, match="allowed: base_params, coarse, coarsest, h, levels, repair"):
        CMRSolver(BASE).solve(qp32, SolverSettings(params={"hh": 2.0}))
    with pytest.raises(ParamError, match="'levels'"):
        CMRSolver(BASE).solve(qp32, SolverSettings(params={"levels": [8.5]}))
    with pytest.raises(ParamError, match="no parameter 'K'"):  # base_params go to the base, checked there
        CMRSolver(BASE).solve(qp32, SolverSettings(params={"base_params": {"K": 3}}))
    with pytest.raises(ProblemInputError, match="coarsest level 16 is not available on the 16 x 16 surface"):
        CMRSolver(BASE).solve(rmd_instance(N=16).qp, SolverSettings())  # no coarser level to start from


def test_skipped_where_the_problem_has_no_surface() -> None:
    """The counterexample carries no surface: the skip policy refuses CMR up front."""
    cmr = CMRSolver(BASE)
    assert cmr.capabilities.needs_geometry
    no_surface = counterexample(25, 0)
    assert no_surface.geometry is not None and not no_surface.geometry.has_surface
    why = cmr.skip(ProblemTraits(n=25, operator="dense", has_surface=no_surface.geometry.has_surface))
    assert why is not None and "surface" in why
    with_surface = rmd_instance(N=16)
    assert with_surface.geometry is not None and with_surface.geometry.has_surface
    assert cmr.skip(ProblemTraits(n=with_surface.n, operator="fft", has_surface=True)) is None


def test_base_solves_get_what_is_left_of_the_time_limit() -> None:
    inst = rmd_instance(N=64)
    CMRSolver(BASE).solve(inst.qp, SolverSettings(time_limit=60.0, params={"coarsest": 8}))
    limits = [t for _, _, t in ExactBase.calls]
    assert len(limits) == 4 and all(t is not None and 0 < t <= 60.0 for t in limits)
    assert limits == sorted(limits, reverse=True)  # each solve gets less
    ExactBase.calls = []
    CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"coarsest": 8}))
    assert [t for _, _, t in ExactBase.calls] == [None] * 4


def test_a_slow_base_cannot_take_cmr_past_its_time_limit() -> None:
    """4 levels x 0.3 s of base work, a 0.45 s limit: the cascade is cut short, the fine
    level is still solved (with no time left) and the result says time_limit."""
    inst = rmd_instance(N=64)
    t0 = time.perf_counter()
    r = CMRSolver(SlowBase.name).solve(inst.qp, SolverSettings(time_limit=0.45, params={"coarsest": 8}))
    assert time.perf_counter() - t0 < 2.0  # generous bound on a 0.45 s limit (1.2 s without it)
    assert r.status == "time_limit" and not r.converged
    assert len(r.info["levels"]) < 4 and r.info["levels"][-1]["N"] == 64
    assert r.p.shape == (inst.n,)


def test_trace_ends_at_the_full_problems_final_iterate() -> None:
    inst = rmd_instance(N=64, H=0.5, seed=2)
    r = CMRSolver(BASE).solve(inst.qp, SolverSettings(params={"h": 1.0, "coarsest": 16}))
    assert r.trace[-1][0] == r.iterations
    assert r.trace[-1][2] == pytest.approx(kkt_check(inst, r.p).kkt_error, rel=1e-6)


def test_availability_names_a_missing_base() -> None:
    ok, why = CMRSolver("no-such-base").availability()
    assert not ok and "no-such-base" in why
    assert CMRSolver(BASE).availability()[0]
    # the registered names the results tables use
    assert {f"cmr+{b}" for b in CMR_BASES} == {"cmr+nnls", "cmr+pk", "cmr+scipy-nnls", "cmr+nnls-gp", "cmr+fast-ccg",
                                               "cmr+fast-dual-pccg"}
    assert {f"cmr+{b}" for b in CMR_BASES} <= set(all_solvers())


def test_within_radius_minimum_image() -> None:
    centres = np.array([[0.5, 0.5]])
    pts = np.array([[9.8, 0.5], [5.0, 5.0], [0.5, 2.4]])
    np.testing.assert_array_equal(within_radius(pts, centres, 1.0, period=10.0), [True, False, False])
    np.testing.assert_array_equal(within_radius(pts, centres, 1.0, period=None), [False, False, False])
    np.testing.assert_array_equal(within_radius(pts, centres, 2.0, period=None), [False, False, True])
    assert not within_radius(pts, np.zeros((0, 2)), 1.0, None).any()


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
    assert sc.load_history and sc.config(None).steps == 10
    cfg = sc.config(SceneConfig(size=32, steps=2, seeds=(0,)))
    specs = sc.instances(cfg)
    assert [sp.params["hurst"] for sp in specs] == [0.3, 0.5, 0.7, 0.9]
    assert specs[0].instance == "saupe-H0.3-N32-bcc-np-s0-K2" and specs[0].params["family"] == "saupe"
    seq = specs[0].build()
    assert len(seq) == 2 and seq.deltas[-1] == pytest.approx(paper_max_displacement(seq.surface))
    assert [x.N for x in seq.surface.levels][-1] == 16 and seq.surface.meta["family"] == "saupe"
    assert sc.warnings(sc.config(SceneConfig(seeds=(0, 8)))) == []  # (PSD checks need 256^2; seed 8 is steep at low q)
    periodic = sc.instances(sc.config(SceneConfig(size=32, seeds=(0,), extra={"family": "periodic"})))
    assert periodic[0].instance == "periodic-H0.3-N32-bcc-np-s0" and periodic[0].params_json() != specs[0].params_json()


@pytest.mark.parametrize("scene", ["cmr", "cmr-h-sweep"])
def test_cmr_scenes_default_to_twenty_saupe_seeds(scene: str) -> None:
    sc = get_scene(scene)
    specs = sc.instances(sc.config(None))
    hursts = sorted({sp.params["hurst"] for sp in specs})
    assert hursts == ([0.3, 0.5, 0.7, 0.9] if scene == "cmr" else [0.7])
    assert len(specs) == 20 * len(hursts) and {sp.params["seed"] for sp in specs} == set(range(20))
    assert {sp.params["family"] for sp in specs} == {"saupe"} and {sp.params["size"] for sp in specs} == {256}
    with pytest.raises(ProblemInputError, match="unknown RMD surface family 'fbm'"):
        sc.instances(sc.config(SceneConfig(extra={"family": "fbm"})))


def test_h_grid_covers_the_papers_fig_9() -> None:
    hs = CMRSolver(BASE).grid["h"]
    assert hs[0] == 1.25 and hs[-1] == 3.0 and len(set(hs)) == len(hs) == 8
    for h in hs:  # every grid value is a valid parameter
        assert CMRSolver(BASE).resolve_params({"h": h})["h"] == h


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
        errs[spec.params["family"]] = abs(r.p.sum() - ref) / ref
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


def test_cmr_claims_convergence_only_when_the_full_problem_is_solved() -> None:
    """A base that converged on the pruned set is not a claim about the full QP: when the
    cascade pruned points that come into contact, CMR says so (stalled, not converged);
    with repair it is exact and claims convergence."""
    inst = rmd_instance(N=64, H=0.5, seed=2)
    settings = SolverSettings(tol=1e-9, params={"h": 1.0, "coarsest": 16})
    plain = CMRSolver(BASE).solve(inst.qp, settings)
    full = kkt_check(inst, plain.p).kkt_error
    assert full > 1e-9  # this cascade misses contacts (the premise of the test)
    assert not plain.converged and plain.status == "stalled"
    assert "full problem's scaled KKT error" in plain.message
    settings.params["repair"] = True
    repaired = CMRSolver(BASE).solve(inst.qp, settings)
    assert repaired.converged and kkt_check(inst, repaired.p).kkt_error <= 1e-9


class BackendDefaultsBase(ExactBase):
    """ExactBase that declares no tolerance of its own (``default_tol`` None: a backend's
    own defaults, as scipy-nnls and the QP adapters do)."""

    name = "test-cmr-backend-defaults"
    default_tol = None


def test_no_tolerance_asked_still_checks_the_claim_on_the_full_problem() -> None:
    """Neither CMR nor its base names a tolerance: the claim is still checked on the full
    problem (at ``DEFAULT_TOL``), so a pruning cascade is reported stalled, never claimed."""
    register(BackendDefaultsBase, replace=True)
    try:
        inst = rmd_instance(N=64, H=0.5, seed=2)
        r = CMRSolver(BackendDefaultsBase.name).solve(inst.qp, SolverSettings(params={"h": 1.0, "coarsest": 16}))
    finally:
        unregister(BackendDefaultsBase.name)
    assert kkt_check(inst, r.p).kkt_error > 1e-6  # the cascade misses contacts (the premise)
    assert not r.converged and r.status == "stalled", r.message


def test_cmr_over_scipy_nnls_never_claims_a_pruned_answer() -> None:
    """The registered wrapper over the reference (no tolerance of its own) on the bench's
    32^2 rough case: not converged, as every other wrapper reports there."""
    scene = get_scene("paper-sweep")
    seq = scene.build(scene.instances(scene.config(SceneConfig(size=32, steps=3, seeds=(0,))))[0])
    inst = seq.at(len(seq) - 1)
    r = all_solvers()["cmr+scipy-nnls"].solve(inst.qp, SolverSettings())
    assert r.converged is (kkt_check(inst, r.p).kkt_error <= 1e-8), r.message


def test_a_variant_whose_coarse_levels_the_grid_cannot_give_is_skipped_not_failed(tmp_path: Path) -> None:
    """cmr-cutoff at 32^2 runs its CMR variant with coarsest = 64: the harness asks the
    variant's own parameters (``skip_params``), so the row is a skip naming the level, not
    a failed solve; explicit ``levels`` are checked the same way."""
    from contactbench.harness import run_benchmark
    from contactbench.harness.table.store import load_table

    run_benchmark(["cmr-cutoff"], SceneConfig(size=32), out_dir=tmp_path / "run")
    rows = load_table(tmp_path / "run")
    cmr = rows[rows["base_solver"] == "cmr+nnls"]
    assert len(cmr) == 2 and set(cmr["status"]) == {"skipped"}
    assert cmr["skip_reason"].str.contains("coarsest level of 64 points per side").all()
    assert set(rows[rows["base_solver"] == "nnls"]["status"]) == {"solved"}
    s, traits = CMRSolver("nnls"), ProblemTraits(n=500, operator="fft", has_surface=True, surface_side=32)
    assert s.skip_params(traits, s.resolve_params({"coarsest": 8})) is None
    assert "coarse level of 5" in (s.skip_params(traits, s.resolve_params({"levels": (4, 5)})) or "")


@pytest.mark.parametrize(("side", "params", "skipped_for"), [
    (48, {"coarsest": 12}, None), (48, {}, "coarsest level of 16"), (48, {"coarsest": 64}, "coarsest level of 64"),
    (16, {"coarsest": 4}, None), (48, {"levels": (6, 12)}, None), (48, {"levels": (6, 16)}, "coarse level of 16")])
def test_a_variant_is_judged_by_its_own_levels_not_the_default(side: int, params: dict, skipped_for: str | None) -> None:
    """The harness's skip decision for a CMR variant reads the variant's own ``coarsest`` or
    ``levels``: at 48^2 (levels 3, 6, 12, 24) coarsest = 12 runs and coarsest = 64 is skipped
    naming 64 -- the default coarsest (16) decided both before, skipping the first and naming
    16 for the second."""
    from contactbench.harness.run.skips import capability_decision

    traits = ProblemTraits(n=500, operator="fft", has_surface=True, surface_side=side)
    d = capability_decision(CMRSolver("nnls"), traits, float("inf"), params)
    assert d.skip == (skipped_for is not None) and not d.failed, d.reason
    assert skipped_for is None or skipped_for in d.reason
