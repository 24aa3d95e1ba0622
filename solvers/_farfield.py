"""The far-field correction of the island preconditioner (not a solver module: the registry
skips "_" names): the "farfield" preconditioner of solvers/_preconditioners.py.

Block-Jacobi over contact islands (``IslandPreconditioner``) inverts the short-range part of
H_SS exactly and leaves out the coupling *between* blocks.  H is a compliance, its large
eigenvalues are the smooth modes, and that coupling is what makes B^-1 H large on them: the
CG iterations on a fixed contact set grow with the grid (37 at 1024^2, 50 at 2048^2 on the
paper's top step).  The correction puts the coupling back on a coarse space:

    M = B + Z E Z',   E = W Z'(H - B)Z W,   W = diag(1 / |aggregate|),

with Z the indicators of *aggregates*: the set's points grouped by T x T grid tiles, whole
blocks at a time (a block goes to the tile of its first point), so that B^-1 Z = diag(v) Z
with v = B^-1 1.  M^-1 follows from the Woodbury identity with no product with H:

    M^-1 = B^-1 - V Z K Z' V,   K = D^-1/2 Q diag(mu / (1 + mu)) Q' D^-1/2,

where D = Z' B^-1 Z (diagonal), D^1/2 E D^1/2 = Q diag(mu) Q' with the negative mu clipped
to 0 (E+ is positive semidefinite, so M is SPD and K < D^-1 keeps M^-1 positive definite).
Z'HZ is summed exactly over neighbouring tiles (``ContactOperator.unit_sums``: gathered from
the kernel table, or by small FFT windows for populous aggregates) and
taken as point masses |I| |J| H(c_I, c_J) between farther ones (c: the member nearest the
aggregate's centroid).  Measured offline on the fixed contact set (results/perf/two-level.md):
37 -> 25 iterations at 1024^2, 50 -> 28 at 2048^2.

The tile T is the smallest of 16, 32, 64, ... giving at most ``MAX_AGGREGATES`` aggregates.
The correction is built only on sets of at most ``MAX_SET_FRACTION`` of the unknowns (a
contact set, not a cold start's first, shrinking trial sets) and while the exact near-tile
sums cost at most the island build's budget of entries read (``unit_sums_cost``), and rebuilt when the set has
drifted by ``REBUILD_FRACTION`` since.  In fast-dual-pccg (its default), the paper's cold
top step: 77 -> 57 iterations at 2048^2, 116 -> 74 at 4096^2 (results/perf/large-cold-top-step.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contactbench.problems.operators import ContactOperator

#: At most this many aggregates (an m x m eigendecomposition per build).
MAX_AGGREGATES = 1024

#: The smallest tile (grid points on a side).
MIN_TILE = 16

#: Rebuild the correction when the set has changed in more than this fraction of its points.
REBUILD_FRACTION = 0.05

#: Built only on sets of at most this fraction of the unknowns: a contact set, not the
#: shrinking trial sets of a cold start's first iterations (there it costs iterations).  A
#: solve opened by the wave numbers (solvers/_opening.py) comes to the islands with those
#: iterations behind it and takes its own fraction (``_opening.OPENED_FAR_FRACTION``).
MAX_SET_FRACTION = 0.2


@dataclass
class FarField:
    """The coarse term of M^-1 on the set it was built for (module doc)."""

    aggregate: np.ndarray  # aggregate of each position of the operator's set (-1: none)
    v: np.ndarray  # B^-1 1 on the set
    K: np.ndarray  # m x m

    def correct(self, z: np.ndarray, r: np.ndarray, pos: np.ndarray) -> None:
        """z -= V Z K Z' V r on the positions ``pos`` (the set now)."""
        a = self.aggregate[pos]
        keep = a >= 0
        p, a = pos[keep], a[keep]
        u = np.bincount(a, weights=self.v[p] * r[p], minlength=self.K.shape[0])
        z[p] -= self.v[p] * (self.K @ u)[a]


