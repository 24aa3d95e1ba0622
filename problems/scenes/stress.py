"""Stress scenes: the numerical-stability battery.

One battery of hard cases serves two jobs: ``contactbench run stress`` (these scenes,
run like any other) and ``contactbench validate`` (``harness.conformance``, which runs
a solver through the same recipes and judges every answer with ``harness.judging``).

Groups (each is also a scene of its own, ``stress-<group>``; ``stress`` is the union):

conditioning
    H_II of the BCC and Love kernels (paper eqs. green2 and Love 1929) on trial sets of
    n = 1e2 .. 1e5 points packed at densities from sparse to full; ubar ~ U(0, 1).
    ``condition_number`` estimates cond(H_II) (dense eigvalsh within reach, Lanczos /
    ``eigsh`` on ``op.as_linear_operator()`` beyond).
units
    One physical problem in m/Pa, um/MPa and nm/GPa, and with E over 12 orders of
    magnitude; scaled KKT figures and P/(E A) must agree (to 1e-8).
edge
    Delta = 0 (one point touching, ubar = 0), a single-point trial set, full contact,
    two identical maxima, a plateau of equal maxima, a 2 x N strip (built directly from
    ``problems.kernels``/``problems.operators``: a Surface must be square), a surface
    with 12 orders of magnitude of height range, and near-touching points (w ~ 1e-14 by
    construction, with the exact solution known).
random
    LCPs of the contact family: random SPD matrices with positive entries, and the BCC
    matrix with random ubar (paper Example 1) at packing densities from sparse to full.
precision
    float32 ubar: a solver must solve it in float64 or refuse it with a clear error.
perturbation
    ubar and ubar + eps d (||d|| = ||ubar||): p may move by at most ~cond(H) eps.
counterexample
    Paper Example 1 itself (``problems.instances.counterexample``: every element of an
    N x N grid in the trial set, ubar ~ U(0, 1), BCC, E = 0.01) at n = 400 and several
    seeds -- the family that refutes the greedy loop and stalls inexact pivoting.
packing
    Full packing with every point in contact: an LCP built from a solution p* > 0 on
    every element of an N x N grid (ubar = H p*, w* = 0), BCC and Love kernels.
periodic
    Periodic rough surfaces (spectral kernel 2/(E|q|) and periodic BCC) posed on the
    whole N x N grid: H is singular along the constant vector, has entries of both
    signs, and points below the rigid-body trial set (ubar < 0) touch.  The exact
    solution is certified on the whole grid (``problems.lcp.exact_solution_on_subset``).
constrained, rectangular
    Load control, a hardness, and both; a rectangular map with square and with 1.5:1
    pixels (``battery_families``).

Every recipe is an ``InstanceSpec`` whose params carry ``group``, the verdict
``profile`` (``mid``, or ``high`` where precision is the point) and ``compare``
(``units`` / ``perturbation`` for multi-step recipes whose steps are compared).
Cases with a known exact solution put it in ``instance.meta["p_exact"]``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from typing import Any, Callable

import numpy as np
from scipy.sparse.linalg import ArpackNoConvergence, eigsh

from ..errors import ProblemInputError
from ..instances import (
    QP,
    ContactInstance,
    Geometry,
    InstanceBuilder,
    counterexample,
    paper_max_displacement,
    rigid_body_ubar,
    trial_set,
)
from ..kernels import kernel_table
from ..lcp import exact_solution_on_subset
from ..operators import ContactOperator, DenseOperator, FFTOperator, KernelTransform, check_dense_budget
from ..surfaces import Surface, rmd_surface_n
from . import register_scene
from .base import InstanceSpec, LoadSequence, Scene, SceneConfig
from .battery_families import build_constrained, build_rectangular, constrained_specs, rectangular_specs

#: (length factor from metres, stress factor from pascals) of each unit system.
UNIT_SYSTEMS: dict[str, tuple[float, float]] = {
    "m/Pa": (1.0, 1.0),
    "um/MPa": (1e6, 1e-6),
    "nm/GPa": (1e9, 1e-9),
}
#: Composite moduli (Pa) of the E-range recipe: 12 orders of magnitude.
E_RANGE: tuple[float, ...] = (1e-3, 1e0, 1e3, 1e6, 1e9)
#: Relative size ||d|| / ||ubar|| of the perturbation recipe.
PERTURBATION_EPS = 1e-6
#: w of the near-touching points, relative to max |H p|.
NEAR_TOUCH_GAP = 1e-14
#: Largest n whose condition number is computed densely (eigvalsh).
DENSE_EIG_LIMIT = 2500
#: Far-field displacement of the periodic recipes, in units of ``paper_max_displacement``
#: (below 2, where sum(ubar) reaches 0 and the whole-grid QP becomes unbounded).
PERIODIC_DISPLACEMENT = 1.6

GROUPS: tuple[str, ...] = ("conditioning", "units", "edge", "random", "precision", "perturbation",
                           "counterexample", "packing", "periodic", "constrained", "rectangular")


# ---------------------------------------------------------------------------
# Condition numbers
# ---------------------------------------------------------------------------


def extreme_eigenvalues(op: ContactOperator, dense_limit: int = DENSE_EIG_LIMIT, tol: float = 1e-6) -> tuple[float, float, str]:
    """(lambda_min, lambda_max, method) of the SPD operator.

    n <= dense_limit: LAPACK eigvalsh on the assembled matrix.  Beyond: Lanczos
    (ARPACK ``eigsh``) on the matrix-free operator -- the largest eigenvalue directly,
    the smallest as lambda_max - (largest eigenvalue of lambda_max I - H), which needs
    no inverse and converges because H's low end is well separated for these kernels.
    """
    n = op.n
    if n == 1:
        d = float(op.diagonal()[0])
        return d, d, "exact"
    if n <= dense_limit:
        ev = np.linalg.eigvalsh(op.to_dense())
        return float(ev[0]), float(ev[-1]), "eigvalsh"
    A = op.as_linear_operator()
    v0 = np.ones(n)
    lmax = float(eigsh(A, k=1, which="LA", tol=tol, v0=v0, return_eigenvectors=False)[0])
    from scipy.sparse.linalg import LinearOperator

    shifted = LinearOperator((n, n), matvec=lambda x: lmax * x - op.matvec(x), dtype=np.float64)
    rng = np.random.default_rng(0)
    try:
        top = float(eigsh(shifted, k=1, which="LA", tol=tol, v0=rng.standard_normal(n), maxiter=20 * n,
                          ncv=min(n, 64), return_eigenvectors=False)[0])
        method = "lanczos"
    except ArpackNoConvergence as exc:  # keep the best estimate, say so
        top = float(np.max(exc.eigenvalues)) if len(exc.eigenvalues) else float("nan")
        method = "lanczos-unconverged"
    return lmax - top, lmax, method


def condition_number(op: ContactOperator, dense_limit: int = DENSE_EIG_LIMIT) -> float:
    """cond_2(H_II) = lambda_max / lambda_min (see ``extreme_eigenvalues``)."""
    lmin, lmax, _ = extreme_eigenvalues(op, dense_limit)
    return lmax / lmin if lmin > 0 else float("inf")


# ---------------------------------------------------------------------------
# Building blocks
# ---------------------------------------------------------------------------


def grid_operator(shape: tuple[int, int], delta: float, E: float, kernel: str, idx: np.ndarray,
                  operator: str = "fft", periodic: bool = False) -> ContactOperator:
    """H restricted to the flat grid indices ``idx`` of any N1 x N2 grid (square or not)."""
    transform = KernelTransform(kernel_table(kernel, shape, delta, E, periodic), shape)
    op = FFTOperator(transform, np.asarray(idx, dtype=np.int64))
    if operator == "dense":
        check_dense_budget(op.n)
        return DenseOperator(op.to_dense())
    return op


def heights_instance(heights: np.ndarray, delta: float, E: float, Delta: float, kernel: str = "bcc",
                     operator: str = "fft", unit: str = "m", name: str = "stress") -> ContactInstance:
    """Contact QP of a height map at far-field displacement ``Delta`` (paper section 2).

    Square maps go through ``InstanceBuilder`` (the surface is kept for solvers that
    need it); other shapes (the 2 x N strip) are assembled here from the same kernel
    tables, with no Surface attached.
    """
    h = np.asarray(heights, dtype=np.float64)
    if h.shape[0] == h.shape[1]:
        surf = Surface(h, delta, unit=unit, name=name)
        return InstanceBuilder(surf, E, kernel, periodic=False, operator=operator).build(Delta)
    idx = trial_set(h, Delta)
    ubar = np.maximum(rigid_body_ubar(h, Delta, idx), 0.0)
    geom = Geometry(h.shape, delta, idx, far_field=float(Delta), E=E, kernel=kernel, periodic=False)
    qp = QP(grid_operator(h.shape, delta, E, kernel, idx, operator), ubar, geom)
    return ContactInstance(qp, delta=float(Delta), E=E, kernel=kernel, periodic=False)


def packed_instance(n_target: int, density: float, kernel: str, seed: int, operator: str = "fft",
                    E: float = 1.0, delta: float = 1.0) -> ContactInstance:
    """The contact-family LCP of paper Example 1 generalised: H_II of ``kernel`` on a
    random set I of about ``n_target`` points packed at ``density`` in an N x N grid
    (N = round(sqrt(n_target / density))), ubar ~ U(0, 1)."""
    if not (0.0 < density <= 1.0):
        raise ProblemInputError(f"packing density must lie in (0, 1], got {density}")
    N = max(2, int(round(math.sqrt(n_target / density))))
    n = min(N * N, max(1, int(round(density * N * N))))
    rng = np.random.default_rng(seed)
    idx = np.arange(N * N) if n == N * N else np.sort(rng.choice(N * N, size=n, replace=False))
    ubar = rng.random(n)
    geom = Geometry((N, N), delta, idx, E=E, kernel=kernel, periodic=False)
    qp = QP(grid_operator((N, N), delta, E, kernel, idx, operator), ubar, geom)
    return ContactInstance(qp, delta=float("nan"), E=E, kernel=kernel, periodic=False,
                           meta={"density": n / (N * N), "N": N})


def random_spd_instance(n: int, seed: int) -> ContactInstance:
    """A random SPD matrix with positive entries, H = B B' / k + a I (B ~ U(0, 1)^{n x k},
    a ~ 1e-3 of the mean diagonal: one dominant Perron eigenvalue, the rest clustered
    low -- a hard conditioning profile), ubar ~ U(0, 1)."""
    rng = np.random.default_rng(seed)
    k = max(2, n // 2)
    B = rng.random((n, k))
    H = B @ B.T / k
    H += 1e-3 * float(np.mean(np.diag(H))) * np.eye(n)
    ubar = rng.random(n)
    return ContactInstance(QP(DenseOperator(H), ubar, None), delta=float("nan"), E=1.0, kernel="random-spd",
                           periodic=False, meta={"seed": seed})


def known_solution_instance(N: int, seed: int, kernel: str = "bcc", operator: str = "fft",
                            gap: float = NEAR_TOUCH_GAP, active_fraction: float = 0.5) -> ContactInstance:
    """An LCP built from its solution: p* > 0 on a random ``active_fraction`` of an N x N
    grid (1.0: every point in contact), w* > 0 elsewhere, ubar = H p* - w*.  A tenth of
    the inactive points are near-touching: w* = gap * max|H p*|.  The exact solution p*
    is in ``meta["p_exact"]``."""
    if not (0.0 < active_fraction <= 1.0):
        raise ProblemInputError(f"active_fraction must lie in (0, 1], got {active_fraction}")
    rng = np.random.default_rng(seed)
    n = N * N
    idx = np.arange(n)
    op = grid_operator((N, N), 1.0, 1.0, kernel, idx, operator)
    active = rng.random(n) < active_fraction if active_fraction < 1.0 else np.ones(n, dtype=bool)
    p_star = np.where(active, 0.1 + rng.random(n), 0.0)
    Hp = op.matvec(p_star)
    u_s = float(np.max(np.abs(Hp)))
    w_star = np.where(active, 0.0, (0.05 + rng.random(n)) * u_s)
    inactive = np.flatnonzero(~active)
    near = rng.choice(inactive, size=inactive.size // 10 or min(1, inactive.size), replace=False)
    w_star[near] = gap * u_s
    ubar = Hp - w_star
    op.matvec_count = 0
    geom = Geometry((N, N), 1.0, idx, E=1.0, kernel=kernel, periodic=False)
    return ContactInstance(QP(op, ubar, geom), delta=float("nan"), E=1.0, kernel=kernel, periodic=False,
                           meta={"p_exact": p_star, "near_touching": near.size, "gap": gap})


def rough_heights(N: int, seed: int, rms: float = 1e-6, length: float = 100e-6) -> Surface:
    """An RMD (H = 0.7) surface of N x N points, lengths in metres."""
    return rmd_surface_n(N, 0.7, length=length, rms_height=rms, seed=seed)


# ---------------------------------------------------------------------------
# Edge cases: each returns (heights, delta, Delta); lengths in metres, E = 1 GPa
# ---------------------------------------------------------------------------

EDGE_E = 1e9


def _edge_delta0(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    s = rough_heights(N, seed)
    return s.heights, s.delta, 0.0


def _edge_single_point(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    s = rough_heights(N, seed)
    top = np.sort(s.heights.ravel())[-2:]
    return s.heights, s.delta, 0.5 * float(top[1] - top[0])


def _edge_full_contact(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    return np.zeros((N, N)), 100e-6 / N, 1e-7


def _edge_two_equal(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    s = rough_heights(N, seed)
    h = s.heights.copy()
    order = np.argsort(h.ravel())
    h.ravel()[order[-2]] = h.ravel()[order[-1]]  # two identical maxima
    gap = float(h.ravel()[order[-1]] - h.ravel()[order[-3]])
    return h, s.delta, 0.5 * gap


def _edge_plateau(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    s = rough_heights(N, seed)
    h = s.heights - s.heights.max()
    c = N // 2
    r = max(1, N // 6)
    h[c - r:c + r, c - r:c + r] = 0.0  # a plateau of (2r)^2 equal maxima
    return h, s.delta, 1e-3 * s.rms_height


def _edge_strip(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    rng = np.random.default_rng(seed)
    h = 1e-6 * rng.standard_normal((2, 4 * N))
    return h, 100e-6 / (4 * N), 0.5 * float(h.max() - h.mean())


def _edge_dynamic_range(N: int, seed: int) -> tuple[np.ndarray, float, float]:
    s = rough_heights(N, seed)
    z = (s.heights - s.heights.min()) / (s.heights.max() - s.heights.min())
    h = 1e-6 * 10.0 ** (12.0 * (z - 1.0))  # heights from 1e-18 m to 1e-6 m
    return h, s.delta, float(h.max() - h.min())


EDGE_CASES: dict[str, Callable[[int, int], tuple[np.ndarray, float, float]]] = {
    "delta0": _edge_delta0,
    "single-point": _edge_single_point,
    "full-contact": _edge_full_contact,
    "two-equal-heights": _edge_two_equal,
    "plateau": _edge_plateau,
    "strip-2xN": _edge_strip,
    "dynamic-range": _edge_dynamic_range,
}


# ---------------------------------------------------------------------------
# Periodic problems on the whole grid
# ---------------------------------------------------------------------------


def periodic_builder(N: int, kernel: str, seed: int, operator: str = "fft") -> InstanceBuilder:
    """Periodic ``kernel`` on the periodic RMD surface ``rough_heights(N, seed)``, E = 1 GPa."""
    return InstanceBuilder(rough_heights(N, seed), EDGE_E, kernel, periodic=True, operator=operator)


@lru_cache(maxsize=8)
def periodic_exact(N: int, kernel: str, seed: int, factor: float) -> np.ndarray:
    """The exact solution of ``periodic_instance`` (read-only; cached: a recipe is
    rebuilt by every solve of the battery), certified on the whole grid."""
    b = periodic_builder(N, kernel, seed)
    p = exact_solution_on_subset(b.build(factor * paper_max_displacement(b.surface)).qp).p
    p.flags.writeable = False
    return p


def periodic_instance(N: int, kernel: str, seed: int, factor: float = PERIODIC_DISPLACEMENT,
                      operator: str = "fft") -> ContactInstance:
    """A periodic rough-surface problem on the whole N x N grid at Delta = ``factor``
    x ``paper_max_displacement`` with its exact solution in ``meta["p_exact"]``, and in
    meta the number of contact points and of those with ubar < 0 (below the rigid body)."""
    b = periodic_builder(N, kernel, seed, operator)
    inst = b.build(factor * paper_max_displacement(b.surface))
    p = periodic_exact(int(N), str(kernel), int(seed), float(factor)).copy()
    touching = p > 0
    return _with_meta(inst, p_exact=p, contact_points=int(np.count_nonzero(touching)),
                      below_rigid_body=int(np.count_nonzero(touching & (inst.qp.ubar < 0))))


# ---------------------------------------------------------------------------
# Recipes -> load sequences
# ---------------------------------------------------------------------------


def _single(spec: InstanceSpec, make: Callable[[], ContactInstance], delta: float = float("nan")) -> LoadSequence:
    return LoadSequence(spec.instance, [delta], lambda k: make())


def _with_meta(inst: ContactInstance, **meta: Any) -> ContactInstance:
    inst.meta.update(meta)
    return inst


def build_conditioning(spec: InstanceSpec) -> LoadSequence:
    p = spec.params
    return _single(spec, lambda: packed_instance(int(p["n"]), float(p["density"]), str(p["kernel"]),
                                                 int(p["seed"]), str(p.get("operator", "fft"))))


def build_units(spec: InstanceSpec) -> LoadSequence:
    """Steps = unit systems (``variant: units``) or moduli (``variant: E-range``) of one
    RMD surface at the paper's top displacement."""
    p = spec.params
    base = rough_heights(int(p["size"]), int(p["seed"]))
    Delta_m = paper_max_displacement(base)
    op = str(p.get("operator", "fft"))
    if p["variant"] == "units":
        systems = list(UNIT_SYSTEMS.items())

        def factory(k: int) -> ContactInstance:
            name, (lf, sf) = systems[k]
            surf = base.scaled(lf)
            E = float(p["E"]) * sf
            b = InstanceBuilder(replace(surf, unit=name.split("/")[0]), E, str(p["kernel"]), periodic=False,
                                operator=op)
            return _with_meta(b.build(Delta_m * lf), unit_system=name, length_factor=lf, stress_factor=sf)

        return LoadSequence(spec.instance, [Delta_m * lf for _, (lf, _) in systems], factory, surface=base)
    moduli = [float(e) for e in p.get("moduli", E_RANGE)]

    def factory_E(k: int) -> ContactInstance:
        b = InstanceBuilder(base, moduli[k], str(p["kernel"]), periodic=False, operator=op)
        return _with_meta(b.build(Delta_m), unit_system=f"E={moduli[k]:g}Pa")

    return LoadSequence(spec.instance, [Delta_m] * len(moduli), factory_E, surface=base)


