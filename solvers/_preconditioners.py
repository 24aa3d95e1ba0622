"""Preconditioners for CG on a contact (free) set S: the one factory
(``make_preconditioner``) of fast-pccg, fast-dual-pccg (and the unpreconditioned CCGs'
``precondition`` option) and of fast-pdas's inner CG.

Both act as z = R M^-1 R r, with R the restriction to the current set S, so each is
symmetric positive definite on S and CG stays valid while M is held fixed.  Each also
says what it would do to a point that forms a set alone (``solo``), which scales the
force of a point entering Polonsky-Keer's contact set (solvers/_ccg.py).

``IslandPreconditioner`` (the default, "islands") -- block-Jacobi over contact islands.

On a rough surface the contact set is thousands of small islands.  H restricted to it
is dominated by the blocks *within* each island (the half-space kernel decays like
1/r), so the exact inverse of each island's block -- a block-Jacobi preconditioner
whose blocks are the 8-connected components of the set on the grid -- removes the
short-range part of the spectrum that limits CG, and leaves the smooth far-field
coupling between islands.  Measured on the 1024^2 paper surface (3,428 contact
points, 1,002 islands, largest 136): CG on H_AA p = ubar_A to 1e-9 takes 67
matvecs, 47 with the continuous |q| E*/2 Fourier preconditioner of Vollebregt (2014),
and 33 with this one (docs/fast-solvers.md).

Islands larger than the block limit -- ``max_block`` (128), smaller when the set is large
(``BUILD_BUDGET``: a build costs a few matvecs at most) -- are cut into compact grid patches,
and islands of up to a few hundred points stay whole where the build can afford them
(solvers/_partition.py: ``patches``, ``whole_limit``).  The block
inverses are held in float64, or in float32 for the mixed-precision solves
(``block_dtype``): a preconditioner only has to be SPD and fixed, not exact, so the fixed
point and the float64 KKT test are unchanged, while the batched inversion (most of a
cold 1024^2 solve's preconditioner time) and ``apply`` move half the bytes.  The
blocks are gathered from the operator's kernel table (``ContactOperator.submatrix``),
grouped by size into buckets of powers of two, padded with the identity and
inverted batch-wise (``_partition.block_inverses``), so neither the build nor ``apply``
loops over islands in Python (but over the few wide blocks Cholesky inverts).  Needs the unknowns' grid positions (``QP.geometry``); without them
``IslandPreconditioner.build`` returns None and callers run unpreconditioned.

Settled sets: the blocks are refactored when the set has drifted by ``REBUILD_FRACTION`` (20 %)
from the set they were built for -- a cold start's set shrinks by thousands of points an
iteration, and a build costs a few matvecs -- and, once the set is settling (it changed by at
most ``SETTLING_FRACTION`` of its points since the last update), already at
``SETTLED_REBUILD_FRACTION`` (1 %).  Without the second rule the blocks that served the last
stretch of a solve -- CG on a contact set that no longer moves -- were built on a larger set
of the approach and restricted: on the held-out Saupe H 0.9 member of
results/perf/farfield-1024 (1024^2, seed 3) built on 36,806 points for a set of 31,399, CG
there cut the error by a factor 0.79 an iteration, where blocks (and a far field) built on
that set cut it by 0.51.

"farfield" -- the island blocks plus the far-field coupling between them on grid tiles
(``IslandPreconditioner(far_field=True)``, solvers/_farfield.py): M = B + Z E Z', applied
by the Woodbury identity; the default of fast-dual-pccg.

``FourierPreconditioner`` ("fourier") -- Vollebregt's FFT-based preconditioner for
BCCG (Vollebregt, J. Optim. Theory Appl. 162 (2014) 931): the inverse of the
continuous half-space compliance, |q| E*/2 up to a constant, applied on the physical
N1 x N2 grid (periodic approximation: one N^2 transform pair, about a quarter of the
padded matvec), gathered on S.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Protocol

import numpy as np
import scipy.fft as sfft
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from contactbench.problems.instances import QP
from contactbench.problems.kkt import read_scalars
from contactbench.problems.fft_threads import each_band, each_on_pool, fft_workers, share_out, spectral_multiply
from contactbench.problems.operators import ContactOperator
from contactbench.problems.operators_gpu import HOST, ArraySpace, on_host

from ._farfield import REBUILD_FRACTION as FAR_REBUILD_FRACTION
from ._farfield import MAX_SET_FRACTION, FarField, build_far_field
from ._partition import block_inverses, block_width, by_cholesky, patches, whole_limit

#: Islands above this many points are cut into patches (keeps a block inverse cheap), but
#: for the whole islands of solvers/_partition.py.
MAX_BLOCK = 128

#: Block entries gathered and inverted at a time (bounds the build's temporaries).
BUILD_CHUNK_ENTRIES = 1 << 22

#: A build's block entries (|S| s^2 for blocks of s points) stay under this many times the
#: grid's points, i.e. a few matvecs' worth of work (``IslandPreconditioner.block_limit``).
BUILD_BUDGET = 40

#: A bucket whose inverses take at least this many bytes is applied on the FFT threads,
#: its blocks cut evenly (NumPy's batched products release the GIL: 1.33x on two threads
#: for 16-point blocks, memory-bound); smaller ones in this thread.
PARALLEL_BUCKET_BYTES = 1 << 22
#: A bucket's blocks are inverted on the threads from this much work (m s^3) up.
POOL_MIN_WORK = 1 << 22

#: Refactor when the set has changed in more than this fraction of its points ...
REBUILD_FRACTION = 0.2

#: ... or in more than this fraction once it is settling: changed in at most
#: ``SETTLING_FRACTION`` of its points since the last update (module doc, "Settled sets").
SETTLED_REBUILD_FRACTION = 0.01
SETTLING_FRACTION = 0.001

_NEIGHBOURS = ((0, 1), (1, -1), (1, 0), (1, 1))  # half of the 8-neighbourhood


def drifted(S: np.ndarray, reference: np.ndarray | None, fraction: float) -> bool:
    """Whether the set S differs from ``reference`` (None: nothing built yet) in more than
    ``fraction`` of |S| points: the rebuild test of the island blocks and of the far field."""
    if reference is None:
        return True
    changed, size = read_scalars(np.count_nonzero(S != reference), np.count_nonzero(S))
    return changed > fraction * max(1.0, size)


#: The preconditioners ``make_preconditioner`` knows ("none": no preconditioner; "auto":
#: ``resolved_kind``).
KINDS = ("islands", "farfield", "fourier", "none", "auto")

#: The grid size (points) from which the fast solvers' "auto" precision is mixed (float32
#: inner rounds, solvers/_refine.py): 512^2, the smallest size measured.  Over the surface
#: population with the island blocks of today (results/perf/mixed-512: quiet 2-core vm, one
#: run, the same window) mixed / double seconds median 0.95x at 512^2 (48 members, worst
#: 1.23x) and 0.88x at 1024^2 (32 members, worst 1.09x), the median and worst members' times
#: no higher; the 512^2 warm paper sweep 0.82-0.83x (the same 355-356 matvecs); load control
#: at 512^2 0.50-0.87x on three problems.  Its set-up (the float32 twin, the refinement's
#: float64 products) once made it lose below 2048^2 (results/perf/surface-population.md).
MIXED_GRID_POINTS = 512 * 512

#: The grid size (points) from which "auto" takes the far-field correction: 1024^2.  Its
#: builds (near-tile sums, an m x m eigendecomposition) cost what a few iterations save on
#: rough surfaces (many small islands), and it removes a third of the products on smooth ones
#: (few large islands cut into patches).  Over the surface population at 1024^2
#: (results/perf/farfield-1024: 48 members, and 32 held-out ones on seeds 3-4; quiet 2-core
#: vm, one run): median / worst matvecs 62 / 126 -> 50.5 / 83 (held out 70 / 204 -> 53 / 142),
#: seconds median 0.90x the islands alone (held out 0.90x), worst member 1.56x (1.36x held
#: out; H 0.3, where the products barely change).  At 512^2 the products fall too
#: (48 / 109 -> 42 / 65) but the time does not (median 1.01x), so the islands stay there.
FAR_FIELD_GRID_POINTS = 1024 * 1024

#: The grid size (points) from which "auto" takes the far field for a warm start of a
#: non-periodic problem with no constraint beyond p >= 0: 512^2.  A warm start's first steps
#: are held on its contact set (solvers/_ccg.py, "A warm start's first iterations"), so the
#: blocks and their far field are built on contact sets, not on the band of penetrating points
#: a deeper approach makes.  The paper's 512^2 BCC sweep: 323 -> 225 products, 0.78-0.79x the
#: seconds; the population's 512^2 sweeps: results/perf/warm-far-field.  A periodic grid is
#: not padded, so its products cost a quarter and the builds weigh more: on the paper's
#: periodic 512^2 sweep 277 -> 206 products took 1.1-1.5x the seconds, so it keeps
#: ``FAR_FIELD_GRID_POINTS``.
WARM_FAR_FIELD_GRID_POINTS = 512 * 512

#: Why "auto" is "fourier" under load control, with or without a hardness: there the free set
#: moves with the approach at every iteration, the island blocks were refactored every few
#: iterations (10 builds in 66 iterations, periodic RMD 512^2), and the wave-number
#: preconditioner needs no build.  On the 14 load-controlled problems of the ASPHER race
#: (results/peers/aspher.md: four families at 512^2 and 1024^2, 2048^2, both boundaries,
#: P/(E* A) = 0.015; quiet 2-core vm, one run) it took 0.44-0.99x the islands' time, median
#: 0.62x.  Held out on 54 problems of three other cells (results/peers/held-out): median
#: 0.79-0.88x non-periodic and 0.45-0.48x periodic, worst 1.25x (H 0.3, rms slope 1, where it
#: needs 1.77x the products).  A hardness moves the set further (points reach and leave the
#: bound): 0.51-0.73x the islands' or far field's seconds (medians of four tables, 64 members
#: at 512^2 and 1024^2, hardness 1.5-20 times the mean pressure, faster on every member;
#: results/perf/load-hardness), with more products where most of the contact is plastic.
#: Displacement control keeps the islands, with a hardness too (fewer matvecs,
#: docs/fast-solvers.md).
LOAD_FOURIER = "fourier"


#: ... but a warm step of a non-periodic load-controlled sweep without a hardness, with
#: little contact, moves its set little, and there the island kinds won for the Bugnicourt
#: loop (``fast-dual-pccg``, which sets ``_FastCCG.warm_load_islands``; the P&K loop cycles
#: on blocks under a load, results/perf/load-pk-default): the load-sweep recipe over the
#: families' surfaces (H 0.3-0.9), 10 steps, the first cold, the island kind of the warm
#: displacement rule (``WARM_FAR_FIELD_GRID_POINTS``) against the wave numbers, median
#: 0.67-0.75x the seconds at 256^2-1024^2.  The rule holds where at most this share of the
#: caller's warm start is in contact: with more the island kinds lost (at ten times the
#: load-sweep's loads, 256^2: 1.27-1.59x per step on a H 0.9 surface from 5.5 % in contact,
#: 1.15-1.19x on a H 0.7 one from 18 %; 0.73-0.89x below 9 %; results/perf/warm-load).
WARM_LOAD_MAX_CONTACT = 0.03

#: Why "auto" is "fourier" on a device (``ContactOperator.space`` not the host): it is FFTs
#: there, where the island kinds' block factorisations and far field are host work
#: (solvers/_device.py), and it took the islands' products then: over the surface population
#: (results/perf/device-choice) median 51.5 / 63 matvecs against 48 / 62 at 512^2 / 1024^2,
#: worst 110 / 145 against 109 / 126.  On the CPU the same products take 1.18-1.26x the
#: islands' time, so the host keeps the islands.  The host's defaults have since gained (the
#: far field at 1024^2, the settled-set rebuild: median 47 / 44, worst 99 / 66,
#: results/perf/settled-rebuild), so the islands' blocks on the device (batched
#: factorisations) are the open lever there.
DEVICE_FOURIER = "fourier"


def grid_points(qp: QP) -> int:
    """Points of the physical grid the QP's unknowns sit on (its own size without a geometry)."""
    geo = getattr(qp, "geometry", None)
    return int(np.prod(geo.grid_shape)) if geo is not None else int(qp.n)


