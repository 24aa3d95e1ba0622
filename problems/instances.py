"""Contact QP instances (paper section 2) and load sequences.

For a surface xi on an N x N grid and a far-field displacement Delta >= 0:

* trial set  I_C = {(i, j): xi_ij >= xi_max - Delta}
* ubar_ij = Delta - xi_max + xi_ij  on I_C  (the rigid-body interpenetration)
* H = influence coefficients restricted to I_C

The QP is  min 1/2 p'Hp - ubar'p  s.t. p >= 0, equivalently the LCP
w = Hp - ubar >= 0, p >= 0, w'p = 0.  p is the force on each element (N when E is
in Pa and lengths in m), so the total load is P = sum(p).

Two generalisations live on the QP's ``constraints`` (``problems.constraints``):

* a hardness H_A bounds every element, 0 <= p <= H_A delta^2 (``InstanceBuilder.build``
  and ``build_load`` with ``hardness=``);
* load control (``InstanceBuilder.build_load``): the total force P is given and the
  approach Delta is the multiplier of sum(p) = P.  Delta being unknown, the trial set
  is the whole grid and ubar = xi - xi_max (ubar at Delta = 0), so the multiplier is
  the far-field displacement itself: w = Hp - ubar - Delta.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from .constraints import CONTROLS, Constraints, fit_multiplier, hardness_bounds, make_constraints
from .errors import MemoryBudgetError, ProblemInputError, check_nonnegative, check_positive, check_whole
from .kernels import check_kernel, kernel_table
from .kkt import constrained_scales, problem_scales
from .layers import Layer
from .operators import (ContactOperator, DenseOperator, FFTOperator, KernelTransform, budget_or_default,
                        check_dense_budget, check_positions)
from .operators_gpu import ArrayFFTOperator, ArrayKernelTransform, gpu_unavailable_reason
from .preprocessing import MapPreprocessing
from .surfaces import Surface, check_grid_size, check_not_flat, check_seed, read_only

OperatorKind = Literal["fft", "dense", "gpu"]
#: The operator kinds an instance can be built with: the matrix-free FFT operator, the
#: dense n x n block, and the FFT operator on a CUDA device (CuPy; the optional ``gpu`` extra).
OPERATOR_KINDS: tuple[str, ...] = ("fft", "dense", "gpu")


def check_operator_kind(kind: str) -> str:
    """``kind`` if instances can be built with it on this machine, else ``ProblemInputError``
    (an unknown kind, or "gpu" where CuPy or a CUDA device is missing).  Cheap: the
    up-front check for a run."""
    if kind not in OPERATOR_KINDS:
        raise ProblemInputError(f"operator must be 'fft' or 'dense', got {kind!r} "
                                "(or 'gpu' where CuPy and a CUDA device exist)")
    if kind == "gpu":
        reason = gpu_unavailable_reason()
        if reason is not None:
            raise ProblemInputError(f"operator 'gpu' is not available here: {reason}")
    return kind


#: The relative test of ``contact_mask``: p_i > CONTACT_THRESHOLD * max(p).
CONTACT_THRESHOLD = 1e-9
#: The tolerance of the contact reading (``ContactInstance.contact_mask``) when the judge's
#: check tolerance is not given: the default profile's ``check_tol``.
CONTACT_TOL = 1e-6
#: Half-width, as a factor, of the band around the contact floor whose elements count as
#: "contact uncertain" (``ContactInstance.contact_uncertain``): a decade either side.
CONTACT_BAND = 10.0


@dataclass(frozen=True)
class Geometry:
    """Where the QP's unknowns sit on the physical grid (for warm-start mapping,
    field reconstruction and the cascade multi-resolution method)."""

    grid_shape: tuple[int, int]
    delta: float
    indices: np.ndarray  # flat indices into grid_shape, one per unknown
    # Physical context, for solvers that rebuild related problems (CMR builds the
    # coarse-level instances of the same surface at the same far-field displacement).
    surface: Surface | None = None
    far_field: float | None = None
    E: float | None = None
    kernel: str | None = None
    periodic: bool | None = None
    #: Spacing along axis 1 (None: square elements, ``delta``); the elastic layer (None: half-space).
    delta1: float | None = None
    layer: Layer | None = None

    def __post_init__(self) -> None:
        """The trial set is read-only (``surfaces.read_only``, its integer type kept)."""
        object.__setattr__(self, "indices", read_only(self.indices, None))

    @property
    def spacing(self) -> tuple[float, float]:
        """(d0, d1): the grid spacings along axis 0 and axis 1."""
        return (float(self.delta), float(self.delta if self.delta1 is None else self.delta1))

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) element-centre coordinates."""
        i, j = np.divmod(self.indices, self.grid_shape[1])
        return np.column_stack([i, j]).astype(np.float64) * np.asarray(self.spacing)

    @property
    def has_surface(self) -> bool:
        """Whether the QP can be rebuilt from its surface: the surface (on this grid), the
        far-field displacement, E and the kernel are all known.  The cascade
        multi-resolution method needs this (``ProblemTraits.has_surface``)."""
        return self.far_field is not None and self.has_surface_under_load

    @property
    def has_surface_under_load(self) -> bool:
        """``has_surface`` for a QP under load control, which poses no far-field
        displacement: the surface (on this grid), E and the kernel are known."""
        return (self.surface is not None and self.E is not None and self.kernel is not None
                and tuple(self.grid_shape) == self.surface.shape)

    def subset(self, pos: np.ndarray) -> "Geometry":
        """The geometry of the unknowns at positions ``pos`` (0..n-1) of this one."""
        return replace(self, indices=self.indices[np.asarray(pos)])


