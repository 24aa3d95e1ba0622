"""The peers and the problems they may not pose: rectangular pixels (two spacings) and an
elastic layer of finite thickness.

ContactMechanics poses both: its half-spaces take the physical size (L0, L1) with the
grid, its Love kernel is the loaded d0 x d1 rectangle, and a layer is posed through our
table (which carries it).  Tamaas poses rectangular pixels (its model takes [L0, L1]) but
has no layer operator, so its solvers skip a layered problem with the reason.  The skip
reasons and the posing (sizes, element area, the table a dense QP is rebuilt from) are
checked without the peers; the solves only where the peers are installed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from contactbench.harness.run.worker import problem_traits
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.layers import Layer
from contactbench.problems.lcp import exact_solution
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers._peers import grid_problem
from contactbench.solvers.base import ProblemTraits, SolverSettings
from contactbench.solvers.peer_cm import native_green
from contactbench.solvers.peer_tamaas import tamaas_serves
from contactbench.solvers.registry import get_solver

E = 1e9
TAMAAS = ("tamaas-pkr", "tamaas-kato", "tamaas-beck-teboulle", "tamaas-condat", "tamaas-kato-saturated")
CM = ("cm-pk-ccg", "cm-dual-ccg")


def surface(N: int = 16):
    return fourier_synthesis(N, 0.8, 0.1, length=1e-4, seed=3)


def rectangular(N: int = 16):
    s = surface(N)
    return dataclasses.replace(s, delta1=2.0 * s.delta)


def instance(surf, kernel: str, periodic: bool, layer: Layer | None = None, operator: str = "fft"):
    b = InstanceBuilder(surf, E, kernel, periodic=periodic, operator=operator, layer=layer)
    return b.build(paper_max_displacement(surf))


@pytest.mark.parametrize("name", TAMAAS)
@pytest.mark.parametrize("kernel,periodic", [("spectral", True), ("love", False)])
def test_tamaas_skips_a_layer_with_the_reason(name: str, kernel: str, periodic: bool) -> None:
    """A fake problem's traits: the one Tamaas kernel it has, on a layer (load control, so
    that the load-controlled solvers reach the layer check)."""
    traits = ProblemTraits(n=256, operator="fft", kernel=kernel, periodic=periodic, layer=True, load_control=True)
    why = get_solver(name).skip(traits)
    assert why is not None and "elastic layer of finite thickness" in why, why
    assert tamaas_serves(kernel, periodic, layer=False) is None  # the half-space it poses


@pytest.mark.parametrize("name", CM)
def test_contactmechanics_does_not_skip_a_layer_and_poses_it_with_our_table(name: str) -> None:
    for kernel, periodic in (("love", False), ("spectral", True), ("bcc", False)):
        assert get_solver(name).skip(ProblemTraits(n=256, operator="fft", kernel=kernel, periodic=periodic,
                                                   layer=True)) is None
        assert not native_green(kernel, periodic, layer=True)
    assert native_green("love", False) and native_green("spectral", True)


def test_the_traits_say_whether_the_kernel_is_a_layer() -> None:
    s = surface()
    assert problem_traits(instance(s, "bcc", False, Layer(20 * s.delta, 0.3))).layer
    assert not problem_traits(instance(s, "bcc", False)).layer


@pytest.mark.parametrize("operator", ["fft", "dense"])
@pytest.mark.parametrize("case", ["rectangular-love", "layer-love", "layer-spectral"])
def test_the_grid_posing_keeps_both_spacings_and_the_layer(operator: str, case: str) -> None:
    """The peers' sizes are (d0 N0, d1 N1), an element's area d0 d1, and the table a peer
    gets is the operator's (rebuilt from the geometry for a dense H: spacings and layer)."""
    s = rectangular() if case.startswith("rectangular") else surface()
    layer = Layer(20 * s.delta, 0.3) if case.startswith("layer") else None
    kernel = case.split("-")[1]
    periodic = kernel == "spectral"
    inst = instance(s, kernel, periodic, layer, operator)
    fft = instance(s, kernel, periodic, layer, "fft")
    gp = grid_problem(inst.qp)
    d0, d1 = s.spacing
    assert gp.sizes == pytest.approx((d0 * 16, d1 * 16), rel=1e-15)
    assert gp.area == pytest.approx(d0 * d1, rel=1e-15)
    want = np.asarray(fft.qp.H.transform.table)
    assert np.max(np.abs(gp.table(inst.qp) - want)) <= 1e-12 * np.max(np.abs(want))


