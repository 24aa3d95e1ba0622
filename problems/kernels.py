"""Influence coefficients H_{i-k,j-l} of the elastic half-space (paper eqs. green, green2).

All kernels are *per unit force*: the displacement at element (i, j) caused by a unit
resultant force on element (k, l).  With E the composite modulus E* = E/(1-nu^2) in Pa
and lengths in metres, H is in m/N and the unknown p of the QP is the force in N carried
by each element (the paper's p_{i,j}, the resultant of the pressure over S_ij).

Grids are N1 x N2 with spacings (d1, d2) along axis 0 and axis 1 (``delta`` a float:
square elements, d1 = d2); every element is a d1 x d2 rectangle.

Kernels are returned as *offset tables*: ``K[dx, dy]`` for the grid offsets
(dx, dy) in the layout the FFT operator needs (``kernel_table``):

* non-periodic: a (2*N1) x (2*N2) circulant embedding; offsets -(N-1)..(N-1) wrap
  around, the unused offset N is zero.  Convolving a zero-padded field with it is the
  exact aperiodic (finite patch on an infinite half-space) convolution.
* periodic: an N1 x N2 circulant table, with the mean (the q = 0 mode) removed.

Kernels
-------
``bcc``
    Uniform pressure on a rounded patch of radius delta/2 (Borri-Brunetto, Carpinteri
    & Chiaia 1999; paper eq. green2): 2/(pi E delta) on the diagonal and
    2/(pi E delta) arcsin(delta / (2 r)) for (i, j) != (k, l).  (The paper prints
    "i != k, j != l"; it means (i, j) != (k, l).)
    Square elements only (the patch is a disc of the element's width; a rectangular
    element has no such patch): a grid with d1 != d2 is refused, beyond round-off
    (``SQUARE_SPACING_RTOL``: then the spacing along axis 0 is the one used).
``love``
    Uniform pressure on the rectangular element (Love 1929; Johnson, Contact Mechanics,
    eq. 3.25, a rectangle of half-sides a = d1/2, b = d2/2), evaluated at the element
    centres.
``spectral``
    Periodic only: the continuum Boussinesq compliance 2/(E* |q|) sampled at the
    discrete wave vectors q = (2 pi k1 / (N1 d1), 2 pi k2 / (N2 d2)) (q = 0 removed), as
    used by FFT-based codes such as ContactMechanics' PeriodicFFTElasticHalfSpace and
    Tamaas.

An elastic *layer* of finite thickness on a rigid base (``layer=``, a
``problems.layers.Layer``) replaces the half-space: its kernels are built in
problems/layers.py (the formula, its source and its limits: docs/layers.md).

Periodic real-space kernels (``bcc``, ``love``) sum the patch kernel over the periodic
images (periods P1 = N1 d1 and P2 = N2 d2) |m_i| <= M_i and subtract the cell mean.  The
box of images is a physical square (``image_counts``: M_i = ceil(M P_max / P_i), M =
``images``; M1 = M2 = M on a square cell), so that every image outside it is at least
M P_max from every offset of the cell: an elongated cell takes more images along its short
period (a box of M short periods would not reach past the long one, and the tail below
would not hold).  A cell longer than ``MAX_CELL_ASPECT`` times its width is refused
towards 'spectral'.  Removing the mean is removing
the q = 0 mode, whose compliance is infinite for a periodic half-space: the
displacement is then measured from its own mean plane (so on the *whole* grid the
periodic H is singular along the constant vector; on any proper subset it is SPD).
After the subtraction an image at R = (X, Y) contributes, to leading order in |x| / |R|,
the second-order Taylor term of 1/(pi E |R - x|): (3 (x.R)^2 / R^5 - |x|^2 / R^3) / (2 pi E),
which does not cancel over a shell (the in-plane Laplacian of 1/R is 1/R^3, not 0).
Summed over the images outside the box the cross terms cancel and it is
(x^2 (3 Sxx - S) + y^2 (3 Syy - S)) / (2 pi E), S = sum R^-3, Sxx = sum X^2 / R^5,
Syy = sum Y^2 / R^5 (a square lattice: Sxx = Syy = S/2, (|x|^2) S / (4 pi E)).
Truncating at the box therefore leaves an O(1/M) paraboloid error; it is added back in
closed form from these lattice sums (``_image_tail_correction``), minus
its mean, leaving O(M^-3): with M = 2 the table matches M = 24 to ~4e-5 of its diagonal
at N = 16 (6.6e-3 without); on an 8 x 256 or 4 x 256 cell M = 2 matches M = 6 to 6e-5, and
the longest mode's compliance is Boussinesq's 2 / (E* q) to 2e-4 ('love').

Every periodic table is checked before use (``check_periodic_spectrum``): its spectrum,
the eigenvalues of the periodic H, must be > 0 at every q != 0, or the build is a one-line
``ProblemInputError`` pointing to 'spectral' (an indefinite H is a non-convex QP).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .errors import ProblemInputError, check_positive
from .layers import Layer, aperiodic_layer_correction, periodic_layer_correction, spectral_layer_table

KERNELS: tuple[str, ...] = ("bcc", "love", "spectral")

#: A grid spacing: one float (square elements) or (d1, d2) along axis 0 and axis 1.
Spacing = float | tuple[float, float]


def grid_spacing(delta: Spacing, what: str = "delta (grid spacing)") -> tuple[float, float]:
    """(d1, d2) of a spacing given as one float or a pair, each finite and > 0, else a
    one-line ``ProblemInputError``."""
    if np.ndim(delta) == 0:
        d = check_positive(what, delta)  # type: ignore[arg-type]
        return (float(d), float(d))
    pair = tuple(delta)  # type: ignore[arg-type]
    if len(pair) != 2:
        raise ProblemInputError(f"{what} must be one spacing or a pair (axis 0, axis 1), got {delta!r}")
    return (float(check_positive(f"{what} along axis 0", pair[0])), float(check_positive(f"{what} along axis 1", pair[1])))


#: Two spacings that differ by at most this fraction of the larger are one spacing (square
#: elements): the round-off of L0 / N0 against L1 / N1 for equal pixels (150e-6 / 48 and
#: 100e-6 / 32 differ by one ulp), a few ulps; anything larger is a rectangular element.
SQUARE_SPACING_RTOL = 4.0 * float(np.finfo(np.float64).eps)


def square_spacing(delta: Spacing) -> float | None:
    """The one spacing of a grid of square elements: d1 (the spacing along axis 0) when
    |d1 - d2| <= ``SQUARE_SPACING_RTOL`` max(d1, d2), else None (rectangular elements).
    A bad spacing is a one-line ``ProblemInputError`` (``grid_spacing``)."""
    d1, d2 = grid_spacing(delta)
    return d1 if abs(d1 - d2) <= SQUARE_SPACING_RTOL * max(d1, d2) else None


def check_element_shape(kernel: str, delta: Spacing) -> tuple[float, float]:
    """The spacings (d1, d2) of the elements ``kernel`` uses when it takes elements of that
    shape, else a one-line ``ProblemInputError``: 'bcc' needs square elements (``square_spacing``:
    equal to round-off), and uses (d, d), d the spacing along axis 0."""
    d1, d2 = grid_spacing(delta)
    if kernel != "bcc":
        return d1, d2
    d = square_spacing((d1, d2))
    if d is None:
        raise ProblemInputError(f"the 'bcc' kernel needs square elements (its patch is a disc of the element's width); "
                                f"the grid spacings are {d1!r} x {d2!r}: use the 'love' kernel (rectangular elements) "
                                "or 'spectral' (periodic)")
    return d, d


def compliance_scale(E: float, length: float, factor: float) -> float:
    """``factor / (pi E length)``, the scale of a real-space kernel's coefficients, if it
    is a finite float64 of at least the smallest normal one; else a one-line
    ``ProblemInputError`` naming E (an E so small or so large, for the grid, that every
    coefficient overflows to inf or underflows to 0)."""
    with np.errstate(all="ignore"):
        scale = float(np.float64(factor) / (np.pi * np.float64(E) * np.float64(length)))
    if not (np.isfinite(scale) and scale >= np.finfo(np.float64).tiny):
        raise ProblemInputError(_scale_problem(E, f"{factor:g}/(pi E delta) = {scale:g} (delta = {length:g})"))
    return scale


def _scale_problem(E: float, what: str) -> str:
    """The one line for an E whose influence coefficients float64 cannot hold."""
    return (f"E (composite modulus) = {E:g} gives influence coefficients float64 cannot hold: {what}; they must "
            f"be finite and at least {np.finfo(np.float64).tiny:g} (give E in Pa and lengths in m)")


def check_table(table: np.ndarray, E: float) -> np.ndarray:
    """``table`` if every coefficient is finite and the largest is at least the smallest
    normal float64, else a one-line ``ProblemInputError`` naming E (``_scale_problem``)."""
    with np.errstate(all="ignore"):
        top = float(np.max(np.abs(table))) if table.size else 0.0
    if not np.all(np.isfinite(table)):
        raise ProblemInputError(_scale_problem(E, f"{int(np.count_nonzero(~np.isfinite(table)))} of "
                                                  f"{table.size} coefficients are NaN or inf"))
    if not top >= np.finfo(np.float64).tiny:
        raise ProblemInputError(_scale_problem(E, f"the largest coefficient is {top:g}"))
    return table


def bcc_coefficients(dx: np.ndarray, dy: np.ndarray, delta: Spacing, E: float) -> np.ndarray:
    """BCC rounded-patch influence coefficients for grid offsets (dx, dy) (in cells);
    square elements only (a rectangular spacing is a ``ProblemInputError``)."""
    d1, _ = check_element_shape("bcc", delta)
    r = np.hypot(dx, dy) * d1
    out = np.empty(np.broadcast(dx, dy).shape, dtype=np.float64)
    diag = r == 0.0
    scale = compliance_scale(E, d1, 2.0)
    with np.errstate(divide="ignore"):
        out[...] = scale * np.arcsin(np.minimum(1.0, d1 / (2.0 * np.where(diag, 1.0, r))))
    out[diag] = scale
    return out


def _love_term(X: np.ndarray, s: np.ndarray, b: float) -> np.ndarray:
    """X * ln{[(s+b)+sqrt((s+b)^2+X^2)] / [(s-b)+sqrt((s-b)^2+X^2)]}, written with asinh.

    ln(s + sqrt(s^2 + X^2)) = asinh(s/|X|) + ln|X| is free of the cancellation the
    printed form suffers when s is large and negative.
    """
    aX = np.abs(X)
    return X * (np.arcsinh((s + b) / aX) - np.arcsinh((s - b) / aX))


def love_coefficients(dx: np.ndarray, dy: np.ndarray, delta: Spacing, E: float) -> np.ndarray:
    """Love's uniformly loaded rectangle (sides d1 x d2; a float ``delta``: a square)
    influence coefficients at centre offsets (dx, dy) in cells, per unit force."""
    d1, d2 = grid_spacing(delta)
    a, b = 0.5 * d1, 0.5 * d2
    x = np.asarray(dx, dtype=np.float64) * d1
    y = np.asarray(dy, dtype=np.float64) * d2
    # Element centres sit at integer multiples of the spacing, so x +- a and y +- b never vanish.
    u = (
        _love_term(x + a, y, b)
        + _love_term(y + b, x, a)
        - _love_term(x - a, y, b)
        - _love_term(y - b, x, a)
    )
    return u * compliance_scale(E, d1 * d2, 1.0)


_REAL_SPACE: dict[str, Callable[[np.ndarray, np.ndarray, Spacing, float], np.ndarray]] = {
    "bcc": bcc_coefficients,
    "love": love_coefficients,
}


def check_kernel(kernel: str, periodic: bool, layer: Layer | None = None) -> None:
    """A one-line ``ProblemInputError`` for a kernel the boundary condition (or the layer)
    cannot take: unknown names, 'spectral' on a non-periodic domain; a layer needs a
    kernel ``problems.layers`` builds for it (``Layer.check_kernel``)."""
    if kernel not in KERNELS:
        raise ProblemInputError(f"unknown kernel {kernel!r}; choose one of {', '.join(KERNELS)}")
    if kernel == "spectral" and not periodic:
        raise ProblemInputError("the 'spectral' kernel is defined for periodic domains only")
    if layer is not None:
        layer.check_kernel(kernel, periodic)


def _wrapped_offsets(n: int, period: int) -> np.ndarray:
    """Signed offsets for positions 0..period-1 of a circulant table of length ``period``."""
    k = np.arange(period)
    return np.where(k <= period // 2, k, k - period)


def aperiodic_table(kernel: str, shape: tuple[int, int], delta: Spacing, E: float) -> np.ndarray:
    """(2*N1) x (2*N2) circulant embedding of the aperiodic kernel.  Both real-space kernels
    are even in each offset, so the coefficients are evaluated on the quarter of offsets
    0..N-1 and mirrored: the table is exactly even, and a quarter of the work."""
    n1, n2 = shape
    quarter = _REAL_SPACE[kernel](np.arange(n1)[:, None], np.arange(n2)[None, :], delta, E)
    table = np.zeros((2 * n1, 2 * n2))
    table[:n1, :n2] = quarter
    table[n1 + 1:, :n2] = quarter[:0:-1, :]
    # Offset +-N is never needed by an N-point grid: row N1 and column N2 stay zero.
    table[:, n2 + 1:] = table[:, n2 - 1:0:-1]
    return table


#: The longest periodic cell the real-space periodic kernels ('bcc', 'love') take, as the
#: ratio of its longer period to its shorter (physical lengths N_i d_i).  The image box is a
#: physical square (``image_counts``), so the images summed grow with the ratio: (4 r + 1) x 5
#: at ``images`` = 2, 1285 at r = 64, against 25 for a square cell.  A longer cell is refused
#: (``check_cell_aspect``): 'spectral' is exact on every shape at the cost of one FFT.
MAX_CELL_ASPECT = 64.0


def cell_aspect(shape: tuple[int, int], spacing: tuple[float, float]) -> float:
    """The periodic cell's longer period over its shorter: max(N_i d_i) / min(N_i d_i)."""
    p1, p2 = shape[0] * spacing[0], shape[1] * spacing[1]
    return max(p1, p2) / min(p1, p2)


