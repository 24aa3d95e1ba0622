"""One-line refusals of bad positions, candidates, closed-form inputs, spectral cutoffs,
constraints, seeds and counts."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pytest

from contactbench.problems.constraints import Constraints, hardness_bounds, make_constraints
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import (
    QP,
    InstanceBuilder,
    flat_punch_load,
    flat_punch_surface,
    hertz_solution,
    hertz_surface,
    load_ramp,
    load_unload_cycle,
)
from contactbench.problems.kernels import kernel_table
from contactbench.problems.operators import DenseOperator, FFTOperator, KernelTransform
from contactbench.problems.surfaces import fourier_synthesis, rmd_surface, rmd_surface_n, spectral_surface


def refused(fn: Callable[[], Any], *words: str) -> str:
    """The one-line ProblemInputError message of fn(), which names each of ``words``."""
    with pytest.raises(ProblemInputError) as err:
        fn()
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg
    return msg


@pytest.fixture(scope="module")
def hertz() -> Any:
    s = hertz_surface(32, 1e-3, 100e-6)
    return InstanceBuilder(s, 1e9).build((100e-6 / 6) ** 2 / 1e-3)


def test_restrict_refuses_repeated_negative_out_of_range_and_bad_masks(hertz: Any) -> None:
    qp = hertz.qp
    n = qp.n
    refused(lambda: qp.restrict(np.r_[np.arange(n), 0]), "repeat", "0")
    refused(lambda: qp.H.restrict(np.array([3, 1, 3])), "repeat", "3")
    refused(lambda: qp.restrict(np.array([-1])), "-1")
    refused(lambda: qp.H.restrict(np.array([n])), str(n))
    refused(lambda: qp.H.restrict(np.array([True, False])), "mask", f"({n},)")
    refused(lambda: qp.H.restrict(np.array([0.0, 1.0])), "integer")
    dense = DenseOperator(np.eye(64) + 1.0)
    refused(lambda: dense.restrict(np.array([True, False])), "mask", "(64,)")
    refused(lambda: dense.restrict(np.array([2, 2])), "repeat")
    mask = np.zeros(n, dtype=bool)
    mask[[1, 4]] = True
    assert np.array_equal(qp.H.restrict(mask).submatrix(np.arange(2)), qp.H.submatrix(np.array([1, 4])))
    unsorted = np.array([5, 2, 9])
    x = np.ones(3)
    assert np.allclose(qp.restrict(unsorted).H.matvec(x), qp.H.partial_product(unsorted, unsorted, x))


def test_fft_operator_refuses_bad_grid_indices() -> None:
    transform = KernelTransform(kernel_table("bcc", (8, 8), 1e-6, 1e9, False), (8, 8))
    refused(lambda: FFTOperator(transform, np.array([100])), "grid indices", "100")
    refused(lambda: FFTOperator(transform, np.array([0, 5, 0])), "grid indices", "repeat")
    refused(lambda: FFTOperator(transform, np.array([-2])), "grid indices", "-2")


def test_candidates_are_flat_indices_or_a_boolean_mask(hertz: Any) -> None:
    s = hertz.surface
    B = InstanceBuilder(s, 1e9)
    D = hertz.delta
    ones = np.ones(s.shape, dtype=np.int64)
    refused(lambda: B.build(D, candidates=ones), "candidates", "1-D integers")
    refused(lambda: B.build(D, candidates=np.array([1.9, 2.9])), "candidates", "float64")
    refused(lambda: B.build(D, candidates=np.array([np.nan])), "candidates")
    refused(lambda: B.build(D, candidates=np.array(["a"])), "candidates")
    assert B.build(D, candidates=np.ones(s.shape, dtype=bool)).n == hertz.n


def test_closed_forms_refuse_nonsense() -> None:
    refused(lambda: hertz_solution(1e-3, 1e9, -1e-6), "Delta")
    refused(lambda: hertz_solution(1e-3, 0.0, 1e-6), "E*")
    refused(lambda: hertz_solution(0.0, 1e9, 1e-6), "sphere radius")
    refused(lambda: flat_punch_surface(32, 1e-5, 1e-4, depth=-1.0), "punch depth")
    refused(lambda: flat_punch_surface(32, 1e-5, 1e-4, depth=0.0), "punch depth")
    refused(lambda: flat_punch_surface(32, 1e-3, 1e-4), "punch radius")
    refused(lambda: flat_punch_load(-1.0, 1e9, 1e-6), "punch radius")
    refused(lambda: hertz_surface(32, 1e-3, -1.0), "side length")
    refused(lambda: hertz_surface(32, 1e-3, float("nan")), "side length")


@pytest.mark.parametrize("cutoff", [100e-6, 200e-6, -1e-6, float("inf"), float("nan")])
def test_spectral_surface_refuses_bad_short_cutoff(cutoff: float) -> None:
    refused(lambda: spectral_surface(16, 0.7, length=100e-6, short_cutoff_wavelength=cutoff), "cutoff")


def test_spectral_rolloff_and_tiny_fourier_grids() -> None:
    refused(lambda: spectral_surface(16, 0.7, rolloff_wavelength=-1e-6), "rolloff wavelength")
    for N in (2, 3):
        refused(lambda: fourier_synthesis(N, 0.7, 0.1), "no wave number is left")


def test_constraints_validate_themselves(hertz: Any) -> None:
    qp = hertz.qp
    n = qp.n
    refused(lambda: Constraints(np.full(n, -1.0), None), "upper")
    refused(lambda: Constraints(np.zeros(n), None), "upper")
    refused(lambda: Constraints(np.full(n, np.nan), None), "upper")
    refused(lambda: QP(qp.H, qp.ubar, qp.geometry, Constraints(np.ones(3), None)), "upper", "(3,)")
    refused(lambda: Constraints(None, float("nan")), "load")
    refused(lambda: Constraints(None, -5.0), "load")
    refused(lambda: make_constraints(3, None, "3"), "load")  # type: ignore[arg-type]
    refused(lambda: make_constraints(3, None, True), "load")
    refused(lambda: hardness_bounds(True, 1e-6, 3), "hardness")  # type: ignore[arg-type]


def test_seeds_levels_and_counts() -> None:
    for seed in (-1, 1.5, None, True):
        refused(lambda: spectral_surface(8, 0.7, seed=seed), "seed")  # type: ignore[arg-type]
        refused(lambda: rmd_surface(3, 0.7, seed=seed), "seed")  # type: ignore[arg-type]
    refused(lambda: rmd_surface(True, 0.7), "RMD level k")  # type: ignore[arg-type]
    refused(lambda: rmd_surface(float("nan"), 0.7), "RMD level k")  # type: ignore[arg-type]
    refused(lambda: rmd_surface(3, 0.7, min_level=2.5), "min_level")  # type: ignore[arg-type]
    refused(lambda: rmd_surface_n(True, 0.7), "N")  # type: ignore[arg-type]
    for cycles in (0, -1, 1.7):
        refused(lambda: load_unload_cycle(1e-6, 3, cycles=cycles), "cycles")  # type: ignore[arg-type]
    for steps in (float("inf"), True):
        refused(lambda: load_ramp(1e-6, steps), "load steps")  # type: ignore[arg-type]
    assert load_unload_cycle(1e-6, 2, cycles=2).size == 5


def test_nan_memory_budget_is_refused(hertz: Any) -> None:
    refused(lambda: hertz.qp.H.to_dense(float("nan")), "memory budget")
    refused(lambda: DenseOperator(np.eye(3)).to_dense(float("nan")), "memory budget")
    refused(lambda: InstanceBuilder(hertz.surface, 1e9, memory_budget=float("nan")), "memory budget")
