"""The fast CCGs with their vectors in the operator's array space (solvers/_device.py).

On a device that is not there (tests/fake_device.py: arrays that refuse every implicit
trip to the host, as CuPy's do) each fast CCG solves the plain and the load-controlled
problem to the same answer as on the host, with the same products under load control,
and moves whole arrays only a fixed number of times per solve -- however many
iterations it runs.  On the NumPy space (the host itself) the iterates are the host
operator's.  A preconditioner or a bound that runs on the host only keeps the loop on
the host, and says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from contactbench.problems.constraints import make_constraints
from contactbench.problems.instances import QP, InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.operators_gpu import gpu_unavailable_reason
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers.base import SolverSettings
from contactbench.solvers.registry import get_solver
from tests.fake_device import SPACE, TRANSFERS, DeviceArray
from tests.helpers import on_space

E = 1e9
TOL = 1e-10
#: Arrays a solve moves: up, ubar, the start, the wave numbers, the grid indices, the
#: kernel spectrum, the trial set's padded indices, its grid rows and columns and the
#: kernel table's quarter (the partial products'); down, p and its gap.
FIXED_TRANSFERS = 11
#: And in mixed precision: the float32 spectrum and the float32 twin's padded indices.
MIXED_TRANSFERS = 2
#: And a screened round's proof on the whole grid (solvers/_screen.py): p up, its product down.
SCREEN_TRANSFERS = 2


#: Products two FFT libraries may differ by on these ~30-product solves: the fake device's
#: transforms are NumPy's, the host's ducc0's, and in float32 (mixed precision) their
#: rounding moves a load-controlled 64^2 solve by up to 2 (32 against 34); else 5 %.
PRODUCT_SLACK = 2


def transfers_allowed(info: dict) -> int:
    """The arrays a solve with this ``info`` may move: the fixed ones (and the mixed
    ones) each round, and a screened round's proof."""
    rounds = info.get("screened_rounds")
    fixed = FIXED_TRANSFERS + (MIXED_TRANSFERS if info["precision"] == "mixed" else 0)
    return (fixed + (SCREEN_TRANSFERS if rounds else 0)) * (rounds or 1)


def same_products(dev, host) -> bool:
    """The device solve took the host's products, within ``PRODUCT_SLACK`` or 5 %."""
    return abs(dev.matvecs - host.matvecs) <= max(PRODUCT_SLACK, 0.05 * host.matvecs)


@pytest.fixture(scope="module")
def builder_and_instance():
    surf = rmd_surface_n(64, 0.7, length=1e-4, seed=3)
    builder = InstanceBuilder(surf, E)
    return builder, builder.build(paper_max_displacement(surf))


def loaded(qp: QP) -> QP:
    """``qp`` under half the load of its displacement-controlled answer."""
    ref = get_solver("fast-dual-pccg").solve(qp, SolverSettings(tol=TOL))
    return QP(qp.H, qp.ubar, qp.geometry, make_constraints(qp.n, None, 0.5 * float(np.sum(ref.p))))


def solve(name: str, qp: QP, **params):
    return get_solver(name).solve(qp, SolverSettings(tol=TOL, params=params or None))


def test_the_fake_device_refuses_implicit_transfers() -> None:
    """The fake holds: a host array mixed in, an implicit conversion, a host index or a
    keyword CuPy lacks is refused; scalars cross and are counted."""
    x = SPACE.put(np.arange(4.0))
    assert isinstance(x * 2.0 + np.sum(x), DeviceArray)
    for bad in (lambda: x + np.ones(4), lambda: np.asarray(x), lambda: x[np.array([0, 1])], lambda: float(x),
                lambda: np.min(x, initial=0.0)):
        with pytest.raises(TypeError):
            bad()
    before = TRANSFERS.scalars
    assert float(x @ x) == 14.0 and TRANSFERS.scalars == before + 1
    assert np.array_equal(SPACE.get(x), np.arange(4.0))