def check_cell_aspect(kernel: str, shape: tuple[int, int], spacing: tuple[float, float]) -> None:
    """A one-line ``ProblemInputError`` when the periodic cell is longer than
    ``MAX_CELL_ASPECT`` times its width, for a real-space kernel ('spectral' takes any cell)."""
    ratio = cell_aspect(shape, spacing)
    if kernel != "spectral" and ratio > MAX_CELL_ASPECT:
        raise ProblemInputError(
            f"the periodic '{kernel}' kernel on the {shape[0]} x {shape[1]} grid: the cell's aspect ratio {ratio!r} "
            f"exceeds {MAX_CELL_ASPECT:g} (its image sum would need about {ratio:.0f} x the images of a square cell); "
            "use --kernel spectral (exact on every cell shape)")


def image_counts(periods: tuple[float, float], images: int) -> tuple[int, int]:
    """(M1, M2): the periodic images summed along each axis, |m_i| <= M_i, so that the box is
    a physical square to within one period: M_i = ceil(images P_max / P_i) (a relative 1e-9
    of slack, so equal periods up to round-off give M1 = M2 = ``images``).  The shorter
    period takes more images; the tail beyond the box is then at a distance >= images
    P_max from every offset of the cell, the condition of ``_image_tail_correction``."""
    top = max(periods)
    return tuple(max(int(images), int(np.ceil(images * top / p * (1.0 - 1e-9)))) for p in periods)  # type: ignore[return-value]


