"""The performance population's surface families (problems/surfaces.py: Fourier synthesis
with roll-off, rms-slope scaling, measured-like maps) and the default fast solver on them:
exact answers in both precisions, and the rule that keeps its preconditioned direction from
pointing out of the feasible set at points at the bound (solvers/_ccg.py, "Points at the
bound").  Small grids; matvec bounds, no timing."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.io import fill_missing
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.lcp import exact_solution_on_subset
from contactbench.problems.surfaces import (
    Surface,
    fourier_synthesis,
    measured_like_heights,
    radial_psd,
    rmd_surface_n,
    with_rms_slope,
)
from contactbench.solvers import _ccg
from contactbench.solvers._ccg import GapState, inward, precondition_on
from contactbench.solvers._preconditioners import IslandPreconditioner
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver
from tests.helpers import REPO

E = 1e9
L = 100e-6


def top_step(s: Surface):
    return InstanceBuilder(s, E, "bcc", periodic=False).build(paper_max_displacement(s))


def measured(N: int, seed: int) -> Surface:
    base = fourier_synthesis(N, 0.7, 0.3, length=L, seed=seed)
    raw = measured_like_heights(base, base.rms_height / L, 0.03, seed=seed + 1000)
    with pytest.warns(UserWarning, match="filled"):
        z = fill_missing(raw, "fill-nearest", "measured", {})
    return Surface(z, base.delta, name="measured", periodic=False)


# -- generators ------------------------------------------------------------------------


@pytest.mark.parametrize("slope", [0.05, 1.0])
def test_fourier_synthesis_has_the_rms_slope_asked_for_and_is_periodic(slope):
    s = fourier_synthesis(128, 0.6, slope, length=L, seed=2)
    assert s.periodic and s.meta["family"] == "fourier"
    assert s.rms_slope() == pytest.approx(slope, rel=1e-12)
    assert abs(s.z_mean) <= 1e-12 * s.rms_height


def test_fourier_synthesis_rolls_off_and_cuts_off():
    """Below the roll-off the PSD is flat, above the short cutoff it is zero; in between
    it falls like q^-2(1+H)."""
    N, H = 256, 0.8
    s = fourier_synthesis(N, H, 0.2, length=L, seed=1, rolloff_wavelength=L / 4, short_cutoff_wavelength=8 * L / N)
    psd = radial_psd(s, bins_per_decade=10, window=False)
    q_r, q_s = 2 * np.pi / (L / 4), 2 * np.pi / (8 * L / N)
    plateau = psd.C[psd.q < 0.8 * q_r]
    assert plateau.max() / plateau.min() < 30  # a few modes, random: flat within the scatter, not q^-3.6 (~100x)
    assert np.all(psd.C[psd.q > 1.5 * q_s] <= 1e-20 * psd.C.max())
    mid = (psd.q > 1.5 * q_r) & (psd.q < 0.6 * q_s)
    slope = np.polyfit(np.log(psd.q[mid]), np.log(psd.C[mid]), 1)[0]
    assert slope == pytest.approx(-2 * (1 + H), abs=0.3)


def test_with_rms_slope_scales_heights_only():
    s = rmd_surface_n(64, 0.9, "periodic", length=L, seed=0)
    t = with_rms_slope(s, 0.1)
    f = t.heights[0, 0] / s.heights[0, 0]
    np.testing.assert_allclose(t.heights, f * s.heights, rtol=1e-13)
    assert t.delta == s.delta and t.rms_slope() == pytest.approx(0.1)
    assert all(np.allclose(a.heights, f * b.heights) for a, b in zip(t.levels, s.levels))


def test_with_rms_slope_refuses_a_flat_surface_and_a_bad_slope():
    flat = Surface(np.zeros((8, 8)), 1.0)
    with pytest.raises(ProblemInputError, match="flat"):
        with_rms_slope(flat, 0.1)
    s = fourier_synthesis(16, 0.5, 0.1)
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ProblemInputError):
            with_rms_slope(s, bad)


def test_measured_like_heights_leave_a_tilt_and_holes():
    s = fourier_synthesis(128, 0.7, 0.3, length=L, seed=4)
    tilt = 0.02
    z = measured_like_heights(s, tilt, 0.05, seed=1)
    miss = np.isnan(z)
    assert 0.03 <= miss.mean() <= 0.06
    # The holes are discs, not single points: most missing points have a missing neighbour.
    assert (miss & np.roll(miss, 1, 0)).sum() > 0.5 * miss.sum()
    ii, jj = np.nonzero(~miss)
    A = np.c_[ii * s.delta, jj * s.delta, np.ones(ii.size)]
    gx, gy, _ = np.linalg.lstsq(A, z[~miss], rcond=None)[0]
    assert np.hypot(gx, gy) == pytest.approx(tilt, rel=0.1)
    assert not np.isnan(measured_like_heights(s, 0.0, 0.0)).any()


@pytest.mark.parametrize("kw", [{"tilt": np.nan}, {"tilt": -0.1}, {"tilt": np.inf}, {"missing_fraction": 0.7},
                                {"missing_fraction": np.nan}, {"hole_radius": -1}, {"hole_radius": 1.5}])
def test_measured_like_heights_refuse_bad_input(kw):
    s = fourier_synthesis(16, 0.5, 0.1)
    args = {"tilt": 0.01, "missing_fraction": 0.03, "hole_radius": 2} | kw
    with pytest.raises(ProblemInputError):
        measured_like_heights(s, **args)


# -- the default solver on the families: exact in both precisions ------------------------

FAMILY_SURFACES = {
    "periodic-rmd": lambda: with_rms_slope(rmd_surface_n(64, 0.9, "periodic", length=L, seed=3), 0.1),
    "fourier": lambda: fourier_synthesis(128, 0.6, 0.3, length=L, seed=1),
    "measured": lambda: measured(64, 2),
}


@pytest.mark.parametrize("family", sorted(FAMILY_SURFACES))
@pytest.mark.parametrize("precision", ["mixed", "double"])
def test_default_solver_is_exact_on_each_family(family, precision):
    inst = top_step(FAMILY_SURFACES[family]())
    ref = exact_solution_on_subset(inst.qp)
    res = get_solver("fast-dual-pccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"precision": precision}))
    assert res.converged and np.all(res.p >= 0)
    assert kkt_check(inst, res.p).kkt_error <= 1e-8
    assert relative_error(res.p, ref.p) <= 1e-6


# -- points at the bound ---------------------------------------------------------------


def bound_point_case():
    """A point j at the bound (p = 0, a small negative residual: it penetrates) next to at
    least three points of the contact set S of the exact answer, whose residual is -1."""
    inst = top_step(rmd_surface_n(33, 0.7, "saupe", length=L, seed=3))
    ref = exact_solution_on_subset(inst.qp)
    S = ref.p > 0
    g = inst.qp.geometry
    where = np.full(int(np.prod(g.grid_shape)), -1)
    where[g.indices] = np.arange(inst.n)
    i, j = np.divmod(g.indices, g.grid_shape[1])
    for k in np.flatnonzero(S):  # a neighbour of S in the trial set, outside S, with >= 3 contact neighbours
        for di, dj in ((0, 1), (1, 0), (0, -1), (-1, 0)):
            a, b = i[k] + di, j[k] + dj
            if 0 <= a < g.grid_shape[0] and 0 <= b < g.grid_shape[1] and where[a * g.grid_shape[1] + b] >= 0:
                m = where[a * g.grid_shape[1] + b]
                nbrs = [where[(a + x) * g.grid_shape[1] + b + y] for x in (-1, 0, 1) for y in (-1, 0, 1)
                        if 0 <= a + x < g.grid_shape[0] and 0 <= b + y < g.grid_shape[1]]
                touching = [q for q in nbrs if q >= 0 and S[q]]
                if not S[m] and len(touching) >= 3:
                    res = np.zeros(inst.n)
                    res[touching] = -1.0  # the neighbours want more force ...
                    res[m] = -1e-3  # ... and so, a little, does j
                    return inst, GapState(inst.qp.H, inst.qp.ubar, ref.p.copy()), res, int(m)
    raise AssertionError("no bound point next to the contact set")


def test_a_direction_never_points_out_at_the_bound():
    inst, state, res, j = bound_point_case()
    M = IslandPreconditioner.build(inst.qp)
    # Coupled to its contact neighbours, M^-1 turns the sign at j: the direction -z would
    # push p_j below 0 (what the projection clipped at every iteration of a stall) ...
    z = precondition_on(M, res, res != 0.0)
    assert z[j] > 0.0 > res[j]
    d = inward(-z, state, res)
    assert d[j] == 0.0  # ... so it is held at the bound
    S = state.p > 0
    np.testing.assert_array_equal(d[S], -z[S])
    enter = (state.p == 0) & (res < 0) & (z < 0)
    np.testing.assert_array_equal(d[enter], -z[enter])
    assert np.all(d[(state.p == 0) & (res == 0)] == 0.0)
    assert res @ d < res @ -z < 0.0  # still a descent direction, a steeper one


def old_inward(d, state, res, upper=None):
    """The rule before: only the points at rest at the bound (res = 0) were held (no upper
    bounds on this case)."""
    np.copyto(d, 0.0, where=(res == 0.0) & (state.p == 0.0))
    return d


#: A measured-like 128^2 map on which the old rule kept clipping the same points (old, and no
#: restart on new factors: 31 / 32 matvecs in mixed / double; now 22 / 22, and 23 / 21 without
#: those restarts), and a bound between them with a margin of four.
STALL_CASE_BOUND = 27


@pytest.mark.parametrize("precision", ["mixed", "double"])
def test_constructed_case_converges_within_its_matvec_bound(precision, monkeypatch):
    inst = top_step(measured_population_member())
    solver = get_solver("fast-dual-pccg")
    # The island blocks from the first iteration (no opening): the preconditioner the old rule
    # stalled with.
    settings = SolverSettings(tol=1e-9, params={"precision": precision, "opening": "none"})
    res = solver.solve(inst.qp, settings)
    assert res.converged and res.matvecs <= STALL_CASE_BOUND
    # Restarts on new factors (solvers/_ccg.py, "A refactored preconditioner") break the
    # old rule's clipping cycle on this case too; without them the rule alone must hold.
    monkeypatch.setattr(_ccg, "version_of", lambda M: 0)
    alone = solver.solve(inst.qp, settings)
    assert alone.converged and alone.matvecs <= STALL_CASE_BOUND
    monkeypatch.setattr(_ccg, "inward", old_inward)
    old = solver.solve(inst.qp, settings)
    assert old.matvecs > STALL_CASE_BOUND  # the case still tells the two rules apart
    assert relative_error(res.p, old.p) <= 1e-6


def measured_population_member() -> Surface:
    """The population's measured-like member at 128^2, H 0.7, rms slope 0.3, seed 1
    (benchmarks/bench_surface_population.py ``surface_of``)."""
    base = fourier_synthesis(128, 0.7, 0.3, length=L, seed=1)
    raw = measured_like_heights(base, base.rms_height / L, 0.03, seed=1001)
    with pytest.warns(UserWarning, match="filled"):
        z = fill_missing(raw, "fill-nearest", "measured", {})
    return Surface(z, base.delta, name="measured", periodic=False)


# -- the population benchmark's checks ----------------------------------------------------


def population_script():
    folder = REPO / "benchmarks"
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))  # the script's sibling csv_rows, as when it runs
    spec = importlib.util.spec_from_file_location("bench_surface_population", folder / "bench_surface_population.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def fake_row(bench, family: str, seed: int, variant: str, matvecs: int, status: str = "solved", N: int = 2048):
    return bench.PopulationRow(family, N, 0.7, 0.3, seed, f"{family}-s{seed}", 100, variant, "{}", status, matvecs,
                               matvecs, 0, matvecs, 1, float(matvecs), 1e-10, 1.0, 100.0, 1, "h", "c", "t")


def test_population_checks_flag_a_stall_a_slower_default_and_a_failure():
    bench = population_script()
    rows = []
    for seed, (mv, ref) in enumerate([(40, 40), (42, 40), (41, 45), (90, 95), (50, 44)]):
        rows += [fake_row(bench, "periodic", seed, "default", mv), fake_row(bench, "periodic", seed, "double-islands", ref)]
    rows.append(fake_row(bench, "fourier", 0, "default", 0, status="timeout"))
    why = sorted(f.why.split(" ")[0] + ":" + str(f.row.seed) + f.row.family for f in bench.checks(rows))
    # median 42: 90 > 84 is a stall; 50 > 1.1 x 44; the timeout is reported; 42 vs 40 (1.05x) is not.
    assert why == ["matvecs:3periodic", "matvecs:4periodic", "status:0fourier"]
    # below 512^2 the default is the double-islands configuration itself: its seconds against the
    # reference are the machine's spread, reported, not checked; a stall still is
    small = [fake_row(bench, "saupe", seed, variant, count, N=256)
             for seed, (mv, ref) in enumerate([(40, 40), (50, 44), (41, 41)])
             for variant, count in (("default", mv), ("double-islands", ref))]
    assert [f.why.split(" ")[0] for f in bench.checks(small, "seconds")] == []
    assert any("seconds ratio" in line for line in bench.noise_lines(small))
    assert not bench.checks([r for r in rows if r.seed < 3 and r.status == "solved"])


def test_population_plan_and_member_keys():
    bench = population_script()
    members = bench.plan([512, 4096], list(bench.FAMILIES), {512: 2, 4096: 1})
    assert len(members) == len(bench.CELLS) * 4 * 2 + len(bench.LARGE_CELLS) * 4
    assert all(bench.Member.parse(m.key) == m for m in members)
    assert {m.family for m in members} == set(bench.FAMILIES)
    held_out = bench.plan([512], ["saupe"], {512: 2}, first_seed=3)
    assert {m.seed for m in held_out} == {3, 4} and len(held_out) == len(bench.CELLS) * 2


def bench_script(name: str):
    """A sibling script of benchmarks/bench_surface_population.py, imported as it runs."""
    population_script()  # its sibling modules on the path first
    folder = REPO / "benchmarks"
    spec = importlib.util.spec_from_file_location(name, folder / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_sweep_ratio_counts_only_members_both_solvers_solved_throughout():
    sweep = bench_script("bench_population_sweep")
    T = sweep.SweepTotals
    assert sweep.ratio([T("ours", 1.0, 10, 10, 300), T(sweep.CM, 20.0, 10, 10, 3000)], "ours") == 0.05
    assert np.isnan(sweep.ratio([T("ours", 1.0, 9, 10, 300), T(sweep.CM, 20.0, 10, 10, 3000)], "ours"))
    assert np.isnan(sweep.ratio([T("ours", 1.0, 10, 10, 300), T(sweep.CM, 20.0, 7, 10, 3000)], "ours"))
    assert np.isnan(sweep.ratio([T("ours", 1.0, 10, 10, 300)], "ours"))
    members = sweep.members_of(",".join(sweep.MEMBERS), 256)
    assert len(members) >= 5 and {m.N for m in members} == {256}
    assert {m.family for m in members} == set(population_script().FAMILIES)


@pytest.mark.parametrize("argv,what", [(["--size", "500"], "power of two"), (["--members", "rough:512:0.7:0.3:0"],
                                        "unknown family"), (["--members", "saupe:512"], "--members"),
                                       (["--steps", "0"], "--steps")])
def test_sweep_refuses_bad_input_in_one_line_before_running(argv, what, tmp_path):
    import subprocess

    script = REPO / "benchmarks" / "bench_population_sweep.py"
    proc = subprocess.run([sys.executable, str(script), *argv, "--out", str(tmp_path / "o")], capture_output=True, check=False,
                          text=True, timeout=120)
    assert proc.returncode == 2 and what in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()


def test_a_member_the_cli_refuses_is_recorded_with_its_reason_and_a_crash_stops_the_run(tmp_path, monkeypatch):
    """``sweep_member``: the CLI's exit 2 (a surface it does not take) is the member's
    one-line reason, in OUT/<key>.refused and the summary, and the run goes on; any other
    failure stops it."""
    import argparse
    import subprocess

    sweep = bench_script("bench_population_sweep")
    fake = tmp_path / "contactbench"
    args = argparse.Namespace(out=str(tmp_path / "o"), steps=2, ours="fast-dual-pccg", threads=1, timeout=10.0,
                              size=256)
    (m,) = sweep.members_of("saupe:256:0.7:0.3:0", 256)
    monkeypatch.setattr(sweep, "CB", str(fake))
    fake.write_text("#!/bin/sh\necho 'contactbench: error: paper-sweep: too steep' >&2\nexit 2\n")
    fake.chmod(0o755)
    assert sweep.sweep_member(m, args) == "contactbench: error: paper-sweep: too steep"
    assert "| saupe:256:0.7:0.3:0 | refused: contactbench: error: paper-sweep: too steep |" in sweep.summary([m], args)
    fake.write_text("#!/bin/sh\nexit 1\n")
    with pytest.raises(subprocess.CalledProcessError):
        sweep.sweep_member(m, args)


def test_cost_law_per_family_recovers_known_exponents(tmp_path):
    bench = population_script()
    plot = bench_script("plot_population_cost_law")
    rows = []
    for N in (256, 512, 1024):
        for seed in range(2):
            for fam, a in (("saupe", 0.25), ("fourier", 0.1)):
                r = fake_row(bench, fam, seed, "default", round(10 * (N * N) ** a))
                r.N, r.seconds = N, 1e-6 * (N * N) ** 1.1
                rows.append(r)
    fits = {fam: plot.family_fit(plot.solved(rows, fam, "default"), "matvecs") for fam in ("saupe", "fourier")}
    assert fits["saupe"].exponent == pytest.approx(0.25, abs=0.01) and fits["fourier"].exponent == pytest.approx(0.1,
                                                                                                              abs=0.02)
    assert plot.family_fit(plot.solved(rows, "all", "default"), "seconds").exponent == pytest.approx(1.1, abs=1e-9)
    assert plot.family_fit([r for r in rows if r.N == 256], "matvecs") is None  # one size: no fit
    plot.write_markdown(rows, ["default"], tmp_path)
    text = (tmp_path / f"{plot.STEM}.md").read_text()
    assert "| saupe | default | 256, 512, 1024 | 6 | 0.25 |" in text and "Host(s): h" in text


def test_side_by_side_summary_pairs_members_and_names_where_the_head_needs_more(tmp_path):
    side = bench_script("bench_side_by_side")
    table = tmp_path / "side.csv"
    rows = [("a:1", "base", 50, 1.0, "solved"), ("a:1", "head", 40, 0.8, "solved"),
            ("b:1", "base", 60, 2.0, "solved"), ("b:1", "head", 66, 2.2, "solved"),
            ("c:1", "base", 70, 3.0, "solved"), ("c:1", "head", 0, float("nan"), "failed")]
    table.write_text(",".join(side.COLUMNS) + "\n" + "".join(
        f"{m},{c},{mv},{mv},1,{s},{st},100\n" for m, c, mv, s, st in rows))
    lines = side.summary(table)
    assert lines[0].startswith("base: matvecs median 55, worst 60")
    assert lines[1].startswith("head: matvecs median 53, worst 66")
    assert "median 0.950, range 0.80-1.10; 2 members solved by both, 1 not" in lines[2]
    assert lines[3] == "head needs more matvecs on 1: b:1"


def test_side_by_side_refuses_a_checkout_without_its_environment(tmp_path):
    import subprocess

    script = REPO / "benchmarks" / "bench_side_by_side.py"
    proc = subprocess.run([sys.executable, str(script), "--base", str(tmp_path), "--out", str(tmp_path / "o.csv")],
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 2 and "--base" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o.csv").exists()


def test_side_by_side_sweep_child_sums_a_judged_warm_sweep():
    """``--sweep K``: the child solves the member's K-step paper sweep in the checkout's own
    interpreter and reports the steps' sums, "solved" when every step passes the judge."""
    side = bench_script("bench_side_by_side")
    if not (REPO / ".venv" / "bin" / "python").is_file():
        pytest.skip("no .venv in this checkout (the child runs in the checkout's own environment)")
    member = side.Member.parse("saupe:64:0.7:0.3:0")
    row = side.solve_in(REPO, member, 1, 120.0, sweep=3)
    assert row["status"] == "solved", row
    assert row["matvecs"] >= 3 and row["iterations"] >= 3 and row["seconds"] > 0.0
    single = side.solve_in(REPO, member, 1, 120.0)
    assert single["status"] == "solved" and single["matvecs"] < row["matvecs"]