def mixed_grid(qp: QP) -> bool:
    """The rule of the fast solvers' "auto" precision: the QP's grid has at least
    ``MIXED_GRID_POINTS`` points."""
    return grid_points(qp) >= MIXED_GRID_POINTS


def resolved_kind(kind: str, qp: QP, warm: bool = False, far_from: int | None = None,
                  warm_load_contact: float | None = None) -> str:
    """``kind`` with "auto" decided: "fourier" on a device (``DEVICE_FOURIER``) and under
    load control, with or without a hardness (``LOAD_FOURIER``), except a ``warm`` step of a
    non-periodic QP under a load alone whose caller's warm start has at most
    ``WARM_LOAD_MAX_CONTACT`` of it in contact (``warm_load_contact``; None: the solver's
    loop keeps the wave numbers under a load); else by the grid: the far field from
    ``far_from`` grid points when given (a solver's own rule), else from
    ``FAR_FIELD_GRID_POINTS`` (from ``WARM_FAR_FIELD_GRID_POINTS`` for a ``warm`` start of a
    non-periodic QP with no constraint beyond p >= 0, or under a load alone), the islands
    alone below."""
    if kind != "auto":
        return kind
    space = qp.H.space
    if space is not None and not space.host:
        return DEVICE_FOURIER
    c = qp.constraints
    geo = getattr(qp, "geometry", None)
    padded = not (geo is not None and geo.periodic)
    warm_padded = warm and padded and not c.bounded
    little_contact = warm_load_contact is not None and warm_load_contact <= WARM_LOAD_MAX_CONTACT
    if c.load_control and not (warm_padded and little_contact):
        return LOAD_FOURIER
    if far_from is None:
        far_from = WARM_FAR_FIELD_GRID_POINTS if warm_padded else FAR_FIELD_GRID_POINTS
    return "farfield" if grid_points(qp) >= far_from else "islands"


