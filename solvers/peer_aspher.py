"""ASPHER (Yastrebov et al., BSD-3; ``pip install contactbench[peers]``, built from its
sdist: docs/peers.md) as registered solvers, judged raw by our KKT check.

What ASPHER poses.  Normal contact of a rigid surface on an elastic half-space under
*load control*: ``gap`` (the separation of an N x N grid of square elements at zero
approach) and ``p_nominal`` (the mean pressure) given, the pressure field and the rigid
approach returned.  Its operators are

* free space (non-periodic): the exact Love (uniformly loaded square) kernel, applied by
  zero-padded FFT convolution (``backend="fft"``) or by its matrix-free H^2/FMM
  approximation (``backend="h2"``) -- our non-periodic ``love`` kernel;
* doubly periodic (``backend="periodic"``): the compliance 2/(E* |q|) on the torus with the
  q = 0 mode removed -- our periodic ``spectral`` kernel (not our periodic ``love``, the
  real-space Love kernel summed over images).

So it poses exactly: kernel ``love`` non-periodic or ``spectral`` periodic, a square grid of
square elements, a half-space (no layer), load control, no hardness.  Everything else is
skipped with the reason (``aspher_serves``): BCC, periodic Love, a layer, a hardness,
rectangular pixels or grids.

Displacement control.  ASPHER takes a mean pressure, never an approach.  A
displacement-controlled QP of at most ``EXACT_LOAD_MAX_N`` unknowns is translated exactly:
ASPHER is handed the load of our exact answer (``problems.lcp.exact_solution``, periodic
``exact_solution_on_subset``: dense, in the solve's setup time, not ASPHER's), which has the same unique answer;
the row says so (``info["posing"]``, ``info["exact_load"]``, and ASPHER's approach, ~0 for
this posing, in ``info["approach_m"]``).  Larger ones are skipped with the reason.

Units.  The problem is handed over dimensionless (ASPHER's ``domain_size = 1``,
``E_star = 1``): lengths in units of the side L = N delta, stresses in units of E*.  With
our QP's full-grid field U (solvers/_peers.py; U = xi - xi_max under load control),
``gap = -U / L`` and ``p_nominal = P / (E* L^2)``.  ASPHER's pressure p' is read back as
the force per element p' E* delta^2 (our force units), its approach a' as the load-control
multiplier Delta = a' L (its gap g = gap + S p - a is our w = Hp - ubar - Delta / L).

Tolerance.  ASPHER's certified errors are relative to its gap scale g_ref = max(gap) -
min(gap); our scaled KKT error to u_s (problems.kkt.constrained_scales).  It is handed
``tol x min(1, u_s / (L g_ref))`` (``handed_tol``: its penetration bound is then at most
ours, tol u_s, and never looser than ``tol``; under load control u_s = L g_ref on the whole
grid and it gets ``tol`` itself).

Its claim.  ``converged`` is ASPHER's own status ("converged": its Frank-Wolfe certificate
and penetration error below ``tol``), read as a claim only at the tolerance asked: where it
relaxed it (``effective_tol`` above ``requested_tol``: single precision stops at its
``float_floor`` 2e-6) the solve is STALLED, and the note says so; the certified figures (``fw_error``,
``penetration_error``, ``load_error``, ``status``) go to ``info`` as its claim.  The verdict
is our judge's, on our operator.

Threads.  ASPHER runs OpenMP; each solve sets its OpenMP threads to our FFT thread count
(``problems.operators.fft_workers``: ``CONTACTBENCH_FFT_WORKERS``, which the harness's
``--threads`` sets) through threadpoolctl, and records it in ``info["threads"]``.

Registrations (one per configuration):

aspher-pcg
    ``ContactSolver(backend="fft" | "periodic").solve(..., precond=...)``: Polonsky-Keer
    CG on the exact FFT operator with its |q| preconditioner (``precond``: "fourier", the
    13-tap stencil on the contact set; "fourier-fft", the full-grid transform; "none").
    Warm start: primal (``p_init``).
aspher-nested
    ``solve_nested(backend="fft" | "periodic", precision="double")``: the nested-grid
    (cascadic) continuation from the coarsest level (``coarsest_level``) up, each level
    warm-started by the prolonged coarse pressure, preconditioned.  ``backend="h2"``
    (non-periodic) runs it on its H^2/FMM operator instead, an approximation of the Love
    operator (Chebyshev order ``q``): certified on its operator, judged on ours.
    Warm start: none.
aspher-nested-f32
    ``solve_nested(backend="fft" | "periodic", precision="float_then_double")``: the
    contact identified in single precision, polished in double to ``tol``
    (``precision="float"``: single only, which cannot go below ASPHER's ``float_floor``
    2e-6 and then says "stagnated: precision_limit").  Warm start: none.
aspher-active-f32
    ``solve_nested(backend="h2", active_set=True, precision="float")``: its large-grid path
    (single precision, the finest level restricted to candidate points, on its H^2
    operator, where alone it has the active set): non-periodic only.  Handed our ``tol``,
    it stops at its float floor and says so (not a claim of convergence); its promise is
    the floor ``ACTIVE_F32_FLOOR`` of scaled KKT error (docs/peers.md has the figures).

Matvecs are ASPHER's own count (``matvec_count``, every level of a nested solve, plus its
verification products); the stages (level, precision, iterations, matvecs) are in
``info["stages"]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from typing import Any

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP
from contactbench.problems.lcp import UncertifiedSolutionError, exact_solution, exact_solution_on_subset
from contactbench.problems.kkt import constrained_scales
from contactbench.problems.operators import fft_workers

from ._peers import INSTALL_HINT, GridProblem, PeerSolver, full_field, grid_problem, package_availability
from .base import Capabilities, Outcome, Param, ProblemTraits, SolveContext, Status
from .registry import register

#: The install hint of ASPHER (an sdist: it builds with CMake against Eigen 3.4).
ASPHER_HINT = ("pip install contactbench[peers] (aspher>=0.1.3, built from its sdist; "
               "`make setup-peers` installs Debian's libeigen3-dev for it first)")
#: Our kernel that ASPHER's operator is, by periodicity.
ASPHER_KERNEL = {False: "love", True: "spectral"}
#: ASPHER's coarsest nested level (its default); smaller grids start at their own size.
COARSEST = 64
#: The scaled KKT floor aspher-active-f32 promises: its float floor (2e-6 of its own
#: certificate) on its H^2 operator (measured by our judge: 1.2e-6 at 64^2, q = 6).
ACTIVE_F32_FLOOR = 1e-5
#: Largest displacement-controlled QP translated to the load of its exact answer (dense).
EXACT_LOAD_MAX_N = 4096
#: ASPHER's termination states, as ours.
STATUSES = {"converged": Status.CONVERGED, "max_iterations": Status.MAX_ITER, "stagnated": Status.STALLED,
            "nonpositive_curvature": Status.STALLED, "verification_failed": Status.STALLED,
            "nonfinite": Status.FAILED, "resource_limit": Status.FAILED}


def aspher_version() -> str:
    """The installed ASPHER's version (its module has no ``__version__``)."""
    try:
        return metadata.version("aspher")
    except metadata.PackageNotFoundError:
        return "?"


