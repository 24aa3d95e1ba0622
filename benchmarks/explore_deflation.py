"""Exploration (the held-out worst member's products): how many CG iterations a deflated
two-level preconditioner would take on a solve's final contact set, against the default
island blocks and far field.

For each member (keys of bench_surface_population.py) this solves the cold top step with
``fast-dual-pccg``'s defaults, takes the answer's contact set S, and runs preconditioned CG
(``bench_set_finding.cg_on_set``) on H_SS p = ubar_S from 0 until the max-norm residual falls by
1e-9, as bench_set_finding.py does, with:

* ``default``: ``make_preconditioner("farfield")`` on S -- the island blocks B and the far
  field's Woodbury correction (solvers/_farfield.py);
* ``bnn blocks``: the balancing (BNN) form of deflation, z = P' B^-1 P r + Q r, with
  Q = Z E^-1 Z', P = I - AZ E^-1 Z', E = Z' AZ, Z the far field's aggregates (T x T tiles,
  whole blocks) -- symmetric for any AZ, so a projected loop's changing residual keeps it
  valid, unlike A-DEF2, which needs its start;
* ``bnn overlap``: the same over additive Schwarz blocks, each island block grown by one
  ring of its grid neighbours in S (the Woodbury form cannot take overlapping blocks);
* with AZ exact (one product per aggregate: ``--exact``) or approximated: exact sums over
  the aggregate's members for the points within ``--near`` tiles of its centroid, a point
  mass |a| H(x_i, c_a) beyond (what a build could afford); with ``--exact`` also the
  aggregates smoothed once by the blocks, Z_s = Z - omega B^-1 AZ, and H Z_s exact.

``--point-tiles T ...`` adds a table of the balancing deflation with Z the points' own T x T
tiles (aggregates may split blocks, which the Woodbury form cannot take), over three kinds of
blocks: today's (islands above ``_partition.WHOLE_ISLAND`` points cut into patches), patches
of up to 512 points (the build budget lifted), and every island whole (a dense block each:
slow where islands hold thousands of points).

``--inner K ...`` adds, under the same deflation on the first ``--point-tiles`` T, blocks
that approximate every island's exact solve: islands of up to ``_partition.WHOLE_ISLAND``
points whole (the whole-island budgets lifted), and on each bigger island K iterations of
PCG on H_II with today's patch blocks (``_kit.conjugate_gradient`` from 0; its products
restricted to the island, so on the island's padded bounding box they would cost that box's
share of a product).  Printed: the outer iterations, and outer x (1 + K x the boxes' share of
the padded grid) -- the work in products.

``--in-loop T`` measures the whole cold solve instead, with the far field replaced *in the
solver's loop* by the balancing deflation on T x T point tiles around the island blocks
(``balancing_in_loop``: built where the far field would be built, applied on the loop's
changing set), beside the default; ``--whole`` adds the same with every island one block.

Not a solver: AZ is an |S| x m dense array, and the overlapping blocks are factored one by
one.  Usage:
  python benchmarks/explore_deflation.py saupe:1024:0.9:0.1:3 periodic:1024:0.9:0.1:6 [--exact]
      [--point-tiles 16 8] [--inner 2 3] [--in-loop 8 [--whole]]
"""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Callable, Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_surface_population as bp  # noqa: E402
from bench_set_finding import cg_on_set, cold_solve  # noqa: E402

from contactbench.solvers import _partition, _preconditioners  # noqa: E402
from contactbench.solvers._farfield import tile_size  # noqa: E402
from contactbench.solvers._kit import conjugate_gradient  # noqa: E402
from contactbench.solvers._preconditioners import IslandPreconditioner, make_preconditioner  # noqa: E402

Map = Callable[[np.ndarray], np.ndarray]
NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))


def island_blocks(M: IslandPreconditioner) -> list[np.ndarray]:
    """The positions of each block M built, and each point of its set outside them alone."""
    blocks = [members[valid] for b in M._buckets for members, valid in zip(b.members, b.valid)]
    covered = np.zeros(M.n, dtype=bool)
    for blk in blocks:
        covered[blk] = True
    return blocks + [np.array([k]) for k in M._pos[~covered[M._pos]]]