#: The kinds built on the island blocks (``IslandPreconditioner``).
ISLAND_KINDS = ("islands", "farfield")


class SetPreconditioner(Protocol):
    """What the preconditioned CGs use: act on a set S, apply z = R M^-1 R r, and
    ``solo``: z_j = m_j r_j, m_j = 1 / M_jj, M's inverse on each point j as a one-point set
    (the force scale of a point entering the set)."""

    builds: int
    #: Changes whenever M^-1 itself changes beyond its restriction to a new set (a block
    #: factorisation, a far-field build): the Bugnicourt loop restarts its conjugacy then
    #: (solvers/_ccg.py, "A refactored preconditioner").
    version: int

    @property
    def on(self) -> np.ndarray: ...

    def update(self, S: np.ndarray) -> None: ...

    def apply(self, r: np.ndarray) -> np.ndarray: ...

    def solo(self, r: np.ndarray) -> np.ndarray: ...

    def simplify(self, blocks: bool = False) -> bool:
        """Drop a coarse part, if any, for the rest of the solve; with ``blocks`` and no
        coarse part left, the island blocks too (True when something was dropped)."""
        ...

    def progress(self, kkt: float) -> bool:
        """Told the loop's scaled KKT error at each of its checks; True when M changed its
        stage, and the loop restarts its conjugacy (solvers/_opening.py)."""
        ...

    def ones(self) -> np.ndarray:
        """M^-1 1 on the current set (``_OnesCache``)."""
        ...