def aspher_serves(kernel: str, periodic: bool, layer: bool = False, bounded: bool = False) -> str | None:
    """None when ASPHER poses exactly this problem, else the reason it does not (module doc)."""
    if layer:
        return "ASPHER has no elastic layer of finite thickness (its operators are the half-space's)"
    if bounded:
        return "ASPHER poses no hardness (no upper bound on the pressure)"
    if kernel != ASPHER_KERNEL[periodic]:
        return (f"ASPHER cannot pose the {'periodic' if periodic else 'non-periodic'} {kernel!r} kernel "
                "(its operators: non-periodic Love, periodic 2/(E*|q|), i.e. our 'spectral')")
    return None


def displacement_served(n: int, load_control: bool) -> str | None:
    """None when the control can be handed to ASPHER (module doc), else why not."""
    if load_control or n <= EXACT_LOAD_MAX_N:
        return None
    return (f"ASPHER poses load control only; a displacement-controlled problem is handed the load of its exact "
            f"answer, computed densely up to n = {EXACT_LOAD_MAX_N} (this one has n = {n})")


def exact_load(qp: QP) -> tuple[float, dict[str, Any]]:
    """The total force of the exact answer of a displacement-controlled ``qp`` and how it
    was found (``ProblemInputError`` when it cannot be certified)."""
    periodic = bool(qp.geometry is not None and qp.geometry.periodic)
    try:  # periodic: H is singular on the whole grid, so on growing proper subsets
        p = exact_solution_on_subset(qp).p if periodic else exact_solution(qp.H.to_dense(), qp.ubar).p
    except (UncertifiedSolutionError, np.linalg.LinAlgError, RuntimeError) as exc:
        raise ProblemInputError(f"the exact answer's load, handed to ASPHER, could not be certified: {exc}") from None
    how = "exact_solution_on_subset" if periodic else "exact_solution"
    return float(np.sum(p)), {"posing": f"load control at the load of the exact answer ({how}, setup time)"}


