"""Under load control the approach Delta is part of an answer (``harness.judging.answer_report``):
the judge reads the figures at the Delta it fits from p and at the one the solver reports,
whichever is smaller -- each a certificate -- so an answer within the tolerance at the
Delta it stopped on is accepted, and no reported Delta makes a wrong answer pass."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.judging import answer_report, judge
from contactbench.problems.instances import ContactInstance, InstanceBuilder
from contactbench.problems.kkt import constrained_figures
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.surfaces import fourier_synthesis

TOL = 1e-6


def load_instance(side: int = 24, load: float = 4e-4) -> ContactInstance:
    E = 1e9
    surface = fourier_synthesis(side, 0.8, 0.1, length=1e-4, seed=3)
    return InstanceBuilder(surface, E, operator="dense").build_load(load * E * (side * surface.delta) ** 2)


def interior_point_like(inst: ContactInstance) -> tuple[np.ndarray, float]:
    """An answer as an interior-point method leaves one: small forces on the clearly open
    gaps, their products at 0.9 x the tolerance each and together (as a share of the load,
    ``kkt.load_share``), the contact forces closing their gaps exactly at an approach D with
    the load exact.  (p, D)."""
    H, ubar, c = inst.qp.H.to_dense(), np.asarray(inst.qp.ubar, dtype=np.float64), inst.qp.constraints
    ref = constrained_exact_solution(H, ubar, c)
    u_s, p_s = inst.problem_scales()
    w = H @ ref.p - ubar - ref.multiplier
    touch, open_ = ref.p > 0, (ref.p <= 0) & (w > 0.05 * u_s)
    p = np.zeros(inst.n)
    each = 0.9 * TOL / max(1.0, p_s * int(open_.sum()) / float(c.load))
    p[open_] = each * u_s * p_s / w[open_]
    HCC = H[np.ix_(touch, touch)]
    a = np.linalg.solve(HCC, ubar[touch] - H[np.ix_(touch, open_)] @ p[open_])
    e = np.linalg.solve(HCC, np.ones(int(touch.sum())))
    approach = (float(c.load) - p.sum() - a.sum()) / e.sum()
    p[touch] = a + approach * e
    return p, approach


def test_an_answer_within_the_tolerance_at_its_own_approach_is_accepted() -> None:
    inst = load_instance()
    p, approach = interior_point_like(inst)
    H = inst.qp.H.to_dense()
    ubar = np.asarray(inst.qp.ubar, dtype=np.float64)
    own = constrained_figures(p, H @ p - ubar, ubar, float(np.max(np.diag(H))), inst.qp.constraints, approach)
    assert own.kkt_error <= TOL  # (what the solver stopped on)
    fitted_only = judge(inst, p, True, TOL)
    assert fitted_only.status == "inaccurate"  # the fitted Delta alone reads it wrong ...
    v = judge(inst, p, True, TOL, multiplier=approach)
    assert v.status == "solved" and v.reading == "pass", v.message()
    assert v.kkt.multiplier == pytest.approx(approach, rel=1e-12)


@pytest.mark.parametrize("wrap", [np.float32, np.array, lambda x: np.array([x])[0], np.longdouble],
                         ids=["float32", "0-d array", "numpy scalar", "longdouble"])
def test_an_approach_reported_as_a_numpy_number_is_read(wrap: object) -> None:
    inst = load_instance()
    p, approach = interior_point_like(inst)
    v = judge(inst, p, True, TOL, multiplier=wrap(approach))  # type: ignore[operator]
    assert v.status == "solved", v.message()
    assert v.kkt.multiplier == pytest.approx(approach, rel=1e-6)


@pytest.mark.parametrize("claimed", [float("nan"), float("inf"), None, True, "1e-6", np.array([1.0, 2.0]),
                                     np.array(np.nan), np.bool_(True), 1 + 2j])
def test_a_reported_approach_that_is_no_number_leaves_the_fitted_one(claimed: object) -> None:
    inst = load_instance()
    p, _ = interior_point_like(inst)
    plain = judge(inst, p, True, TOL)
    v = judge(inst, p, True, TOL, multiplier=claimed)  # type: ignore[arg-type]
    assert v.kkt.kkt_error == plain.kkt.kkt_error and v.status == plain.status


def test_no_reported_approach_lets_a_wrong_answer_pass() -> None:
    """The exact answer with a tenth of the load moved from the most to the least loaded
    contact element: the load is exact, the distribution wrong, and at every reported
    Delta over a wide range the answer stays inaccurate."""
    inst = load_instance(load=4e-3)
    H, ubar = inst.qp.H.to_dense(), np.asarray(inst.qp.ubar, dtype=np.float64)
    ref = constrained_exact_solution(H, ubar, inst.qp.constraints)
    p = ref.p.copy()
    touch = np.flatnonzero(p > 0)
    most, least = touch[np.argmax(p[touch])], touch[np.argmin(p[touch])]
    moved = 0.1 * p[most]
    p[most] -= moved
    p[least] += moved
    u_s, _ = inst.problem_scales()
    for shift in np.linspace(-0.5, 0.5, 41):
        v = judge(inst, p, True, TOL, multiplier=ref.multiplier + shift * u_s)
        assert v.status == "inaccurate" and v.reading == "wrong", (shift, v.kkt_error)
    assert judge(inst, ref.p, True, TOL, multiplier=ref.multiplier).status == "solved"


def test_without_load_control_a_reported_approach_is_not_read() -> None:
    surface = fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=1)
    inst = InstanceBuilder(surface, 1e9, operator="dense").build(0.5 * (surface.z_max - surface.z_mean))
    p = constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar, dtype=np.float64),
                                   inst.qp.constraints).p
    assert judge(inst, p, True, TOL, multiplier=1e3).kkt.kkt_error == judge(inst, p, True, TOL).kkt.kkt_error


def test_both_approaches_are_read_from_one_product(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fitted and the reported Delta share the answer's product H p: the judge's cost
    does not double under load control (a 16384^2 product is seconds on the host)."""
    inst = load_instance()
    p, approach = interior_point_like(inst)
    H = inst.qp.H
    products = []
    real_matvec = H.matvec

    def counted(x: np.ndarray) -> np.ndarray:
        products.append(x.size)
        return real_matvec(x)

    monkeypatch.setattr(H, "matvec", counted)
    report = answer_report(inst, p, approach)
    assert products == [inst.n]
    assert report.multiplier == pytest.approx(approach, rel=1e-12)