@dataclass(frozen=True, eq=False)
class QP:
    """What a solver sees (frozen): the operator H (n x n, SPD) and the vector ubar.

    ``geometry`` is optional and read only by solvers that need positions (CMR).
    ``constraints``: upper bounds and a load equality beyond p >= 0
    (``problems.constraints``; the default poses none); its bounds have ubar's shape.
    """

    H: ContactOperator
    ubar: np.ndarray
    geometry: Geometry | None = None
    constraints: Constraints = field(default_factory=Constraints)

    def __post_init__(self) -> None:
        up = self.constraints.upper
        if up is not None and up.shape != self.ubar.shape:
            raise ProblemInputError(f"upper bounds must have the shape of ubar {self.ubar.shape}, got {up.shape}")

    @property
    def n(self) -> int:
        return int(self.ubar.size)

    def objective(self, p: np.ndarray) -> float:
        return float(0.5 * p @ self.H.matvec(p) - self.ubar @ p)

    def restrict(self, pos: np.ndarray) -> "QP":
        """The QP on the unknowns at positions ``pos`` (0..n-1): H_PP, ubar_P and their
        geometry (the others held at p = 0).  ``pos``: distinct positions or a boolean mask
        of length n (``check_positions``)."""
        pos = check_positions(pos, self.n)
        geom = None if self.geometry is None else self.geometry.subset(pos)
        return QP(self.H.restrict(pos), self.ubar[pos], geom, self.constraints.restrict(pos))

    def scaled(self, factor: float) -> "QP":
        """This QP with ubar, the bounds and the load times ``factor``: its answer, gap and
        approach are factor times this one's, its scaled KKT figures the same."""
        return QP(self.H, self.ubar * factor, self.geometry, self.constraints.scaled(factor))

    def can_touch(self, load: float, approach: float = 0.0) -> np.ndarray | None:
        """Positions that can carry force in the solution if its total force sum(p) is at
        most ``load`` and its approach (the load equality's multiplier Delta; 0 without
        one) at most ``approach`` (a safe screening rule): with f <= H_ij for all i, j
        (``ContactOperator.entry_floor``) and p >= 0, w_i = (Hp)_i - ubar_i - Delta >=
        f sum(p) - ubar_i - Delta >= f load - ubar_i - approach, so w_i = 0 needs
        ubar_i >= f load - approach.  With an aperiodic kernel (f = 0) and no approach this
        is the rigid-body set {ubar >= 0}; with a periodic one (f < 0, the surface rises
        between contacts) a margin below it.  None when the operator has no entry floor."""
        floor = self.H.entry_floor()
        if floor is None:
            return None
        return np.flatnonzero(self.ubar >= floor * max(float(load), 0.0) - float(approach))