def tile_size(i: np.ndarray, j: np.ndarray) -> int:
    """The smallest tile (MIN_TILE, doubled) that gives at most MAX_AGGREGATES occupied tiles."""
    T = MIN_TILE
    while np.unique((i // T) * (1 << 32) + j // T).size > MAX_AGGREGATES:
        T *= 2
    return T


def build_far_field(H: ContactOperator, i: np.ndarray, j: np.ndarray, pos: np.ndarray, lead: np.ndarray,
                    v: np.ndarray, block_sums: np.ndarray, budget: float, max_fraction: float) -> FarField | None:
    """The correction for the set ``pos`` (sorted positions in H's set; ``i``, ``j``: grid row
    and column of every position).  ``lead[k]``: the point whose tile point k's block takes
    (the block's first point; k itself for a one-point block); ``v`` = B^-1 1 and
    ``block_sums[k]`` = sum_l H_kl over k's block, both on the set.  None on a set of more
    than ``max_fraction`` of the unknowns (``MAX_SET_FRACTION`` unless the solve was opened,
    ``IslandPreconditioner.far_fraction``), when the near-tile sums (each pair once) would
    cost more than ``budget`` entries read (``ContactOperator.unit_sums``' cost: on an FFT
    operator, compact populous aggregates are summed by small FFT windows), there is
    one aggregate, or an
    aggregate's 1'B^-1 1 is not positive (round-off in float32 blocks: the Woodbury form
    divides by its square root)."""
    if pos.size < 2 or pos.size > max_fraction * i.size:
        return None
    T = tile_size(i[pos], j[pos])
    lp = lead[pos]
    labels, agg = np.unique((i[lp] // T) * (1 << 32) + j[lp] // T, return_inverse=True)
    m = labels.size
    count = np.bincount(agg, minlength=m).astype(float)
    ti, tj = labels // (1 << 32), labels % (1 << 32)
    if m < 2:
        return None
    A = coarse_matrix(H, i, j, pos, agg, count, later_neighbours(ti, tj), budget)
    if A is None:
        return None
    aggregate = np.full(i.size, -1, dtype=np.int64)
    aggregate[pos] = agg
    w = 1.0 / count
    E = w[:, None] * (A - np.diag(np.bincount(agg, weights=block_sums[pos], minlength=m))) * w[None, :]
    d2 = np.bincount(agg, weights=v[pos], minlength=m)
    if not (np.all(d2 > 0.0) and np.all(np.isfinite(E))):  # 1'B^-1 1 lost to round-off: no correction
        return None
    d = np.sqrt(d2)
    mu, Q = np.linalg.eigh(d[:, None] * E * d[None, :])
    mu = np.maximum(mu, 0.0)
    K = (Q * (mu / (1.0 + mu))) @ Q.T / d[:, None] / d[None, :]
    return FarField(aggregate, v, K)


def coarse_matrix(H: ContactOperator, i: np.ndarray, j: np.ndarray, pos: np.ndarray, agg: np.ndarray,
                  count: np.ndarray, later: list[np.ndarray], budget: float) -> np.ndarray | None:
    """Z'HZ over the aggregates ``agg`` of the set ``pos`` (``count`` members each): the exact
    sums 1_a' H 1_b between neighbouring aggregates (``later``: ``later_neighbours``), and
    the point masses of ``galerkin_far`` between farther ones, made symmetric; None when the
    exact sums would read more than ``budget`` entries (``ContactOperator.unit_sums``)."""
    m = count.size
    members = count.astype(np.int64)
    order = np.argsort(agg, kind="stable")
    starts = np.r_[0, np.cumsum(members)]
    members_of = [pos[order[starts[a]:starts[a + 1]]] for a in range(m)]
    # Exact sums over neighbouring tiles, each pair once (H is symmetric): the displacement
    # of unit forces on each aggregate at the members of its later neighbours.
    near = [np.concatenate([members_of[b] for b in nb]) for nb in later]
    sums = H.unit_sums([(cols, members_of[a]) for a, cols in enumerate(near)], budget)
    if sums is None:
        return None
    A = galerkin_far(H, i, j, pos, agg, count)
    pa = np.repeat(np.arange(m), [nb.size for nb in later])  # the neighbouring pairs (a, b), in near's order
    pb = np.concatenate(later)
    into = np.repeat(pa * m + pb, members[pb])  # the pair of each sum: item a's rows are b's members
    near_sums = np.bincount(into, weights=np.concatenate(sums), minlength=m * m).reshape(m, m)
    A[pa, pb] = A[pb, pa] = near_sums[pa, pb]
    return 0.5 * (A + A.T)


def later_neighbours(ti: np.ndarray, tj: np.ndarray) -> list[np.ndarray]:
    """For each aggregate a (tile row ``ti[a]``, column ``tj[a]``; one aggregate a tile), the
    aggregates b >= a on the tiles around it and its own, in increasing order: each
    neighbouring pair once.  Looked up tile by tile among the sorted tile keys, not
    compared with every aggregate."""
    ti, tj = np.asarray(ti, dtype=np.int64), np.asarray(tj, dtype=np.int64)
    m = ti.size
    key = (ti + 1) * (1 << 32) + (tj + 1)  # + 1: a neighbour's row or column -1 keys above 0
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    pairs_a, pairs_b = [], []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            want = (ti + 1 + di) * (1 << 32) + (tj + 1 + dj)
            at = np.minimum(np.searchsorted(sorted_key, want), max(m - 1, 0))
            hit = sorted_key[at] == want
            a, b = np.flatnonzero(hit), order[at[hit]]
            keep = b >= a
            pairs_a.append(a[keep])
            pairs_b.append(b[keep])
    a, b = np.concatenate(pairs_a), np.concatenate(pairs_b)
    sort = np.lexsort((b, a))
    a, b = a[sort], b[sort]
    return np.split(b, np.searchsorted(a, np.arange(1, m)))


def galerkin_far(H: ContactOperator, i: np.ndarray, j: np.ndarray, pos: np.ndarray, agg: np.ndarray,
                 count: np.ndarray) -> np.ndarray:
    """Point-mass Galerkin sums |I| |J| H(c_I, c_J), c the member nearest the centroid."""
    m = count.size
    ci = np.bincount(agg, weights=i[pos], minlength=m) / count
    cj = np.bincount(agg, weights=j[pos], minlength=m) / count
    dist = (i[pos] - ci[agg]) ** 2 + (j[pos] - cj[agg]) ** 2
    rep = pos[first_nearest(agg, dist, m)]  # one per aggregate, in aggregate order
    rows = np.repeat(rep, m)
    cols = np.tile(rep, m)
    return (count[:, None] * count[None, :]) * H.entries(rows, cols).reshape(m, m)


def first_nearest(agg: np.ndarray, dist: np.ndarray, m: int) -> np.ndarray:
    """For each of the ``m`` aggregates (every one occupied), the first position k in the
    set with ``agg[k]`` = a at its least ``dist``: the minima by ``np.minimum.at``, then the
    first position at its aggregate's minimum."""
    least = np.full(m, np.inf)
    np.minimum.at(least, agg, dist)
    at = np.flatnonzero(dist == least[agg])
    _, first = np.unique(agg[at], return_index=True)
    return at[first]