def build_edge(spec: InstanceSpec) -> LoadSequence:
    p = spec.params
    case, N, seed = str(p["case"]), int(p["size"]), int(p["seed"])
    op = str(p.get("operator", "fft"))
    if case == "near-touching":
        return _single(spec, lambda: known_solution_instance(N, seed, str(p["kernel"]), op))
    h, delta, Delta = EDGE_CASES[case](N, seed)
    return _single(spec, lambda: _with_meta(heights_instance(h, delta, EDGE_E, Delta, str(p["kernel"]), op,
                                                              name=case), case=case), Delta)


def build_random(spec: InstanceSpec) -> LoadSequence:
    p = spec.params
    if p["family"] == "spd":
        return _single(spec, lambda: random_spd_instance(int(p["n"]), int(p["seed"])))
    return _single(spec, lambda: packed_instance(int(p["n"]), float(p["density"]), "bcc", int(p["seed"]),
                                                 str(p.get("operator", "dense")), E=0.01))


def build_precision(spec: InstanceSpec) -> LoadSequence:
    """A rough-surface instance whose ubar is handed over as float32 (the values are
    exactly representable in float64, so the float64 problem is well defined)."""
    p = spec.params
    s = rough_heights(int(p["size"]), int(p["seed"]))

    def make() -> ContactInstance:
        inst = InstanceBuilder(s, EDGE_E, str(p["kernel"]), operator=str(p.get("operator", "fft"))).build(
            paper_max_displacement(s))
        inst.qp = replace(inst.qp, ubar=inst.qp.ubar.astype(np.float32))
        return _with_meta(inst, dtype="float32")

    return _single(spec, make, paper_max_displacement(s))


