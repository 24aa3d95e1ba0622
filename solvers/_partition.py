"""How the island preconditioner cuts a set into blocks (not a solver module: the registry
skips "_" names): ``IslandPreconditioner`` in solvers/_preconditioners.py inverts one dense
block per piece, so the pieces decide what its blocks hold.

A set's 8-connected islands are its pieces, within two limits.  The block limit (``limit``,
``IslandPreconditioner.block_limit``: 128 points, fewer on a large set) bounds the build of
a set whose islands are all big; an island above it is cut into grid patches.  Islands of
up to ``WHOLE_ISLAND`` points stay whole where the build can afford them (``whole_limit``).

Blocks of big islands: on smooth surfaces (Saupe RMD, H 0.9, rms slope 0.1) the contact set
is a few islands of hundreds to thousands of points (1024^2: 11,382 points, the largest
islands 3,350 and 696; 54 % of the set in islands above 128 points), far above the block
limit (48 on that set).  Cut into runs of consecutive row-major points, as they once were,
such an island's blocks are pieces of single grid rows: they hold the coupling along a row
and none across rows, and CG on the fixed contact set crawled (the default needed 158
matvecs there, 3.2x the population's median; float64 with the islands alone 157).  Cut by
the grid into h x w patches (``patch_shape``: h = floor(sqrt(limit)), w = limit // h; 6 x 8
for 48), every block holds a point's nearest neighbours in both directions: 158 -> 84
matvecs on that member; on a disk of 1,804 points at 64^2 with 16-point blocks, CG on the
fixed set needs 35 iterations instead of 66.

Whole islands: the block limit follows from the set's size alone, as if every point sat in
a full block (``BUILD_BUDGET``: |S| s^2 <= 40 grid points), so on a set of 4,874 points at
1024^2 it is 80, and the set's islands of 147-273 points were cut although their blocks cost
little.  Patches of one island leave the strong coupling across their edges out of the
blocks, and there the far field (solvers/_farfield.py), which averages over 16 x 16 tiles,
does not put it back: PCG on that final contact set (measured, H 0.7, rms slope 0.3, seed 6)
needs 29 iterations, and 15 with every island whole.  So an island of up to ``WHOLE_ISLAND``
points is one block when the build's work, counted as ``block_limit`` counts it (s^3 a
block of s points, i.e. s^2 a point), stays within ``WHOLE_BUDGET`` times the build budget.
Where most of the set lies in islands above that (``WHOLE_SHARE``: islands of thousands of
points, H 0.9), the patches and the far field set the rate whatever the smaller islands
get (the same 31 PCG iterations on the final set of the population's worst member, seed 3),
so the blocks stay as the limit cuts them and the build costs what it did.  Figures:
results/perf/whole-islands.

Inverting the blocks (``block_inverses``): a short batch of wide blocks (``by_cholesky``)
is inverted one block a LAPACK call by Cholesky (potrf, potri: a third of LU's work, and
the inverse exactly symmetric); the rest by NumPy's batched LU in one call, whose
per-block work is too small to pay for a call each.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

#: Islands of up to this many points can be one block each, whatever the block limit ...
WHOLE_ISLAND = 512

#: ... while the build's work stays within this many times the build budget ...
WHOLE_BUDGET = 4.0

#: ... and the islands above that hold at most this fraction of the set's points.
WHOLE_SHARE = 0.5


def block_width(sizes: np.ndarray) -> np.ndarray:
    """Padded block size: powers of two up to 16, then multiples of 16 (little padding)."""
    small = 1 << np.ceil(np.log2(np.maximum(sizes, 1))).astype(np.int64)
    return np.where(sizes <= 16, small, 16 * ((sizes + 15) // 16))


def patch_shape(limit: int) -> tuple[int, int]:
    """Rows and columns of the grid patches a big island is cut into: h = floor(sqrt(limit)),
    w = limit // h, so a patch holds at most ``limit`` points and is as square as that allows."""
    h = max(1, int(np.sqrt(limit)))
    return h, max(1, limit // h)


def whole_limit(sizes: np.ndarray, limit: int, budget: float) -> int:
    """The largest island kept whole, given the island ``sizes`` of a set, its block
    ``limit`` and its build ``budget`` (``BUILD_BUDGET`` x grid points): the largest W in
    (limit, ``WHOLE_ISLAND``], a multiple of 16, with sum_{s <= W} s^3 + limit^2
    sum_{s > W} s <= ``WHOLE_BUDGET`` x budget -- the work of the whole islands' blocks and
    of the bigger islands' patches (module doc).  ``limit`` itself where no W fits, or where
    the islands above W hold more than ``WHOLE_SHARE`` of the points."""
    sizes = np.sort(np.asarray(sizes, dtype=np.int64))
    if sizes.size == 0:
        return limit
    whole = np.cumsum(sizes.astype(float) ** 3)  # the work of the k smallest islands kept whole
    rest = np.cumsum(sizes[::-1].astype(float))[::-1]  # the points of the islands from k on
    best = limit
    for W in range(16 * (limit // 16 + 1), WHOLE_ISLAND + 1, 16):
        k = int(np.searchsorted(sizes, W, side="right"))
        work = (whole[k - 1] if k else 0.0) + (limit**2 * rest[k] if k < sizes.size else 0.0)
        if work > WHOLE_BUDGET * budget:
            break
        best = W
    beyond = float(np.sum(sizes[sizes > best]))
    return best if beyond <= WHOLE_SHARE * float(rest[0]) else limit


def patches(labels: np.ndarray, i: np.ndarray, j: np.ndarray, shape: tuple[int, int], limit: int,
            whole: int | None = None) -> np.ndarray:
    """Block labels of a set's points: the island ``labels`` (one per point, grid row ``i``
    and column ``j``), with every island above ``whole`` points (default ``limit``) cut by
    the grid into ``patch_shape(limit)`` patches (module doc).  Labels are 0..k-1; no block
    holds more than max(limit, whole) points."""
    labels = np.asarray(labels, dtype=np.int64)
    if labels.size == 0:
        return labels
    big = np.bincount(labels)[labels] > (limit if whole is None else max(limit, whole))
    if not big.any():
        return labels
    h, w = patch_shape(limit)
    cols = -(-shape[1] // w)
    tiles = (-(-shape[0] // h)) * cols
    key = np.where(big, labels.max() + 1 + labels * tiles + (i // h) * cols + j // w, labels)
    return np.unique(key, return_inverse=True)[1].ravel()


#: Block width from which ``block_inverses`` inverts by Cholesky, a block a call ...
#: Measured on 2 AMD EPYC cores, float32: one block of 192 in 0.48 ms against LU's 1.35,
#: six of 64 in 0.25 against 0.47; 70 blocks of 16 in 0.45 against 0.30.
CHOLESKY_FROM = 48
#: ... in a batch of at most this many blocks: the calls hold the GIL, so a long batch
#: is LU's, shared out over the threads.
CHOLESKY_MAX_BLOCKS = 64


def by_cholesky(m: int, s: int) -> bool:
    """Whether ``block_inverses`` inverts m blocks of s points one by one by Cholesky."""
    return s >= CHOLESKY_FROM and m <= CHOLESKY_MAX_BLOCKS


def block_inverses(blocks: np.ndarray, cholesky: bool) -> np.ndarray:
    """The inverses of a batch (m, s, s) of symmetric positive definite blocks, in their
    dtype, symmetric, by Cholesky a block at a time or by batched LU (``cholesky``: the
    caller decides for a whole bucket, ``by_cholesky``, so that each block is inverted on
    its own the same way however the bucket is cut into batches).  Under Cholesky a block
    it cannot factor in this precision is inverted by LU and symmetrised;
    ``np.linalg.LinAlgError`` when one is singular, as ``np.linalg.inv`` raises."""
    if not cholesky:
        return _symmetrised(np.linalg.inv(blocks))
    potrf, potri = lapack.get_lapack_funcs(("potrf", "potri"), (blocks,))
    out = np.empty_like(blocks)
    for i in range(blocks.shape[0]):
        c, info = potrf(blocks[i], lower=1, clean=0)
        if info == 0:
            x, info = potri(c, lower=1)  # the inverse in the lower triangle
        if info != 0:  # not numerically positive definite here: LU's inverse, symmetrised
            out[i] = _symmetrised(np.linalg.inv(blocks[i]))
            continue
        out[i] = np.tril(x) + np.tril(x, -1).T
    return out


def _symmetrised(inverse: np.ndarray) -> np.ndarray:
    """LU's inverse is symmetric only up to round-off: (X + X') / 2."""
    inverse += np.swapaxes(inverse, -1, -2)
    inverse *= 0.5
    return inverse