def one_ring(M: IslandPreconditioner, S: np.ndarray, block: np.ndarray) -> np.ndarray:
    """``block`` and its grid neighbours (8-connected) in S."""
    rows, cols = M._i[block], M._j[block]
    grown = [block]
    for di, dj in NEIGHBOURS:
        ii, jj = rows + di, cols + dj
        ok = (ii >= 0) & (ii < M._shape[0]) & (jj >= 0) & (jj < M._shape[1])
        where = M._where[ii[ok] * M._shape[1] + jj[ok]]
        grown.append(where[(where >= 0) & S[np.maximum(where, 0)]])
    return np.unique(np.concatenate(grown))


def schwarz(qp, blocks: list[np.ndarray]) -> Map:
    """Additive Schwarz: sum over the (overlapping) blocks of R' H_bb^-1 R r."""
    inverses = [np.linalg.inv(qp.H.submatrix(b, b)) for b in blocks]

    def apply(r: np.ndarray) -> np.ndarray:
        z = np.zeros_like(r)
        for b, inv in zip(blocks, inverses):
            z[b] += inv @ r[b]
        return z

    return apply


def approximate_AZ(qp, M: IslandPreconditioner, pos: np.ndarray, agg: np.ndarray, m: int, tile: int,
                   near: float) -> np.ndarray:
    """AZ on S: exact member sums within ``near`` tiles of each aggregate's centroid, a
    point mass at its member nearest the centroid beyond."""
    i, j = M._i[pos].astype(float), M._j[pos].astype(float)
    count = np.bincount(agg, minlength=m).astype(float)
    ci, cj = np.bincount(agg, weights=i, minlength=m) / count, np.bincount(agg, weights=j, minlength=m) / count
    AZ = np.empty((pos.size, m))
    for a in range(m):
        members = np.flatnonzero(agg == a)
        rep = pos[members[np.argmin((i[members] - ci[a]) ** 2 + (j[members] - cj[a]) ** 2)]]
        close = np.hypot(i - ci[a], j - cj[a]) <= near * tile
        AZ[close, a] = qp.H.submatrix(pos[close], pos[members]).sum(axis=1)
        far = np.flatnonzero(~close)
        AZ[far, a] = count[a] * qp.H.entries(pos[far], np.full(far.size, rep))
    return AZ


def exact_AZ(qp, pos: np.ndarray, agg: np.ndarray, m: int) -> np.ndarray:
    AZ = np.empty((pos.size, m))
    for a in range(m):
        e = np.zeros(qp.n)
        e[pos[agg == a]] = 1.0
        AZ[:, a] = qp.H.matvec(e)[pos]
    return AZ


@dataclass(frozen=True)
class Basis:
    """A coarse basis Z (|S| x m) by its two actions: Z' x (x a vector or an |S| x k array)
    and Z c."""

    transpose: Map
    times: Map


def aggregates(agg: np.ndarray, m: int) -> Basis:
    """Z the indicators of the aggregates ``agg`` (one label in 0..m-1 a position)."""

    def transpose(x: np.ndarray) -> np.ndarray:
        out = np.zeros((m,) + x.shape[1:])
        np.add.at(out, agg, x)
        return out

    return Basis(transpose, lambda c: c[agg])


def dense(Z: np.ndarray) -> Basis:
    return Basis(lambda x: Z.T @ x, lambda c: Z @ c)


def balancing(pos: np.ndarray, Z: Basis, AZ: np.ndarray, inner: Map) -> Map:
    """z = P' inner(P r) + Q r (module doc), on the positions ``pos``; AZ = H_SS Z (or its
    approximation)."""
    E = Z.transpose(AZ)
    Einv = np.linalg.inv(0.5 * (E + E.T))

    def apply(r: np.ndarray) -> np.ndarray:
        rs = r[pos]
        c = Einv @ Z.transpose(rs)
        Pr = np.zeros_like(r)
        Pr[pos] = rs - AZ @ c
        y = inner(Pr)[pos]
        z = np.zeros_like(r)
        z[pos] = y - Z.times(Einv @ (AZ.T @ y)) + Z.times(c)
        return z

    return apply