def square_grid(gp: GridProblem) -> str | None:
    """None on an N x N grid of square elements, else why ASPHER cannot take it."""
    if gp.shape[0] != gp.shape[1] or gp.delta1 not in (None, gp.delta):
        return (f"ASPHER poses an N x N grid of square elements (grid_size, domain_size); this grid is "
                f"{gp.shape[0]} x {gp.shape[1]} with spacings {gp.spacing}")
    return None


def coarsest_level(N: int, coarsest: int = COARSEST, smallest: int = 8) -> int:
    """ASPHER's coarsest nested level for an N-point side (its nested solve needs
    N = coarsest 2^k): N halved at least once, and while above ``coarsest``, but not below
    ``smallest``; N itself when it cannot be halved (odd, or below 2 ``smallest``)."""
    c = N
    while c % 2 == 0 and c // 2 >= smallest and (c == N or c > coarsest):
        c //= 2
    return c


@dataclass(frozen=True)
class Posed:
    """One QP in ASPHER's dimensionless variables (module doc)."""

    gp: GridProblem
    side: float  # L = N delta (m): the length unit
    gap: np.ndarray  # N x N, -U / L
    p_nominal: float  # P / (E* L^2)
    how: dict[str, Any]  # the posing, for the row (module doc)

    @property
    def force_per_pressure(self) -> float:
        """Force per element (N) of a dimensionless pressure 1: E* delta^2."""
        return self.gp.E * self.gp.area

    def force(self, pressure: Any) -> np.ndarray:
        return np.asarray(pressure, dtype=np.float64).reshape(self.gp.shape) * self.force_per_pressure

    def pressure(self, force: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(force.reshape(self.gp.shape) / self.force_per_pressure)


def posed(ctx: SolveContext) -> Posed:
    """The QP as ASPHER's problem; ``ProblemInputError`` when it is not one (module doc)."""
    gp = grid_problem(ctx.qp)
    c = ctx.constraints
    why = (aspher_serves(gp.kernel, gp.periodic, gp.layer is not None, c.bounded)
           or displacement_served(ctx.n, c.load_control) or square_grid(gp))
    if why is not None:
        raise ProblemInputError(why)
    load, how = (float(c.load), {"posing": "load control (native)"}) if c.load_control else exact_load(ctx.qp)
    side = gp.delta * gp.shape[0]
    return Posed(gp, side, np.ascontiguousarray(-gp.U / side), load / (gp.E * side * side), {**how, "load": load})


def handed_tol(pz: Posed, ctx: SolveContext) -> float:
    """Our ``tol`` in ASPHER's units (module doc): tol min(1, u_s / (L g_ref))."""
    g_ref = float(np.ptp(pz.gap)) * pz.side
    u_s, _ = constrained_scales(ctx.qp.ubar, ctx.diag_max, ctx.constraints, ctx.ubar_scale())  # (the judge's)
    return float(ctx.tol) * (min(1.0, u_s / g_ref) if g_ref > 0.0 and u_s > 0.0 else 1.0)


def claim_info(res: Any, threads: int, config: dict[str, Any]) -> dict[str, Any]:
    """ASPHER's own certified figures and counts (its claim, not the verdict)."""
    stages = [f"{s['name']}:{s['precision']}:{s['iterations']}it/{s['matvec_count']}mv"
              for s in getattr(res, "stage_stats", [])]
    return {**config, "threads": threads, "peer_status": str(res.status), "peer_reason": str(res.status_reason),
            "peer_iterations": int(res.iterations), "fw_error": float(res.fw_error),
            "effective_tol": float(res.effective_tol),
            "penetration_error": float(res.penetration_error), "load_error": float(res.load_error),
            "peer_matvecs": int(res.matvec_count), "verification_matvecs": int(res.verification_matvec_count),
            "precond_applications": int(res.precond_count), "stages": " ".join(stages),
            "peer_seconds": float(res.timings["total"]), "peer_memory_peak_bytes": int(res.memory["peak"])}


def aspher_outcome(pz: Posed, res: Any, ctx: SolveContext, threads: int, config: dict[str, Any]) -> Outcome:
    """ASPHER's raw answer on the trial set, in our force units, with its approach as the
    multiplier and its claim in ``info``."""
    force = pz.force(res.pressure)
    p = pz.gp.on_set(force)
    off = pz.gp.force_off_set(force)
    ctx.add_matvecs(int(res.matvec_count) + int(res.verification_matvec_count))
    relaxed = float(res.effective_tol) > float(res.requested_tol)  # it stopped at a looser tol than asked
    claimed = str(res.status) == "converged" and not relaxed
    status = Status.FAILED if not np.all(np.isfinite(p)) else STATUSES.get(str(res.status), Status.FAILED)
    if status is Status.CONVERGED and relaxed:
        status = Status.STALLED
    note = (f"ASPHER {res.status}: fw_error {res.fw_error:.1e}, penetration {res.penetration_error:.1e}"
            + (f" ({res.status_reason})" if res.status_reason else "")
            + (f"; at its effective tol {res.effective_tol:.0e} > the {res.requested_tol:.0e} asked" if relaxed else "")
            + (f"; force off the trial set {off:.1e} of max" if off > 0 else ""))
    approach = float(res.approach) * pz.side
    info = {**pz.how, **claim_info(res, threads, config), "force_off_set": off, "approach_m": approach,
            "tol_handed": float(res.requested_tol)}
    return Outcome(p, int(res.iterations), claimed, note, status=status, info=info, multiplier=approach)


class _AspherSolver(PeerSolver):
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none", load_control=True)

    def availability(self) -> tuple[bool, str]:
        ok, why = package_availability("aspher", "ASPHER")
        return ok, f"available (ASPHER {aspher_version()})" if ok else why.replace(INSTALL_HINT, ASPHER_HINT)

    def default_max_iter(self, n: int) -> int | None:
        return 20_000

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why:
            return why
        if traits.rectangular:
            return ("ASPHER poses an N x N grid of square elements (grid_size, domain_size); this problem's grid "
                    "or its pixels are rectangular")
        # a problem without a surface is checked when posed (``square_grid``)
        return aspher_serves(traits.kernel, traits.periodic, traits.layer, traits.bounded) or displacement_served(
            traits.n, traits.load_control)

    def solve_posed(self, pz: Posed, ctx: SolveContext) -> tuple[Any, dict[str, Any]]:
        """ASPHER's result on the posed problem, and the configuration it ran."""
        raise NotImplementedError

    def iterate(self, ctx: SolveContext) -> Outcome:
        from threadpoolctl import threadpool_limits

        pz = posed(ctx)
        threads = fft_workers()
        ctx.mark_setup_done()
        if pz.p_nominal <= 0.0:  # no load: no contact (ASPHER takes a positive load)
            return Outcome(np.zeros(ctx.n), 0, True, "zero load: p = 0", info={**pz.how, "threads": threads})
        with threadpool_limits(limits=threads, user_api="openmp"):
            try:
                res, config = self.solve_posed(pz, ctx)
            except ValueError as exc:  # its own check of the input, before it solves
                raise ProblemInputError(f"ASPHER refuses the problem: {exc}") from None
        return aspher_outcome(pz, res, ctx, threads, {**config, "aspher": aspher_version()})


@register
class AspherPCG(_AspherSolver):
    """ASPHER's preconditioned Polonsky-Keer CG on its exact FFT operator (free-space Love
    or periodic 2/(E*|q|)), load control (module doc).  Warm start: primal (``p_init``)."""

    name = "aspher-pcg"
    description = ("ASPHER: Polonsky-Keer CG with its |q| preconditioner on the exact FFT operator, "
                   "load control [peers extra]")
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="primal", load_control=True)
    params = (Param("precond", str, "fourier", "fourier: its 13-tap |q| stencil; fourier-fft: full-grid; none",
                    choices=("fourier", "fourier-fft", "none")),)

    def solve_posed(self, pz: Posed, ctx: SolveContext) -> tuple[Any, dict[str, Any]]:
        import aspher

        backend = "periodic" if pz.gp.periodic else "fft"
        solver = aspher.ContactSolver(grid_size=pz.gp.shape[0], domain_size=1.0, E_star=1.0, backend=backend)
        init = None if ctx.p0 is None else pz.pressure(full_field(pz.gp, ctx.p0))
        res = solver.solve(pz.gap, p_nominal=pz.p_nominal, tol=handed_tol(pz, ctx), max_iter=int(ctx.max_iter),
                           precond=ctx.params["precond"], p_init=init)
        return res, {"entry": "ContactSolver.solve", "backend": backend, "precond": ctx.params["precond"]}


