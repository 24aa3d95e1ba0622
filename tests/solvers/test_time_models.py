"""The solvers' time models (``time_estimate``, built on ``_kit.product_seconds`` and
``_kit.matvec_seconds``) against products and solves recorded on the host they were fitted
on (results/perf/time-model/README.md: host, date, commit, how).  Nothing is timed here:
the recorded figures are constants, and the tests hold the models to them and to the skip
policy's use of them (``harness.run.skips``)."""

from __future__ import annotations

import math

import pytest

from contactbench.harness.run.plan import RunConfig
from contactbench.harness.run.skips import SkipPolicy, problem_time_estimate, skip_decision
from contactbench.problems.operators import dense_block_pays
from contactbench.solvers._kit import product_seconds
from contactbench.solvers.base import ProblemTraits
from contactbench.solvers.registry import get_solver

GiB = float(2**30)

#: The fastest float64 product of the FFT operator measured on each padded grid (README):
#: (grid side N, trial set n of the paper's top step, padded points P, seconds).
RECORDED_FFT_PRODUCTS = ((64, 253, 16_384, 0.140e-3), (128, 929, 65_536, 0.326e-3), (256, 3_669, 262_144, 1.204e-3),
                         (512, 14_145, 1_048_576, 6.242e-3), (1024, 56_250, 4_194_304, 25.29e-3))
#: The fastest dense product measured (README): (n, seconds).
RECORDED_DENSE_PRODUCTS = ((64, 1.9e-6), (256, 10.7e-6), (1_024, 0.101e-3), (2_048, 0.353e-3), (4_096, 3.671e-3))
#: How far the dense figure may stray from the fastest measured product either way
#: (``product_seconds``' doc: the cache makes one flop rate about 2x off somewhere).
DENSE_FACTOR = 2.5
#: How far a solver's prediction may stray from a recorded solve either way.
SOLVE_FACTOR = 3.0

#: Cold solves on the paper sweep's grids (README): solver -> ((grid side, n, seconds), ...).
#: 128^2 and 256^2: ``contactbench run paper-sweep --steps 4 --cold``, default profile
#: (pk-printed: single solves at tol 1e-8); 512^2: admm at step 3 of 10, greedy-cg at the top
#: step (the committed results/paper run).
RECORDED_SOLVES: dict[str, tuple[tuple[int, int, float], ...]] = {
    "pk": ((128, 2_227, 0.108), (256, 4_497, 0.169), (256, 8_803, 0.276)),
    "pk-printed": ((128, 2_227, 0.734), (256, 4_497, 2.47)),
    "gp": ((128, 2_227, 1.32), (256, 1_518, 6.09)),
    "nnls": ((128, 2_227, 0.252), (256, 8_803, 2.49)),
    "nnls-gp": ((256, 4_497, 0.801), (256, 8_803, 0.787)),
    "admm": ((128, 2_227, 2.14), (256, 1_518, 5.6), (256, 4_497, 16.6), (512, 1_881, 16.0)),
    "greedy-cg": ((128, 2_227, 0.51), (256, 8_803, 1.18), (512, 35_218, 6.29)),
    "greedy-chol": ((256, 4_497, 4.11), (256, 8_803, 24.1)),
    "fast-dual-pccg": ((256, 8_803, 0.202),),
    "fast-ccg": ((256, 8_803, 0.418),),
    "fast-pdas": ((256, 8_803, 0.688),),
}
#: greedy-gs gathers dense rows whatever the grid, so its own model is the prediction.
RECORDED_GS_SOLVES = ((1_163, 0.994), (1_518, 2.46), (2_227, 6.75))
#: The paper sweep's third step at 512^2 (n = 1,881; admm's cold solve there: 16 s).
ADMM_STEP = ProblemTraits(n=1_881, operator="fft", has_surface=True, surface_side=512)


def grid_traits(side: int, n: int) -> ProblemTraits:
    return ProblemTraits(n=n, operator="fft", has_surface=True, surface_side=side)


def operator_of(name: str) -> str:
    """The operator the skip policy hands the solver on an FFT scene (``capability_decision``)."""
    caps = get_solver(name).capabilities
    return "dense" if caps.needs_dense or "fft" not in caps.operators else "fft"


def test_the_fft_product_is_at_or_above_the_fastest_measured_and_within_2x() -> None:
    for side, n, points, seconds in RECORDED_FFT_PRODUCTS:
        assert not dense_block_pays(n, points), side  # the FFT path, as measured
        model = product_seconds(n, "fft", points / n)
        assert seconds <= model <= 2.0 * seconds, (side, model, seconds)


def test_the_dense_product_is_within_the_stated_factor_of_the_fastest_measured() -> None:
    for n, seconds in RECORDED_DENSE_PRODUCTS:
        model = product_seconds(n, "dense")
        assert seconds / DENSE_FACTOR <= model <= DENSE_FACTOR * seconds, (n, model, seconds)


@pytest.mark.parametrize("name", sorted(RECORDED_SOLVES))
def test_a_model_is_finite_growing_and_within_3x_of_its_recorded_solves(name: str) -> None:
    solver, operator = get_solver(name), operator_of(name)
    sizes = (10, 100, 1_000, 10_000, 100_000)
    for kind in ("fft", "dense"):
        bare = [solver.time_estimate(n, kind) for n in sizes]
        assert all(t is not None and math.isfinite(t) and t > 0.0 for t in bare), (kind, bare)
        assert all(a <= b for a, b in zip(bare, bare[1:])), (kind, bare)
    for side, n, seconds in RECORDED_SOLVES[name]:
        pred = problem_time_estimate(solver, grid_traits(side, n), operator)
        assert pred is not None and seconds / SOLVE_FACTOR <= pred <= SOLVE_FACTOR * seconds, (side, n, pred, seconds)


def test_greedy_gs_predicts_its_recorded_solves_within_3x() -> None:
    gs = get_solver("greedy-gs")
    for n, seconds in RECORDED_GS_SOLVES:
        pred = gs.time_estimate(n, "fft")
        assert pred is not None and seconds / SOLVE_FACTOR <= pred <= SOLVE_FACTOR * seconds, (n, pred, seconds)


def test_admm_is_predicted_within_the_default_limit_on_the_third_512_step() -> None:
    """The run's default limit (``RunConfig.timeout``, below the paper run's 120 s) holds
    admm's prediction for the 512^2 step of n = 1,881, and the skip policy runs it there
    under a profile whose check admm can reach (``mid``); a limit below the prediction
    still skips it with the prediction as the reason."""
    limit = RunConfig().timeout
    pred = problem_time_estimate(get_solver("admm"), ADMM_STEP, "fft")
    assert pred is not None and pred < limit
    assert not SkipPolicy(limit, 8 * GiB).decide("admm", ("admm", "mid"), ADMM_STEP, 2).skip
    d = skip_decision("admm", ADMM_STEP, pred / 2, 8 * GiB)
    assert d.skip and "predicted solve time" in d.reason


def test_no_recorded_solve_well_within_the_limit_is_skipped() -> None:
    """A solve recorded in under a third of the default limit is predicted within it (the
    models' stated factor), so the skip policy runs it."""
    limit = RunConfig().timeout
    cases = [(name, side, n) for name, solves in RECORDED_SOLVES.items() for side, n, seconds in solves
             if seconds * SOLVE_FACTOR < limit]
    assert len(cases) >= len(RECORDED_SOLVES)
    for name, side, n in cases:
        d = skip_decision(name, grid_traits(side, n), limit, 8 * GiB)
        assert not d.skip, (name, side, n, d.reason)