def test_side_by_side_load_child_solves_the_judged_load_problem():
    """``--load-per-slope X``: the child solves the member's load-controlled problem of
    bench_aspher.py in the checkout's own interpreter, judged there."""
    side = bench_script("bench_side_by_side")
    if not (REPO / ".venv" / "bin" / "python").is_file():
        pytest.skip("no .venv in this checkout (the child runs in the checkout's own environment)")
    row = side.solve_in(REPO, side.Member.parse("fourier:64:0.7:0.3:0"), 1, 120.0, load_per_slope=0.0166667)
    assert row["status"] == "solved", row
    assert row["matvecs"] >= 3 and row["n"] == 64 * 64 and row["seconds"] > 0.0


def test_side_by_side_bounded_child_solves_a_mostly_plastic_load_problem():
    """``--hardness-over-pressure R``: the child poses the load problem with every pressure
    bounded by R P / A, and the judge passes it; near R = 1 most of the contact is plastic,
    far above it little is."""
    side = bench_script("bench_side_by_side")
    if not (REPO / ".venv" / "bin" / "python").is_file():
        pytest.skip("no .venv in this checkout (the child runs in the checkout's own environment)")
    member = side.Member.parse("fourier:64:0.7:0.3:0")
    near = side.solve_in(REPO, member, 1, 120.0, load_per_slope=0.05, hardness_over_pressure=1.5)
    far = side.solve_in(REPO, member, 1, 120.0, load_per_slope=0.05, hardness_over_pressure=50.0)
    assert near["status"] == far["status"] == "solved", (near, far)
    assert near["plastic"] > 0.5 > far["plastic"] and near["n"] == 64 * 64


