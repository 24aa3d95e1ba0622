"""An elastic layer of finite thickness on a rigid base: its surface compliance and the
influence-coefficient tables built from it (docs/layers.md has the derivation's source
and the limits the tests check).

A layer of thickness T (Young's modulus E, Poisson's ratio nu, composite modulus
E* = E / (1 - nu^2), the ``E`` every kernel takes) lies on a rigid flat base; its top is
loaded by a normal pressure, frictionless.  A pressure mode p(q) e^{i q.x} displaces the
top by u(q) = 2 / (E* |q|) f(|q| T) p(q): the half-space compliance 2 / (E* q) times a
factor f(s), s = q T, that tends to 1 for s -> infinity (short waves do not feel the base)
and to 0 for s -> 0:

* base bonded to the layer (no slip; Carbone & Mangialardi 2008, eq. A.30; Carbone,
  Lorenz, Persson & Wohlers 2009, eq. A9)::

      f(s) = [(3 - 4 nu) sinh 2s - 2s] / [(3 - 4 nu) cosh 2s + 2 s^2 + 5 - 12 nu + 8 nu^2]

  thin limit f ~ s (1 - 2 nu) / (2 (1 - nu)^2): u = p T (1 - 2 nu) / (E* (1 - nu)^2)
  = p T / M, M the confined (oedometric) modulus; incompressible (nu = 1/2):
  f ~ 2 s^3 / 3, u = q^2 T^3 p / (3 G) (the lubrication limit);
* base frictionless (the layer slides on it)::

      f(s) = (cosh 2s - 1) / (sinh 2s + 2s)      (no nu: E* carries it)

  thin limit f ~ s / 2.

Both were re-derived for this module from Navier's equations for one plane-strain
Fourier mode (sympy: displacements (a + b z) e^{+-qz}, traction-free shear and unit
pressure on top, u = 0 (bonded) or u_z = sigma_xz = 0 (frictionless) at z = -T); the
bonded one is what ContactMechanics' PeriodicFFTElasticHalfSpace(thickness=, poisson=)
evaluates.

Tables (per unit force, the layout of problems/kernels.py):

* periodic ``spectral``: 2 f(qT) / (E* q) at the grid's wave vectors, q = 0 removed;
* periodic ``bcc`` / ``love``: the half-space table plus the correction
  2 (f(qT) - 1) / (E* q) F(q), F the element's form factor (a disc of the element's
  width / the d1 x d2 rectangle), its aliases |m| <= ``ALIASES`` folded in;
* non-periodic ``bcc`` / ``love``: the half-space table plus the point-force correction
  c(r) = (1 / (pi E* T)) int_0^inf (f(s) - 1) J0(s r / T) ds, tabulated once per
  (nu, interface) in r / T and averaged over the d1 x d2 element by Gauss-Legendre
  quadrature (``ELEMENT_GAUSS`` points a side).  The layer's own kernel decays
  exponentially in r / T, so beyond ``RHO_FAR`` thicknesses c(r) = -1 / (pi E* r).

The q = 0 mode: a periodic layer, like the periodic half-space, has its q = 0 mode removed
(displacements are measured from the mean plane); the uniform compression it would add,
p_mean T / M for either base, is ``Layer.mean_compliance``.  Real-space kernels need
T >= the grid spacing (the correction must be smooth on an element), and 'bcc' T >=
``BCC_MIN_THICKNESS`` spacings (its self-term makes a thin layer too stiff by ~0.58 spacing
/ T); 'spectral' takes any T.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np

from .errors import ProblemInputError, check_positive

Interface = Literal["bonded", "frictionless"]
INTERFACES: tuple[str, ...] = ("bonded", "frictionless")
#: Poisson's ratio when none is given.
DEFAULT_NU = 0.3
#: The range of Poisson's ratio: (-1, 0.5], open below, closed above (incompressible).
NU_RANGE: tuple[float, float] = (-1.0, 0.5)
#: Aliases folded into a periodic real-space correction: |m1|, |m2| <= ALIASES.
ALIASES = 2
#: Gauss-Legendre points per side averaging the non-periodic correction over an element.
ELEMENT_GAUSS = 4
#: Beyond RHO_FAR thicknesses the layer's own point kernel is below 1e-12 of 1/(pi E* r)
#: and the correction is -1 / (pi E* r).
RHO_FAR = 60.0
#: Tabulation step of the non-periodic correction in r / T (cubic spline).
RHO_STEP = 0.02
#: The thinnest layer the 'bcc' kernel takes, in grid spacings (T >= BCC_MIN_THICKNESS x the
#: larger spacing).  The paper's bcc self-term, 2 / (pi E* delta) per unit force, is 0.64 p delta
#: / E* per unit pressure where Love's uniformly loaded square gives 1.12 p delta / E*: a
#: deficit that does not shrink with the load's extent a, so bcc is too stiff by a relative
#: error first order in delta / a.  In a layer the load acts over ~T, and the centre of a wide
#: uniformly loaded bonded layer (nu = 0.3) sinks 0.417, 0.708, 0.854, 0.927, 0.956, 0.971
#: x p T / M at T = 1, 2, 4, 8, 12.8, 20 spacings ('love': 1.000 to 1e-3): about 0.58 delta / T
#: too stiff.  From 12 spacings on the error is under 5 %; the layer-sweep scene's thinnest
#: layer (0.1 L at 128^2, 12.8 spacings) is 4.4 % too stiff.  'love' has no such bias.
BCC_MIN_THICKNESS = 12.0
#: The relative round-off ``Layer.check_kernel`` forgives a thickness typed as a decimal
#: (12 x L / N written out is not always 12 spacings to the last bit).
THICKNESS_ROUNDING = 1e-12


@dataclass(frozen=True)
class Layer:
    """An elastic layer of ``thickness`` (metres, the surface's length unit) on a rigid
    base, Poisson's ratio ``nu`` in (-1, 1/2], its base ``interface`` "bonded" or
    "frictionless"."""

    thickness: float
    nu: float = DEFAULT_NU
    interface: Interface = "bonded"

    def __post_init__(self) -> None:
        check_positive("layer thickness", self.thickness)
        if not (isinstance(self.nu, (int, float, np.floating)) and np.isfinite(self.nu)
                and NU_RANGE[0] < self.nu <= NU_RANGE[1]):
            raise ProblemInputError(f"Poisson's ratio nu must lie in ({NU_RANGE[0]:g}, {NU_RANGE[1]:g}], got {self.nu!r}")
        if self.interface not in INTERFACES:
            raise ProblemInputError(f"layer interface must be 'bonded' or 'frictionless', got {self.interface!r}")

    @property
    def label(self) -> str:
        """A short name: "layer-T1e-05-nu0.3-bonded"."""
        return f"layer-T{self.thickness:g}-nu{self.nu:g}-{self.interface}"

    def factor(self, s: np.ndarray) -> np.ndarray:
        """f(s), s = |q| T >= 0 (module doc); f(0) = 0."""
        return compliance_factor(np.asarray(s, dtype=np.float64), float(self.nu), self.interface)

    def thin_slope(self) -> float:
        """f'(0): (1 - 2 nu) / (2 (1 - nu)^2) bonded, 1/2 frictionless."""
        return 0.5 if self.interface == "frictionless" else (1.0 - 2.0 * self.nu) / (2.0 * (1.0 - self.nu) ** 2)

    def mean_compliance(self, E: float) -> float:
        """Displacement per unit uniform pressure, T / M = T (1 - 2 nu) / (E* (1 - nu)^2)
        (uniaxial strain; either base): the q = 0 mode the periodic tables leave out."""
        return self.thickness * (1.0 - 2.0 * self.nu) / (float(E) * (1.0 - self.nu) ** 2)

    def check_kernel(self, kernel: str, periodic: bool, spacing: tuple[float, float] | None = None) -> None:
        """A ``ProblemInputError`` when this layer cannot be built for ``kernel`` (when
        ``spacing`` is known): a real-space kernel ('bcc', 'love') needs T >= the grid spacing,
        and 'bcc' T >= ``BCC_MIN_THICKNESS`` spacings (its bias, ~0.58 spacing / T too stiff)."""
        if kernel == "spectral" or spacing is None:
            return
        d = max(spacing)
        if self.thickness < d:
            raise ProblemInputError(
                f"a layer of thickness {self.thickness:g} is thinner than a grid element ({d:g}): the "
                f"'{kernel}' kernel's layer correction needs T >= the spacing; use the periodic 'spectral' kernel "
                "or a finer grid")
        if kernel == "bcc" and self.thickness < BCC_MIN_THICKNESS * d * (1.0 - THICKNESS_ROUNDING):
            raise ProblemInputError(
                f"a layer of thickness {self.thickness:g} is {self.thickness / d:.3g} grid spacings ({d:g}): the 'bcc' "
                f"kernel is too stiff on it by ~{58.0 * d / self.thickness:.0f} % (0.58 spacing / T) and needs "
                f"T >= {BCC_MIN_THICKNESS:g} spacings; use --kernel love (or a finer grid)")


def compliance_factor(s: np.ndarray, nu: float, interface: str) -> np.ndarray:
    """f(s) of the module doc, written with e^{-2s} so it neither overflows nor cancels."""
    s = np.asarray(s, dtype=np.float64)
    e2 = np.exp(-2.0 * s)
    if interface == "frictionless":
        one_m_e2 = -np.expm1(-2.0 * s)
        den = -np.expm1(-4.0 * s) + 4.0 * s * e2
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(s > 0, one_m_e2 * one_m_e2 / np.where(s > 0, den, 1.0), 0.0)
    k = 3.0 - 4.0 * nu
    off = 5.0 - 12.0 * nu + 8.0 * nu * nu
    num = -k * np.expm1(-4.0 * s) - 4.0 * s * e2
    den = k * (1.0 + e2 * e2) + (4.0 * s * s + 2.0 * off) * e2
    return num / den


def _wave_numbers(shape: tuple[int, int], spacing: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    q1 = 2.0 * np.pi * np.fft.fftfreq(shape[0], d=spacing[0])
    q2 = 2.0 * np.pi * np.fft.fftfreq(shape[1], d=spacing[1])
    return q1, q2


def spectral_layer_table(shape: tuple[int, int], spacing: tuple[float, float], E: float,
                         layer: Layer | None) -> np.ndarray:
    """N1 x N2 periodic table of 2 f(qT) / (E* q) (f = 1: the half-space), q = 0 removed,
    per unit force on a d1 x d2 element."""
    q1, q2 = _wave_numbers(shape, spacing)
    q = np.hypot(q1[:, None], q2[None, :])
    safe = np.where(q > 0, q, 1.0)
    f = 1.0 if layer is None else layer.factor(safe * layer.thickness)
    g = np.where(q > 0, 2.0 * f / (E * safe), 0.0)
    return np.real(np.fft.ifft2(g)) / (spacing[0] * spacing[1])


def _form_factor(kernel: str, q1: np.ndarray, q2: np.ndarray, spacing: tuple[float, float]) -> np.ndarray:
    """Fourier transform of the element's unit pressure distribution (1 at q = 0)."""
    if kernel == "bcc":
        from scipy.special import j1

        qa = np.hypot(q1, q2) * 0.5 * spacing[0]
        return np.where(qa > 0, 2.0 * j1(qa) / np.where(qa > 0, qa, 1.0), 1.0)
    return np.sinc(q1 * spacing[0] / (2.0 * np.pi)) * np.sinc(q2 * spacing[1] / (2.0 * np.pi))


def periodic_layer_correction(kernel: str, shape: tuple[int, int], spacing: tuple[float, float], E: float,
                              layer: Layer) -> np.ndarray:
    """N1 x N2 table of the layer's correction to a periodic real-space kernel (module doc)."""
    layer.check_kernel(kernel, True, spacing)
    q1, q2 = _wave_numbers(shape, spacing)
    g = np.zeros(shape)
    for m1 in range(-ALIASES, ALIASES + 1):
        for m2 in range(-ALIASES, ALIASES + 1):
            a1 = (q1 + 2.0 * np.pi * m1 / spacing[0])[:, None]
            a2 = (q2 + 2.0 * np.pi * m2 / spacing[1])[None, :]
            q = np.hypot(a1, a2)
            safe = np.where(q > 0, q, 1.0)
            term = 2.0 * (layer.factor(safe * layer.thickness) - 1.0) / (E * safe) * _form_factor(kernel, a1, a2, spacing)
            g += np.where(q > 0, term, 0.0)
    table = np.real(np.fft.ifft2(g)) / (spacing[0] * spacing[1])
    return table - table.mean()


@lru_cache(maxsize=16)
def _correction_spline(nu: float, interface: str) -> object:
    """Cubic spline of C(rho) = int_0^inf (f(s) - 1) J0(s rho) ds on [0, RHO_FAR]."""
    from scipy.interpolate import CubicSpline
    from scipy.special import j0

    # (f - 1) < 1e-18 beyond s = 30; Gauss-Legendre panels of 0.05 resolve J0(s rho) for rho <= RHO_FAR.
    nodes, weights = np.polynomial.legendre.leggauss(8)
    edges = np.arange(0.0, 30.0 + 1e-12, 0.05)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    s = (mid[:, None] + half[:, None] * nodes[None, :]).ravel()
    w = (half[:, None] * weights[None, :]).ravel()
    g = (compliance_factor(s, nu, interface) - 1.0) * w
    rho = np.arange(0.0, RHO_FAR + RHO_STEP, RHO_STEP)
    values = np.empty(rho.size)
    for b0 in range(0, rho.size, 256):
        r = rho[b0:b0 + 256]
        values[b0:b0 + 256] = j0(r[:, None] * s[None, :]) @ g
    return CubicSpline(rho, values)


def point_correction(r: np.ndarray, E: float, layer: Layer) -> np.ndarray:
    """c(r): the layer's point-force displacement minus the half-space's 1/(pi E* r)."""
    T = layer.thickness
    rho = np.asarray(r, dtype=np.float64) / T
    spline = _correction_spline(float(layer.nu), layer.interface)
    with np.errstate(divide="ignore"):
        far = -1.0 / np.where(rho > 0, rho, 1.0)
    near = spline(np.minimum(rho, RHO_FAR))  # type: ignore[operator]
    return np.where(rho <= RHO_FAR, near, far) / (np.pi * E * T)


def aperiodic_layer_correction(kernel: str, shape: tuple[int, int], spacing: tuple[float, float], E: float,
                               layer: Layer) -> np.ndarray:
    """(2 N1) x (2 N2) circulant table of the layer's correction to the non-periodic ``kernel``
    ('bcc' or 'love'; ``Layer.check_kernel`` judges the thickness): c averaged over the
    d1 x d2 element (module doc)."""
    layer.check_kernel(kernel, False, spacing)
    n1, n2 = shape
    k1 = np.arange(2 * n1)
    k2 = np.arange(2 * n2)
    x = np.where(k1 <= n1, k1, k1 - 2 * n1) * spacing[0]
    y = np.where(k2 <= n2, k2, k2 - 2 * n2) * spacing[1]
    nodes, weights = np.polynomial.legendre.leggauss(ELEMENT_GAUSS)
    out = np.zeros((2 * n1, 2 * n2))
    for u, wu in zip(nodes * 0.5 * spacing[0], weights * 0.5):
        for v, wv in zip(nodes * 0.5 * spacing[1], weights * 0.5):
            out += wu * wv * point_correction(np.hypot((x + u)[:, None], (y + v)[None, :]), E, layer)
    return out


__all__ = [
    "ALIASES",
    "BCC_MIN_THICKNESS",
    "DEFAULT_NU",
    "ELEMENT_GAUSS",
    "INTERFACES",
    "Layer",
    "aperiodic_layer_correction",
    "compliance_factor",
    "periodic_layer_correction",
    "point_correction",
    "spectral_layer_table",
]