@pytest.mark.parametrize("control", ["displacement", "load"])
@pytest.mark.parametrize("name, params", [
    ("fast-dual-pccg", {}),
    ("fast-dual-pccg", {"precision": "mixed"}),
    ("fast-pccg", {"precondition": "fourier"}),
    ("fast-dual-ccg", {}),
    ("fast-ccg", {}),
])
def test_a_device_solve_keeps_its_vectors_there(builder_and_instance, control, name, params) -> None:
    builder, inst = builder_and_instance
    qp = inst.qp if control == "displacement" else loaded(inst.qp)
    same = {"precondition": "fourier"} if name.endswith("pccg") else {}  # what "auto" is on a device
    host = solve(name, qp, **{**params, **same})
    before = dataclasses.replace(TRANSFERS)
    dev = solve(name, on_space(builder, qp, SPACE), **params)
    moved = TRANSFERS.arrays() - before.arrays()
    assert dev.status == "converged", dev.message
    assert dev.info["array_space"] == "fake"
    assert dev.iterations >= 10 and moved <= transfers_allowed(dev.info), moved
    assert np.max(np.abs(dev.p - host.p)) <= 1e-6 * np.max(host.p)
    assert kkt_check(qp, dev.p, dev.multiplier).kkt_error <= 10 * TOL
    assert same_products(dev, host), (dev.matvecs, host.matvecs)
    if control == "load":
        assert dev.multiplier == pytest.approx(host.multiplier, rel=1e-6)


#: Host waits an iteration of the device loop may cost: under displacement control the KKT
#: figures, the exact step, the clip test, the Polak-Ribiere beta and a clip's settling;
#: under load control also the approach (the mean gap inside), the projection onto the load
#: and the set's drift -- each a single read of its scalars (``kkt.read_scalars``), not one
#: read per scalar (12 and 28 an iteration when they were read one by one).
SCALAR_READS_PER_ITERATION = {"displacement": 7, "load": 15}


@pytest.mark.parametrize("control", ["displacement", "load"])
def test_a_device_iteration_waits_on_the_host_a_few_times(builder_and_instance, control) -> None:
    builder, inst = builder_and_instance
    qp = inst.qp if control == "displacement" else loaded(inst.qp)
    before = TRANSFERS.scalars
    dev = solve("fast-dual-pccg", on_space(builder, qp, SPACE))
    reads = TRANSFERS.scalars - before
    assert dev.status == "converged" and dev.iterations >= 10
    assert reads <= SCALAR_READS_PER_ITERATION[control] * dev.iterations + 10, (reads, dev.iterations)


def test_read_scalars_reads_a_device_s_values_at_once() -> None:
    from contactbench.problems.kkt import read_scalars

    x = SPACE.put(np.array([1.0, -2.0, np.nan]))
    before = TRANSFERS.scalars
    got = read_scalars(np.min(x[:2]), np.max(x), np.all(np.isfinite(x[:2])), np.count_nonzero(x > 0.0))
    assert TRANSFERS.scalars == before + 1
    assert got[0] == -2.0 and np.isnan(got[1]) and got[2:] == [1.0, 1.0]
    host = read_scalars(np.float32(0.5), np.bool_(False), 3)
    assert host == [0.5, 0.0, 3.0] and all(type(v) is float for v in host)


@pytest.mark.parametrize("control", ["displacement", "load"])
@pytest.mark.parametrize("name", ["fast-dual-pccg", "fast-ccg"])
def test_the_numpy_space_is_the_host_loop(builder_and_instance, control, name) -> None:
    """On the NumPy space the loop is the host's: the same products (+-5 %) and answer."""
    builder, inst = builder_and_instance
    qp = inst.qp if control == "displacement" else loaded(inst.qp)
    host = solve(name, qp, precondition="fourier") if name == "fast-dual-pccg" else solve(name, qp)
    kw = {"precondition": "fourier"} if name == "fast-dual-pccg" else {}
    arr = solve(name, on_space(builder, qp, "numpy"), **kw)
    assert arr.info["array_space"] == "numpy" and arr.status == "converged"
    assert same_products(arr, host), (arr.matvecs, host.matvecs)
    assert np.max(np.abs(arr.p - host.p)) <= 1e-8 * np.max(host.p)


def test_host_only_work_keeps_the_loop_on_the_host_and_says_why(builder_and_instance) -> None:
    builder, inst = builder_and_instance
    qp = on_space(builder, inst.qp, SPACE)
    islands = solve("fast-dual-pccg", qp, precondition="islands")
    assert islands.status == "converged" and islands.info["array_space"].startswith("host (the 'islands'")
    hard = QP(qp.H, qp.ubar, qp.geometry, make_constraints(qp.n, 0.5 * float(np.max(solve("fast-ccg", inst.qp).p))))
    bounded = solve("fast-dual-ccg", hard)
    assert bounded.status == "converged" and bounded.info["array_space"].startswith("host (a hardness")