@dataclass
class ContactInstance:
    """One contact QP at one far-field displacement, with its physical context."""

    qp: QP
    delta: float  # far-field displacement Delta (length unit)
    E: float  # composite modulus E*
    kernel: str
    periodic: bool
    surface: Surface | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.qp.n

    @property
    def geometry(self) -> Geometry | None:
        return self.qp.geometry

    @property
    def total_elements(self) -> int:
        g = self.qp.geometry
        return int(np.prod(g.grid_shape)) if g is not None else self.n

    @property
    def nominal_area(self) -> float:
        g = self.qp.geometry
        if g is None:
            return float(self.n)
        return float(np.prod(g.grid_shape)) * g.spacing[0] * g.spacing[1]

    def load(self, p: np.ndarray) -> float:
        """Total force P = sum p_ij."""
        return float(np.sum(p))

    def dimensionless_load(self, p: np.ndarray) -> float:
        """P / (E A), A = L^2 the nominal area (paper Fig. 4 abscissa)."""
        return self.load(p) / (self.E * self.nominal_area)

    @property
    def control(self) -> str:
        """One of ``constraints.CONTROLS``: "load" when the total force is given
        (``QP.constraints.load``), else "displacement"."""
        return CONTROLS[1] if self.qp.constraints.load_control else CONTROLS[0]

    def plastic_mask(self, p: np.ndarray, tol: float = CONTACT_TOL) -> np.ndarray:
        """Elements at their upper bound (plastic): u_i - p_i <= tol x p_s (``contact_floor``,
        the plastic floor) with u_i finite (none without bounds; flag: ``plastic_share``)."""
        c = self.qp.constraints
        if not c.bounded:
            return np.zeros(self.n, dtype=bool)
        u = c.upper_or_inf(self.n)
        with np.errstate(invalid="ignore"):
            return np.isfinite(u) & (u - np.asarray(p, dtype=np.float64) <= self.contact_floor(tol))

    def plastic_fraction(self, p: np.ndarray, tol: float = CONTACT_TOL) -> float:
        """Plastic elements (``plastic_mask``) over the elements in contact
        (``contact_mask``); 0 when none touches."""
        touching = self.contact_mask(p, tol)
        k = int(np.count_nonzero(touching))
        return float(np.count_nonzero(self.plastic_mask(p, tol) & touching)) / k if k else 0.0

    def problem_scales(self) -> tuple[float, float]:
        """The judge's scales of this problem (``problems.kkt``): the displacement scale
        u_s = ||ubar||_inf and the force scale p_s = u_s / max diag H (the force that alone
        indents one element by u_s; capped by the least upper bound under a hardness,
        ``problems.kkt.constrained_scales``).  They depend on the problem only, never on an
        answer."""
        return constrained_scales(np.asarray(self.qp.ubar, dtype=np.float64), float(np.max(self.qp.H.diagonal())),
                                  self.qp.constraints)

    def force_scale(self) -> float:
        """p_s of ``problem_scales``."""
        return self.problem_scales()[1]

    def contact_floor(self, tol: float = CONTACT_TOL) -> float:
        """The force above which an element is in contact: tol x p_s (``tol``: the judge's
        check tolerance of the answer read)."""
        return float(tol) * self.force_scale()

    def contact_mask(self, p: np.ndarray, tol: float = CONTACT_TOL) -> np.ndarray:
        """Elements in contact: p_i > tol x p_s (``contact_floor``).  An answer the judge
        accepts at ``tol`` may carry forces of order tol x p_s where the exact one has none
        (its complementarity residual is at most tol x u_s x p_s), so a floor relative to
        max(p) would count them; this one does not (docs/report.md, "Contact fraction")."""
        return np.asarray(p, dtype=np.float64) > self.contact_floor(tol)

    def contact_fraction(self, p: np.ndarray, tol: float = CONTACT_TOL) -> float:
        """A / A0: elements in contact (``contact_mask``) over all N^2 elements."""
        return float(np.count_nonzero(self.contact_mask(p, tol))) / self.total_elements

    def contact_uncertain(self, p: np.ndarray, tol: float = CONTACT_TOL, w: np.ndarray | None = None) -> float:
        """The flag of ``contact_fraction``: the share of all N^2 elements whose contact
        state the tolerance leaves open, those

        * whose force lies within a factor CONTACT_BAND of the contact floor
          (floor / CONTACT_BAND < p_i <= floor x CONTACT_BAND), or
        * counted in contact (p_i > floor) while their gap is open: w_i / u_s >= p_i / p_s
          (on the complementarity curve (w_i / u_s)(p_i / p_s) <= tol of an accepted answer
          the element sits nearer separation than contact: an interior-point answer spreads
          such pairs, e.g. p_i = 1e-5 p_s against w_i = 1e-4 u_s, where the exact answer has
          no force), or w_i > sqrt(tol) x u_s (an accepted contact carrying p_i >= sqrt(tol)
          p_s has w_i <= sqrt(tol) u_s).

        ``w`` = H p - ubar (- Delta under load control, ``gap``) when the caller has it (else
        one product with H).  A share larger than the accuracy wanted means A/A0 is not to be
        trusted to it."""
        u_s, p_s = self.problem_scales()
        floor = float(tol) * p_s
        q = np.asarray(p, dtype=np.float64)
        gap = self.gap(q) if w is None else np.asarray(w)
        with np.errstate(invalid="ignore"):
            near = (q > floor / CONTACT_BAND) & (q <= floor * CONTACT_BAND)
            closed = (gap / u_s < q / p_s) & (gap <= np.sqrt(float(tol)) * u_s)
            open_gap = (q > floor) & ~closed
        return float(np.count_nonzero(near | open_gap)) / self.total_elements

    def gap(self, p: np.ndarray, multiplier: float | None = None) -> np.ndarray:
        """w = Hp - ubar - Delta: Delta = 0 without a load equality, else ``multiplier`` (the
        answer's approach) or, when None, ``problems.constraints.fit_multiplier`` of p."""
        q = np.asarray(p, dtype=np.float64)
        g = self.qp.H.matvec(q) - np.asarray(self.qp.ubar, dtype=np.float64)
        c = self.qp.constraints
        if not c.load_control:
            return g
        return g - (fit_multiplier(g, q, c.upper) if multiplier is None else float(multiplier))

    def pressure_field(self, p: np.ndarray) -> np.ndarray:
        """N x N field of mean pressure p_ij / delta^2 (zero off the trial set)."""
        g = self._require_geometry()
        f = np.zeros(g.grid_shape)
        f.ravel()[g.indices] = p / (g.spacing[0] * g.spacing[1])
        return f

    def _require_geometry(self) -> Geometry:
        if self.qp.geometry is None:
            raise ProblemInputError("this instance has no grid geometry")
        return self.qp.geometry

    @property
    def preprocessing(self) -> MapPreprocessing | None:
        """What was done to the measured map this problem stands on (``problems.io``);
        None for a generated surface or none."""
        return None if self.surface is None else self.surface.preprocessing

    def problem_columns(self) -> dict[str, Any]:
        """The table's columns of the grid, the elastic body and the map's preparation
        (harness/table/schema.py): N0, N1 and the spacings delta0, delta1 (None without a
        grid); the layer's thickness, nu and interface (NaN / "" on the half-space); the
        ``MapPreprocessing.columns`` of a measured map."""
        g = self.qp.geometry
        out: dict[str, Any] = {"N0": None, "N1": None, "delta0": float("nan"), "delta1": float("nan"),
                               "thickness": float("nan"), "nu": float("nan"), "interface": ""}
        if g is not None:
            out.update(N0=int(g.grid_shape[0]), N1=int(g.grid_shape[1]), delta0=g.spacing[0], delta1=g.spacing[1])
            if g.layer is not None:
                out.update(thickness=float(g.layer.thickness), nu=float(g.layer.nu), interface=str(g.layer.interface))
        if self.preprocessing is not None:
            out.update(self.preprocessing.columns())
        return out


