"""Influence coefficients H_{i-k,j-l} of the elastic half-space (paper eqs. green, green2).

All kernels are *per unit force*: the displacement at element (i, j) caused by a unit
resultant force on element (k, l).  With E the composite modulus E* = E/(1-nu^2) in Pa
and lengths in metres, H is in m/N and the unknown p of the QP is the force in N carried
by each element (the paper's p_{i,j}, the resultant of the pressure over S_ij).

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
``love``
    Uniform pressure on the square element (Love 1929; Johnson, Contact Mechanics,
    eq. 3.25), evaluated at the element centres.
``spectral``
    Periodic only: the continuum Boussinesq compliance 2/(E* |q|) sampled at the
    discrete wave vectors (q = 0 removed), as used by FFT-based codes such as
    ContactMechanics' PeriodicFFTElasticHalfSpace and Tamaas.

Periodic real-space kernels (``bcc``, ``love``) sum the patch kernel over
(2M+1)^2 periodic images and subtract the cell mean.  Removing the mean is removing
the q = 0 mode, whose compliance is infinite for a periodic half-space: the
displacement is then measured from its own mean plane (so on the *whole* grid the
periodic H is singular along the constant vector; on any proper subset it is SPD).
After the subtraction an image at distance R contributes, to leading order, the
isotropic second-order Taylor term (|x|^2 - <|x|^2>)/4 * lap(1/(pi E R)) =
(|x|^2 - <|x|^2>) / (4 pi E R^3), which does not cancel over a shell (the in-plane
Laplacian of 1/R is 1/R^3, not 0).  Truncating at M shells therefore leaves an
O(1/M) paraboloid error; it is added back in closed form from the lattice sum of
R^-3 beyond shell M (``_image_tail_correction``), leaving O(M^-3): with M = 2 the
table matches M = 24 to ~4e-5 of its diagonal at N = 16 (6.6e-3 without).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .errors import ProblemInputError, check_positive

KERNELS: tuple[str, ...] = ("bcc", "love", "spectral")


def bcc_coefficients(dx: np.ndarray, dy: np.ndarray, delta: float, E: float) -> np.ndarray:
    """BCC rounded-patch influence coefficients for grid offsets (dx, dy) (in cells)."""
    r = np.hypot(dx, dy) * delta
    out = np.empty(np.broadcast(dx, dy).shape, dtype=np.float64)
    diag = r == 0.0
    scale = 2.0 / (np.pi * E * delta)
    with np.errstate(divide="ignore"):
        out[...] = scale * np.arcsin(np.minimum(1.0, delta / (2.0 * np.where(diag, 1.0, r))))
    out[diag] = scale
    return out


def _love_term(X: np.ndarray, s: np.ndarray, b: float) -> np.ndarray:
    """X * ln{[(s+b)+sqrt((s+b)^2+X^2)] / [(s-b)+sqrt((s-b)^2+X^2)]}, written with asinh.

    ln(s + sqrt(s^2 + X^2)) = asinh(s/|X|) + ln|X| is free of the cancellation the
    printed form suffers when s is large and negative.
    """
    aX = np.abs(X)
    return X * (np.arcsinh((s + b) / aX) - np.arcsinh((s - b) / aX))


def love_coefficients(dx: np.ndarray, dy: np.ndarray, delta: float, E: float) -> np.ndarray:
    """Love's uniformly loaded square (side delta) influence coefficients at centre offsets."""
    a = b = 0.5 * delta
    x = np.asarray(dx, dtype=np.float64) * delta
    y = np.asarray(dy, dtype=np.float64) * delta
    # Element centres sit at integer multiples of delta, so x +- a and y +- b never vanish.
    u = (
        _love_term(x + a, y, b)
        + _love_term(y + b, x, a)
        - _love_term(x - a, y, b)
        - _love_term(y - b, x, a)
    )
    return u / (np.pi * E * delta * delta)


_REAL_SPACE: dict[str, Callable[[np.ndarray, np.ndarray, float, float], np.ndarray]] = {
    "bcc": bcc_coefficients,
    "love": love_coefficients,
}


def check_kernel(kernel: str, periodic: bool) -> None:
    if kernel not in KERNELS:
        raise ProblemInputError(f"unknown kernel {kernel!r}; choose one of {', '.join(KERNELS)}")
    if kernel == "spectral" and not periodic:
        raise ProblemInputError("the 'spectral' kernel is defined for periodic domains only")