def smoothed_basis(qp, pos: np.ndarray, agg: np.ndarray, AZ: np.ndarray, smoother: Map,
                   omega: float) -> tuple[np.ndarray, np.ndarray]:
    """Z_s = Z - omega B^-1 AZ (the aggregates smoothed once by the island blocks) and
    H_SS Z_s, one product per column (exact)."""
    m = AZ.shape[1]
    Zs = np.zeros((pos.size, m))
    Zs[np.arange(pos.size), agg] = 1.0
    AZs = np.empty_like(Zs)
    for a in range(m):
        col = np.zeros(qp.n)
        col[pos] = AZ[:, a]
        Zs[:, a] -= omega * smoother(col)[pos]
        full = np.zeros(qp.n)
        full[pos] = Zs[:, a]
        AZs[:, a] = qp.H.matvec(full)[pos]
    return Zs, AZs


def explore(key: str, exact: bool, near: float, tiles: list[int], inners: list[int]) -> None:
    inst, _ = bp.top_step(bp.Member.parse(key))
    qp = inst.qp
    step = cold_solve(inst)
    S = step.result.p > 0.0
    pos = np.flatnonzero(S)
    far = make_preconditioner("farfield", qp)
    far.far_fraction = 1.0
    far.update(S)
    blocks_only = make_preconditioner("islands", qp)
    blocks_only.update(S)
    agg = far._far.aggregate[pos]
    m = int(agg.max()) + 1
    tile = tile_size(far._i[pos], far._j[pos])
    print(f"{key}: |S| {pos.size}, trial set {qp.n}, solve {step.result.matvecs} products, "
          f"{m} aggregates on {tile} x {tile} tiles")
    print(f"  default (blocks + far field): {cg_on_set(qp, S, far.apply)}")
    print(f"  blocks alone: {cg_on_set(qp, S, blocks_only.apply)}")
    overlap = schwarz(qp, [one_ring(blocks_only, S, b) for b in island_blocks(blocks_only)])
    print(f"  one-ring overlapping blocks alone: {cg_on_set(qp, S, overlap)}")
    kinds = [("approximated", approximate_AZ(qp, far, pos, agg, m, tile, near))]
    if exact:
        kinds.insert(0, ("exact", exact_AZ(qp, pos, agg, m)))
    for name, AZ in kinds:
        print(f"  bnn blocks, AZ {name}: {cg_on_set(qp, S, balancing(pos, aggregates(agg, m), AZ, blocks_only.apply))}")
        print(f"  bnn overlap, AZ {name}: {cg_on_set(qp, S, balancing(pos, aggregates(agg, m), AZ, overlap))}")
    if exact:
        for omega in (0.5, 1.0):
            Zs, AZs = smoothed_basis(qp, pos, agg, kinds[0][1], blocks_only.apply, omega)
            print(f"  bnn overlap, smoothed aggregates (omega {omega}, exact): "
                  f"{cg_on_set(qp, S, balancing(pos, dense(Zs), AZs, overlap))}")
    if tiles:
        point_tiles(qp, S, tiles, near)
    if inners:
        inner_table(qp, S, (tiles or [8])[0], inners, near)


#: The blocks under the point-tile deflation: module constants to set while they are built.
BLOCK_KINDS = {
    "today's": {},
    "patches of up to 512 points": {(_preconditioners, "BUILD_BUDGET"): 1e4, (_preconditioners, "MAX_BLOCK"): 512},
    "islands up to WHOLE_ISLAND whole": {(_partition, "WHOLE_BUDGET"): 1e12, (_partition, "WHOLE_SHARE"): 1.0},
    "every island whole": {(_partition, "WHOLE_ISLAND"): 10**6, (_partition, "WHOLE_BUDGET"): 1e12,
                           (_partition, "WHOLE_SHARE"): 1.0},
}


@contextmanager
def patched(values: dict) -> Iterator[None]:
    saved = {key: getattr(*key) for key in values}
    for (module, name), value in values.items():
        setattr(module, name, value)
    try:
        yield
    finally:
        for (module, name), value in saved.items():
            setattr(module, name, value)