# ---------------------------------------------------------------------------
# Builders
# ---------------------------------------------------------------------------


def relative_contact_mask(p: np.ndarray) -> np.ndarray:
    """A relative contact test, p_i > CONTACT_THRESHOLD * max(p) (none when max(p) <= 0), for
    an algorithm's own use where the problem's scales are not at hand (the cascade's
    refinement).  The table's reading is ``ContactInstance.contact_mask``."""
    pmax = float(np.max(p)) if p.size else 0.0
    if pmax <= 0.0:
        return np.zeros(p.shape, dtype=bool)
    return p > CONTACT_THRESHOLD * pmax


def trial_set(heights: np.ndarray, delta_disp: float) -> np.ndarray:
    """Flat indices of I_C = {xi >= xi_max - Delta} (row-major order)."""
    zmax = float(heights.max())
    return np.flatnonzero(heights.ravel() >= zmax - delta_disp)


def rigid_body_ubar(heights: np.ndarray, delta_disp: float, idx: np.ndarray) -> np.ndarray:
    """ubar = Delta - xi_max + xi on the flat indices ``idx``: the rigid-body
    interpenetration (unclipped; negative below xi_max - Delta)."""
    return delta_disp - float(heights.max()) + heights.ravel()[idx]


class InstanceBuilder:
    """Builds the instances of one surface at many displacements, sharing the kernel
    transform (its FFT is computed once)."""

    def __init__(
        self,
        surface: Surface,
        E: float,
        kernel: str = "bcc",
        periodic: bool = False,
        operator: OperatorKind = "fft",
        memory_budget: float | None = None,
        images: int = 2,
        layer: Layer | None = None,
    ) -> None:
        check_kernel(kernel, periodic, layer)
        self.layer = layer
        self.surface = surface
        self.E = check_positive("E (composite modulus)", E)
        self.kernel = kernel
        self.periodic = periodic
        self.operator_kind = check_operator_kind(operator)
        self.memory_budget = budget_or_default(memory_budget)
        self.images = images
        self._transform: KernelTransform | None = None
        self._device_transform: ArrayKernelTransform | None = None

    @property
    def transform(self) -> KernelTransform:
        if self._transform is None:
            table = kernel_table(
                self.kernel, self.surface.shape, self.surface.spacing, self.E, self.periodic, images=self.images,
                layer=self.layer,
            )
            self._transform = KernelTransform(table, self.surface.shape)
        return self._transform

    @property
    def device_transform(self) -> ArrayKernelTransform:
        """The kernel transform on the CUDA device (shares the host transform's arrays)."""
        if self._device_transform is None:
            self._device_transform = ArrayKernelTransform.from_host(self.transform, "cupy")
        return self._device_transform

    def operator_on(self, indices: np.ndarray, kind: OperatorKind | None = None) -> ContactOperator:
        kind = kind or self.operator_kind
        if kind == "gpu":
            return ArrayFFTOperator(self.device_transform, indices)
        fft_op = FFTOperator(self.transform, indices)
        if kind == "dense":
            check_dense_budget(fft_op.n, self.memory_budget)
            return DenseOperator(fft_op.to_dense(self.memory_budget))
        return fft_op

    def build(
        self,
        delta_disp: float,
        meta: dict[str, Any] | None = None,
        candidates: np.ndarray | None = None,
        hardness: float | None = None,
    ) -> ContactInstance:
        """The QP at far-field displacement ``delta_disp`` (paper section 2).

        ``candidates`` (flat grid indices or an N x N boolean mask) restricts the trial
        set to I_C intersected with it.  ``hardness`` (a pressure; None or inf: none)
        bounds every element, 0 <= p <= hardness x delta^2.  The rigid-body trial set
        stays a superset of the contact set under a bound (the gap off it only grows).
        (The cascade multi-resolution method builds its coarse levels with
        ``problems.coarsen.coarse_qp``.)
        """
        check_nonnegative("far-field displacement Delta", delta_disp)
        h = self.surface.heights
        # Periodic kernels have the q = 0 mode removed: the surface rises between contacts
        # (negative influence coefficients far away), so points below xi_max - Delta can
        # touch and the rigid-body trial set is no superset of the contact set.  Periodic
        # problems are therefore posed on the whole grid, ubar < 0 where the rigid body
        # does not reach; the QP is bounded while sum(ubar) < 0 (H's null vector is 1).
        idx = np.arange(h.size) if self.periodic else trial_set(h, delta_disp)
        if candidates is not None:
            idx = np.intersect1d(idx, self._candidate_indices(candidates), assume_unique=False)
        if idx.size == 0:
            where = " within the given candidate points" if candidates is not None else ""
            raise ProblemInputError(f"empty trial set at Delta = {float(delta_disp)!r}{where}: no element can touch")
        ubar = rigid_body_ubar(h, delta_disp, idx)
        if self.periodic:
            if idx.size == h.size and float(np.sum(ubar)) >= 0.0:
                raise ProblemInputError(
                    f"periodic problem at Delta = {float(delta_disp)!r} >= xi_max - xi_mean: H is singular along the "
                    "constant vector (its q = 0 mode is removed) and the QP is unbounded; use a smaller Delta "
                    "or a non-periodic kernel"
                )
        else:
            ubar = np.maximum(ubar, 0.0)  # ubar = Delta at the top, >= 0 (never -0 by roundoff) at the set's edge
        geom = Geometry(self.surface.shape, self.surface.delta, idx, surface=self.surface,
                        far_field=float(delta_disp), E=self.E, kernel=self.kernel, periodic=self.periodic,
                        delta1=self.surface.delta1, layer=self.layer)
        qp = QP(self.operator_on(idx), ubar, geom, self.constraints(idx.size, hardness))
        return ContactInstance(
            qp=qp,
            delta=float(delta_disp),
            E=self.E,
            kernel=self.kernel,
            periodic=self.periodic,
            surface=self.surface,
            meta=dict(meta or {}),
        )

    def constraints(self, n: int, hardness: float | None = None, load: float | None = None) -> Constraints:
        """The checked constraints of a QP on n of this surface's elements: the hardness's
        bounds (``problems.constraints.hardness_bounds``; None or inf: none) and the load."""
        upper = None if hardness is None else hardness_bounds(hardness, self.surface.spacing, n)
        return make_constraints(n, upper, load)

    def load_force(self, dimensionless_load: float) -> float:
        """The total force P of a dimensionless load P / (E* A), A the nominal area."""
        check_nonnegative("dimensionless load P/(E* A)", dimensionless_load)
        area = float(np.prod(self.surface.shape)) * float(np.prod(self.surface.spacing))
        return float(dimensionless_load) * self.E * area

    def build_load(
        self,
        load: float,
        meta: dict[str, Any] | None = None,
        candidates: np.ndarray | None = None,
        hardness: float | None = None,
    ) -> ContactInstance:
        """The QP under load control: total force ``load`` = P (a force, ``load_force``
        converts a dimensionless one), the equality sum(p) = P whose multiplier is the
        far-field displacement Delta (module doc).  The trial set is the whole grid
        (``candidates`` restricts it), ubar = xi - xi_max.  ``hardness`` as in ``build``.
        The instance's ``delta`` is NaN: the answer's multiplier is its approach."""
        check_nonnegative("load P", load)
        h = self.surface.heights
        idx = np.arange(h.size)
        if candidates is not None:
            idx = np.intersect1d(idx, self._candidate_indices(candidates))
        if idx.size == 0:
            raise ProblemInputError("empty trial set within the given candidate points: no element can touch")
        ubar = rigid_body_ubar(h, 0.0, idx)
        geom = Geometry(self.surface.shape, self.surface.delta, idx, surface=self.surface,
                        far_field=None, E=self.E, kernel=self.kernel, periodic=self.periodic,
                        delta1=self.surface.delta1, layer=self.layer)
        qp = QP(self.operator_on(idx), ubar, geom, self.constraints(idx.size, hardness, float(load)))
        return ContactInstance(qp=qp, delta=float("nan"), E=self.E, kernel=self.kernel, periodic=self.periodic,
                               surface=self.surface, meta={"load": float(load), **(meta or {})})

    def _candidate_indices(self, candidates: np.ndarray) -> np.ndarray:
        """Sorted distinct flat grid indices from ``candidates``: flat grid indices (1-D
        integers in 0..N1 N2 - 1, repeats allowed) or an N1 x N2 boolean mask; anything
        else is a one-line ``ProblemInputError``."""
        c = np.asarray(candidates)
        size = self.surface.heights.size
        if c.dtype == bool:
            if c.shape != self.surface.shape:
                raise ProblemInputError(
                    f"candidate mask has shape {c.shape}, the surface grid is {self.surface.shape}"
                )
            return np.flatnonzero(c)
        if c.ndim != 1 or (c.size and not np.issubdtype(c.dtype, np.integer)):
            raise ProblemInputError(
                f"candidates must be flat grid indices (1-D integers) or a {self.surface.shape} boolean mask, "
                f"got dtype {c.dtype} and shape {c.shape}"
            )
        c = c.astype(np.int64)
        if c.size and (c.min() < 0 or c.max() >= size):
            raise ProblemInputError(f"candidate indices must lie in 0..{size - 1}, got {c.min()}..{c.max()}")
        return np.unique(c)