def build_perturbation(spec: InstanceSpec) -> LoadSequence:
    """Step 0: a contact-family LCP; step 1: the same with ubar + eps d, ||d|| = ||ubar||."""
    p = spec.params
    eps = float(p.get("eps", PERTURBATION_EPS))

    def factory(k: int) -> ContactInstance:
        inst = packed_instance(int(p["n"]), float(p["density"]), str(p["kernel"]), int(p["seed"]),
                               str(p.get("operator", "fft")))
        if k == 1:
            d = np.random.default_rng(int(p["seed"]) + 7919).standard_normal(inst.n)
            d *= np.linalg.norm(inst.qp.ubar) / np.linalg.norm(d)
            inst.qp = replace(inst.qp, ubar=inst.qp.ubar + eps * d)
        return _with_meta(inst, perturbation_eps=eps if k == 1 else 0.0)

    return LoadSequence(spec.instance, [float("nan")] * 2, factory)


def build_counterexample(spec: InstanceSpec) -> LoadSequence:
    """Paper Example 1 (``problems.instances.counterexample``) as one battery recipe."""
    p = spec.params
    return _single(spec, lambda: counterexample(int(p["n"]), int(p["seed"]), operator=str(p.get("operator", "dense"))))


def build_packing(spec: InstanceSpec) -> LoadSequence:
    """Every point of an N x N grid in contact, with the exact solution known."""
    p = spec.params
    return _single(spec, lambda: known_solution_instance(int(p["size"]), int(p["seed"]), str(p["kernel"]),
                                                         str(p.get("operator", "fft")), active_fraction=1.0))


