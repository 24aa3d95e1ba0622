"""Islands kept whole as single blocks (solvers/_partition.py, "Whole islands") and the
Bugnicourt loop letting in the points its direction keeps out (solvers/_ccg.py, "Points kept
out")."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.surfaces import Surface, rmd_surface_n
from contactbench.solvers import _ccg, _partition
from contactbench.solvers._ccg import GapState, bugnicourt
from contactbench.solvers._partition import WHOLE_BUDGET, WHOLE_ISLAND, WHOLE_SHARE, patches, whole_limit
from contactbench.solvers._preconditioners import IslandPreconditioner, make_preconditioner
from tests.helpers import loop_context, pcg_iterations


def brute_whole_limit(sizes: np.ndarray, limit: int, budget: float) -> int:
    """``whole_limit`` as its contract reads, by trying every W."""
    best = limit
    for W in range(limit + 1, WHOLE_ISLAND + 1):
        if W % 16:
            continue
        small, big = sizes[sizes <= W], sizes[sizes > W]
        if float(np.sum(small.astype(float) ** 3)) + limit**2 * float(np.sum(big)) > WHOLE_BUDGET * budget:
            break
        best = W
    return best if np.sum(sizes[sizes > best]) <= WHOLE_SHARE * np.sum(sizes) else limit


@pytest.mark.parametrize("seed", range(12))
def test_whole_limit_is_the_largest_affordable_island_size(seed):
    rng = np.random.default_rng(seed)
    sizes = np.concatenate([rng.integers(1, 40, rng.integers(0, 400)),  # small islands
                            rng.integers(40, 900, rng.integers(0, 30))])  # and some big ones
    if sizes.size == 0:
        sizes = np.array([1])
    limit = int(rng.choice([16, 32, 48, 80, 128]))
    budget = float(rng.choice([1e5, 1e6, 1e7, 1e8]))
    got = whole_limit(sizes, limit, budget)
    assert got == brute_whole_limit(sizes, limit, budget)
    assert got == limit or (got % 16 == 0 and limit < got <= WHOLE_ISLAND)


def test_whole_limit_edges():
    assert whole_limit(np.zeros(0, dtype=int), 48, 1e9) == 48
    assert whole_limit(np.array([300, 300]), 48, 1e12) == WHOLE_ISLAND  # every island affordable
    assert whole_limit(np.array([300, 300]), 48, 1.0) == 48  # nothing affordable
    # most points in islands above WHOLE_ISLAND: the blocks stay as the limit cuts them
    assert whole_limit(np.array([5000, 300, 20]), 48, 1e12) == 48
    assert whole_limit(np.array([600, 300, 300, 20]), 48, 1e12) == WHOLE_ISLAND


def test_patches_keep_islands_up_to_whole_and_cut_the_bigger_ones():
    shape = (60, 60)
    i, j = np.divmod(np.arange(shape[0] * shape[1]), shape[1])
    labels = np.where(j < 20, 0, np.where(j < 30, 1, 2))  # 1,200, 600 and 1,800 points
    out = patches(labels, i, j, shape, limit=48, whole=600)
    assert np.unique(out[labels == 1]).size == 1  # 600 <= whole: one block
    for lab in (0, 2):  # above whole: patches of at most the limit
        blocks = out[labels == lab]
        assert np.unique(blocks).size > 1 and np.bincount(blocks).max() <= 48
    np.testing.assert_array_equal(patches(labels, i, j, shape, 48, whole=10), patches(labels, i, j, shape, 48))


def disks_case(N: int = 96, radius: float = 8.5):
    """A flat punch's trial set and a set of nine disks of ~230 points each on it: above the
    block limit a set of this size gets on this grid (16), below ``WHOLE_ISLAND``."""
    s = Surface(np.zeros((N, N)), 100e-6 / N)
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(1e-7)
    i, j = np.divmod(np.asarray(inst.qp.geometry.indices), N)
    S = np.zeros(inst.n, dtype=bool)
    for ci in (16, 48, 80):
        for cj in (16, 48, 80):
            S |= (i - ci) ** 2 + (j - cj) ** 2 <= radius**2
    return inst, S


def cg_on_set(inst, S: np.ndarray) -> tuple[int, int]:
    """(CG iterations on H_SS p = 1 to 1e-9 with the island blocks, their largest block)."""
    pos = np.flatnonzero(S)
    M = IslandPreconditioner.build(inst.qp)
    M.update(S)
    full = np.zeros(inst.n)

    def prec(r):
        full[pos] = r
        return M.apply(full)[pos]

    its = pcg_iterations(inst.qp.H.submatrix(pos), np.ones(pos.size), prec, tol=1e-9)
    return its, max(bucket.members.shape[1] for bucket in M._buckets)


def test_whole_islands_cut_the_cg_iterations_on_their_set(monkeypatch):
    """Nine islands of ~230 points: whole, one block each; cut into patches of the block
    limit (16 here; ``WHOLE_ISLAND`` set to 0), CG on the fixed set needs many more
    iterations."""
    inst, S = disks_case()
    monkeypatch.setattr(_partition, "WHOLE_BUDGET", 1e6)  # affordable on this small grid
    whole, whole_block = cg_on_set(inst, S)
    monkeypatch.setattr(_partition, "WHOLE_ISLAND", 0)
    cut, cut_block = cg_on_set(inst, S)
    assert whole_block >= 224 and cut_block <= 16
    assert whole < 0.6 * cut, (whole, cut)


class _KeepsOut:
    """A preconditioner whose direction keeps some points at the bound out: the island
    blocks, with z_j turned positive at every third point where p_j = 0 and r_j < 0 (a point
    that should enter), so ``inward`` cuts d_j to 0 there at every iteration."""

    def __init__(self, qp, state: GapState) -> None:
        self.inner = make_preconditioner("islands", qp)
        self.state = state
        self.victims = np.arange(qp.n) % 3 == 0

    @property
    def on(self):
        return self.inner.on

    @property
    def builds(self) -> int:
        return self.inner.builds

    @property
    def version(self) -> int:
        return self.inner.version

    def update(self, S):
        self.inner.update(S)

    def apply(self, r):
        z = self.inner.apply(r)
        out = self.victims & (self.state.p <= 0.0) & (r < 0.0)
        z[out] = np.abs(z[out])
        return z

    def solo(self, r):
        return self.inner.solo(r)

    def ones(self):
        return self.inner.ones()

    def simplify(self, blocks: bool = False) -> bool:
        return False

    def progress(self, kkt: float) -> bool:
        return False


def test_bugnicourt_lets_in_the_points_its_direction_keeps_out(monkeypatch):
    s = rmd_surface_n(33, 0.7, length=100e-6, seed=4)
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(2.0 * paper_max_displacement(s))  # 496 points
    qp = inst.qp

    def run(max_iter: int):
        state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
        return bugnicourt(loop_context(qp, max_iter), state, _KeepsOut(qp, state)), state

    done, state = run(400)
    assert done.converged and kkt_check(inst, state.p).kkt_error <= 1e-8
    monkeypatch.setattr(_ccg, "STALL_PATIENCE", 10**9)  # never let them in
    kept_out, state = run(400)
    assert not kept_out.converged and kept_out.kkt > 1e-6


class _KeepsOutUnderLoad(_KeepsOut):
    """``_KeepsOut`` with what the load-controlled loop also asks of a preconditioner."""

    def ones(self):
        return self.inner.ones()

    def solo(self, r):
        return self.inner.solo(r)

    def progress(self, kkt: float) -> bool:
        return False


def test_load_controlled_bugnicourt_finishes_past_the_points_kept_out(monkeypatch):
    """Under load control the loop has no ``let_in`` (a direction there must keep the load);
    its stagnation test hands a frozen run to the exact finish (solvers/_finish.py), which
    converges where the lying preconditioner keeps points out."""
    from contactbench.solvers import _constrained
    from contactbench.solvers._constrained import bugnicourt_load

    s = rmd_surface_n(33, 0.7, length=100e-6, seed=4)
    b = InstanceBuilder(s, 1e9, "bcc", periodic=False)
    disp = b.build(2.0 * paper_max_displacement(s)).qp
    state = GapState(disp.H, disp.ubar, np.zeros(disp.n))
    assert bugnicourt(loop_context(disp), state).converged
    inst = b.build_load(float(np.sum(state.p)))  # the load that approach carries
    qp = inst.qp

    def run():
        state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
        return bugnicourt_load(loop_context(qp), state, _KeepsOutUnderLoad(qp, state)), state

    done, state = run()
    assert done.converged and done.finish_rounds >= 1
    assert kkt_check(inst, state.p, multiplier=done.multiplier).kkt_error <= 1e-8

    class Never(_constrained.Stagnation):
        def stuck(self, kkt: float) -> bool:
            return False

    monkeypatch.setattr(_constrained, "Stagnation", Never)  # no finish: the run stays frozen
    frozen, _ = run()
    assert not frozen.converged and frozen.kkt > 1e-6