def build_instance(
    surface: Surface,
    delta_disp: float,
    E: float,
    kernel: str = "bcc",
    periodic: bool = False,
    operator: OperatorKind = "fft",
    memory_budget: float | None = None,
) -> ContactInstance:
    """One contact QP instance (see module doc)."""
    return InstanceBuilder(surface, E, kernel, periodic, operator, memory_budget).build(delta_disp)


# ---------------------------------------------------------------------------
# Load sequences
# ---------------------------------------------------------------------------


def paper_max_displacement(surface: Surface) -> float:
    """The paper's top step: (xi_max - xi_mean) / 2 (a flat surface has none:
    ``ProblemInputError``)."""
    check_not_flat(surface)
    return 0.5 * (surface.z_max - surface.z_mean)


def load_ramp(delta_max: float, steps: int) -> np.ndarray:
    """Delta_k = (k / K) * delta_max for k = 1..K (K = ``steps``, a whole number >= 1)."""
    check_positive("maximum displacement", delta_max)
    steps = check_whole("number of load steps", steps, 1)
    return delta_max * np.arange(1, int(steps) + 1) / int(steps)


def load_unload_cycle(delta_max: float, steps: int, cycles: int = 1) -> np.ndarray:
    """Up in ``steps`` steps to delta_max, down to delta_max/steps, repeated ``cycles``
    (a whole number >= 1) times."""
    cycles = check_whole("cycles", cycles, 1)
    up = load_ramp(delta_max, steps)
    one = np.concatenate([up, up[-2::-1]])
    return np.concatenate([one] + [one[1:] for _ in range(int(cycles) - 1)])