def build_periodic(spec: InstanceSpec) -> LoadSequence:
    """A periodic rough-surface problem on the whole grid, with its exact solution."""
    p = spec.params
    s = rough_heights(int(p["size"]), int(p["seed"]))
    return _single(spec, lambda: periodic_instance(int(p["size"]), str(p["kernel"]), int(p["seed"]),
                                                   float(p["displacement"]), str(p.get("operator", "fft"))),
                   float(p["displacement"]) * paper_max_displacement(s))


BUILDERS: dict[str, Callable[[InstanceSpec], LoadSequence]] = {
    "conditioning": build_conditioning,
    "units": build_units,
    "edge": build_edge,
    "random": build_random,
    "precision": build_precision,
    "perturbation": build_perturbation,
    "counterexample": build_counterexample,
    "packing": build_packing,
    "periodic": build_periodic,
    "constrained": build_constrained,
    "rectangular": build_rectangular,
}


# ---------------------------------------------------------------------------
# Recipe lists (sizes depend on the mode: "fast" for the test suite, "full")
# ---------------------------------------------------------------------------


def _spec(scene: str, group: str, instance: str, profile: str = "mid", compare: str = "none", **params: Any) -> InstanceSpec:
    return InstanceSpec(scene, f"{group}/{instance}",
                        {"group": group, "profile": profile, "compare": compare, **params})