class _AspherNested(_AspherSolver):
    """``aspher.solve_nested`` with this registration's backend, active set and precision
    (``params`` may override ``backend``, ``precision`` and ``q``)."""

    free_backend: str = "fft"
    active_set: bool = False
    precision: str = "double"
    limit_per_stage = True  # ``solve_nested``'s max_iter bounds each level and precision

    def solve_posed(self, pz: Posed, ctx: SolveContext) -> tuple[Any, dict[str, Any]]:
        import aspher

        periodic = pz.gp.periodic
        backend = "periodic" if periodic else ctx.params.get("backend", self.free_backend)
        precision = ctx.params.get("precision", self.precision)
        q = int(ctx.params.get("q", 6))
        N = pz.gp.shape[0]
        coarsest = coarsest_level(N)
        res = aspher.solve_nested(grid_size=N, gap=pz.gap.ravel(), p_nominal=pz.p_nominal, domain_size=1.0,
                                  E_star=1.0, coarsest=coarsest, q=q, tol=handed_tol(pz, ctx),
                                  max_iter=int(ctx.max_iter), precision=precision, backend=backend,
                                  active_set=self.active_set)
        return res, {"entry": "solve_nested", "backend": backend, "precision": precision,
                     "active_set": self.active_set, "coarsest": coarsest, **({"q": q} if backend == "h2" else {})}