def _reference(inst) -> np.ndarray:
    return exact_solution(inst.qp.H.to_dense(), inst.qp.ubar).p


@pytest.mark.parametrize("name,case", [("cm-pk-ccg", "rectangular"), ("cm-dual-ccg", "rectangular"),
                                       ("cm-pk-ccg", "layer"), ("tamaas-pkr", "rectangular")])
def test_the_peers_pose_what_they_do_not_skip(name: str, case: str) -> None:
    """16^2 non-periodic Love: rectangular pixels (d1 = 2 d0), and a bonded layer 20
    spacings thick; the peer's answer is judged by our KKT check and the exact answer."""
    solver = get_solver(name)
    ok, why = solver.availability()
    if not ok:
        pytest.skip(why)
    s = rectangular() if case == "rectangular" else surface()
    inst = instance(s, "love", False, Layer(20 * s.delta, 0.3) if case == "layer" else None)
    assert solver.skip(problem_traits(inst)) is None
    r = solver.solve(inst.qp, SolverSettings(tol=1e-10))
    ref = _reference(inst)
    assert kkt_check(inst, r.p).kkt_error <= 1e-8
    assert np.max(np.abs(r.p - ref)) <= 1e-7 * np.max(ref)


def test_cm_pk_ccg_skips_a_periodic_real_space_kernel_with_the_reason() -> None:
    """It stayed at p = 0 until its iteration limit there (a 16^2 periodic 'love' step timed
    out at 30 s): skipped and said why, where cm-dual-ccg and the spectral kernel are run."""
    pk, dual = get_solver("cm-pk-ccg"), get_solver("cm-dual-ccg")
    for kernel in ("love", "bcc"):
        traits = ProblemTraits(n=256, operator="fft", kernel=kernel, periodic=True)
        why = pk.skip(traits)
        assert why is not None and "periodic real-space kernel" in why
        assert dual.skip(traits) is None
    assert pk.skip(ProblemTraits(n=256, operator="fft", kernel="spectral", periodic=True)) is None
    assert pk.skip(ProblemTraits(n=256, operator="fft", kernel="love", periodic=False)) is None


def saturated(margin: float, N: int = 8):
    """An N^2 non-periodic BCC problem under a hardness of 0.3 E* whose load is what
    n - ``margin`` elements carry at their bound."""
    s = surface(N)
    b = InstanceBuilder(s, E, "bcc", periodic=False)
    h = 0.3 * E
    return b.build_load((N * N - margin) * h * s.delta ** 2, hardness=h)


@pytest.mark.parametrize("margin,skipped", [(0.99, True), (0.5, True), (1.01, False), (2.0, False)])
def test_cm_pk_ccg_skips_a_load_above_all_elements_but_one_at_their_bound(margin: float, skipped: bool) -> None:
    """ContactMechanics' plastic-area bisection has no sign change for a load above (n - 1)
    bounds: skipped with the reason (the traits carry the load's share of the capacity)."""
    inst = saturated(margin)
    traits = problem_traits(inst)
    assert traits.capacity_share == pytest.approx((inst.n - margin) / inst.n, rel=1e-12)
    why = get_solver("cm-pk-ccg").skip(traits)
    assert (why is not None and "all elements but one" in why) if skipped else why is None


def test_cm_pk_ccg_raises_where_it_skips_a_nearly_saturated_load() -> None:
    """The peer's own behaviour behind the skip (its ``solve`` does not ask ``skip``): it
    raises at n - 0.99 bounds and answers at n - 1.01."""
    solver = get_solver("cm-pk-ccg")
    ok, why = solver.availability()
    if not ok:
        pytest.skip(why)
    with pytest.raises(ValueError, match="different signs"):
        solver.solve(saturated(0.99).qp, SolverSettings(max_iter=3000))
    assert np.isfinite(solver.solve(saturated(1.01).qp, SolverSettings(max_iter=3000)).p).all()