def conditioning_specs(scene: str, sizes: tuple[int, ...], densities: tuple[float, ...],
                       kernels: tuple[str, ...] = ("bcc", "love"), seed: int = 0) -> list[InstanceSpec]:
    return [_spec(scene, "conditioning", f"{k}-n{n}-d{d:g}", kernel=k, n=int(n), density=float(d), seed=seed,
                  operator="fft")
            for k in kernels for n in sizes for d in densities]


def units_specs(scene: str, size: int, seed: int = 0) -> list[InstanceSpec]:
    common = {"size": int(size), "seed": seed, "kernel": "bcc", "E": 1e9, "operator": "fft"}
    return [_spec(scene, "units", f"unit-systems-N{size}", compare="units", variant="units", **common),
            _spec(scene, "units", f"E-range-N{size}", compare="units", variant="E-range",
                  moduli=list(E_RANGE), **common)]


def edge_specs(scene: str, size: int, seed: int = 0, kernel: str = "bcc") -> list[InstanceSpec]:
    cases = list(EDGE_CASES) + ["near-touching"]
    return [_spec(scene, "edge", f"{c}-N{size}", case=c, size=int(size), seed=seed, kernel=kernel, operator="fft")
            for c in cases]


def random_specs(scene: str, spd_sizes: tuple[int, ...], bcc_sizes: tuple[int, ...],
                 densities: tuple[float, ...], seeds: tuple[int, ...]) -> list[InstanceSpec]:
    out = [_spec(scene, "random", f"spd-n{n}-s{s}", family="spd", n=int(n), seed=int(s))
           for n in spd_sizes for s in seeds]
    out += [_spec(scene, "random", f"bcc-n{n}-d{d:g}-s{s}", family="bcc", n=int(n), density=float(d),
                  seed=int(s), operator="dense")
            for n in bcc_sizes for d in densities for s in seeds]
    return out


