"""Exploration (fewer matvecs for the large solves): how many CG iterations a coarse correction on top
of the island block-Jacobi preconditioner would save, on the contact set of the paper's cold
top step.  Not a solver: it forms H on the final contact set S densely (feasible up to
2048^2, |S| ~ 11,000) and runs plain PCG on H_SS p = ubar_S to a relative residual of 1e-10
with each preconditioner:

* ``islands``: the solvers' own ``IslandPreconditioner`` on S (strips of up to 128 points);
* ``additive T``: islands + Z (Z' H Z)^-1 Z', Z the indicators of T x T grid tiles on S;
* ``multiplicative T``: the symmetric two-level cycle (two extra products with H per
  application: not affordable in a matrix-free solver, shown as a bound);
* ``woodbury T``: M = B + Z E Z' with E = (Z'Z)^-1 Z' (H - B) Z (Z'Z)^-1, the far-field
  coupling that block-Jacobi leaves out, projected on the tiles, applied by the Woodbury
  identity (no extra product with H; B^-1 Z and an m x m matrix per build).

Usage: python benchmarks/explore_two_level.py [--size 1024] [--tiles 8 16 32 64]
Measured (2026-11-23, code 1b4985f, 2-core Intel Xeon VM; docs/fast-solvers.md "Next lever"):
1024^2 islands 37, woodbury 8: 25; 2048^2 islands 50, woodbury 16: 28, 32: 32, 64: 37 (results/perf/two-level.md).
"""

from __future__ import annotations

import argparse
from typing import Callable

import numpy as np
import scipy.linalg as sla

from contactbench.harness import solve_sequence
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers._preconditioners import IslandPreconditioner
from contactbench.solvers.base import SolverSettings

Precond = Callable[[np.ndarray], np.ndarray]


def pcg_iterations(H: np.ndarray, b: np.ndarray, prec: Precond, tol: float = 1e-10, max_iter: int = 500) -> int:
    """Iterations of preconditioned CG from 0 until ||r|| <= tol ||b||."""
    x, r = np.zeros_like(b), b.copy()
    z = prec(r)
    d, rz = z.copy(), float(r @ z)
    for it in range(1, max_iter + 1):
        q = H @ d
        a = rz / float(d @ q)
        x += a * d
        r -= a * q
        if np.linalg.norm(r) <= tol * np.linalg.norm(b):
            return it
        z = prec(r)
        rz_new = float(r @ z)
        d = z + (rz_new / rz) * d
        rz = rz_new
    return max_iter


def block_matrix(H: np.ndarray, blocks: list[np.ndarray]) -> np.ndarray:
    """B: H's diagonal blocks over ``blocks`` (positions in S), zero elsewhere."""
    B = np.zeros_like(H)
    for bb in blocks:
        B[np.ix_(bb, bb)] = H[np.ix_(bb, bb)]
    return B


def tile_indicators(rows: np.ndarray, cols: np.ndarray, T: int) -> np.ndarray:
    """Z: one column per T x T grid tile holding points of S."""
    label = np.unique((rows // T) * (1 << 20) + cols // T, return_inverse=True)[1]
    Z = np.zeros((rows.size, int(label.max()) + 1))
    Z[np.arange(rows.size), label] = 1.0
    return Z


def coarse_solve(H: np.ndarray, Z: np.ndarray) -> Precond:
    factor = sla.cho_factor(Z.T @ H @ Z)
    return lambda r: Z @ sla.cho_solve(factor, Z.T @ r)


def woodbury(H: np.ndarray, B: np.ndarray, Binv: Precond, Z: np.ndarray) -> Precond:
    w = 1.0 / Z.sum(axis=0)
    E = w[:, None] * (Z.T @ (H - B) @ Z) * w[None, :]
    E = 0.5 * (E + E.T)
    BZ = np.column_stack([Binv(Z[:, j]) for j in range(Z.shape[1])])
    K = np.linalg.inv(np.linalg.pinv(E) + Z.T @ BZ)
    return lambda r: Binv(r) - BZ @ (K @ (BZ.T @ r))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--tiles", type=int, nargs="+", default=[8, 16, 32, 64])
    args = ap.parse_args()
    surf = rmd_surface_n(args.size, 0.7, length=100e-6, seed=0)
    inst = InstanceBuilder(surf, 1e9, "bcc", periodic=False).build(paper_max_displacement(surf))
    qp = inst.qp
    (step,) = solve_sequence("fast-dual-pccg", [inst], SolverSettings(tol=1e-9))
    S = step.result.p > 0
    pos = np.flatnonzero(S)
    H, b = qp.H.submatrix(pos), qp.ubar[pos]
    M = IslandPreconditioner.build(qp)
    assert M is not None
    M.update(S)
    full = np.zeros(qp.n)

    def Binv(r: np.ndarray) -> np.ndarray:
        full[:] = 0.0
        full[pos] = r
        return M.apply(full)[pos]

    where = np.full(qp.n, -1)
    where[pos] = np.arange(pos.size)
    blocks = [where[m[m >= 0]] for bucket in M._buckets for m in bucket.members]
    B = block_matrix(H, blocks)
    alone = B.diagonal() == 0  # one-point blocks: the diagonal
    B[alone, alone] = H.diagonal()[alone]
    idx = np.asarray(qp.geometry.indices)[pos]
    gi, gj = np.divmod(idx, qp.geometry.grid_shape[1])
    print(f"N = {args.size}, n = {qp.n}, |S| = {pos.size}, island blocks <= {M._limit} points")
    print(f"islands: {pcg_iterations(H, b, Binv)} iterations")
    for T in args.tiles:
        Z = tile_indicators(gi, gj, T)
        C = coarse_solve(H, Z)

        def multiplicative(r: np.ndarray, C: Precond = C) -> np.ndarray:
            y = C(r)
            z = y + Binv(r - H @ y)
            return z + C(r - H @ z)

        print(f"T = {T:3d} (m = {Z.shape[1]}): additive {pcg_iterations(H, b, lambda r: Binv(r) + C(r))}, "
              f"multiplicative {pcg_iterations(H, b, multiplicative)}, "
              f"woodbury {pcg_iterations(H, b, woodbury(H, B, Binv, Z))}")


if __name__ == "__main__":
    main()
