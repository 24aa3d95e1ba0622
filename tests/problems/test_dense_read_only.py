"""``to_dense`` hands out no matrix of the problem's to write into: on ``DenseOperator`` it is
the operator's own H, read-only (the array given stays the caller's, writeable), so a
solver that writes into it is stopped at the write (the FFT operator's is a fresh copy)."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.harness.conformance import battery as cf
from contactbench.problems.operators import DenseOperator
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver
from tests.helpers import dense_exact_solution


def test_dense_to_dense_is_read_only_and_the_given_array_stays_writeable() -> None:
    given = np.array([[2.0, 1.0], [1.0, 2.0]])
    op = DenseOperator(given)
    A = op.to_dense()
    assert np.shares_memory(A, given) and not A.flags.writeable and not op.H.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        A[0, 0] = 3.0
    given[0, 0] = 5.0  # the caller's own array: still theirs
    assert given.flags.writeable and op.matvec(np.array([1.0, 0.0]))[0] == 5.0


class FactorsInPlace(Solver):
    """Exact, after an in-place change of what ``to_dense`` returned (a shift undone)."""

    name = "test-factors-in-place"
    family = "test"
    capabilities = Capabilities(exact=True, needs_dense=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        A = ctx.qp.H.to_dense()
        A[np.diag_indices_from(A)] += 1.0
        A[np.diag_indices_from(A)] -= 1.0
        return Outcome(dense_exact_solution(ctx.qp), 1, True, "done")


def test_a_solver_writing_into_the_dense_matrix_is_stopped_at_the_write() -> None:
    """Not judged WRONG after the fact on the dense cases only: the write itself fails, and
    the row says where."""
    table = cf.validate(FactorsInPlace(), cf.conformance_cases("fast", groups=["random"]), isolate=False)
    dense = [r for r in table.rows if r.status != "skipped"]
    assert dense and all(r.status == "crashed" and "read-only" in r.message for r in dense), table.format()