def precision_specs(scene: str, size: int) -> list[InstanceSpec]:
    return [_spec(scene, "precision", f"float32-ubar-N{size}", profile="high", size=int(size), seed=0,
                  kernel="bcc", operator="fft")]


def perturbation_specs(scene: str, n: int, seeds: tuple[int, ...] = (0,)) -> list[InstanceSpec]:
    return [_spec(scene, "perturbation", f"bcc-n{n}-d0.5-s{s}", profile="high", compare="perturbation",
                  kernel="bcc", n=int(n), density=0.5, seed=int(s), operator="fft", eps=PERTURBATION_EPS)
            for s in seeds]


def counterexample_specs(scene: str, sizes: tuple[int, ...], seeds: tuple[int, ...]) -> list[InstanceSpec]:
    return [_spec(scene, "counterexample", f"example1-n{n}-s{s}", n=int(n), seed=int(s), operator="dense")
            for n in sizes for s in seeds]


def packing_specs(scene: str, size: int, kernels: tuple[str, ...] = ("bcc", "love"), seed: int = 0) -> list[InstanceSpec]:
    return [_spec(scene, "packing", f"all-in-contact-{k}-N{size}", size=int(size), kernel=k, seed=seed,
                  operator="fft")
            for k in kernels]


def periodic_specs(scene: str, sizes: tuple[int, ...], kernels: tuple[str, ...] = ("spectral", "bcc"),
                   seed: int = 0, factor: float = PERIODIC_DISPLACEMENT) -> list[InstanceSpec]:
    return [_spec(scene, "periodic", f"whole-grid-{k}-N{N}", size=int(N), kernel=k, seed=seed,
                  displacement=float(factor), operator="fft")
            for N in sizes for k in kernels]