def point_tiles(qp, S: np.ndarray, tiles: list[int], near: float) -> None:
    """The ``--point-tiles`` table (module doc) for the set S."""
    pos = np.flatnonzero(S)
    print("  | blocks | default | blocks alone | " + " | ".join(f"bnn, {T} x {T} point tiles" for T in tiles) + " |")
    for kind, values in BLOCK_KINDS.items():
        with patched(values):
            blocks = IslandPreconditioner.build(qp, max_block=_preconditioners.MAX_BLOCK)
            blocks.update(S)
            far = IslandPreconditioner.build(qp, max_block=_preconditioners.MAX_BLOCK, far_field=True)
            far.far_fraction = 1.0
            far.update(S)
        cells = [cg_on_set(qp, S, far.apply), cg_on_set(qp, S, blocks.apply)]
        for T in tiles:
            i, j = blocks._i[pos], blocks._j[pos]
            agg = np.unique((i // T) * (1 << 32) + j // T, return_inverse=True)[1].ravel()
            m = int(agg.max()) + 1
            AZ = approximate_AZ(qp, blocks, pos, agg, m, T, near)
            cells.append(cg_on_set(qp, S, balancing(pos, aggregates(agg, m), AZ, blocks.apply)))
        print(f"  | {kind} | " + " | ".join(str(c) for c in cells) + " |", flush=True)


def island_solves(qp, S: np.ndarray, K: int) -> tuple[Map, float]:
    """The ``--inner`` blocks (module doc) on S, and the padded bounding boxes' share of the
    padded grid over the islands above ``WHOLE_ISLAND`` points."""
    with patched(BLOCK_KINDS["islands up to WHOLE_ISLAND whole"]):
        blocks = make_preconditioner("islands", qp)
        blocks.update(S)
    pos = np.flatnonzero(S)
    islands = blocks._components(pos)
    sizes = np.bincount(islands)
    big = [pos[islands == c] for c in np.flatnonzero(sizes > _partition.WHOLE_ISLAND)]
    i, j = blocks._i, blocks._j
    share = sum(float((np.ptp(i[b]) + 1) * (np.ptp(j[b]) + 1)) for b in big) / float(np.prod(blocks._shape))
    masks = []
    for b in big:
        mask = np.zeros(qp.n, dtype=bool)
        mask[b] = True
        masks.append(mask)

    def apply(r: np.ndarray) -> np.ndarray:
        z = blocks.apply(r)
        for b, mask in zip(big, masks):
            run = conjugate_gradient(lambda d, mask=mask: np.where(mask, qp.H.matvec(d), 0.0), np.where(mask, r, 0.0),
                                     None, atol=0.0, max_iter=K, precond=lambda v, mask=mask: np.where(mask, blocks.apply(v), 0.0))
            z[b] = run.x[b]
        return z

    return apply, share


def inner_table(qp, S: np.ndarray, T: int, inners: list[int], near: float) -> None:
    """The ``--inner`` rows (module doc) for the set S under the deflation on T x T point tiles."""
    pos = np.flatnonzero(S)
    grid = make_preconditioner("islands", qp)
    i, j = grid._i[pos], grid._j[pos]
    agg = np.unique((i // T) * (1 << 32) + j // T, return_inverse=True)[1].ravel()
    m = int(agg.max()) + 1
    AZ = approximate_AZ(qp, grid, pos, agg, m, T, near)
    for K in inners:
        apply, share = island_solves(qp, S, K)
        outer = cg_on_set(qp, S, balancing(pos, aggregates(agg, m), AZ, apply))
        print(f"  bnn on {T} x {T} point tiles, islands whole up to {_partition.WHOLE_ISLAND} points and {K} inner "
              f"iterations on the bigger ones (their boxes: {share:.3f} of the grid): {outer} outer, "
              f"{outer * (1 + K * share):.1f} products' work", flush=True)


class LoopBalancing:
    """The balancing deflation on T x T point tiles (approximated AZ), built on the set S and
    applied on the loop's current set ``pos``: its points outside S take no coarse part, so
    the operator stays z = P' inner(P r) + Q r, symmetric positive definite for any AZ."""

    def __init__(self, M: IslandPreconditioner, S: np.ndarray, tile: int, near: float) -> None:
        pos = np.flatnonzero(S)
        T = tile
        while True:  # at most 2048 aggregates (an m x m inverse per build)
            labels, agg = np.unique((M._i[pos] // T) * (1 << 32) + M._j[pos] // T, return_inverse=True)
            if labels.size <= 2048:
                break
            T *= 2
        self.agg, self.m = agg.ravel(), labels.size
        self.AZ = approximate_AZ(SimpleNamespace(H=M.H), M, pos, self.agg, self.m, T, near)
        E = np.zeros((self.m, self.m))
        np.add.at(E, self.agg, self.AZ)
        self.Einv = np.linalg.inv(0.5 * (E + E.T))
        self.row = np.full(M.n, -1)
        self.row[pos] = np.arange(pos.size)

    def apply(self, r: np.ndarray, pos: np.ndarray, inner: Map) -> np.ndarray:
        row = self.row[pos]
        keep = row >= 0
        p, rw = pos[keep], row[keep]
        a = self.agg[rw]
        c = self.Einv @ np.bincount(a, weights=r[p], minlength=self.m)
        Pr = np.zeros_like(r)
        Pr[pos] = r[pos]
        Pr[p] -= self.AZ[rw] @ c
        z = inner(Pr)
        g = self.Einv @ (self.AZ[rw].T @ z[p])
        z[p] += c[a] - g[a]
        return z


@contextmanager
def balancing_in_loop(tile: int, near: float) -> Iterator[None]:
    """While on, an island preconditioner builds a ``LoopBalancing`` wherever it would build
    its far field, and applies it around its blocks instead of the Woodbury correction."""
    cls = IslandPreconditioner
    saved = cls.apply, cls._update_far_field, cls.simplify

    def apply(self: IslandPreconditioner, r: np.ndarray) -> np.ndarray:
        bal = getattr(self, "_balancing", None)
        if bal is None:
            return saved[0](self, r)
        far, self._far = self._far, None
        try:
            return bal.apply(r, self._pos, lambda x: saved[0](self, x))
        finally:
            self._far = far

    def update_far_field(self: IslandPreconditioner, S: np.ndarray) -> None:
        before = self._far_set
        saved[1](self, S)
        if self._far_set is not before:  # the far field was (re)built, or dropped
            self._balancing = LoopBalancing(self, S, tile, near) if self._far is not None else None

    def simplify(self: IslandPreconditioner, blocks: bool = False) -> bool:
        self._balancing = None
        return saved[2](self, blocks)

    cls.apply, cls._update_far_field, cls.simplify = apply, update_far_field, simplify
    try:
        yield
    finally:
        cls.apply, cls._update_far_field, cls.simplify = saved


def in_loop(key: str, tile: int, near: float, whole: bool) -> None:
    """The ``--in-loop`` line of one member: products of the whole cold solve (module doc)."""
    inst, _ = bp.top_step(bp.Member.parse(key))

    def products() -> str:
        step = cold_solve(inst)
        return f"{step.result.matvecs} ({step.verdict.status})"

    cells = [f"default {products()}"]
    with balancing_in_loop(tile, near):
        cells.append(f"bnn on {tile} x {tile} point tiles {products()}")
    if whole:
        with patched(BLOCK_KINDS["every island whole"]):
            cells.append(f"every island whole {products()}")
            with balancing_in_loop(tile, near):
                cells.append(f"every island whole + bnn {products()}")
    print(f"{key}: whole-solve products: " + ", ".join(cells), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("members", nargs="+", help="member keys, e.g. saupe:1024:0.9:0.1:3")
    ap.add_argument("--exact", action="store_true", help="also AZ exact, one product per aggregate")
    ap.add_argument("--near", type=float, default=1.5, help="exact sums within this many tiles (default 1.5)")
    ap.add_argument("--point-tiles", type=int, nargs="*", default=[], help="tile sides T of the point-tile table")
    ap.add_argument("--inner", type=int, nargs="*", default=[], help="inner iterations K on the big islands")
    ap.add_argument("--in-loop", type=int, default=0, help="the whole solve with bnn on T x T point tiles in the loop")
    ap.add_argument("--whole", action="store_true", help="with --in-loop: also every island one block")
    args = ap.parse_args()
    if args.near <= 0.0 or any(T < 1 for T in args.point_tiles) or any(K < 1 for K in args.inner) \
            or args.in_loop < 0:
        ap.exit(2, "explore_deflation: --near must be > 0, --point-tiles, --inner and --in-loop >= 1\n")
    for key in args.members:
        try:
            bp.Member.parse(key)
        except ValueError as err:
            ap.exit(2, f"explore_deflation: member {key!r} is not family:size:hurst:rms-slope:seed ({err})\n")
    for key in args.members:
        if args.in_loop:
            in_loop(key, args.in_loop, args.near, args.whole)
        else:
            explore(key, args.exact, args.near, args.point_tiles, args.inner)


if __name__ == "__main__":
    main()