# ---------------------------------------------------------------------------
# The greedy counterexample (paper Example 1)
# ---------------------------------------------------------------------------


def counterexample(n: int, seed: int, E: float = 0.01, delta: float = 1.0, operator: OperatorKind = "dense",
                   kernel: str = "bcc", periodic: bool = False, layer: Layer | None = None,
                   hardness_over_ps: float | None = None) -> ContactInstance:
    """Paper Example 1: an N x N grid (n = N^2), every element in the trial set,
    ubar ~ U(0, 1) drawn as ``numpy.random.default_rng(seed).random(n)``, BCC kernel,
    delta = 1 and E = 0.01 (arbitrary consistent units: delta in a.u. of length, E in
    a.u. of force per length^2, as the paper's Fig. 2).

    The paper's open question -- is greedy reliable "for other forms of H"? -- takes the
    same draw on another operator: ``kernel`` and ``periodic`` (``kernels.kernel_table``),
    an elastic ``layer`` on a rigid base, or a hardness bound u_i = ``hardness_over_ps`` x
    p_s on every element (p_s the problem's force scale, ``kkt.problem_scales``).

    Its geometry is the grid with its spacing, E, kernel and periodicity (so a code that
    poses the problem on a grid, such as the peers, can pose it); it has no surface and
    no far-field displacement (ubar is drawn, not derived from heights), so
    ``Geometry.has_surface`` is False."""
    N = int(round(np.sqrt(n))) if isinstance(n, (int, np.integer)) and n >= 0 else -1
    if N * N != n or N < 2:
        raise ProblemInputError(f"counterexample needs n = N^2 with N >= 2, got n = {n}")
    check_kernel(kernel, periodic)
    ubar = np.random.default_rng(check_seed(seed)).random(n)
    surf = Surface(np.zeros((N, N)), delta, unit="a.u.", name=f"counterexample-n{n}")
    builder = InstanceBuilder(surf, E, kernel, periodic=periodic, operator=operator, layer=layer)
    idx = np.arange(n)
    geom = Geometry((N, N), delta, idx, E=float(E), kernel=kernel, periodic=periodic, layer=layer)
    op = builder.operator_on(idx)
    upper = None
    if hardness_over_ps is not None:
        _, p_s = problem_scales(ubar, float(np.max(op.diagonal())))
        upper = np.full(n, check_positive("hardness over p_s", hardness_over_ps) * p_s)
    qp = QP(op, ubar, geom, make_constraints(n, upper, None))
    return ContactInstance(qp, delta=float("nan"), E=E, kernel=kernel, periodic=periodic, surface=surf,
                           meta={"seed": seed, "family": "counterexample"})