#: Sizes per mode.  "fast" keeps every case dense-solvable in well under a second.
MODES: dict[str, dict[str, Any]] = {
    "fast": {"cond_sizes": (100,), "densities": (1.0, 0.2), "units_size": 16, "edge_size": 16,
             "spd_sizes": (30,), "bcc_sizes": (64,), "random_densities": (0.1, 0.5, 1.0), "seeds": (0, 2),
             "precision_size": 32, "perturbation_n": 100, "example1_sizes": (400,), "example1_seeds": (0, 1, 2),
             "packing_size": 20, "periodic_sizes": (32,)},
    "full": {"cond_sizes": (100, 400, 1000), "densities": (1.0, 0.5, 0.1), "units_size": 32, "edge_size": 32,
             "spd_sizes": (50, 200), "bcc_sizes": (100, 400), "random_densities": (0.05, 0.3, 1.0),
             "seeds": (0, 1), "precision_size": 32, "perturbation_n": 400, "example1_sizes": (100, 400),
             "example1_seeds": tuple(range(10)), "packing_size": 32, "periodic_sizes": (32, 64)},
    # The stress scene: conditioning up to 1e5 (FFT operator; dense-only solvers are
    # skipped by the runner's memory model), the rest as in "full".
    "scene": {"cond_sizes": (100, 1000, 10000, 100000), "densities": (1.0, 0.2), "units_size": 64,
              "edge_size": 32, "spd_sizes": (50, 200), "bcc_sizes": (100, 400, 1600),
              "random_densities": (0.05, 0.3, 1.0), "seeds": (0, 1, 2), "precision_size": 64,
              "perturbation_n": 1000, "example1_sizes": (25, 100, 400), "example1_seeds": tuple(range(10)),
              "packing_size": 64, "periodic_sizes": (32, 64)},
}


