"""The wave-number preconditioner (``FourierPreconditioner``: |q| on the grid's spectrum,
solvers._preconditioners.py), its transforms, and "auto" under load control."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.solvers._preconditioners import (
    FourierPreconditioner,
    floored_wavenumbers,
    multiply_by_wavenumbers,
    make_preconditioner,
)
from contactbench.solvers.base import SolverSettings, WarmStart
from contactbench.solvers.registry import get_solver
from tests.helpers import top_step as build


@pytest.mark.parametrize("name", ["fast-pccg", "fast-dual-pccg"])
def test_fourier_preconditioner_option_reaches_the_same_answer(name):
    inst = build(65)
    ref = get_solver(name.replace("pccg", "ccg")).solve(inst.qp, SolverSettings(tol=1e-9))
    res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-9, params={"precondition": "fourier"}))
    assert res.converged
    assert np.linalg.norm(res.p - ref.p) <= 1e-6 * np.linalg.norm(ref.p)


def test_the_fourier_preconditioner_of_a_mixed_solve_runs_in_float32():
    """Its transforms in float32 (``make_preconditioner``'s block_dtype): within float32's
    round-off of the float64 one, nearly symmetric on the set, returned in the residual's
    precision; a mixed load-controlled solve with it reaches the double one's answer."""
    inst = build(65)
    n = inst.n
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.6)
    apply = {}
    for dt in (np.float64, np.float32):
        M = make_preconditioner("fourier", inst.qp, dt)
        M.update(S)
        apply[dt] = M.apply
    rng = np.random.default_rng(5)
    r, v = rng.normal(size=n), rng.normal(size=n)
    z64, z32 = apply[np.float64](r), apply[np.float32](r)
    assert z32.dtype == np.float64 and not np.any(z32[~S])
    assert 1e-10 * np.linalg.norm(z64) < np.linalg.norm(z32 - z64) <= 1e-5 * np.linalg.norm(z64)  # float32's
    assert abs(v @ apply[np.float32](r) - r @ apply[np.float32](v)) <= 1e-5 * abs(v @ z64) + 1e-5 * np.linalg.norm(
        v) * np.linalg.norm(z64)
    surf = rmd_surface_n(65, 0.7, length=100e-6, seed=2)
    builder = InstanceBuilder(surf, 1e9, "bcc", periodic=False)
    loaded = builder.build_load(builder.load_force(0.01)).qp
    out = {p: get_solver("fast-dual-pccg").solve(loaded, SolverSettings(tol=1e-9, params={
        "precondition": "fourier", "precision": p})) for p in ("mixed", "double")}
    assert all(o.converged for o in out.values()) and out["mixed"].info["matvecs_float32"] > 0
    assert np.linalg.norm(out["mixed"].p - out["double"].p) <= 1e-6 * np.linalg.norm(out["double"].p)


def test_the_whole_grid_skips_the_scatter_and_gives_the_same_product():
    """A preconditioner on the whole grid in order (load control's trial set) transforms r
    itself, unmodified; it equals the scatter-and-gather product."""
    shape = (24, 20)
    q = floored_wavenumbers(shape)
    r = np.random.default_rng(7).normal(size=shape[0] * shape[1])
    kept = r.copy()
    whole = multiply_by_wavenumbers(q, shape, None, r)
    np.testing.assert_array_equal(r, kept)
    np.testing.assert_allclose(whole, multiply_by_wavenumbers(q, shape, np.arange(r.size), r), rtol=1e-13, atol=1e-13)
    M = FourierPreconditioner(shape, np.arange(r.size))
    S = r > 0
    M.update(S)
    np.testing.assert_allclose(M.apply(r), multiply_by_wavenumbers(q, shape, np.arange(r.size), r * S) * S,
                               rtol=1e-13, atol=1e-13)


def test_the_wave_numbers_solo_is_their_inverse_on_a_one_point_set():
    """``solo`` is M's inverse on a one-point set, as the island blocks' r / H_jj: M =
    F^-1[1/|q|] F (M^-1 multiplies by |q|), so 1 / M_jj = 1 / mean(1/|q|) over the full
    spectrum (numpy's full 2-D transform here), below the diagonal of M^-1 (mean |q|)."""
    shape = (24, 20)
    q0 = 2.0 * np.pi * np.fft.fftfreq(shape[0])
    q1 = 2.0 * np.pi * np.fft.fftfreq(shape[1])
    q = np.hypot(q0[:, None], q1[None, :])
    q[0, 0] = np.min(q[q > 0])  # floored as floored_wavenumbers does
    M = FourierPreconditioner(shape, np.arange(shape[0] * shape[1]))
    r = np.random.default_rng(3).normal(size=shape[0] * shape[1])
    np.testing.assert_allclose(M.solo(r), r / np.mean(1.0 / q), rtol=1e-12)
    assert np.mean(1.0 / q) * np.mean(q) > 1.2  # the diagonal of M^-1 would overshoot


