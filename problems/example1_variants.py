"""Two variants of paper Example 1 (Bemporad & Paggi 2015, sec. 3.1) that test the words
around it, both with ubar ~ U(0, 1) drawn as ``numpy.random.default_rng(seed).random(n)``,
the draw of ``instances.counterexample`` (the same seed gives the same ubar):

* ``spaced_counterexample`` -- "for less densely packed boundary elements belonging to
  I_C, for instance with a minimum distance of 2 delta between them instead of delta as
  in Example 1, the algorithm was found to always provide a solution satisfying
  w* >= 0" (tex 647-651): the N x N trial elements (n = N^2) are every ``spacing``-th
  element of a mesh of side spacing (N - 1) + 1 with grid spacing delta, so neighbouring
  trial elements lie ``spacing`` x delta apart; Q is Eq. (green2) (the BCC kernel, E =
  0.01, delta = 1, as Example 1) between those elements.  ``spacing`` = 1 is Example 1.
* ``random_positive`` -- "if the algorithm is applied to randomly generated ubar vectors
  and Q positive definite matrices with positive coefficients, in many cases the LCP is
  not solved exactly" (tex 601-604): Q a random symmetric positive definite matrix with
  every entry positive (``random_positive_matrix``: Q = B B' / n, B ~ U(0, 1)).
"""

from __future__ import annotations

import numpy as np

from .constraints import make_constraints
from .errors import ProblemInputError, check_whole
from .instances import ContactInstance, Geometry, InstanceBuilder, OperatorKind, QP, counterexample
from .operators import DenseOperator
from .surfaces import Surface, check_seed

#: The spacings of the trial elements, in grid spacings delta: 1 is Example 1, 2 the
#: paper's "minimum distance of 2 delta".
SPACINGS: tuple[int, ...] = (1, 2)
#: The matrices Q of the variants: "green2" (Eq. green2 on the mesh, Example 1's) and
#: "random-positive" (``random_positive_matrix``).
MATRICES: tuple[str, ...] = ("green2", "random-positive")
#: Example 1's modulus and grid spacing (arbitrary consistent units, ``instances.counterexample``).
EXAMPLE1_E = 0.01
EXAMPLE1_DELTA = 1.0
#: The modulus a random matrix's instance records (it has no elastic body: a.u., so that
#: P / (E A) is the total force over n).
RANDOM_E = 1.0


def example1_side(n: int) -> int:
    """N with n = N^2 and N >= 2 (Example 1's grid of trial elements), else a one-line
    ``ProblemInputError``."""
    N = int(round(np.sqrt(n))) if isinstance(n, (int, np.integer)) and n >= 0 else -1
    if N * N != n or N < 2:
        raise ProblemInputError(f"Example 1 needs n = N^2 with N >= 2, got n = {n}")
    return N


def spaced_counterexample(n: int, seed: int, spacing: int = 2, operator: OperatorKind = "dense") -> ContactInstance:
    """Example 1 with its N x N trial elements ``spacing`` grid spacings apart (module doc):
    the mesh has side M = spacing (N - 1) + 1 elements of side delta = 1, the trial set is
    the elements (spacing i, spacing j), i, j = 0..N-1 (flat indices into the M x M mesh, in
    row-major order), ubar = ``default_rng(seed).random(n)`` on them, and Q = H restricted
    to them (Eq. green2, E = 0.01: its entries at distance 2 delta, 2 sqrt(2) delta, ...).
    The geometry is the mesh with the trial set, E and the kernel; it has no surface and no
    far-field displacement, as Example 1 (``Geometry.has_surface`` is False).  ``spacing``
    1 returns ``instances.counterexample`` itself; a spacing that is not a whole number
    >= 1, or n not N^2 with N >= 2, is a ``ProblemInputError``."""
    spacing = check_whole("trial-element spacing (in grid spacings)", spacing, 1)
    N = example1_side(n)
    if spacing == 1:
        return counterexample(n, seed, E=EXAMPLE1_E, delta=EXAMPLE1_DELTA, operator=operator)
    ubar = np.random.default_rng(check_seed(seed)).random(n)
    M = spacing * (N - 1) + 1
    surf = Surface(np.zeros((M, M)), EXAMPLE1_DELTA, unit="a.u.", name=f"counterexample-n{n}-spacing{spacing}")
    builder = InstanceBuilder(surf, EXAMPLE1_E, "bcc", periodic=False, operator=operator)
    rows = spacing * np.arange(N)
    idx = (rows[:, None] * M + rows[None, :]).ravel()
    geom = Geometry((M, M), EXAMPLE1_DELTA, idx, E=EXAMPLE1_E, kernel="bcc", periodic=False)
    qp = QP(builder.operator_on(idx), ubar, geom, make_constraints(n))
    return ContactInstance(qp, delta=float("nan"), E=EXAMPLE1_E, kernel="bcc", periodic=False, surface=surf,
                           meta={"seed": seed, "family": "counterexample", "spacing": spacing})


def random_positive_matrix(n: int, rng: np.random.Generator) -> np.ndarray:
    """Q = B B' / n with B's n x n entries ~ U(0, 1), drawn from ``rng`` (symmetrised to
    the last bit).

    The paper names only the class ("Q positive definite matrices with positive
    coefficients", tex 601-604), so this is its plainest member, the usual way to draw one
    (``A = rand(n); Q = A*A'``): B B' has every entry positive (a sum of products of
    positive numbers) and is positive definite whenever B is nonsingular (with probability
    one); dividing by n keeps its entries O(1) at any n (mean 1/4 off the diagonal, 1/3 on
    it) and changes no decision of the greedy method (Q / n scales p by n and leaves w).
    No multiple of I is added: a shift c I moves Q towards the identity and the failures
    go with it (greedy CG at eps = 1e-8 over seeds 0-39: c = 0.01 rejected on about 35 %,
    c = 0.1 and c = 1 on none, at n = 25 and 100), the diagonal weight the paper suspects
    of making greedy robust (tex 655-657), so a shift would choose the verdict.  Its
    condition number is large (median about 1e5 at n = 25, 1e7 at n = 100); the failures
    it shows are the active-set logic's (w_j well below zero on a dropped element, down to
    -0.35 max(ubar)), not the linear solver's."""
    n = check_whole("n", n, 1)
    B = rng.random((n, n))
    Q = B @ B.T / n
    return 0.5 * (Q + Q.T)


def random_positive(n: int, seed: int, operator: OperatorKind = "dense") -> ContactInstance:
    """ubar = ``default_rng(seed).random(n)`` (Example 1's draw) and, from the same
    generator next, Q = ``random_positive_matrix(n)``, as a dense operator.

    It is no surface: no grid (``QP.geometry`` None: ``ContactInstance.nominal_area`` is n),
    no kernel (""), E = ``RANDOM_E`` (a.u.), no far-field displacement (delta NaN), the
    same context as Example 1 less the mesh it does not have.  A random matrix has no FFT
    form: ``operator`` other than "dense" is a ``ProblemInputError``; so is n < 2."""
    if operator != "dense":
        raise ProblemInputError(f"a random matrix Q is dense only (operator 'dense'), got operator {operator!r}")
    n = check_whole("n", n, 2)
    rng = np.random.default_rng(check_seed(seed))
    ubar = rng.random(n)
    qp = QP(DenseOperator(random_positive_matrix(n, rng)), ubar, None, make_constraints(n))
    return ContactInstance(qp, delta=float("nan"), E=RANDOM_E, kernel="", periodic=False, surface=None,
                           meta={"seed": seed, "family": "random-positive"})
