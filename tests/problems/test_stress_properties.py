"""Property tests over random LCPs of the contact family (fixed seed, bounded examples)."""

from __future__ import annotations

from unittest import mock

import numpy as np
from hypothesis import given, seed, settings
from hypothesis import strategies as st

from contactbench.harness.conformance.battery import exact_reference
from contactbench.problems import fft_threads
from contactbench.problems.kkt import kkt_check
from contactbench.problems.instances import QP, ContactInstance
from contactbench.problems.operators import DenseOperator
from contactbench.problems.scenes.stress import packed_instance, random_spd_instance

SETTINGS = settings(max_examples=12, deadline=None, derandomize=True, database=None)

sizes = st.integers(min_value=1, max_value=120)
densities = st.sampled_from([0.02, 0.1, 0.3, 0.6, 1.0])
seeds = st.integers(min_value=0, max_value=10_000)
kernels = st.sampled_from(["bcc", "love"])


@seed(20150101)
@SETTINGS
@given(n=sizes, density=densities, s=seeds, kernel=kernels)
def test_contact_family_lcp_reference_is_exact(n: int, density: float, s: int, kernel: str) -> None:
    inst = packed_instance(n, density, kernel, s, operator="dense")
    ref = exact_reference(inst)
    assert ref.kkt_error < 1e-11
    assert np.all(ref.p >= 0)
    # Clipping the unconstrained solution at 0 is exact only when nothing is clipped.
    H = inst.qp.H.to_dense()
    clipped = np.maximum(np.linalg.solve(H, inst.qp.ubar), 0.0)
    if np.any(np.linalg.solve(H, inst.qp.ubar) < 0):
        assert kkt_check(inst, clipped).kkt_error > 1e-6


@seed(20150102)
@SETTINGS
@given(n=st.integers(min_value=2, max_value=60), s=seeds)
def test_random_positive_spd_lcp_reference_is_exact(n: int, s: int) -> None:
    inst = random_spd_instance(n, s)
    H = inst.qp.H.to_dense()
    assert np.all(H > 0) and np.linalg.eigvalsh(H)[0] > 0
    assert exact_reference(inst).kkt_error < 1e-9


@seed(20150103)
@SETTINGS
@given(n=st.integers(min_value=4, max_value=100), density=densities, s=seeds,
       eps=st.sampled_from([1e-9, 1e-6, 1e-3]))
def test_perturbing_ubar_moves_p_by_at_most_cond_eps(n: int, density: float, s: int, eps: float) -> None:
    """Lipschitz bound of the SPD LCP: ||dp|| <= ||du|| / lambda_min and, ubar >= 0
    giving ||ubar|| <= lambda_max ||p||, ||dp|| / ||p|| <= cond(H) ||du|| / ||ubar||."""
    inst = packed_instance(n, density, "bcc", s, operator="dense")
    ref0 = exact_reference(inst)
    d = np.random.default_rng(s + 1).standard_normal(inst.n)
    d *= eps * np.linalg.norm(inst.qp.ubar) / np.linalg.norm(d)
    moved = ContactInstance(QP(inst.qp.H, inst.qp.ubar + d), inst.delta, inst.E, inst.kernel, False)
    ref1 = exact_reference(moved)
    rel_move = np.linalg.norm(ref1.p - ref0.p) / np.linalg.norm(ref0.p)
    assert rel_move <= ref0.cond * eps * (1 + 1e-6) + 1e-13


@seed(20150104)
@SETTINGS
@given(n=st.integers(min_value=1, max_value=50), s=seeds,
       length=st.sampled_from([1e-9, 1e-6, 1.0, 1e3]), force=st.sampled_from([1e-12, 1e-3, 1.0, 1e6]))
def test_scaled_kkt_figures_are_unit_invariant(n: int, s: int, length: float, force: float) -> None:
    """H [length/force] -> H length/force, ubar -> ubar length, p -> p force: every scaled
    figure of any candidate (here a deliberately rough one) is unchanged to 1e-8."""
    inst = packed_instance(n, 0.5, "love", s, operator="dense")
    rng = np.random.default_rng(s)
    p = np.maximum(exact_reference(inst).p + 0.01 * rng.standard_normal(inst.n) * 0.1, -1e-3)
    scaled = QP(DenseOperator(inst.qp.H.to_dense() * (length / force)), inst.qp.ubar * length)
    a, b = kkt_check(inst, p), kkt_check(scaled, p * force)
    for name in ("primal", "dual", "complementarity", "complementarity_sum", "kkt_error"):
        assert abs(getattr(a, name) - getattr(b, name)) <= 1e-8 * max(1.0, abs(getattr(a, name)))


@seed(20151128)
@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(n=st.integers(min_value=1, max_value=40), s=seeds, where=st.sampled_from(["p", "w"]),
       bad=st.sampled_from([np.nan, np.inf, -np.inf]), finite=st.booleans())
def test_a_non_finite_entry_anywhere_makes_every_figure_infinite(n: int, s: int, where: str, bad: float,
                                                                 finite: bool) -> None:
    """``kkt_figures`` reads finiteness from each array's least and greatest entries: one
    NaN or infinity in p or in w, at any position, makes all three figures inf; finite
    arrays of moderate size give finite figures -- the same figures read in bands on the
    threads, the bad entry in any band."""
    from contactbench.problems.kkt import kkt_figures

    rng = np.random.default_rng(s)
    p, w, ubar = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    if not finite:
        (p if where == "p" else w)[rng.integers(n)] = bad
    f = kkt_figures(p, w, ubar, 1.0)
    figures = (f.primal, f.dual, f.complementarity)
    assert all(v == np.inf for v in figures) if not finite else all(np.isfinite(v) for v in figures)
    with mock.patch.multiple(fft_threads, BANDED_VECTOR_MIN=1, VECTOR_BAND=3):  # bands of 3 on the threads
        banded = kkt_figures(p, w, ubar, 1.0)
    assert (banded.primal, banded.dual, banded.complementarity) == figures