def test_the_wave_numbers_are_dropped_only_when_the_constrained_loops_ask():
    """Without ``blocks`` (the displacement loop's "Cycling") nothing is dropped; with it
    (a constrained loop's stagnation) the wave numbers go once: z = c r on the set (the
    unpreconditioned direction, ``solo``'s scale), the version moves so a loop restarts its
    conjugacy, and nothing is left to drop."""
    shape = (24, 20)
    rng = np.random.default_rng(5)
    r = rng.normal(size=shape[0] * shape[1])
    M = FourierPreconditioner(shape, np.arange(r.size))
    S = rng.random(r.size) < 0.4
    M.update(S)
    full = M.apply(r)
    assert not M.simplify() and M.version == 0
    np.testing.assert_array_equal(M.apply(r), full)
    assert M.simplify(blocks=True) and M.version == 1
    np.testing.assert_allclose(M.apply(r), M.solo(np.where(S, r, 0.0)), rtol=1e-15)
    T = ~S
    M.update(T)
    np.testing.assert_allclose(M.apply(r), M.solo(np.where(T, r, 0.0)), rtol=1e-15)
    np.testing.assert_allclose(M.ones(), M.solo(T.astype(float)), rtol=1e-15)
    assert not M.simplify(blocks=True) and M.version == 1