#: ``ones`` is recomputed when the set has drifted by more than this fraction of its size
#: from the set it was computed for (``drifted``).
ONES_DRIFT = 0.01


class _OnesCache:
    """``ones``: v = M^-1 1 on the set M acts on, for the load-controlled loops' zero-sum
    projection z - (1'z / 1'v) v (solvers/_constrained.py).  That projection sums to zero
    on the set for any v; v = M^-1 1 makes it the symmetric one of the preconditioned CG.
    The set follows the approach and changes by a few points at most iterations, so v is
    kept until the set has drifted by ``ONES_DRIFT`` or the factors change (the subclass
    calls ``_forget_ones``): one application of M an iteration, not two."""

    _on: np.ndarray
    _ones: np.ndarray | None = None
    _ones_set: np.ndarray | None = None

    def apply(self, r: np.ndarray) -> np.ndarray:  # pragma: no cover - the subclasses'
        raise NotImplementedError

    def ones(self) -> np.ndarray:
        if self._ones is None or drifted(self._on, self._ones_set, ONES_DRIFT):
            self._ones_set = self._on.copy()
            self._ones = self.apply(self._on.astype(np.float64))
            if on_host(self._ones):  # a device array has no flags
                self._ones.flags.writeable = False
        return self._ones

    def _forget_ones(self) -> None:
        self._ones = self._ones_set = None


@dataclass
class _Bucket:
    members: np.ndarray  # (m, s) positions in the operator's set, -1 = padding (masked by valid)
    inverse: np.ndarray  # (m, s, s)
    valid: np.ndarray  # (m, s) not padding
    row_sums: np.ndarray  # (m, s) sum_l H_kl over the block (the far-field correction's)