def test_side_by_side_load_sweep_child_sums_a_judged_warm_load_sweep():
    """``--sweep K --load-per-slope X`` (and a hardness): the child solves the member's K-step
    load sweep, warm-started, and sums it; solved only when every step is."""
    side = bench_script("bench_side_by_side")
    if not (REPO / ".venv" / "bin" / "python").is_file():
        pytest.skip("no .venv in this checkout (the child runs in the checkout's own environment)")
    member = side.Member.parse("fourier:64:0.7:0.3:0")
    for hardness in (0.0, 3.0):
        sweep = side.solve_in(REPO, member, 1, 120.0, sweep=3, load_per_slope=0.05, hardness_over_pressure=hardness)
        single = side.solve_in(REPO, member, 1, 120.0, load_per_slope=0.05, hardness_over_pressure=hardness)
        assert sweep["status"] == single["status"] == "solved", (sweep, single)
        assert sweep["matvecs"] > single["matvecs"] and sweep["n"] == 64 * 64


@pytest.mark.parametrize("bad", [["--load-per-slope", "-1"], ["--load-per-slope", "nan", "--sweep", "2"],
                                 ["--cells", "0.7-0.3"], ["--hardness-over-pressure", "3"],
                                 ["--hardness-over-pressure", "0.9", "--load-per-slope", "0.01"],
                                 ["--hardness-over-pressure", "nan", "--load-per-slope", "0.01"]])