def test_a_scattered_set_is_scattered_and_gathered_in_bands_to_the_same_product(monkeypatch: pytest.MonkeyPatch) -> None:
    """On a set of the grid (shuffled positions) the scatter and the gather go in bands over
    the threads (``fft_threads.each_band``, bands of 7 on 1 or 3 threads): the product of the
    whole set, equal to the dense periodic convolution by |q| restricted to the set."""
    from contactbench.problems import fft_threads

    shape = (24, 20)
    q = floored_wavenumbers(shape)
    rng = np.random.default_rng(8)
    idx = rng.permutation(shape[0] * shape[1])[:300]
    r = rng.normal(size=idx.size)
    f = np.zeros(shape[0] * shape[1])
    f[idx] = r
    want = np.fft.irfft2(np.fft.rfft2(f.reshape(shape)) * q, s=shape).ravel()[idx]
    whole = multiply_by_wavenumbers(q, shape, idx, r)
    np.testing.assert_allclose(whole, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    monkeypatch.setattr(fft_threads, "BANDED_VECTOR_MIN", 1)
    monkeypatch.setattr(fft_threads, "VECTOR_BAND", 7)
    for workers in ("1", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        np.testing.assert_allclose(multiply_by_wavenumbers(q, shape, idx, r), whole, rtol=1e-15, atol=0)


@pytest.mark.parametrize("backend", ["ducc", "scipy"])
def test_spectral_multiply_is_the_periodic_convolution(monkeypatch, backend):
    from contactbench.problems.fft_threads import spectral_multiply

    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", backend)
    rng = np.random.default_rng(1)
    for shape in ((16, 16), (12, 10), (9, 7)):
        f = rng.normal(size=shape)
        m = rng.random((shape[0], shape[1] // 2 + 1))
        want = np.fft.irfft2(np.fft.rfft2(f) * m, s=shape)
        np.testing.assert_allclose(spectral_multiply(f.copy(), m), want, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("workers", ["1", "3"])
def test_a_float32_convolution_with_its_rows_in_batches_is_the_periodic_convolution(monkeypatch, workers):
    """``periodic_convolve`` where ``row_batch`` limits a ducc0 call (long float32 rows,
    here every row): the row transforms in batches shared over the threads, the columns
    whole -- the same convolution, on row counts that are and are not a batch's multiple."""
    from contactbench.problems import fft_threads

    monkeypatch.setattr(fft_threads, "FLOAT32_LONG_ROW", 1)
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
    monkeypatch.setenv("CONTACTBENCH_FFT_BACKEND", "ducc")
    rng = np.random.default_rng(2)
    for shape in ((16, 16), (27, 10), (9, 7), (3, 12)):
        assert fft_threads.row_batch(shape[1], 4) > 0
        f = rng.normal(size=shape).astype(np.float32)
        m = rng.random((shape[0], shape[1] // 2 + 1)).astype(np.float32)
        want = np.fft.irfft2(np.fft.rfft2(f.astype(np.float64)) * m, s=shape)
        got = fft_threads.spectral_multiply(f.copy(), m)
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * float(np.max(np.abs(want))))


def test_auto_is_the_wave_number_preconditioner_under_load_control_only():
    """"auto" under load control is the wave numbers, with a hardness too; under displacement
    control the grid's rule, or a solver's own: fast-pccg takes the far field at every size
    and the wave numbers under load control (with the island blocks its loop cycled on the
    256^2 load sweep: results/perf/load-pk-default)."""
    from contactbench.solvers._preconditioners import resolved_kind

    s = rmd_surface_n(33, 0.7, length=100e-6, seed=2)
    b = InstanceBuilder(s, 1e9, "love")
    disp = b.build(paper_max_displacement(s))
    load = b.build_load(b.load_force(0.01))
    hard = b.build_load(b.load_force(0.01), hardness=1e12)
    plastic = b.build(paper_max_displacement(s), hardness=1e8)
    assert resolved_kind("auto", load.qp) == "fourier"
    assert resolved_kind("auto", hard.qp) == "fourier"  # a hardness under load control too
    assert resolved_kind("auto", disp.qp) == "islands"
    assert resolved_kind("auto", plastic.qp) == "islands"  # displacement control keeps the islands
    assert resolved_kind("islands", load.qp) == "islands"
    assert resolved_kind("auto", disp.qp, far_from=0) == "farfield"  # a solver's own grid rule
    assert resolved_kind("auto", load.qp, far_from=0) == "fourier"
    for inst, kind in ((disp, "farfield"), (plastic, "farfield"), (load, "fourier"), (hard, "fourier")):
        r = get_solver("fast-pccg").solve(inst.qp, SolverSettings(tol=1e-9))
        assert r.converged and r.info["preconditioner"] == kind, (kind, r.message)


@pytest.mark.parametrize("shape", [(1, 1), (1, 2), (2, 1), (2, 2), (2, 6), (3, 2), (5, 4), (6, 2)])
def test_the_wave_number_multiplier_is_positive_on_every_grid(shape) -> None:
    """|q| with its zero mode floored is positive everywhere, so M is SPD: on a side of 2
    points the only non-zero frequency is the Nyquist one, -pi, which once floored the
    zero mode to a negative value."""
    assert np.all(floored_wavenumbers(shape) > 0.0)


def test_a_flat_punch_on_a_two_row_grid_is_solved_with_the_wave_numbers() -> None:
    """All 12 points of a 2 x 6 flat punch in contact, the opening's wave-number
    preconditioner first: fast-dual-pccg's defaults stalled there at a KKT error of 1."""
    b = InstanceBuilder(Surface(np.zeros((2, 6)), 1e-6), 1e9, "bcc", periodic=False)
    qp = b.build(3e-7).qp
    assert qp.n == 12
    for params in ({}, {"precondition": "fourier"}):
        r = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=1e-10, params=params))
        assert r.converged, (params, r.message)
        assert kkt_check(qp, r.p).kkt_error <= 1e-10
        assert np.all(r.p > 0.0)


def test_auto_takes_the_island_kinds_for_a_warm_load_step_of_the_bugnicourt_loop():
    """A step of a non-periodic problem under a load alone, warm-started by the caller with
    at most ``WARM_LOAD_MAX_CONTACT`` of it in contact: fast-dual-pccg's "auto" is the warm
    displacement rule's island kind (the islands below 512^2 grid points); cold (its
    screening rounds too), with more contact, with a hardness, on a periodic grid or in the
    P&K loop (fast-pccg) it stays the wave numbers (results/perf/warm-load)."""
    from contactbench.solvers._preconditioners import WARM_LOAD_MAX_CONTACT, resolved_kind

    s = rmd_surface_n(33, 0.7, length=100e-6, seed=2)
    b = InstanceBuilder(s, 1e9, "love")
    load = b.build_load(b.load_force(0.0005))
    hard = b.build_load(b.load_force(0.0005), hardness=1e12)
    pb = InstanceBuilder(rmd_surface_n(32, 0.7, family="periodic", length=100e-6, seed=2), 1e9, "spectral",
                         periodic=True)
    periodic = pb.build_load(pb.load_force(0.0005))
    assert resolved_kind("auto", load.qp, warm=True, warm_load_contact=0.01) == "islands"
    assert resolved_kind("auto", load.qp, warm=True, warm_load_contact=WARM_LOAD_MAX_CONTACT) == "islands"
    assert resolved_kind("auto", load.qp, warm=True, warm_load_contact=0.05) == "fourier"  # much in contact
    assert resolved_kind("auto", load.qp, warm=False, warm_load_contact=0.01) == "fourier"
    assert resolved_kind("auto", load.qp, warm=True) == "fourier"  # a loop that keeps the wave numbers
    assert resolved_kind("auto", hard.qp, warm=True, warm_load_contact=0.01) == "fourier"
    assert resolved_kind("auto", periodic.qp, warm=True, warm_load_contact=0.01) == "fourier"
    settings = SolverSettings(tol=1e-9)
    for force, kind in ((0.0005, "islands"), (0.01, "fourier")):
        inst = b.build_load(b.load_force(force))
        cold = get_solver("fast-dual-pccg").solve(inst.qp, settings)
        assert cold.converged and cold.info["preconditioner"] == "fourier"
        share = float(np.mean(cold.p > 0.0))
        assert (share <= WARM_LOAD_MAX_CONTACT) == (kind == "islands"), share
        start = WarmStart(p=0.9 * cold.p)
        for name, want in (("fast-dual-pccg", kind), ("fast-pccg", "fourier")):
            warm = get_solver(name).solve(inst.qp, settings, start)
            assert warm.converged and warm.info["preconditioner"] == want, (name, force, warm.message)