class IslandPreconditioner(_OnesCache):
    """z = blockdiag(H_BB)^-1 r on a set S, zero outside S (see module doc)."""

    def __init__(self, H: ContactOperator, grid_shape: tuple[int, int], grid_idx: np.ndarray,
                 max_block: int | None = None, dtype: type = np.float64, far_field: bool = False) -> None:
        self.H = H
        self.far_field = far_field
        #: Whether the island blocks are built (``simplify`` may turn them off: z = r / H_jj).
        self.blocks = True
        self._far: FarField | None = None
        self._far_set: np.ndarray | None = None
        self.dtype = np.dtype(dtype)
        self.n = int(grid_idx.size)
        self.max_block = int(max_block or MAX_BLOCK)
        self._i, self._j = np.divmod(np.asarray(grid_idx, dtype=np.int64), grid_shape[1])
        self._shape = (int(grid_shape[0]), int(grid_shape[1]))
        # Position of each grid point in the set (-1: not in the set), for neighbour lookups.
        self._where = np.full(self._shape[0] * self._shape[1], -1, dtype=np.int32 if self.n < 2**31 else np.int64)
        self._where[np.asarray(grid_idx)] = np.arange(self.n)
        self._buckets: list[_Bucket] = []
        self._on = np.zeros(self.n, dtype=bool)
        self._pos = np.zeros(0, dtype=np.int64)
        self._built: np.ndarray | None = None
        self._diag = H.diagonal()
        self.rebuild_fraction = REBUILD_FRACTION
        #: The far field is built on sets of at most this fraction of the unknowns.
        self.far_fraction = MAX_SET_FRACTION
        self.builds = 0
        self.version = 0

    @classmethod
    def build(cls, qp: QP, max_block: int | None = None, dtype: type = np.float64,
              far_field: bool = False) -> IslandPreconditioner | None:
        g = qp.geometry
        if g is None or g.indices is None or np.asarray(g.indices).size != qp.n:
            return None
        return cls(qp.H, tuple(g.grid_shape), np.asarray(g.indices), max_block, dtype, far_field)

    def update(self, S: np.ndarray) -> None:
        """Make the preconditioner act on the set S (boolean mask over the operator's set).

        The island blocks are refactored only when S has drifted by more than
        ``rebuild_fraction`` of its size from the set they were built for, or by more than
        ``SETTLED_REBUILD_FRACTION`` while it is settling (module doc); in between,
        z = R B^-1 R r with R the restriction to S (and 1/H_ii on points of S outside
        the built set), which is still symmetric positive definite on S, so CG stays
        valid while the factorisation is reused."""
        S = np.asarray(S, dtype=bool)
        settling = not drifted(S, self._on, SETTLING_FRACTION)
        self._on = S.copy()
        self._pos = np.flatnonzero(S)
        limit = SETTLED_REBUILD_FRACTION if settling else self.rebuild_fraction
        if drifted(S, self._built, limit):
            self._forget_ones()
            self.builds += 1
            self.version += 1
            self._built = S.copy()
            pos = self._pos
            self._limit = self.block_limit(pos.size)
            buckets = (self._factor(members) for members in self._blocks(pos)) if pos.size and self.blocks else ()
            self._buckets = [b for b in buckets if b is not None]
            self._far_set = None
        if self.far_field:
            self._update_far_field(S)

    def _update_far_field(self, S: np.ndarray) -> None:
        """(Re)build the far-field correction (solvers/_farfield.py) when S has drifted by
        ``farfield.REBUILD_FRACTION`` from the set it was built for, or the blocks changed."""
        if not drifted(S, self._far_set, FAR_REBUILD_FRACTION):
            return
        had = self._far is not None
        self._far, self._far_set = None, S.copy()
        self._forget_ones()
        lead = np.arange(self.n)
        sums = self._diag.copy()
        on = self._on
        for b in self._buckets:  # blocks restricted to S: their first point of S leads
            ok = b.valid & on[np.where(b.valid, b.members, 0)]
            first = np.where(ok.any(axis=1), b.members[np.arange(ok.shape[0]), ok.argmax(axis=1)], -1)
            lead[b.members[ok]] = np.broadcast_to(first[:, None], ok.shape)[ok]
            sums[b.members[ok]] = b.row_sums[ok]
        ones = np.zeros(self.n)
        ones[self._pos] = 1.0
        v = self.apply(ones)
        budget = BUILD_BUDGET * self._shape[0] * self._shape[1]
        self._far = build_far_field(self.H, self._i, self._j, self._pos, lead, v, sums, budget, self.far_fraction)
        self.version += had or self._far is not None

    def block_limit(self, size: int) -> int:
        """The largest block for a build on ``size`` points: s with s^2 size <= BUILD_BUDGET
        x grid points, a multiple of 16 in [16, max_block].  A cold start's first sets are
        the whole trial set, which the next few iterations shrink by orders of magnitude:
        small blocks there cost a fraction and lose little (2048^2 cold top step: the same
        77 iterations, builds 6.0 -> 1.9 s)."""
        s = int(np.sqrt(BUILD_BUDGET * self._shape[0] * self._shape[1] / max(size, 1)))
        return int(min(self.max_block, max(16, 16 * (s // 16))))

    @property
    def on(self) -> np.ndarray:
        """The set the preconditioner acts on now."""
        return self._on

    def apply(self, r: np.ndarray) -> np.ndarray:
        # Work on the set's positions only: on a periodic whole grid S is a few % of n.
        z = np.zeros(self.n)
        pos = self._pos
        z[pos] = r[pos] / self._diag[pos]
        for b in self._buckets:  # each block on its own: shared out over the FFT threads when large
            parts = min(fft_workers(), len(b.members)) if b.inverse.nbytes >= PARALLEL_BUCKET_BYTES else 1
            if parts <= 1:
                self._apply_blocks(b, slice(None), r, z)
                continue
            cuts = np.linspace(0, len(b.members), parts + 1).astype(int)
            share_out([partial(self._apply_blocks, b, slice(lo, hi), r, z) for lo, hi in zip(cuts[:-1], cuts[1:])])
        if self._far is not None:
            self._far.correct(z, r, pos)
        return z

    def _apply_blocks(self, b: _Bucket, part: slice, r: np.ndarray, z: np.ndarray) -> None:
        """z on the members of bucket ``b``'s blocks ``part``: their inverses times r, a
        member of the built set that left S counting as 0 (disjoint writes: safe on threads)."""
        members = b.members[part]
        valid = b.valid[part] & self._on[members]
        rb = np.where(valid, r[members], 0.0).astype(self.dtype, copy=False)
        zb = np.einsum("mij,mj->mi", b.inverse[part], rb)
        z[members[valid]] = zb[valid]

    def solo(self, r: np.ndarray) -> np.ndarray:
        """r / H_jj: the inverse of a one-point island."""
        return r / self._diag

    def simplify(self, blocks: bool = False) -> bool:
        """Drop the far-field correction, the island blocks staying; with none to drop and
        ``blocks``, the blocks too (z = r / H_jj on the set from then on: a load-controlled
        warm step of the P&K loop cycled on its blocks for 900 iterations, rebuilding them at
        each; the constrained loops ask for it, solvers/_constrained.py).  True when
        something was dropped."""
        if self.far_field:
            self._forget_ones()
            self.version += self._far is not None
            self.far_field, self._far, self._far_set = False, None, None
            return True
        if not (blocks and self.blocks):
            return False
        self._forget_ones()
        self.blocks, self._buckets = False, []
        self.version += 1
        return True

    def progress(self, kkt: float) -> bool:
        """One stage: never changes."""
        return False

    # -- partition -------------------------------------------------------------------

    def _components(self, pos: np.ndarray) -> np.ndarray:
        """Component label of each point of ``pos`` (8-connectivity on the grid)."""
        k = pos.size
        local = np.full(self.n, -1, dtype=np.int64)
        local[pos] = np.arange(k)
        i, j = self._i[pos], self._j[pos]
        rows, cols = [], []
        n1, n2 = self._shape
        for di, dj in _NEIGHBOURS:
            ii, jj = i + di, j + dj
            ok = (ii < n1) & (jj >= 0) & (jj < n2)
            nb = np.full(k, -1, dtype=np.int64)
            nb[ok] = self._where[ii[ok] * n2 + jj[ok]]
            has = nb >= 0
            nb[has] = local[nb[has]]
            has &= nb >= 0
            rows.append(np.flatnonzero(has))
            cols.append(nb[has])
        r, c = np.concatenate(rows), np.concatenate(cols)
        graph = coo_matrix((np.ones(r.size, dtype=np.int8), (r, c)), shape=(k, k))
        return connected_components(graph, directed=False)[1]

    def _blocks(self, pos: np.ndarray):
        """Yield (m, s) member arrays, one per padded size s (see ``block_width``)."""
        islands = self._components(pos)
        whole = whole_limit(np.bincount(islands), self._limit, BUILD_BUDGET * self._shape[0] * self._shape[1])
        labels = patches(islands, self._i[pos], self._j[pos], self._shape, self._limit, whole)
        order = np.argsort(labels, kind="stable")  # pos is sorted, so row-major within a block
        labels = labels[order]
        starts = np.flatnonzero(np.r_[True, labels[1:] != labels[:-1]])
        sizes = np.diff(np.r_[starts, labels.size])
        width = block_width(sizes)
        for s in np.unique(width):
            sel = np.flatnonzero(width == s)
            offs = np.arange(s)
            idx = starts[sel, None] + offs[None, :]
            valid = offs[None, :] < sizes[sel, None]
            members = np.full(idx.shape, -1, dtype=np.int64)
            members[valid] = pos[order[idx[valid]]]
            yield members

    def _factor(self, members: np.ndarray) -> _Bucket | None:
        """The bucket of blocks ``members`` (None for one-point blocks: ``apply``'s
        diagonal part already inverts those; None too when a block is singular -- a
        periodic kernel's whole tiny grid, H 1 = 0 -- so the diagonal stands in for it)."""
        m, s = members.shape
        if s == 1:
            return None
        # Gather and invert in chunks, so the temporaries stay near 32 MiB in all: on the
        # threads, at least one a thread, where the work pays the pool's round trip and the
        # inversion releases the GIL (batched LU; Cholesky's calls hold it).  Each block is
        # inverted on its own, the method chosen for the bucket: the same inverses on every
        # thread count.
        inverse = np.empty((m, s, s), dtype=self.dtype)
        row_sums = np.empty((m, s))
        valid = members >= 0
        cholesky = by_cholesky(m, s)
        workers = 1 if cholesky or m * s ** 3 < POOL_MIN_WORK else fft_workers()
        step = max(1, min(BUILD_CHUNK_ENTRIES // (s * s * workers), -(-m // workers)))

        def factor_chunk(k: int) -> bool:
            part = slice(k * step, (k + 1) * step)
            blocks = self.H.blocks(members[part])
            row_sums[part] = np.einsum("mkl,ml->mk", blocks, valid[part])
            try:
                inverse[part] = block_inverses(blocks.astype(self.dtype, copy=False), cholesky)
            except np.linalg.LinAlgError:  # a singular block (a periodic whole grid's): the diagonal there
                return False
            return True

        if not all(each_on_pool(factor_chunk, -(-m // step), workers)):
            return None
        return _Bucket(members, inverse, valid, row_sums)


class FourierPreconditioner(_OnesCache):
    """z = R F^-1[|q| F[R r]] on the physical grid (see module doc), with r, z, the set,
    the wave numbers and the grid indices in the array ``space`` (the host by default;
    a device's FFTs there: solvers/_device.py); the transforms in ``dtype`` (float32: a
    1024^2 application in 18 ms against 30 ms, median of 15, 2 threads), z in r's."""

    def __init__(self, grid_shape: tuple[int, int], grid_idx: np.ndarray, space: ArraySpace = HOST,
                 dtype: type = np.float64) -> None:
        self._shape = (int(grid_shape[0]), int(grid_shape[1]))
        self._space = space
        self._q = space.put(floored_wavenumbers(self._shape).astype(dtype))
        idx = np.asarray(grid_idx)
        whole = idx.size == self._shape[0] * self._shape[1] and bool(np.all(idx == np.arange(idx.size)))
        self._idx = None if whole else space.put(idx)  # None: the whole grid in order, no scatter
        self._on = space.xp.zeros(int(np.asarray(grid_idx).size), dtype=bool)
        self._solo: float | None = None
        self.wave_numbers = True  # False once ``simplify(blocks=True)`` dropped them
        self.builds = 0
        self.version = 0  # no factors

    @classmethod
    def build(cls, qp: QP, space: ArraySpace = HOST, dtype: type = np.float64) -> FourierPreconditioner | None:
        g = qp.geometry
        if g is None or g.indices is None or np.asarray(g.indices).size != qp.n:
            return None
        return cls(tuple(g.grid_shape), np.asarray(g.indices), space, dtype)

    @property
    def on(self) -> np.ndarray:
        return self._on

    def update(self, S: np.ndarray) -> None:
        self._on = S.astype(bool)  # a copy

    def apply(self, r: np.ndarray) -> np.ndarray:
        if not self.wave_numbers:
            return self.solo(r * self._on)
        # Masks as products (r finite): several times faster than np.where on a scattered set.
        z = multiply_by_wavenumbers(self._q, self._shape, self._idx, r * self._on, self._space.xp)
        return np.multiply(z, self._on, out=z) if z.dtype == r.dtype else np.multiply(z, self._on, dtype=r.dtype)

    def solo(self, r: np.ndarray) -> np.ndarray:
        """c r: the inverse of M on a one-point set, as the island blocks' r / H_jj, with
        M = F^-1[1/|q|] F, so c = 1 / mean(1/|q|) over the full spectrum (F^-1[1/|q|] at
        offset 0).  In the scale where M approximates H (the steps' tau), an entering
        point takes the force that closes its own gap alone; the diagonal of M^-1, mean |q|,
        is 1.34x that on a large grid, and the Polonsky-Keer loop under a load cycled on it
        at 128^2 (solvers/_constrained.py)."""
        if self._solo is None:
            self._solo = 1.0 / float(sfft.irfft2(1.0 / floored_wavenumbers(self._shape), s=self._shape)[0, 0])
        return self._solo * r

    def simplify(self, blocks: bool = False) -> bool:
        """No coarse part to drop; with ``blocks``, the wave numbers themselves: z = c r on
        the set from then on (``solo``'s scale, the unpreconditioned direction), as the
        island blocks are dropped (``IslandPreconditioner.simplify``): the Polonsky-Keer
        loop under a load cycled on the wave numbers at a KKT error of 0.4-0.55 for 4,500
        iterations on a 128^2 step that it solves in 512 without them.  True when they
        were dropped."""
        if not (blocks and self.wave_numbers):
            return False
        self._forget_ones()
        self.wave_numbers = False
        self.version += 1
        return True

    def progress(self, kkt: float) -> bool:
        """One stage: never changes."""
        return False


def floored_wavenumbers(shape: tuple[int, int]) -> np.ndarray:
    """|q| on the rfft2 half-spectrum of a grid, |q(0, 0)| floored at the lowest
    non-zero |wave number| (so the multiplier below is positive definite; on a side of 2
    points the only non-zero frequency is the Nyquist one, -pi)."""
    p0, p1 = shape
    q0 = 2.0 * np.pi * sfft.fftfreq(p0)
    q1 = 2.0 * np.pi * sfft.rfftfreq(p1)
    q = np.hypot(q0[:, None], q1[None, :])
    q[0, 0] = min(abs(q0[1]) if p0 > 1 else 1.0, q1[1] if q1.size > 1 else 1.0)
    return q


def multiply_by_wavenumbers(q: np.ndarray, shape: tuple[int, int], idx: np.ndarray | None, r: np.ndarray,
                            xp: Any = np) -> np.ndarray:
    """gather_idx F^-1[ q F[scatter_idx r] ] on a grid of ``shape`` (flat indices idx; None:
    r is the whole grid in row-major order), in q's precision and the array module ``xp``
    (numpy: the operator's FFT library, ``spectral_multiply``)."""
    if idx is None:
        f = r.reshape(shape).astype(q.dtype)  # a copy: the transform overwrites it
    else:  # scattered and gathered in bands of the set (``each_band``; idx has no repeats)
        f = xp.zeros(shape, dtype=q.dtype)
        flat = f.ravel()

        def scatter(s: slice) -> None:
            flat[idx[s]] = r[s]

        each_band(scatter, r)
    if xp is np:
        z = spectral_multiply(f, q).ravel()
    else:
        F = xp.fft.rfft2(f)
        F *= q
        z = xp.fft.irfft2(F, s=shape).ravel()
    if idx is None:
        return z
    out = xp.empty(idx.shape, dtype=z.dtype)

    def gather(s: slice) -> None:
        np.take(z, idx[s], out=out[s])

    each_band(gather, out)
    return out


def make_preconditioner(kind: str, qp: QP, block_dtype: type = np.float64,
                        space: ArraySpace = HOST) -> SetPreconditioner | None:
    """The preconditioner ``kind`` (one of ``KINDS``) for CG on sets of ``qp``'s unknowns;
    None for "none", and also when the QP has no grid positions (``QP.geometry``), which
    both preconditioners need: the caller then runs unpreconditioned.  ``block_dtype``:
    the precision of the island blocks' inverses (module doc) and of the wave-number
    preconditioner's transforms (float32 for a mixed solve: a preconditioner has to be
    fixed and near SPD, not exact).  ``space``: where its
    vectors live (the Fourier one runs on a device; the islands on the host only)."""
    kind = resolved_kind(kind, qp)
    if kind in ISLAND_KINDS:
        return IslandPreconditioner.build(qp, dtype=block_dtype, far_field=kind == "farfield")
    if kind == "fourier":
        return FourierPreconditioner.build(qp, space, block_dtype)
    if kind == "none":
        return None
    raise ValueError(f"unknown preconditioner {kind!r}: expected one of {', '.join(KINDS)}")


def on_subset(M: SetPreconditioner, subset: np.ndarray, n: int) -> Callable[[np.ndarray], np.ndarray]:
    """M moved to the set ``subset`` (positions among n) as a map on vectors of length
    |subset|: z_A = (R M^-1 R r)_A, for a CG on the restricted system H_AA x = b."""
    mask = np.zeros(n, dtype=bool)
    mask[subset] = True
    M.update(mask)
    full = np.zeros(n)

    def apply(r: np.ndarray) -> np.ndarray:
        full[subset] = r
        return M.apply(full)[subset]

    return apply
