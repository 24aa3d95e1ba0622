"""A refactored preconditioner restarts the Bugnicourt loop's conjugacy (solvers/_ccg.py, "A
refactored preconditioner"), and ``SetPreconditioner.version`` says when one was refactored."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kkt import kkt_check
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import _ccg
from contactbench.solvers._ccg import GapState, bugnicourt
from contactbench.solvers._preconditioners import IslandPreconditioner, make_preconditioner
from tests.helpers import loop_context


def instance(size: int = 65, seed: int = 2):
    s = rmd_surface_n(size, 0.8, length=100e-6, seed=seed)
    return InstanceBuilder(s, 1e9, "bcc", periodic=False).build(2.0 * paper_max_displacement(s))


def test_version_moves_with_the_factors_not_with_the_set():
    qp = instance().qp
    M = IslandPreconditioner.build(qp, far_field=True)
    M.far_fraction = 1.0
    rng = np.random.default_rng(0)
    S = rng.random(qp.n) < 0.3
    M.update(S)
    built = M.version
    assert built >= 1 and M.builds == 1
    T = S.copy()
    T[np.flatnonzero(S)[0]] = False  # one point less: within every rebuild fraction
    M.update(T)
    assert M.version == built
    M.update(rng.random(qp.n) < 0.3)  # another set: new blocks and a new far field
    assert M.version > built and M.builds == 2
    before, had_far = M.version, M._far is not None
    assert had_far
    M.simplify()  # the far field dropped: another M^-1
    assert M.version == before + 1
    M.update(S)  # and none to rebuild
    assert M.version == before + 1 + (M.builds == 3)


class _Watched:
    """A preconditioner that records its version at every application."""

    def __init__(self, M) -> None:
        self.M, self.versions = M, []

    def __getattr__(self, name):  # on, update, solo, builds, progress: M's
        return getattr(self.M, name)

    @property
    def version(self) -> int:
        return self.M.version

    def apply(self, r: np.ndarray) -> np.ndarray:
        self.versions.append(self.M.version)
        return self.M.apply(r)


def betas_after_refactoring(monkeypatch, qp) -> tuple[list[float], list[float], _ccg.CCGRun, GapState]:
    """The loop's beta at the iterations whose direction came from new factors, and at the
    others."""
    M = _Watched(make_preconditioner("islands", qp))
    seen: list[tuple[bool, float]] = []
    conjugate = _ccg.conjugate

    def spy(d, z, beta):
        v = M.versions
        seen.append((len(v) > 1 and v[-1] != v[-2], beta))
        return conjugate(d, z, beta)

    monkeypatch.setattr(_ccg, "conjugate", spy)
    state = GapState(qp.H, qp.ubar, np.zeros(qp.n))
    run = bugnicourt(loop_context(qp), state, M)
    return [b for new, b in seen if new], [b for new, b in seen if not new], run, state


@pytest.mark.parametrize("seed", [2, 5])
def test_bugnicourt_restarts_on_new_factors(monkeypatch, seed):
    inst = instance(seed=seed)
    refactored, others, run, state = betas_after_refactoring(monkeypatch, inst.qp)
    assert run.converged and kkt_check(inst, state.p).kkt_error <= 1e-8
    assert refactored and all(b == 0.0 for b in refactored)
    assert any(b != 0.0 for b in others)  # the conjugacy is kept elsewhere
    # The same loop told nothing of the factors keeps Polak-Ribiere's beta there: the test
    # above can fail.
    monkeypatch.setattr(_ccg, "version_of", lambda M: 0)
    refactored, _, run, _ = betas_after_refactoring(monkeypatch, inst.qp)
    assert refactored and any(b != 0.0 for b in refactored)
