"""The island block-Jacobi preconditioner (solvers._preconditioners.py) and the operators'
block gathers it uses, checked against independent constructions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.kkt import kkt_check, relative_error
from contactbench.problems.lcp import exact_solution_on_subset
from contactbench.problems.operators import DenseOperator
from contactbench.problems.surfaces import Surface
from contactbench.solvers._preconditioners import (
    ISLAND_KINDS,
    REBUILD_FRACTION,
    SETTLED_REBUILD_FRACTION,
    SETTLING_FRACTION,
    IslandPreconditioner,
    make_preconditioner,
)
from contactbench.solvers._partition import block_width, patch_shape, patches
from tests.helpers import loop_context, pcg_iterations
from contactbench.solvers.base import ParamError, SolverSettings
from contactbench.solvers.registry import get_solver
from tests.helpers import top_step as build


@pytest.mark.parametrize("kernel,periodic", [("bcc", False), ("love", False), ("bcc", True), ("spectral", True)])
def test_operator_blocks_equal_submatrices(kernel, periodic):
    inst = build(32 if periodic else 33, kernel, periodic)
    H = inst.qp.H
    rng = np.random.default_rng(0)
    members = rng.choice(H.n, size=(5, 7), replace=False)
    members[1, 5:] = -1  # padding
    dense = DenseOperator(H.submatrix(np.arange(H.n), np.arange(H.n)))
    for op in (H, dense):
        blocks = op.blocks(members)
        for k in range(members.shape[0]):
            valid = members[k] >= 0
            m = members[k, valid]
            np.testing.assert_allclose(blocks[k][np.ix_(valid, valid)], H.submatrix(m, m), rtol=1e-14, atol=0)
            pad = np.flatnonzero(~valid)
            np.testing.assert_array_equal(blocks[k][pad][:, pad], np.eye(pad.size))
            assert not np.any(blocks[k][np.ix_(valid, ~valid)])


def islands_by_label(inst, S: np.ndarray) -> list[np.ndarray]:
    """8-connected components of S on the grid, by scipy.ndimage.label."""
    g = inst.qp.geometry
    mask = np.zeros(int(np.prod(g.grid_shape)), dtype=bool)
    mask[g.indices[S]] = True
    lab, k = ndimage.label(mask.reshape(g.grid_shape), structure=np.ones((3, 3)))
    lab_on_set = lab.ravel()[g.indices]
    return [np.flatnonzero(S & (lab_on_set == c)) for c in range(1, k + 1)]


def test_apply_is_the_inverse_of_the_island_blocks():
    inst = build(65)
    H = inst.qp.H
    res = get_solver("fast-dual-ccg").solve(inst.qp, SolverSettings(tol=1e-9))
    S = res.p > 0
    islands = islands_by_label(inst, S)
    assert len(islands) > 5 and max(map(len, islands)) <= 128
    M = IslandPreconditioner.build(inst.qp)
    M.update(S)
    r = np.random.default_rng(1).normal(size=H.n)
    z = M.apply(r)
    expected = np.zeros(H.n)
    for isl in islands:
        expected[isl] = np.linalg.solve(H.submatrix(isl, isl), r[isl])
    np.testing.assert_allclose(z, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
    assert not np.any(z[~S])


def test_a_large_bucket_is_applied_on_threads_to_the_same_numbers(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every bucket shared out over 1, 2 or 3 threads (``PARALLEL_BUCKET_BYTES`` 0): each
    block is its own product, so the numbers are those of one thread, after a drift too
    (members that left the set count as 0)."""
    from contactbench.solvers import _preconditioners

    inst = build(65)
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.3)
    M = IslandPreconditioner(inst.qp.H, inst.qp.geometry.grid_shape, inst.qp.geometry.indices, max_block=16)
    M.update(S)
    S2 = S.copy()
    S2[np.flatnonzero(S)[::40]] = False  # a drift under the rebuild fraction: the blocks stay
    M.update(S2)
    assert M.builds == 1
    r = np.random.default_rng(4).normal(size=inst.n)
    serial = M.apply(r)
    monkeypatch.setattr(_preconditioners, "PARALLEL_BUCKET_BYTES", 0)
    for workers in ("1", "2", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        assert np.array_equal(M.apply(r), serial)
    assert not np.any(serial[~S2]) and np.all(serial[S2] != 0)


def test_big_islands_are_cut_and_the_preconditioner_stays_spd():
    inst = build(65)
    H = inst.qp.H
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.3)  # a large, well-connected set
    M = IslandPreconditioner(H, inst.qp.geometry.grid_shape, inst.qp.geometry.indices, max_block=16)
    M.update(S)
    pos = np.flatnonzero(S)
    P = np.column_stack([M.apply(np.eye(H.n)[:, j]) for j in pos])[pos]
    np.testing.assert_allclose(P, P.T, atol=1e-12 * np.abs(P).max())
    assert np.min(np.linalg.eigvalsh(0.5 * (P + P.T))) > 0
    assert max(b.members.shape[1] for b in M._buckets) <= 16