# ---------------------------------------------------------------------------
# Analytic scenes
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class HertzSolution:
    contact_radius: float
    load: float
    peak_pressure: float


def hertz_solution(radius: float, E: float, delta_disp: float) -> HertzSolution:
    """Rigid sphere of radius R on an elastic half-space (composite modulus E*),
    indentation Delta: a = sqrt(R Delta), P = 4/3 E* sqrt(R) Delta^{3/2},
    p0 = 2 E* a / (pi R); R > 0, E* > 0, Delta >= 0 (finite; else ``ProblemInputError``)."""
    radius, E = check_positive("sphere radius", radius), check_positive("modulus E*", E)
    delta_disp = check_nonnegative("far-field displacement Delta", delta_disp)
    a = np.sqrt(radius * delta_disp)
    return HertzSolution(a, 4.0 / 3.0 * E * np.sqrt(radius) * delta_disp**1.5, 2.0 * E * a / (np.pi * radius))


def hertz_surface(N: int, radius: float, length: float) -> Surface:
    """Paraboloid cap xi = -r^2 / (2R) centred on an N x N grid of side ``length``
    (the element centres of an even N straddle the apex symmetrically); R, length > 0."""
    N = check_grid_size(N, "hertz surface")
    check_positive("sphere radius", radius)
    delta = check_positive("side length", length) / N
    x = (np.arange(N) - (N - 1) / 2.0) * delta
    r2 = x[:, None] ** 2 + x[None, :] ** 2
    return Surface(-r2 / (2.0 * radius), delta, name=f"hertz-N{N}", meta={"radius": radius})