def periodic_table(
    kernel: str, shape: tuple[int, int], delta: Spacing, E: float, images: int = 2
) -> np.ndarray:
    """N1 x N2 circulant table of the periodic kernel, with the q = 0 mode removed.

    Real-space kernels sum |m_i| <= M_i images (``image_counts``: a physically square box)
    plus the closed-form tail beyond it; a cell longer than ``MAX_CELL_ASPECT`` times its
    width is a one-line ``ProblemInputError`` (``check_cell_aspect``)."""
    n1, n2 = shape
    if kernel == "spectral":
        return _spectral_table(shape, delta, E)
    f = _REAL_SPACE[kernel]
    d1, d2 = grid_spacing(delta)
    check_cell_aspect(kernel, (n1, n2), (d1, d2))
    m1, m2 = image_counts((n1 * d1, n2 * d2), images)
    ox = _wrapped_offsets(n1, n1).astype(np.float64)
    oy = _wrapped_offsets(n2, n2).astype(np.float64)
    table = np.zeros(shape)
    for mx in range(-m1, m1 + 1):
        for my in range(-m2, m2 + 1):
            table += f(ox[:, None] + mx * n1, oy[None, :] + my * n2, delta, E)
    table += _image_tail_correction((n1, n2), delta, E, (m1, m2))
    # Make the table exactly even (the half-period offset has an asymmetric image set).
    table = 0.5 * (table + np.roll(table[::-1, :], 1, axis=0))
    table = 0.5 * (table + np.roll(table[:, ::-1], 1, axis=1))
    table -= table.mean()
    return table