def test_side_by_side_refuses_a_bad_load_or_cell(tmp_path, bad):
    import subprocess

    script = REPO / "benchmarks" / "bench_side_by_side.py"
    proc = subprocess.run([sys.executable, str(script), "--base", str(REPO), *bad, "--out", str(tmp_path / "o.csv")],
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 2 and bad[0] in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o.csv").exists()


def test_side_by_side_refuses_a_negative_sweep(tmp_path):
    import subprocess

    script = REPO / "benchmarks" / "bench_side_by_side.py"
    proc = subprocess.run([sys.executable, str(script), "--base", str(REPO), "--sweep", "-1",
                           "--out", str(tmp_path / "o.csv")], capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 2 and "--sweep" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("scene", ["paper-sweep", "load-sweep", "cmr"])
def test_a_surface_at_another_size_or_modulus_is_another_instance(scene: str) -> None:
    """The report reads problems by instance name: one seed at another lateral size or
    modulus is another problem, so its name says so ("-L", "-E"); at the paper's L and E
    (given or not) the name is the paper's."""
    from contactbench.problems.scenes import SceneConfig, get_scene
    from contactbench.problems.scenes.core import PAPER_E, PAPER_LENGTH

    sc = get_scene(scene)

    def names(**kw: object) -> list[str]:
        return [s.instance for s in sc.instances(sc.config(SceneConfig(size=32, seeds=(0,), **kw)))]  # type: ignore[arg-type]

    plain = names()
    assert names(length=PAPER_LENGTH, E=PAPER_E) == plain
    longer, stiffer, both = names(length=1e-3), names(E=2e9), names(length=1e-3, E=2e9)
    assert all(a != b for a, b in zip(longer, plain)) and all("-L0.001" in n for n in longer)
    assert all("-E2e9" in n for n in stiffer) and all(n != m for n, m in zip(stiffer, plain))
    assert len({*plain, *longer, *stiffer, *both}) == 4 * len(plain)