def flat_punch_surface(N: int, punch_radius: float, length: float, depth: float | None = None) -> Surface:
    """A rigid flat circular punch of radius a: xi = 0 inside r <= a, -depth outside
    (depth default: the side length, far beyond any displacement used); a <= length / 2
    (the punch fits on the grid), length > 0, depth > 0."""
    N = check_grid_size(N, "flat-punch surface")
    length = check_positive("side length", length)
    if check_positive("punch radius", punch_radius) > length / 2.0:
        raise ProblemInputError(f"punch radius must be <= half the side length {length / 2.0!r}, got {punch_radius!r}")
    delta = length / N
    x = (np.arange(N) - (N - 1) / 2.0) * delta
    r = np.hypot(x[:, None], x[None, :])
    d = length if depth is None else check_positive("punch depth", depth)
    return Surface(np.where(r <= punch_radius, 0.0, -d), delta, name=f"flat-punch-N{N}", meta={"punch_radius": punch_radius})


def flat_punch_load(punch_radius: float, E: float, delta_disp: float) -> float:
    """P = 2 a E* Delta; a > 0, E* > 0, Delta >= 0 (finite; else ``ProblemInputError``)."""
    check_positive("punch radius", punch_radius)
    check_positive("modulus E*", E)
    check_nonnegative("far-field displacement Delta", delta_disp)
    return 2.0 * punch_radius * E * delta_disp


__all__ = [
    "QP",
    "ContactInstance",
    "Geometry",
    "InstanceBuilder",
    "MemoryBudgetError",
    "OPERATOR_KINDS",
    "check_operator_kind",
    "build_instance",
    "CONTACT_BAND",
    "CONTACT_TOL",
    "CONTACT_THRESHOLD",
    "relative_contact_mask",
    "counterexample",
    "flat_punch_load",
    "flat_punch_surface",
    "hertz_solution",
    "hertz_surface",
    "load_ramp",
    "load_unload_cycle",
    "paper_max_displacement",
    "rigid_body_ubar",
    "trial_set",
]