def battery_specs(mode: str = "fast", groups: tuple[str, ...] = GROUPS, scene: str = "stress") -> list[InstanceSpec]:
    """Every recipe of the battery at the sizes of ``mode`` ("fast", "full", "scene")."""
    if mode not in MODES:
        raise ProblemInputError(f"unknown battery mode {mode!r}; choose one of {', '.join(MODES)}")
    m = MODES[mode]
    makers: dict[str, Callable[[], list[InstanceSpec]]] = {
        "conditioning": lambda: conditioning_specs(scene, m["cond_sizes"], m["densities"]),
        "units": lambda: units_specs(scene, m["units_size"]),
        "edge": lambda: edge_specs(scene, m["edge_size"]),
        "random": lambda: random_specs(scene, m["spd_sizes"], m["bcc_sizes"], m["random_densities"], m["seeds"]),
        "precision": lambda: precision_specs(scene, m["precision_size"]),
        "perturbation": lambda: perturbation_specs(scene, m["perturbation_n"]),
        "counterexample": lambda: counterexample_specs(scene, m["example1_sizes"], m["example1_seeds"]),
        "packing": lambda: packing_specs(scene, m["packing_size"]),
        "periodic": lambda: periodic_specs(scene, m["periodic_sizes"]),
        "constrained": lambda: constrained_specs(scene),
        "rectangular": lambda: rectangular_specs(scene),
    }
    unknown = set(groups) - set(makers)
    if unknown:
        raise ProblemInputError(f"unknown stress group(s) {sorted(unknown)}; choose from {', '.join(GROUPS)}")
    return [s for g in groups for s in makers[g]()]


def build_battery_spec(spec: InstanceSpec) -> LoadSequence:
    """The load sequence of any battery recipe (dispatch on ``params['group']``)."""
    return BUILDERS[str(spec.params["group"])](spec)


# ---------------------------------------------------------------------------
# Scenes
# ---------------------------------------------------------------------------


class _StressScene(Scene):
    """Shared behaviour: recipes from ``battery_specs``; ``extra['mode']`` picks the
    sizes ("scene" by default, "full" or "fast" for quicker runs); ``size`` caps n."""

    groups: tuple[str, ...] = GROUPS
    defaults = SceneConfig(extra={"mode": "scene"})
    options = frozenset[str]()  # every recipe is the battery's own
    load_history = False

    def instances(self, cfg: SceneConfig) -> list[InstanceSpec]:
        specs = battery_specs(str(cfg.extra.get("mode", "scene")), self.groups, scene=self.name)
        cap = cfg.extra.get("max_n")
        if cap is not None:
            specs = [s for s in specs if int(s.params.get("n", 0)) <= int(cap)]
        return specs

    def build(self, spec: InstanceSpec) -> LoadSequence:
        return build_battery_spec(spec)


@register_scene
class StressScene(_StressScene):
    """The whole numerical-stability battery."""

    name = "stress"
    description = "numerical-stability battery: conditioning, units, edge cases, random LCPs, float32, perturbation"


def _group_scene(group: str, text: str) -> type[_StressScene]:
    cls = type(f"Stress{group.title()}Scene", (_StressScene,), {
        "name": f"stress-{group}", "description": text, "groups": (group,),
        "__doc__": f"The '{group}' part of the stress battery: {text}."})
    return register_scene(cls)


_group_scene("conditioning", "cond(H_II) of BCC and Love kernels vs n (1e2-1e5) and packing density")
_group_scene("units", "one problem in m/Pa, um/MPa, nm/GPa and E over 12 decades")
_group_scene("edge", "Delta=0, single point, full contact, equal maxima, plateau, 2xN strip, dynamic range, w~1e-14")
_group_scene("random", "random SPD positive-entry LCPs and BCC with random ubar, sparse to fully packed")
_group_scene("precision", "float32 ubar: solved in float64 or refused")
_group_scene("perturbation", "ubar vs ubar + 1e-6 perturbation: p must move continuously")
_group_scene("counterexample", "paper Example 1 (all of an N x N grid in the trial set, ubar ~ U(0,1)) at n = 400")
_group_scene("packing", "full packing: every point of an N x N grid in contact, exact solution known")
_group_scene("periodic", "periodic rough surfaces (spectral, BCC) on the whole grid: singular H, ubar < 0 touches")
_group_scene("constrained", "load control, a hardness bound, and both, on a 16^2 rough surface")
_group_scene("rectangular", "a 48 x 32 map with square pixels (BCC) and with 1.5:1 pixels (Love)")