def _lattice_tail_sums(periods: tuple[float, float], box: tuple[int, int], shells: int = 400) -> tuple[float, float, float]:
    """(S, Sxx, Syy) = sums of R^-3, X^2 R^-5 and Y^2 R^-5 over the lattice points
    R = (mx P1, my P2) outside the box |mx| <= M1, |my| <= M2: explicit rectangular rings
    (M1 + j, M2 + j), j = 1 .. shells - min(M1, M2), then the integral over the plane outside
    the last ring's rectangle of half-sides (M_i + j + 1/2) P_i at the lattice's density
    1 / (P1 P2): integral dtheta w(theta) / R(theta) with w = 1, cos^2, sin^2.  The last
    ring lies shells - min(M1, M2) periods past the box along each axis: >= 5 of the longer
    period even along the shorter one for a cell of aspect <= ``MAX_CELL_ASPECT``, so the
    integral replaces a sum over many lattice steps (shells = 1600 changes the sums by < 1e-7
    relative on 8 x 256 and 4 x 256 cells).  (A square box, M1 = M2 = M: the shells
    M + 1 .. ``shells``.)"""
    p1, p2 = periods
    m1, m2 = box
    rings = max(shells - min(m1, m2), 0)
    s = sxx = syy = 0.0
    for j in range(1, rings + 1):
        a, b = m1 + j, m2 + j
        iy = np.arange(-b, b + 1, dtype=np.float64)
        ix = np.arange(-(a - 1), a, dtype=np.float64)
        # mx = +-a (all |my| <= b) and my = +-b (|mx| < a)
        X = np.concatenate([np.full(iy.size, a * p1), ix * p1])
        Y = np.concatenate([iy * p2, np.full(ix.size, b * p2)])
        R2 = X * X + Y * Y
        inv3 = R2**-1.5
        s += 2.0 * float(np.sum(inv3))
        sxx += 2.0 * float(np.sum(X * X * inv3 / R2))
        syy += 2.0 * float(np.sum(Y * Y * inv3 / R2))
    a, b = (m1 + rings + 0.5) * p1, (m2 + rings + 0.5) * p2
    theta = (np.arange(20000) + 0.5) * (2.0 * np.pi / 20000)
    c, sn = np.cos(theta), np.sin(theta)
    inv_R = np.maximum(np.abs(c) / a, np.abs(sn) / b)
    w = 2.0 * np.pi / (p1 * p2)
    return (s + w * float(np.mean(inv_R)), sxx + w * float(np.mean(c * c * inv_R)),
            syy + w * float(np.mean(sn * sn * inv_R)))