def test_reuse_between_rebuilds_restricts_to_the_current_set():
    inst = build(65)
    H = inst.qp.H
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.5)
    M = IslandPreconditioner.build(inst.qp)
    M.update(S)
    S2 = S.copy()
    S2[np.flatnonzero(S)[:3]] = False  # small drift: no refactorisation
    M.update(S2)
    assert M.builds == 1
    z = M.apply(np.ones(H.n))
    assert not np.any(z[~S2]) and np.all(z[S2] != 0)


def test_a_settling_set_gets_blocks_of_its_own():
    """A jump of 10 % of the set keeps the blocks (below REBUILD_FRACTION); once the set settles
    (one point changed since the last update) 10 % away from the built set, they are
    refactored, once, and act as blocks built for that set; a settling set within
    SETTLED_REBUILD_FRACTION of the built one keeps them."""
    inst = build(129)
    H = inst.qp.H
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.5)
    pos = np.flatnonzero(S)
    assert pos.size * SETTLING_FRACTION >= 1 and 0.1 < REBUILD_FRACTION and 0.1 > SETTLED_REBUILD_FRACTION
    M = IslandPreconditioner.build(inst.qp)
    M.update(S)
    jumped = S.copy()
    jumped[pos[: pos.size // 10]] = False
    M.update(jumped)
    assert M.builds == 1
    settling = jumped.copy()
    settling[pos[-1]] = False
    M.update(settling)
    assert M.builds == 2
    fresh = IslandPreconditioner.build(inst.qp)
    fresh.update(settling)
    r = np.random.default_rng(3).normal(size=H.n)
    np.testing.assert_allclose(M.apply(r), fresh.apply(r), rtol=1e-12, atol=0)
    still = settling.copy()
    still[pos[-2]] = False
    M.update(still)
    assert M.builds == 2


def test_block_widths_pad_little():
    sizes = np.array([1, 2, 3, 5, 16, 17, 33, 128])
    np.testing.assert_array_equal(block_width(sizes), [1, 2, 4, 8, 16, 32, 48, 128])


def test_preconditioned_ccg_needs_fewer_matvecs_and_reaches_the_same_answer():
    inst = build(129, seed=0)
    out = {}
    for name in ("fast-ccg", "fast-pccg", "fast-dual-ccg", "fast-dual-pccg"):
        res = get_solver(name).solve(inst.qp, SolverSettings(tol=1e-9))
        assert res.converged
        out[name] = res
    assert out["fast-pccg"].info["preconditioner_builds"] >= 1
    assert out["fast-pccg"].matvecs < out["fast-ccg"].matvecs
    assert out["fast-dual-pccg"].matvecs < out["fast-dual-ccg"].matvecs
    for a, b in (("fast-pccg", "fast-ccg"), ("fast-dual-pccg", "fast-dual-ccg")):
        assert np.linalg.norm(out[a].p - out[b].p) <= 1e-6 * np.linalg.norm(out[b].p)


def test_without_geometry_it_runs_unpreconditioned():
    from contactbench.problems.instances import QP

    inst = build(33)
    qp = QP(inst.qp.H, inst.qp.ubar)
    res = get_solver("fast-pccg").solve(qp, SolverSettings(tol=1e-9))
    assert res.converged and "preconditioner_builds" not in res.info


def test_unknown_preconditioner_is_a_clear_error():
    inst = build(33)
    with pytest.raises(ParamError, match="'precondition' must be one of 'islands', 'farfield', 'fourier', 'none'"):
        get_solver("fast-pccg").solve(inst.qp, SolverSettings(tol=1e-9, params={"precondition": "ilu"}))
    with pytest.raises(ValueError, match="unknown preconditioner 'ilu'"):
        make_preconditioner("ilu", inst.qp)


@pytest.mark.parametrize("kind", ISLAND_KINDS)
def test_solo_is_the_preconditioner_of_a_one_point_set(kind):
    """``solo`` (the entering force's scale in Polonsky-Keer) is M's inverse on a one-point
    set; on the island blocks that is what apply does to a point that forms a set alone
    (the wave numbers': ``test_the_wave_numbers_solo_is_their_inverse_on_a_one_point_set``)."""
    inst = build(33)
    M = make_preconditioner(kind, inst.qp)
    r = np.random.default_rng(3).normal(size=inst.n)
    solo = M.solo(r)
    for j in (0, inst.n // 2, inst.n - 1):
        S = np.zeros(inst.n, dtype=bool)
        S[j] = True
        M.update(S)
        assert M.apply(r)[j] == pytest.approx(solo[j], rel=1e-10)


def test_no_preconditioner_without_geometry_or_when_none():
    from contactbench.problems.instances import QP

    inst = build(33)
    assert make_preconditioner("none", inst.qp) is None
    assert make_preconditioner("islands", QP(inst.qp.H, inst.qp.ubar)) is None


def test_float32_island_blocks_are_symmetric_spd_and_close_to_float64():
    """The mixed-precision solves hold the block inverses in float32 (symmetrised): still
    a symmetric positive definite preconditioner, within float32 round-off of float64's."""
    inst = build(65)
    H = inst.qp.H
    S = inst.qp.ubar > np.quantile(inst.qp.ubar, 0.3)
    geo = inst.qp.geometry
    M64 = IslandPreconditioner(H, geo.grid_shape, geo.indices, max_block=16)
    M32 = IslandPreconditioner(H, geo.grid_shape, geo.indices, max_block=16, dtype=np.float32)
    M64.update(S)
    M32.update(S)
    pos = np.flatnonzero(S)
    P = np.column_stack([M32.apply(np.eye(H.n)[:, j]) for j in pos])[pos]
    P64 = np.column_stack([M64.apply(np.eye(H.n)[:, j]) for j in pos])[pos]
    assert all(b.inverse.dtype == np.float32 for b in M32._buckets if b.members.shape[1] > 1)
    np.testing.assert_allclose(P, P.T, atol=1e-12 * np.abs(P).max())
    assert np.min(np.linalg.eigvalsh(P)) > 0
    np.testing.assert_allclose(P, P64, atol=1e-5 * np.abs(P64).max())


def test_large_sets_get_smaller_blocks_within_the_build_budget():
    from contactbench.solvers._preconditioners import BUILD_BUDGET

    inst = build(129)
    qp = inst.qp
    M = IslandPreconditioner.build(qp)
    points = int(np.prod(qp.geometry.grid_shape))
    small = M.block_limit(10)
    large = M.block_limit(qp.n)
    assert small == M.max_block and 16 <= large < small and large % 16 == 0
    limits = [M.block_limit(k) for k in (10, 100, 300, 1000, qp.n)]
    assert limits == sorted(limits, reverse=True)
    assert all(s == 16 or s**2 * k <= BUILD_BUDGET * points for s, k in zip(limits, (10, 100, 300, 1000, qp.n)))
    M.update(np.ones(qp.n, dtype=bool))  # the whole trial set: a cold start's first set
    assert max(b.members.shape[1] for b in M._buckets) <= large
    members = np.concatenate([b.members[b.members >= 0] for b in M._buckets])
    assert np.unique(members).size == members.size <= qp.n  # one-point blocks are the diagonal part


def far_field_case(N: int):
    """The contact set of an N^2 cold top step: many islands over many 16 x 16 tiles."""
    inst = build(N, seed=5)
    res = get_solver("fast-dual-ccg").solve(inst.qp, SolverSettings(tol=1e-10))
    return inst, res.p > 0


def test_far_field_correction_is_symmetric_positive_definite_on_its_set_and_a_subset():
    """M^-1 = B^-1 - V Z K Z' V (solvers/_farfield.py) stays SPD on the set it was built for
    and on a set that drifted a little from it (restricted, not rebuilt)."""
    inst, S = far_field_case(128)
    M = make_preconditioner("farfield", inst.qp)
    M.update(S)
    assert M._far is not None and M._far.K.shape[0] > 4
    S2 = S.copy()
    S2[np.flatnonzero(S)[::50]] = False  # 2 % drift: the correction is reused
    for on in (S, S2):
        M.update(on)
        pos = np.flatnonzero(on)
        P = np.column_stack([M.apply(np.eye(inst.n)[:, j]) for j in pos])
        assert not np.any(P[~on])
        P = P[pos]
        np.testing.assert_allclose(P, P.T, atol=1e-10 * np.abs(P).max())
        assert np.min(np.linalg.eigvalsh(0.5 * (P + P.T))) > 0


def test_blocks_and_far_field_built_on_the_threads_are_those_of_one(monkeypatch: pytest.MonkeyPatch) -> None:
    """The island factorisation goes out in chunks (``BUILD_CHUNK_ENTRIES`` small: many) and
    the far field's near-tile sums one aggregate a thread: the same inverses, row sums and
    coarse matrix on 1, 2 or 3 threads; a singular block still gives the diagonal."""
    from contactbench.solvers import _preconditioners

    inst, S = far_field_case(128)
    monkeypatch.setattr(_preconditioners, "BUILD_CHUNK_ENTRIES", 1024)
    built = []
    for workers in ("1", "2", "3"):
        monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", workers)
        M = make_preconditioner("farfield", inst.qp)
        M.update(S)
        built.append(M)
    one = built[0]
    assert one._far is not None and len(one._buckets) > 1
    assert max(b.members.shape[0] for b in one._buckets) > 4  # several chunks a bucket
    for M in built[1:]:
        for a, b in zip(one._buckets, M._buckets, strict=True):
            np.testing.assert_allclose(b.inverse, a.inverse, rtol=1e-13, atol=1e-13 * np.abs(a.inverse).max())
            np.testing.assert_allclose(b.row_sums, a.row_sums, rtol=1e-13, atol=0)
        np.testing.assert_allclose(M._far.K, one._far.K, rtol=1e-12, atol=1e-12 * np.abs(one._far.K).max())
    members = one._buckets[-1].members
    singular = np.where(members >= 0, members[:, :1], members)  # a block of one point repeated
    monkeypatch.setenv("CONTACTBENCH_FFT_WORKERS", "3")
    assert one._factor(members) is not None and one._factor(singular) is None


def test_far_field_budget_counts_the_work_of_its_near_sums(monkeypatch):
    """The near-tile sums take each neighbouring pair of aggregates once; the build budget
    is compared with their cost (``ContactOperator.unit_sums_cost``: entries read, or a
    window's work where that is less), never more than the pairs-once gather: a budget
    one entry short refuses the correction, the exact cost builds it."""
    from contactbench.problems.operators import ContactOperator
    from contactbench.solvers import _farfield
    from contactbench.solvers import _preconditioners as prec_mod

    inst, S = far_field_case(128)
    calls = []
    monkeypatch.setattr(prec_mod, "build_far_field", lambda *a: calls.append(a) or _farfield.build_far_field(*a))
    M = make_preconditioner("farfield", inst.qp)
    M.update(S)
    H, i, j, pos, lead, v, sums, _budget, fraction = calls[-1]
    T = _farfield.tile_size(i[pos], j[pos])
    labels, agg = np.unique((i[lead[pos]] // T) * (1 << 32) + j[lead[pos]] // T, return_inverse=True)
    count = np.bincount(agg).astype(float)
    ti, tj = labels // (1 << 32), labels % (1 << 32)
    later = _farfield.later_neighbours(ti, tj)
    members = [pos[agg == a] for a in range(count.size)]
    items = [(np.concatenate([members[b] for b in nb]), members[a]) for a, nb in enumerate(later)]
    gather = ContactOperator.unit_sums_cost(H, items)
    both_orders = sum(count[a] * count[(np.abs(ti - ti[a]) <= 1) & (np.abs(tj - tj[a]) <= 1)].sum()
                      for a in range(count.size))
    assert gather == pytest.approx(0.5 * (both_orders + np.sum(count**2)))  # pairs once, each tile with itself
    assert gather < both_orders
    assert all(b.size >= 1 and b[0] == a for a, b in enumerate(later))  # its own tile first, then later ones
    cost = H.unit_sums_cost(items)
    assert 0 < cost <= gather
    assert _farfield.build_far_field(H, i, j, pos, lead, v, sums, cost - 1, fraction) is None
    assert _farfield.build_far_field(H, i, j, pos, lead, v, sums, cost, fraction) is not None


def test_later_neighbours_are_the_tiles_around_each_aggregate_once() -> None:
    """The far field's neighbour lists (looked up among sorted tile keys) are, for every
    aggregate a, the aggregates b >= a whose tiles touch a's, in increasing order: the
    brute-force comparison with every aggregate, on random occupied tiles (row and column 0
    included, one aggregate, none touching)."""
    from contactbench.solvers import _farfield

    rng = np.random.default_rng(3)
    cases = [np.array([0]), np.array([0, 2, 4 * 30 + 1]), np.arange(30)]
    cases += [np.sort(rng.choice(900, int(rng.integers(1, 120)), replace=False)) for _ in range(40)]
    for keys in cases:
        ti, tj = np.divmod(keys, 30)
        got = _farfield.later_neighbours(ti, tj)
        a = np.arange(keys.size)
        want = [np.flatnonzero((np.abs(ti - ti[k]) <= 1) & (np.abs(tj - tj[k]) <= 1) & (a >= k)) for k in a]
        assert len(got) == len(want)
        assert all(np.array_equal(g, w) for g, w in zip(got, want))


def test_coarse_matrix_sums_neighbouring_aggregates_exactly_and_farther_ones_as_point_masses() -> None:
    """The far field's Z'HZ (``coarse_matrix``): 1_a' H 1_b to round-off (against the dense
    H) for aggregates on touching tiles, both orders; the point masses of ``galerkin_far``
    for farther ones; symmetric."""
    from contactbench.solvers import _farfield

    inst, S = far_field_case(64)
    H = inst.qp.H
    g = inst.qp.geometry
    i, j = np.divmod(np.asarray(g.indices), g.grid_shape[1])
    pos = np.flatnonzero(S)
    T = 16
    labels, agg = np.unique((i[pos] // T) * (1 << 32) + j[pos] // T, return_inverse=True)
    m = labels.size
    count = np.bincount(agg, minlength=m).astype(float)
    ti, tj = labels // (1 << 32), labels % (1 << 32)
    A = _farfield.coarse_matrix(H, i, j, pos, agg, count, _farfield.later_neighbours(ti, tj), np.inf)
    Z = np.zeros((inst.qp.n, m))
    Z[pos, agg] = 1.0
    exact = Z.T @ H.to_dense() @ Z
    point_masses = _farfield.galerkin_far(H, i, j, pos, agg, count)
    touching = (np.abs(ti[:, None] - ti[None, :]) <= 1) & (np.abs(tj[:, None] - tj[None, :]) <= 1)
    assert m > 4 and touching.any() and (~touching).any()
    np.testing.assert_allclose(A[touching], exact[touching], rtol=1e-10, atol=1e-12 * np.abs(exact).max())
    np.testing.assert_allclose(A[~touching], (0.5 * (point_masses + point_masses.T))[~touching], rtol=1e-12)
    np.testing.assert_array_equal(A, A.T)


def test_first_nearest_is_the_first_member_at_the_least_distance() -> None:
    """The far field's representative of each aggregate (``first_nearest``) is the member
    a stable sort by (aggregate, distance) puts first: the least distance, ties to the first
    position, on inputs with many ties and one-member aggregates."""
    from contactbench.solvers import _farfield

    rng = np.random.default_rng(11)
    for _ in range(30):
        m = int(rng.integers(1, 40))
        agg = np.concatenate([np.arange(m), rng.integers(0, m, int(rng.integers(0, 200)))])
        rng.shuffle(agg)
        dist = rng.integers(0, 5, agg.size).astype(float) / 4.0  # few values: many ties
        order = np.lexsort((dist, agg))
        first = np.r_[True, agg[order][1:] != agg[order][:-1]]
        np.testing.assert_array_equal(_farfield.first_nearest(agg, dist, m), order[first])


def test_far_field_correction_cuts_the_cg_iterations_on_a_contact_set():
    inst, S = far_field_case(256)
    pos = np.flatnonzero(S)
    H, b = inst.qp.H.submatrix(pos), inst.qp.ubar[pos]
    counts = {}
    for kind in ("islands", "farfield"):
        M = make_preconditioner(kind, inst.qp)
        M.update(S)
        full = np.zeros(inst.n)

        def prec(r, M=M, full=full):
            full[pos] = r
            return M.apply(full)[pos]

        counts[kind] = pcg_iterations(H, b, prec)
    assert counts["farfield"] < 0.85 * counts["islands"], counts


class _Stalling:
    """The island preconditioner with a badly scaled (still SPD) part on top, which makes
    Polonsky-Keer crawl until ``simplify`` drops it."""

    def __init__(self, qp, seed: int = 0) -> None:
        self.islands = make_preconditioner("islands", qp)
        self._bad = np.random.default_rng(seed).uniform(1e-4, 1.0, qp.n) ** 4
        self.dropped = 0

    def __getattr__(self, name):  # on, update, solo, builds: the island preconditioner's
        return getattr(self.islands, name)

    def apply(self, r: np.ndarray) -> np.ndarray:
        z = self.islands.apply(r)
        return z if self._bad is None else z * self._bad

    def simplify(self, blocks: bool = False) -> bool:
        had = self._bad is not None
        self._bad, self.dropped = None, self.dropped + had
        return had


def test_polonsky_keer_drops_a_coarse_part_it_stalls_with():
    """Without halving the KKT error for CYCLE_PATIENCE iterations, Polonsky-Keer asks its
    preconditioner to drop its coarse part (solvers/_ccg.py, "Cycling") and converges."""
    from contactbench.solvers._ccg import CYCLE_PATIENCE, GapState, polonsky_keer

    qp = build(33).qp
    ctx = loop_context(qp)
    M = _Stalling(qp)
    run = polonsky_keer(ctx, GapState(qp.H, qp.ubar, np.zeros(qp.n)), M)
    assert run.converged and M.dropped == 1
    stalled = polonsky_keer(ctx, GapState(qp.H, qp.ubar, np.zeros(qp.n)), _Stalling(qp),
                            max_iter=CYCLE_PATIENCE)
    assert not stalled.converged  # the badly scaled part alone does not get there in that time


# -- blocks of big islands ---------------------------------------------------------------


def row_strips(labels, i, j, shape, limit, whole=None):
    """The cut the island blocks were once made with: runs of ``limit`` consecutive points
    of an island in row-major order -- on an island wider than ``limit``, a piece of one
    grid row (the counterexample of "Blocks of big islands")."""
    labels = np.asarray(labels, dtype=np.int64)
    order = np.argsort(labels, kind="stable")
    lab = labels[order]
    start = np.r_[0, np.flatnonzero(lab[1:] != lab[:-1]) + 1]
    rank = np.arange(lab.size) - np.repeat(start, np.diff(np.r_[start, lab.size]))
    out = np.empty_like(labels)
    out[order] = lab * (labels.size + 1) + rank // limit
    return np.unique(out, return_inverse=True)[1].ravel()


def disk_case(N: int = 64, radius: float = 24.0):
    """A flat punch's trial set (every grid point) and a disk-shaped set on it: one island of
    ~1,800 points, far above the block limit (16 on this grid)."""
    s = Surface(np.zeros((N, N)), 100e-6 / N)
    inst = InstanceBuilder(s, 1e9, "bcc", periodic=False).build(1e-7)
    i, j = np.divmod(np.asarray(inst.qp.geometry.indices), N)
    return inst, (i - N / 2 + 0.5) ** 2 + (j - N / 2 + 0.5) ** 2 <= radius**2


def test_patches_cut_only_big_islands_into_compact_blocks_within_the_limit():
    rng = np.random.default_rng(0)
    shape = (40, 50)
    i, j = np.divmod(np.arange(shape[0] * shape[1]), shape[1])
    labels = np.where(j < 30, 0, 1 + (i >= 20))  # a 40 x 30 island and two 20 x 20 ones
    labels[rng.choice(labels.size, 7, replace=False)] = 3  # and a scattered small one
    limit = 48
    h, w = patch_shape(limit)
    assert (h, w) == (6, 8) and h * w <= limit
    out = patches(labels, i, j, shape, limit)
    assert out.min() == 0 and np.array_equal(np.unique(out), np.arange(out.max() + 1))
    for b in np.unique(out):
        members = out == b
        assert np.unique(labels[members]).size == 1  # no block spans two islands
        assert members.sum() <= limit
        if labels[members][0] != 3:  # a cut island's block is compact: inside one h x w patch
            assert np.ptp(i[members]) < h and np.ptp(j[members]) < w
    assert np.unique(out[labels == 3]).size == 1  # small islands stay whole
    np.testing.assert_array_equal(patches(labels, i, j, shape, 10_000), labels)
    assert patches(np.zeros(0, dtype=int), i[:0], j[:0], shape, limit).size == 0


def test_big_islands_cut_into_patches_need_fewer_cg_iterations_than_row_strips(monkeypatch):
    """On one island far above the block limit, block-Jacobi over compact patches halves the
    CG iterations of row-major strips (1-D pieces of grid rows), which is what made the
    population's smooth surfaces (Saupe RMD, H 0.9) need > 2x the median matvecs."""
    from contactbench.solvers import _preconditioners

    inst, S = disk_case()
    pos = np.flatnonzero(S)
    H, b = inst.qp.H.submatrix(pos), np.ones(pos.size)
    counts = {}
    for name, cut in (("patches", patches), ("strips", row_strips)):
        monkeypatch.setattr(_preconditioners, "patches", cut)
        M = IslandPreconditioner.build(inst.qp)
        M.update(S)
        assert M._limit == 16 and pos.size > 100 * M._limit
        full = np.zeros(inst.n)

        def prec(r, M=M, full=full):
            full[pos] = r
            return M.apply(full)[pos]

        counts[name] = pcg_iterations(H, b, prec)
    assert counts["patches"] < 0.7 * counts["strips"], counts


def paraboloid_step(N: int = 64):
    """A smooth cap pressed to 30 % of its height: one contact island of ~900 points."""
    x = (np.arange(N) - N / 2 + 0.5) / N
    z = -(x[:, None] ** 2 + x[None, :] ** 2) * 1e-5
    s = Surface(z - z.mean(), 100e-6 / N)
    return InstanceBuilder(s, 1e9, "bcc", periodic=False).build(0.3 * float(np.ptp(z)))


@pytest.mark.parametrize("precision", ["mixed", "double"])
def test_default_solver_on_one_big_island_is_exact_and_beats_row_strips(precision, monkeypatch):
    from contactbench.solvers import _preconditioners

    inst = paraboloid_step()
    ref = exact_solution_on_subset(inst.qp)
    settings = SolverSettings(tol=1e-9, params={"precision": precision})
    res = get_solver("fast-dual-pccg").solve(inst.qp, settings)
    assert res.converged and np.count_nonzero(res.p > 0) > 500
    assert kkt_check(inst, res.p).kkt_error <= 1e-8 and relative_error(res.p, ref.p) <= 1e-6
    monkeypatch.setattr(_preconditioners, "patches", row_strips)
    strips = get_solver("fast-dual-pccg").solve(inst.qp, settings)
    assert res.matvecs < 0.9 * strips.matvecs, (res.matvecs, strips.matvecs)


@pytest.mark.parametrize("kind", ["islands", "farfield", "fourier"])
def test_ones_is_the_preconditioner_of_the_indicator_and_follows_the_set(kind):
    """``ones`` (M^-1 1 on the set, cached) equals ``apply`` of the set's indicator; a set
    one point off keeps it (within ONES_DRIFT), a new set or a dropped coarse part gives
    the new one."""
    inst = build(33)
    M = make_preconditioner(kind, inst.qp)
    rng = np.random.default_rng(5)
    for share in (0.6, 0.9, 1.0):
        S = rng.random(inst.n) < share  # over 100 points: one point is within ONES_DRIFT
        M.update(S)
        first = M.ones()
        np.testing.assert_allclose(first, M.apply(S.astype(float)), rtol=1e-12, atol=0.0)
        assert M.ones() is first
        near = S.copy()
        near[np.flatnonzero(S)[0]] = False
        M.update(near)
        assert M.ones() is first
        M.update(S)
    if M.simplify():
        np.testing.assert_allclose(M.ones(), M.apply(S.astype(float)), rtol=1e-12, atol=0.0)


def test_simplify_drops_the_far_field_then_the_blocks():
    """A stagnation the exact finish cannot take asks M to ``simplify(blocks=True)``: the
    far field goes first (the blocks alone after it), then the blocks (z = r / H_jj on the
    set, and no blocks built again), then nothing is left to drop.  Without ``blocks`` (the
    displacement loop's "Cycling") the blocks stay."""
    inst = build(33)
    rng = np.random.default_rng(4)
    S = rng.random(inst.n) < 0.4
    r = rng.standard_normal(inst.n)
    M = IslandPreconditioner.build(inst.qp, far_field=True)
    M.far_fraction = 1.0
    M.update(S)
    assert M._far is not None
    blocks_alone = IslandPreconditioner.build(inst.qp)
    blocks_alone.update(S)
    assert M.simplify() and not M.far_field and M.blocks
    np.testing.assert_allclose(M.apply(r), blocks_alone.apply(r), rtol=1e-12, atol=0.0)
    diagonal = np.where(S, r / inst.qp.H.diagonal(), 0.0)
    assert not M.simplify() and M.blocks
    np.testing.assert_allclose(M.apply(r), blocks_alone.apply(r), rtol=1e-12, atol=0.0)
    assert M.simplify(blocks=True) and not M.blocks
    np.testing.assert_allclose(M.apply(r), diagonal, rtol=1e-12, atol=0.0)
    T = rng.random(inst.n) < 0.4
    M.update(T)
    np.testing.assert_allclose(M.apply(r), np.where(T, r / inst.qp.H.diagonal(), 0.0), rtol=1e-12, atol=0.0)
    assert not M.simplify(blocks=True)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("m,s", [(70, 16), (46, 32), (6, 64), (1, 192), (100, 48)])
def test_block_inverses_invert_each_block_symmetrically(dtype: type, m: int, s: int) -> None:
    """Short batches of wide blocks by Cholesky (``by_cholesky``), the rest by batched LU:
    either way each block's inverse, symmetric, the same whichever way the batch is cut."""
    from contactbench.solvers._partition import block_inverses, by_cholesky

    rng = np.random.default_rng(s)
    a = rng.standard_normal((m, s, s))
    blocks = (a @ np.swapaxes(a, 1, 2) / s + np.eye(s)).astype(dtype)
    cholesky = by_cholesky(m, s)
    assert cholesky == (s >= 48 and m <= 64)
    inv = block_inverses(blocks, cholesky)
    assert inv.dtype == dtype and np.array_equal(inv, np.swapaxes(inv, 1, 2))
    eye = np.broadcast_to(np.eye(s), blocks.shape)
    tol = 1e-4 if dtype == np.float32 else 1e-11
    assert np.max(np.abs(blocks.astype(np.float64) @ inv.astype(np.float64) - eye)) < tol
    half = max(1, m // 2)  # a bucket cut into batches: the same inverses
    np.testing.assert_array_equal(block_inverses(blocks[:half], cholesky), inv[:half])
    other = block_inverses(blocks, not cholesky)  # the other way: the same to round-off
    assert np.max(np.abs(other.astype(np.float64) - inv)) < 1e3 * tol * np.max(np.abs(inv))


def test_block_inverses_fall_back_and_refuse_as_lu_does() -> None:
    """A block Cholesky cannot factor (indefinite) is inverted by LU; a singular one raises
    ``LinAlgError``, as ``np.linalg.inv`` did (the caller then keeps the diagonal)."""
    from contactbench.solvers._partition import block_inverses

    s = 64
    indefinite = np.eye(s)[None].copy()
    indefinite[0, 0, 0] = -2.0
    inv = block_inverses(indefinite, True)
    assert inv[0, 0, 0] == pytest.approx(-0.5) and np.allclose(inv[0, 1:, 1:], np.eye(s - 1))
    singular = np.ones((1, s, s))
    for cholesky in (True, False):
        with pytest.raises(np.linalg.LinAlgError):
            block_inverses(singular, cholesky)