def test_auto_is_the_fourier_preconditioner_on_a_device(builder_and_instance) -> None:
    """The default's islands are host work; on a device "auto" is the wave-number kind,
    on the host (and the NumPy space) it stays the islands."""
    builder, inst = builder_and_instance
    dev = solve("fast-dual-pccg", on_space(builder, inst.qp, SPACE))
    assert dev.info["array_space"] == "fake" and dev.info["preconditioner_builds"] == 0
    host = solve("fast-dual-pccg", on_space(builder, inst.qp, "numpy"))
    assert host.info["preconditioner_builds"] > 0


def test_a_screened_device_solve_moves_its_arrays_once_a_round() -> None:
    """Under a light load the solve is screened (solvers/_screen.py): each round's
    sub-problem runs on the device, its arrays cross once a round, and the products are
    the host's."""
    surf = rmd_surface_n(128, 0.7, length=1e-4, seed=3)
    builder = InstanceBuilder(surf, E)
    qp = loaded(builder.build(paper_max_displacement(surf)).qp)
    qp = QP(qp.H, qp.ubar, qp.geometry, make_constraints(qp.n, None, 0.4 * float(qp.constraints.load)))
    host = solve("fast-dual-pccg", qp, precondition="fourier")
    before = dataclasses.replace(TRANSFERS)
    dev = solve("fast-dual-pccg", on_space(builder, qp, SPACE))
    rounds = dev.info["screened_rounds"]
    assert dev.status == "converged" and rounds >= 2 and dev.info["array_space"] == "fake"
    assert TRANSFERS.arrays() - before.arrays() <= transfers_allowed(dev.info)
    assert same_products(dev, host), (dev.matvecs, host.matvecs)
    assert np.max(np.abs(dev.p - host.p)) <= 1e-6 * np.max(host.p)


@pytest.mark.skipif(gpu_unavailable_reason() is not None, reason=f"no CUDA device: {gpu_unavailable_reason()}")
@pytest.mark.parametrize("control", ["displacement", "load"])
def test_the_cuda_device_gives_the_host_answer(builder_and_instance, control) -> None:
    """On a lent GPU: the same solve on CuPy, the host's answer and products (the answer
    checked first, so a failure on the products says whether the answer held)."""
    builder, inst = builder_and_instance
    qp = inst.qp if control == "displacement" else loaded(inst.qp)
    host = solve("fast-dual-pccg", qp, precondition="fourier")
    dev = solve("fast-dual-pccg", on_space(builder, qp, "cupy"))
    assert dev.status == "converged" and dev.info["array_space"] == "cupy"
    assert np.max(np.abs(dev.p - host.p)) <= 1e-6 * np.max(host.p)
    assert kkt_check(qp, dev.p, dev.multiplier).kkt_error <= 10 * TOL
    assert same_products(dev, host), (dev.matvecs, dev.iterations, dev.info, host.matvecs, host.iterations, host.info)


_ENTRIES = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                     st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 1e308, -1e308, 5e-324]))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.integers(0, 6).flatmap(lambda n: st.tuples(st.lists(_ENTRIES, min_size=n, max_size=n),
                                                     st.lists(_ENTRIES, min_size=n, max_size=n))),
       st.booleans())
def test_the_kkt_figures_on_a_device_are_the_host_s(pw, loaded_: bool) -> None:
    """The figures a device loop stops on (one read of their reductions, ``read_scalars``)
    are the host's, figure by figure, for any entries: NaN, inf, 1e308, signed zeros,
    subnormals, empty; with a load equality too."""
    from contactbench.problems.kkt import constrained_figures

    p, w = (np.array(v, dtype=np.float64) for v in pw)
    ubar = np.linspace(1.0, 2.0, p.size)
    constraints = make_constraints(p.size, None, 1.0 if loaded_ and p.size else None)
    multiplier = 0.5 if loaded_ else None
    with np.errstate(all="ignore"):
        host = constrained_figures(p, w, ubar, 3.0, constraints, multiplier)
        # a loop hands over ||ubar||_inf, read once (CuPy's max takes no initial=)
        dev = constrained_figures(SPACE.put(p), SPACE.put(w), SPACE.put(ubar), 3.0, constraints, multiplier,
                                  ubar_max=float(np.max(ubar, initial=0.0)))
    for name in ("primal", "dual", "complementarity", "kkt_error", "equality"):
        a, b = getattr(host, name), getattr(dev, name)
        assert (np.isnan(a) and np.isnan(b)) or a == b, (name, a, b)