Q_PARAM = Param("q", int, 6, "Chebyshev order of its H^2 operator (backend h2)", low=2, high=16)


@register
class AspherNested(_AspherNested):
    """ASPHER's nested-grid (cascadic) solve in double on its exact FFT operator
    (free-space Love or periodic 2/(E*|q|)), or on its H^2 operator (non-periodic,
    ``backend="h2"``), load control (module doc).  Warm start: none."""

    name = "aspher-nested"
    description = "ASPHER: nested-grid continuation, preconditioned PK CG in double, exact FFT operator [peers extra]"
    params = (Param("backend", str, "fft", "non-periodic operator: fft (exact Love convolution) or h2 (its FMM)",
                    choices=("fft", "h2")), Q_PARAM)


@register
class AspherNestedF32(_AspherNested):
    """ASPHER's nested solve with the contact found in single precision and polished in
    double, on its exact FFT operator (free-space Love or periodic 2/(E*|q|)), load
    control (module doc).  Warm start: none."""

    name = "aspher-nested-f32"
    description = ("ASPHER: nested-grid solve, contact found in single precision then polished in double, "
                   "exact FFT operator [peers extra]")
    precision = "float_then_double"
    params = (Param("precision", str, "float_then_double",
                    "float_then_double: contact found in float, polished in double to tol; float: float only",
                    choices=("float_then_double", "float")),)


@register
class AspherActiveF32(_AspherNested):
    """ASPHER's large-grid path: nested, single precision, the finest level on an active
    set, on its H^2 operator; non-periodic only; promise: ``ACTIVE_F32_FLOOR`` (module
    doc).  Warm start: none."""

    name = "aspher-active-f32"
    description = ("ASPHER: nested solve in single precision on an active set, H^2/FMM operator, non-periodic "
                   "[peers extra]")
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none", load_control=True,
                                promise=ACTIVE_F32_FLOOR)
    free_backend = "h2"
    active_set = True
    precision = "float"
    params = (Q_PARAM,)

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why is None and traits.periodic:
            return "ASPHER's active set runs on its H^2 operator only, which is free-space (non-periodic)"
        side = traits.surface_side
        if why is None and side and coarsest_level(side) == side:
            return (f"ASPHER's active set needs a coarser nested level below the finest, and an N = {side} side "
                    "cannot be halved (N = coarsest 2^k)")
        return why
