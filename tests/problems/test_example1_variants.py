"""Paper Example 1's variants (problems/example1_variants.py, problems/scenes/example1_variants.py):
the trial elements 2 delta apart with Q from Eq. (green2) between them, and a random SPD Q with
positive entries; their scenes' recipes, apart from Example 1's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.example1_variants import random_positive, spaced_counterexample
from contactbench.problems.instances import counterexample
from contactbench.problems.scenes import SceneConfig, get_scene

E, DELTA = 0.01, 1.0


def green2(r: float) -> float:
    """Eq. (green2) of the paper (tex 349-356) at centre distance r (E = 0.01, delta = 1)."""
    scale = 2.0 / (E * math.pi * DELTA)
    return scale if r == 0.0 else scale * math.asin(DELTA / (2.0 * r))


def dense(inst) -> np.ndarray:
    return inst.qp.H.submatrix(np.arange(inst.n))


def test_the_2delta_trial_set_is_every_other_element_and_q_is_green2_at_2_delta() -> None:
    inst = spaced_counterexample(25, 3, spacing=2)
    g = inst.geometry
    assert inst.n == 25 and g.grid_shape == (9, 9) and g.spacing == (DELTA, DELTA)
    i, j = np.divmod(np.asarray(g.indices), 9)
    assert set(i) == set(j) == {0, 2, 4, 6, 8}  # the mesh elements at even (i, j)
    pos = g.positions
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    assert d[~np.eye(25, dtype=bool)].min() == pytest.approx(2 * DELTA)
    H = dense(inst)
    assert H[0, 0] == pytest.approx(green2(0.0), rel=1e-12)
    assert H[0, 1] == pytest.approx(green2(2 * DELTA), rel=1e-12)  # neighbours in a row: 2 delta apart
    assert H[0, 6] == pytest.approx(green2(2 * math.sqrt(2) * DELTA), rel=1e-12)  # diagonal neighbours
    assert H[0, 1] < green2(DELTA)  # Example 1's neighbours couple more strongly
    # Example 1's ubar for the same seed, on the sparser set; no surface to rebuild it from
    assert np.array_equal(inst.qp.ubar, np.random.default_rng(3).random(25))
    assert not g.has_surface and math.isnan(inst.delta)


def test_spacing_one_is_example_1_itself() -> None:
    a, b = spaced_counterexample(25, 7, spacing=1), counterexample(25, 7)
    assert np.array_equal(dense(a), dense(b)) and np.array_equal(a.qp.ubar, b.qp.ubar)
    for bad in (0, 1.5, -2):
        with pytest.raises(ProblemInputError):
            spaced_counterexample(25, 0, spacing=bad)
    with pytest.raises(ProblemInputError, match="N\\^2"):
        spaced_counterexample(24, 0, spacing=2)


@pytest.mark.parametrize("n", [25, 100])
def test_the_random_matrix_is_spd_with_positive_entries(n: int) -> None:
    for seed in range(5):
        inst = random_positive(n, seed)
        Q = dense(inst)
        assert Q.shape == (n, n) and np.array_equal(Q, Q.T)
        assert (Q > 0).all()
        assert np.linalg.eigvalsh(Q).min() > 0.0
        assert np.linalg.cholesky(Q) is not None
        assert np.array_equal(inst.qp.ubar, np.random.default_rng(seed).random(n))  # Example 1's draw first
        assert ((inst.qp.ubar > 0) & (inst.qp.ubar < 1)).all()
        # not a surface: no grid, no kernel, no far-field displacement
        assert inst.geometry is None and inst.kernel == "" and math.isnan(inst.delta) and inst.E > 0
    assert not np.array_equal(dense(random_positive(n, 0)), dense(random_positive(n, 1)))
    with pytest.raises(ProblemInputError, match="dense"):
        random_positive(n, 0, operator="fft")


def test_the_variant_scenes_record_their_variant_and_leave_example_1s_recipes_alone() -> None:
    spaced = get_scene("counterexample-2delta")
    specs = spaced.instances(spaced.config(None))
    assert {s.params["n"] for s in specs} == {25, 100} and {s.params["seed"] for s in specs} == set(range(100))
    assert all(s.params["spacing"] == 2 and s.params["variant"] == "spacing-2" for s in specs)
    assert len({s.instance for s in specs}) == len(specs)
    assert spaced.build(specs[0]).at(0).geometry.grid_shape == (9, 9)
    rand = get_scene("random-positive-h")
    specs = rand.instances(rand.config(None))
    assert all(s.params["matrix"] == "random-positive" and s.params["variant"] == "random-positive" for s in specs)
    assert rand.build(specs[0]).at(0).geometry is None
    assert "operator" not in rand.options
    # Example 1's own recipes carry no variant key (their cell ids are unchanged)
    ex1 = get_scene("counterexample")
    assert set(ex1.instances(ex1.config(SceneConfig(seeds=(0,))))[0].params) == {"n", "seed", "operator"}
    with pytest.raises(ProblemInputError, match="no mesh"):
        ex1.instances(ex1.config(SceneConfig(extra={"matrix": "random-positive", "spacing": 2})))
    with pytest.raises(ProblemInputError, match="matrix must be one of"):
        ex1.instances(ex1.config(SceneConfig(extra={"matrix": "wishart"})))