def _image_tail_correction(shape: tuple[int, int], delta: Spacing, E: float, box: tuple[int, int]) -> np.ndarray:
    """Leading-order contribution of the periodic images outside the box |m_i| <= M_i:
    (x^2 (3 Sxx - S) + y^2 (3 Syy - S)) / (2 pi E) (see the module doc), less its mean.
    The Taylor expansion behind it is in |x| / |R|, |x| <= half the cell's diagonal: valid
    when every image outside the box is far against the cell, as ``image_counts`` makes it."""
    n1, n2 = shape
    d1, d2 = grid_spacing(delta)
    x = _wrapped_offsets(n1, n1) * d1
    y = _wrapped_offsets(n2, n2) * d2
    S, Sxx, Syy = _lattice_tail_sums((n1 * d1, n2 * d2), box)
    quad = x[:, None] ** 2 * (3.0 * Sxx - S) + y[None, :] ** 2 * (3.0 * Syy - S)
    return (quad - quad.mean()) / (2.0 * np.pi * E)


def check_periodic_spectrum(table: np.ndarray, kernel: str, spacing: tuple[float, float]) -> np.ndarray:
    """``table`` (a periodic N1 x N2 circulant table) if its spectrum, the eigenvalues of the
    periodic H, is > 0 at every wave vector q != 0 (q = 0 is removed by definition), else a
    one-line ``ProblemInputError`` naming the kernel, the grid and the cell's aspect ratio:
    an indefinite H is a non-convex QP.  One real FFT of the table."""
    lam = np.fft.rfft2(table).real
    lam.flat[0] = np.inf
    if not lam.min() > 0.0:  # (check_table has ruled out NaN)
        n1, n2 = table.shape
        bad = int(np.count_nonzero(lam <= 0.0))
        raise ProblemInputError(
            f"the periodic '{kernel}' table on the {n1} x {n2} grid (cell aspect ratio "
            f"{cell_aspect((n1, n2), spacing):.4g}) is not positive definite: {bad} wave vector(s) q != 0 have "
            f"eigenvalue <= 0 (least {float(lam.min()):.3g}); "
            "use --kernel spectral")
    return table