def _wrapped_offsets(n: int, period: int) -> np.ndarray:
    """Signed offsets for positions 0..period-1 of a circulant table of length ``period``."""
    k = np.arange(period)
    return np.where(k <= period // 2, k, k - period)


def aperiodic_table(kernel: str, shape: tuple[int, int], delta: float, E: float) -> np.ndarray:
    """(2*N1) x (2*N2) circulant embedding of the aperiodic kernel."""
    n1, n2 = shape
    ox = _wrapped_offsets(n1, 2 * n1)
    oy = _wrapped_offsets(n2, 2 * n2)
    table = _REAL_SPACE[kernel](ox[:, None], oy[None, :], delta, E)
    # Offset +-N is never needed by an N-point grid; zero it so the table stays even.
    table[n1, :] = 0.0
    table[:, n2] = 0.0
    return table


def periodic_table(
    kernel: str, shape: tuple[int, int], delta: float, E: float, images: int = 2
) -> np.ndarray:
    """N1 x N2 circulant table of the periodic kernel, with the q = 0 mode removed."""
    n1, n2 = shape
    if kernel == "spectral":
        return _spectral_table(shape, delta, E)
    f = _REAL_SPACE[kernel]
    ox = _wrapped_offsets(n1, n1).astype(np.float64)
    oy = _wrapped_offsets(n2, n2).astype(np.float64)
    table = np.zeros(shape)
    for mx in range(-images, images + 1):
        for my in range(-images, images + 1):
            table += f(ox[:, None] + mx * n1, oy[None, :] + my * n2, delta, E)
    table += _image_tail_correction((n1, n2), delta, E, images)
    # Make the table exactly even (the half-period offset has an asymmetric image set).
    table = 0.5 * (table + np.roll(table[::-1, :], 1, axis=0))
    table = 0.5 * (table + np.roll(table[:, ::-1], 1, axis=1))
    table -= table.mean()
    return table


def _lattice_tail_sum(periods: tuple[float, float], images: int, shells: int = 400) -> float:
    """sum |(mx P1, my P2)|^-3 over integer (mx, my) with max(|mx|, |my|) > images:
    explicit square shells up to ``shells``, then the integral over the plane outside
    the rectangle of half-sides (shells + 1/2) P, which is integral dtheta / R(theta)."""
    p1, p2 = periods
    total = 0.0
    for k in range(images + 1, shells + 1):
        i = np.arange(-k, k + 1, dtype=np.float64)
        inner = i[1:-1]
        r_rows = np.hypot(k * p1, i * p2)  # mx = +-k, all my
        r_cols = np.hypot(inner * p1, k * p2)  # my = +-k, |mx| < k
        total += 2.0 * float(np.sum(r_rows**-3.0)) + 2.0 * float(np.sum(r_cols**-3.0))
    a, b = (shells + 0.5) * p1, (shells + 0.5) * p2
    theta = (np.arange(20000) + 0.5) * (2.0 * np.pi / 20000)
    inv_R = np.maximum(np.abs(np.cos(theta)) / a, np.abs(np.sin(theta)) / b)
    return total + float(np.mean(inv_R)) * 2.0 * np.pi


def _image_tail_correction(shape: tuple[int, int], delta: float, E: float, images: int) -> np.ndarray:
    """Leading-order contribution of the periodic images beyond shell ``images``:
    (|x|^2 - <|x|^2>) / (4 pi E) * sum_{far images} R^-3 (see the module doc)."""
    n1, n2 = shape
    x = _wrapped_offsets(n1, n1) * delta
    y = _wrapped_offsets(n2, n2) * delta
    r2 = x[:, None] ** 2 + y[None, :] ** 2
    tail = _lattice_tail_sum((n1 * delta, n2 * delta), images)
    return (r2 - r2.mean()) * tail / (4.0 * np.pi * E)


def _spectral_table(shape: tuple[int, int], delta: float, E: float) -> np.ndarray:
    n1, n2 = shape
    q1 = 2.0 * np.pi * np.fft.fftfreq(n1, d=delta)
    q2 = 2.0 * np.pi * np.fft.fftfreq(n2, d=delta)
    q = np.hypot(q1[:, None], q2[None, :])
    with np.errstate(divide="ignore"):
        g = np.where(q > 0, 2.0 / (E * np.where(q > 0, q, 1.0)), 0.0)
    # Force per element -> pressure: divide by the element area.
    return np.real(np.fft.ifft2(g)) / (delta * delta)


def kernel_table(
    kernel: str,
    shape: tuple[int, int],
    delta: float,
    E: float,
    periodic: bool,
    images: int = 2,
) -> np.ndarray:
    """Offset table of the influence coefficients for the FFT operator (see module doc)."""
    check_kernel(kernel, periodic)
    check_positive("E (composite modulus)", E)
    check_positive("delta (grid spacing)", delta)
    n1, n2 = (int(s) for s in shape)
    if n1 < 1 or n2 < 1 or n1 * n2 < 2:
        raise ProblemInputError(f"grid shape {shape} has fewer than two points")
    if periodic:
        return periodic_table(kernel, (n1, n2), delta, E, images=images)
    return aperiodic_table(kernel, (n1, n2), delta, E)