def exactly_even(table: np.ndarray) -> np.ndarray:
    """``table`` made exactly even on its periodic cell: 0.5 (K + K[(-i) mod P1, (-j) mod P2]),
    so that K(-k) == K(k) bit for bit and H is exactly symmetric (an inverse FFT is even only
    to round-off).  A table that is already even is returned unchanged, bit for bit."""
    p1, p2 = table.shape
    reflected = table[(-np.arange(p1)) % p1][:, (-np.arange(p2)) % p2]
    return 0.5 * (table + reflected)


def _spectral_table(shape: tuple[int, int], delta: Spacing, E: float) -> np.ndarray:
    return exactly_even(spectral_layer_table(shape, grid_spacing(delta), E, None))


def kernel_table(
    kernel: str,
    shape: tuple[int, int],
    delta: Spacing,
    E: float,
    periodic: bool,
    images: int = 2,
    layer: Layer | None = None,
) -> np.ndarray:
    """Offset table of the influence coefficients for the FFT operator (see module doc).

    ``delta``: the spacing, one float (square elements) or (d1, d2) along axis 0 and
    axis 1.  ``layer``: None for the elastic half-space, else the elastic layer of finite
    thickness on a rigid base (``problems.layers``; which kernels take one:
    ``Layer.check_kernel``).  Every table is exactly even, K(-k) == K(k) bit for bit, so H
    is exactly symmetric (the spectral and layer tables by ``exactly_even``).  An E for
    which float64 cannot hold the coefficients (any
    NaN or inf, or all below the smallest normal float64) is a one-line
    ``ProblemInputError`` naming E (``check_table``), even where E itself passes.  A
    periodic table whose spectrum is not > 0 at every q != 0 is refused
    (``check_periodic_spectrum``), and so is a periodic real-space kernel on a cell longer
    than ``MAX_CELL_ASPECT`` times its width (``check_cell_aspect``)."""
    check_kernel(kernel, periodic, layer)
    check_positive("E (composite modulus)", E)
    spacing = grid_spacing(delta)
    n1, n2 = (int(s) for s in shape)
    if n1 < 1 or n2 < 1 or n1 * n2 < 2:
        raise ProblemInputError(f"grid shape {shape} has fewer than two points")
    with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):  # (check_table judges)
        if periodic and kernel == "spectral":
            table = check_table(exactly_even(spectral_layer_table((n1, n2), spacing, E, layer)), E)
            return check_periodic_spectrum(table, kernel, spacing)
        if periodic:
            table = periodic_table(kernel, (n1, n2), spacing, E, images=images)
            table = check_table(table if layer is None else
                                exactly_even(table + periodic_layer_correction(kernel, (n1, n2), spacing, E, layer)),
                                E)
            return check_periodic_spectrum(table, kernel, spacing)
        table = aperiodic_table(kernel, (n1, n2), spacing, E)
        if layer is not None:
            table = exactly_even(table + aperiodic_layer_correction(kernel, (n1, n2), spacing, E, layer))
            table[n1, :] = 0.0
            table[:, n2] = 0.0
    return check_table(table, E)
