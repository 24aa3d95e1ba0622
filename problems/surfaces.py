"""Rough surfaces: the ``Surface`` record, random midpoint displacement (RMD) and
spectral generators, and the radially averaged PSD with a Hurst-exponent fit.

Conventions: heights and lengths in metres (``unit`` says otherwise).  A surface is an
N0 x N1 grid (axis 0 = rows, axis 1 = columns) with spacings ``delta`` along axis 0 and
``delta1`` along axis 1 (None: square pixels, ``delta1 = delta``); its physical sizes are
``lengths = (N0 delta, N1 delta1)``.  The generators here make square grids, N x N with
spacing ``delta = L / N`` (periodic, or a cropped 2^k grid of the "saupe" RMD family) or
``L / (N - 1)`` (a whole RMD grid of 2^k + 1 points whose corners both lie on the domain
boundary); measured maps (problems/io.py) may be rectangular with rectangular pixels.
``N`` and ``length`` are defined for square grids (square pixels) only and refuse a
rectangular one with a ``ProblemInputError``: code that reads them assumes a square.

RMD surface families (``RMD_FAMILIES``, recorded in ``Surface.meta["family"]`` and the
surface's name):

* ``"saupe"``    -- Saupe's non-periodic MidPointFM2D on the (2^k + 1)^2 grid (the paper's
  ref. PS88).  For N = 2^k points per side the last row and column are dropped (the paper
  speaks of 512 and 256 heights per side); every coarse stage (2^l + 1 points, last row and
  column dropped) is then still exactly the fine grid sub-sampled, z[::s, ::s] with
  s = 2^(k-l).  N = 2^k + 1 keeps the whole grid.
* ``"periodic"`` -- the wrap-around diamond-square on a 2^k grid (N = 2^k only).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .errors import ProblemInputError, check_hurst, check_positive, check_whole, is_whole
from .kernels import square_spacing
from .preprocessing import MapPreprocessing


def read_only(a: np.ndarray, dtype: object | None = np.float64) -> np.ndarray:
    """``a`` as a C-contiguous array of ``dtype`` (None: its own) no one writes through: its
    data an immutable ``bytes`` copy, so ``flags.writeable = True`` fails on it and on every
    view of it (``a`` itself when it is one already).  A solver handed a surface or a trial
    set (``QP.geometry``) cannot change the steps built from them after."""
    a = np.asarray(a)
    dt = a.dtype if dtype is None else np.dtype(dtype)
    if isinstance(a.base, bytes) and a.dtype == dt and a.flags.c_contiguous:
        return a
    a = np.ascontiguousarray(a, dtype=dt)
    return np.ndarray(a.shape, dt, buffer=a.tobytes())


@dataclass(frozen=True)
class Surface:
    """A rigid rough surface sampled on a rectangular grid (module doc).

    heights : N0 x N1 array of elevations xi_ij (the paper's average heights), read-only
              (``read_only``: a copy of the array given).
    delta   : grid spacing along axis 0 (rows).
    unit    : length unit of heights and delta ("m" by default).
    levels  : coarser representations of the same surface (coarsest first), when the
              generator provides them (RMD) -- the cascade multi-resolution method uses
              them.  The last entry is *not* the surface itself.
    periodic: whether the heights are periodic (wrap-around) -- a hint for kernels.

    Its nominal area ``area`` = L0 L1 must be a float64 of at least the smallest normal
    one and finite (loads are P / (E* A)): lengths whose product under- or overflows are a
    one-line ``ProblemInputError``.
    """

    heights: np.ndarray
    delta: float
    unit: str = "m"
    name: str = "surface"
    levels: tuple[Surface, ...] = ()
    periodic: bool = False
    meta: dict[str, Any] = field(default_factory=dict, compare=False)
    #: Grid spacing along axis 1 (columns); None: square pixels (``delta``), which a spacing
    #: equal to ``delta`` to round-off (``kernels.square_spacing``) is made.
    delta1: float | None = None
    #: What was done to a measured map between its file and these heights (``problems.io``);
    #: None for a generated surface.
    preprocessing: MapPreprocessing | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        h = np.asarray(self.heights)
        if h.ndim != 2:
            raise ProblemInputError(f"surface heights must be a 2-D array, got {h.ndim}-D")
        if min(h.shape) < 2:
            raise ProblemInputError(f"surface grid must be at least 2 x 2, got {h.shape[0]} x {h.shape[1]}")
        if not np.issubdtype(h.dtype, np.number) or np.iscomplexobj(h):
            raise ProblemInputError(f"surface heights must be real numbers, got dtype {h.dtype}")
        h = h.astype(np.float64, copy=False)
        bad = ~np.isfinite(h)
        if bad.any():
            raise ProblemInputError(
                f"surface heights contain {int(bad.sum())} NaN/inf values "
                f"(first at index {tuple(int(v) for v in np.argwhere(bad)[0])})"
            )
        check_positive("grid spacing delta", self.delta)
        if self.delta1 is not None:
            check_positive("grid spacing delta1 (axis 1)", self.delta1)
            if square_spacing((self.delta, self.delta1)) is not None:  # equal to round-off: square pixels
                object.__setattr__(self, "delta1", None)
        object.__setattr__(self, "heights", read_only(h))
        L0, L1 = self.lengths
        if not np.finfo(np.float64).tiny <= self.area < np.inf:
            raise ProblemInputError(f"a surface of lengths L0 x L1 = {L0:g} x {L1:g} has a nominal area A of "
                                    f"{self.area:g} in float64, which must be finite and at least "
                                    f"{np.finfo(np.float64).tiny:g} (loads are P/(E* A)); give the lengths in metres")

    @property
    def spacing(self) -> tuple[float, float]:
        """(dx0, dx1): the grid spacings along axis 0 and axis 1."""
        return (float(self.delta), float(self.delta if self.delta1 is None else self.delta1))

    @property
    def square_pixels(self) -> bool:
        d0, d1 = self.spacing
        return d0 == d1

    @property
    def is_square(self) -> bool:
        """N0 == N1 with square pixels: the grids ``N`` and ``length`` describe."""
        return self.heights.shape[0] == self.heights.shape[1] and self.square_pixels

    @property
    def N(self) -> int:
        """Points per side of a square grid; a rectangular grid (or pixels) is a
        ``ProblemInputError`` (read ``shape``)."""
        self._require_square("N (points per side)")
        return int(self.heights.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape  # type: ignore[return-value]

    @property
    def lengths(self) -> tuple[float, float]:
        """(L0, L1) = (N0 dx0, N1 dx1): the physical sizes along axis 0 and axis 1."""
        d0, d1 = self.spacing
        return (self.heights.shape[0] * d0, self.heights.shape[1] * d1)

    @property
    def length(self) -> float:
        """Lateral side length L = N * delta of a square grid (``lengths`` otherwise)."""
        self._require_square("the side length L")
        return self.N * self.delta

    @property
    def area(self) -> float:
        """L0 * L1, the area covered by the elements."""
        L0, L1 = self.lengths
        return L0 * L1

    def _require_square(self, what: str) -> None:
        if not self.is_square:
            n0, n1 = self.shape
            d0, d1 = self.spacing
            raise ProblemInputError(f"{what} is defined for a square grid; the surface {self.name!r} is {n0} x {n1} "
                                    f"with spacings {d0:g} x {d1:g} (this code path assumes a square grid)")

    @property
    def z_max(self) -> float:
        return float(self.heights.max())

    @property
    def z_mean(self) -> float:
        return float(self.heights.mean())

    @property
    def rms_height(self) -> float:
        return float(np.std(self.heights))

    @property
    def is_flat(self) -> bool:
        """Every height equal: no roughness."""
        return float(self.heights.max()) == float(self.heights.min())

    def rms_slope(self) -> float:
        """sqrt(<|grad h|^2>) by forward differences (periodic wrap when periodic): inf
        where the slopes' squares overflow, 0 where they underflow (no warning: the callers
        judge the figure)."""
        h = self.heights
        d0, d1 = self.spacing
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            if self.periodic:
                gx = (np.roll(h, -1, 0) - h) / d0
                gy = (np.roll(h, -1, 1) - h) / d1
            else:
                gx = np.diff(h, axis=0)[:, :-1] / d0
                gy = np.diff(h, axis=1)[:-1, :] / d1
            return float(np.sqrt(np.mean(gx**2 + gy**2)))

    def scaled(self, length_factor: float) -> Surface:
        """The same surface with every length multiplied by ``length_factor``."""
        return replace(
            self,
            heights=self.heights * length_factor,
            delta=self.delta * length_factor,
            delta1=None if self.delta1 is None else self.delta1 * length_factor,
            levels=tuple(s.scaled(length_factor) for s in self.levels),
        )


def check_not_flat(surface: Surface) -> Surface:
    """The surface, or a one-line ``ProblemInputError`` when all its heights are equal: a
    flat surface has no roughness, so no displacement scale (xi_max - xi_mean = 0) and
    no PSD to build a rough-contact load sequence or a cascade check from."""
    if surface.is_flat:
        raise ProblemInputError(
            f"the surface {surface.name!r} is flat (all heights equal {float(surface.heights.flat[0]):g} "
            f"{surface.unit}): it has no roughness, so no load ramp (xi_max - xi_mean = 0) or PSD can be "
            "derived from it; give a rough surface")
    return surface


def check_grid_size(N: object, what: str = "surface") -> int:
    """N as an int when it is an integer >= 2 (points per side), else a one-line
    ``ProblemInputError``."""
    if not is_whole(N, 2):
        raise ProblemInputError(f"a {what} needs an integer N >= 2 points per side, got N = {N!r}")
    return int(N)  # type: ignore[arg-type]


def check_seed(seed: object) -> int:
    """``seed`` as an int when it is an integer >= 0 (not a bool, not None: a surface's name
    records its seed, so the same name is the same surface), else a one-line
    ``ProblemInputError``."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ProblemInputError(f"seed must be an integer >= 0, got {seed!r}")
    return int(seed)


#: RMD levels k allowed: 2^1 .. 2^16 (65536) points per side.  The generator itself has no
#: limit of its own: past 8192^2 what decides is the grid's memory (8 B a point) and the time
#: to build it (about a minute at 8193^2 on 2 cores).
RMD_MAX_LEVEL = 16


#: RMD surface families: Saupe's non-periodic MidPointFM2D, and the wrap-around diamond-square.
RMD_FAMILIES: tuple[str, ...] = ("saupe", "periodic")


def check_rmd_family(family: object) -> str:
    """``family`` when it is one of ``RMD_FAMILIES``, else a one-line ``ProblemInputError``."""
    if family not in RMD_FAMILIES:
        raise ProblemInputError(f"unknown RMD surface family {family!r}: choose one of "
                                f"{', '.join(repr(f) for f in RMD_FAMILIES)} ('saupe' = non-periodic MidPointFM2D, "
                                "the paper's generator; 'periodic' = wrap-around diamond-square)")
    return str(family)


def rmd_grid_of(N: object, family: str | None = None) -> tuple[int, bool, bool]:
    """(k, periodic, crop) of an RMD surface of N points per side in ``family``:
    "periodic" needs N = 2^k; "saupe" takes N = 2^k (the 2^k + 1 grid, last row and column
    dropped: crop) or 2^k + 1 (whole); None picks by N (2^k periodic, 2^k + 1 saupe).
    Anything else is a one-line ``ProblemInputError``; cheap, for planning."""
    k, periodic = check_rmd_size(N)
    if family is None:
        return k, periodic, False
    fam = check_rmd_family(family)
    if fam == "periodic":
        if not periodic:
            raise ProblemInputError(f"the 'periodic' RMD family needs N = 2^k points per side (e.g. 512), got "
                                    f"N = {N!r} (2^k + 1 grids are the non-periodic 'saupe' family)")
        return k, True, False
    return k, False, periodic


def check_rmd_size(N: object) -> tuple[int, bool]:
    """(k, periodic) of an RMD grid of N points per side: N = 2^k (periodic) or 2^k + 1
    (non-periodic), k = 1..``RMD_MAX_LEVEL``.  Anything else -- not a power of two (plus one), below 2,
    not an integer -- is a one-line ``ProblemInputError``; cheap, for planning."""
    bad = ProblemInputError(f"an RMD surface needs N = 2^k (periodic) or 2^k + 1 (non-periodic) points per "
                            f"side with k = 1..{RMD_MAX_LEVEL} (e.g. 512 or 513), got N = {N!r}")
    try:
        n = check_grid_size(N, "RMD surface")
    except ProblemInputError:
        raise bad from None
    for m, periodic in ((n, True), (n - 1, False)):
        if m >= 2 and (m & (m - 1)) == 0 and m.bit_length() - 1 <= RMD_MAX_LEVEL:
            return m.bit_length() - 1, periodic
    raise bad


# ---------------------------------------------------------------------------
# Random midpoint displacement (diamond-square), Peitgen & Saupe 1988
# ---------------------------------------------------------------------------


def _rmd_grid(
    k: int, hurst: float, rng: np.random.Generator, periodic: bool, additions: bool = False
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Diamond-square on a 2^k (periodic) or 2^k + 1 grid.

    Each level halves the step in two half-steps (diamond: cell centres; square: edge
    midpoints); each half-step scales the displacement deviation by 2^(-H/2), so a
    level scales it by 2^-H (Peitgen & Saupe 1988, "The Science of Fractal Images",
    sec. 2.3.3, MidPointFM2D).  With ``additions`` (Voss's successive random
    additions) every point already defined also receives a displacement of the same
    deviation at each half-step, not only the new midpoints.

    Returns the heights and the construction's states: the grid of every completed
    level (step 2^(k-1), ..., 2), coarsest first.  Without additions these are exact
    sub-samples of the final heights; with additions later stages move them.
    """
    m = 2**k
    size = m if periodic else m + 1
    z = np.zeros((size, size))
    sigma = 1.0
    if not periodic:
        z[::m, ::m] = rng.normal(0.0, sigma, (2, 2))
    step = m
    states: list[np.ndarray] = []
    while step > 1:
        half = step // 2
        sigma *= 0.5 ** (0.5 * hurst)
        c = z[::step, ::step]
        if periodic:
            avg = (c + np.roll(c, -1, 0) + np.roll(c, -1, 1) + np.roll(np.roll(c, -1, 0), -1, 1)) / 4.0
        else:
            avg = (c[:-1, :-1] + c[1:, :-1] + c[:-1, 1:] + c[1:, 1:]) / 4.0
        z[half::step, half::step] = avg + rng.normal(0.0, sigma, avg.shape)
        if additions:
            _add_noise(z[::step, ::step], sigma, rng)
        sigma *= 0.5 ** (0.5 * hurst)
        c = z[::step, ::step]
        d = z[half::step, half::step]
        if periodic:
            a = (c + np.roll(c, -1, 0) + np.roll(d, 1, 1) + d) / 4.0  # at (i*step+half, j*step)
            b = (c + np.roll(c, -1, 1) + np.roll(d, 1, 0) + d) / 4.0  # at (i*step, j*step+half)
        else:
            a = _edge_average(c, d, axis=0)
            b = _edge_average(c, d, axis=1)
        z[half::step, ::step] = a + rng.normal(0.0, sigma, a.shape)
        z[::step, half::step] = b + rng.normal(0.0, sigma, b.shape)
        if additions:
            _add_noise(z[::step, ::step], sigma, rng)
            _add_noise(z[half::step, half::step], sigma, rng)
        step = half
        if step > 1:
            states.append(z[::step, ::step].copy())
    return z, states


def _add_noise(view: np.ndarray, sigma: float, rng: np.random.Generator) -> None:
    """Add N(0, sigma^2) displacements in place to every point of a strided view."""
    view += rng.normal(0.0, sigma, view.shape)


def _edge_average(c: np.ndarray, d: np.ndarray, axis: int) -> np.ndarray:
    """Mean of the 2 corner and up to 2 centre neighbours of the non-periodic edge
    midpoints (3 neighbours on the boundary)."""
    if axis == 1:
        return _edge_average(c.T, d.T, axis=0).T
    # points at (i*step+half, j*step): i in 0..M-1, j in 0..M
    corners = c[:-1, :] + c[1:, :]
    M = d.shape[0]
    total = corners.copy()
    count = np.full(total.shape, 2.0)
    total[:, :-1] += d  # centre to the right (j*step+half)
    count[:, :-1] += 1
    total[:, 1:] += d  # centre to the left
    count[:, 1:] += 1
    assert total.shape == (M, M + 1)
    return total / count


def rmd_surface(
    k: int,
    hurst: float,
    length: float = 100e-6,
    rms_height: float = 1e-6,
    seed: int = 0,
    periodic: bool = True,
    min_level: int = 2,
    additions: bool = False,
    crop: bool = False,
) -> Surface:
    """Random midpoint displacement fractal surface with Hurst exponent ``hurst``
    (diamond-square, Peitgen & Saupe 1988; the paper's section 5 generator).

    Grid: 2^k points per side when ``periodic`` (wrap-around diamond-square), or
    2^k + 1 otherwise.  Heights are scaled so the fine surface has the given rms.
    Every coarse level of the construction with at least 2^min_level points per side is
    kept in ``levels`` (coarsest first), shifted and scaled like the fine surface.

    ``additions=False`` (default, the paper's construction): coarse heights are never
    moved again, so every level is an exact sub-sample of the fine surface -- the
    property the cascade multi-resolution method relies on.  ``additions=True`` (Voss's
    successive random additions) also displaces the existing points at every stage;
    the levels are then the construction's states, not sub-samples.  Both bias a PSD
    fit of H low (see docs/problems.md for the measured bias); additions by ~0.01 less.

    ``crop`` (non-periodic only): drop the last row and column of the 2^k + 1 grid and of
    every level, so the surface has 2^k points per side (spacing L / 2^k) and each level is
    still the fine grid sub-sampled; the rms and mean are those of the cropped grid.
    Family (``meta["family"]``, the name's prefix): "periodic" or "saupe".  ``k`` and
    ``min_level`` are whole numbers, ``seed`` an integer >= 0 (``check_seed``).
    """
    hurst = check_hurst(hurst)
    k, min_level, seed = check_whole("RMD level k", k, 1), check_whole("min_level", min_level, 0), check_seed(seed)
    if k > RMD_MAX_LEVEL:
        raise ProblemInputError(f"RMD level k must be an integer in 1..{RMD_MAX_LEVEL}, got {k!r}")
    check_positive("length L", length)
    check_positive("rms height", rms_height)
    if crop and periodic:
        raise ProblemInputError("crop applies to the non-periodic (2^k + 1) RMD grid only; a periodic RMD "
                                "grid already has 2^k points per side")
    rng = np.random.default_rng(seed)
    z, states = _rmd_grid(int(k), hurst, rng, periodic, additions=additions)
    if crop:
        z, states = z[:-1, :-1], [st[:-1, :-1] for st in states]
    shift = z.mean()
    factor = rms_height / (z - shift).std()
    z = (z - shift) * factor
    size = z.shape[0]
    delta = length / (size if periodic or crop else size - 1)
    family = "periodic" if periodic else "saupe"
    levels = []
    for lev in range(max(1, min_level), int(k)):
        stride = 2 ** (int(k) - lev)
        coarse = (states[lev - 1] - shift) * factor
        levels.append(Surface(coarse, delta * stride, name=f"{family}-level{lev}", periodic=periodic,
                              meta={"level": lev, "stride": stride, "family": family}))
    meta = {"generator": "rmd", "family": family, "hurst": hurst, "seed": seed, "k": k, "rms_height": rms_height,
            "additions": additions, "crop": crop}
    return Surface(z, delta, name=f"{family}-H{hurst:g}-N{size}-s{seed}", levels=tuple(levels), periodic=periodic,
                   meta=meta)


def rmd_surface_n(N: int, hurst: float, family: str | None = None, **kw: Any) -> Surface:
    """RMD surface with exactly N points per side in ``family`` (``rmd_grid_of``):
    "saupe" (non-periodic; N = 2^k cropped from the 2^k + 1 grid, or N = 2^k + 1) or
    "periodic" (N = 2^k).  Without a family the size picks: periodic when N = 2^k,
    saupe when N = 2^k + 1."""
    k, periodic, crop = rmd_grid_of(N, family)
    return rmd_surface(k, hurst, periodic=periodic, crop=crop, **kw)


# ---------------------------------------------------------------------------
# Spectral (FFT-filtered) surfaces
# ---------------------------------------------------------------------------


def wavevectors(N: int | tuple[int, int], delta: float | tuple[float, float]) -> np.ndarray:
    """|q| on the FFT grid (rad per length): N x N with spacing ``delta``, or the
    N0 x N1 grid of spacings (d0, d1) when ``N`` and ``delta`` are pairs."""
    n0, n1 = (N, N) if np.ndim(N) == 0 else N  # type: ignore[misc]
    d0, d1 = (delta, delta) if np.ndim(delta) == 0 else delta  # type: ignore[misc]
    q0 = 2.0 * np.pi * np.fft.fftfreq(int(n0), d=float(d0))
    q1 = 2.0 * np.pi * np.fft.fftfreq(int(n1), d=float(d1))
    return np.hypot(q0[:, None], q1[None, :])


def spectral_surface(
    N: int,
    hurst: float,
    length: float = 100e-6,
    rms_height: float = 1e-6,
    seed: int = 0,
    rolloff_wavelength: float | None = None,
    short_cutoff_wavelength: float | None = None,
) -> Surface:
    """Periodic self-affine surface by filtering white noise with sqrt(C(q)).

    C(q) ~ q^(-2(1+H)) between q_r = 2 pi / rolloff_wavelength (default: the system
    size, i.e. no plateau) and q_s = 2 pi / short_cutoff_wavelength (default: the grid
    Nyquist); C is constant (a roll-off plateau) below q_r and zero above q_s.  Given
    wavelengths are finite and > 0, and some wave number 0 < q <= q_s must remain (else a
    one-line ``ProblemInputError``).
    """
    hurst = check_hurst(hurst)
    N = check_grid_size(N, "spectral surface")
    check_positive("length L", length)
    check_positive("rms height", rms_height)
    seed = check_seed(seed)
    delta = length / N
    q = wavevectors(N, delta)
    roll = length if rolloff_wavelength is None else check_positive("rolloff wavelength", rolloff_wavelength)
    q_r = 2.0 * np.pi / roll
    q_s = np.inf if short_cutoff_wavelength is None else \
        2.0 * np.pi / check_positive("short cutoff wavelength", short_cutoff_wavelength)
    qq = np.maximum(q, q_r)
    amp = qq ** (-(1.0 + hurst))
    amp[q == 0] = 0.0
    amp[q > q_s] = 0.0
    if not np.any(amp > 0.0):
        raise ProblemInputError(f"no wave number is left between the cutoffs: short cutoff wavelength "
                                f"{short_cutoff_wavelength!r} removes every mode of an N = {N} grid of side {length!r}")
    rng = np.random.default_rng(seed)
    noise = np.fft.fft2(rng.normal(size=(N, N)))
    z = np.real(np.fft.ifft2(noise * amp))
    z -= z.mean()
    z *= rms_height / z.std()
    meta = {"generator": "spectral", "hurst": hurst, "seed": seed, "rolloff_wavelength": rolloff_wavelength,
            "short_cutoff_wavelength": short_cutoff_wavelength, "rms_height": rms_height}
    return Surface(z, delta, name=f"spectral-H{hurst:g}-N{N}-s{seed}", periodic=True, meta=meta)


#: Fourier synthesis defaults: the roll-off at a quarter of the system size, the short
#: cutoff at four grid spacings (so the smallest features span a few points).
ROLLOFF_FRACTION = 0.25
SHORT_CUTOFF_SPACINGS = 4.0


def fourier_synthesis(N: int, hurst: float, rms_slope: float, length: float = 100e-6, seed: int = 0,
                      rolloff_wavelength: float | None = None,
                      short_cutoff_wavelength: float | None = None) -> Surface:
    """Periodic self-affine surface by Fourier synthesis with a roll-off and a short cutoff
    (``spectral_surface``'s filter): C(q) flat below q_r = 2 pi / rolloff_wavelength
    (default ``ROLLOFF_FRACTION`` L), ~ q^(-2(1+H)) up to q_s = 2 pi / short_cutoff_wavelength
    (default ``SHORT_CUTOFF_SPACINGS`` grid spacings), zero above; heights scaled to the
    given rms slope (``with_rms_slope``); a wavelength given leaves the roll-off longer than
    the cutoff (else ``ProblemInputError``).  Name "fourier-H..-N..-s..", family "fourier"."""
    check_positive("rms slope", rms_slope)
    N = check_grid_size(N, "Fourier-synthesis surface")
    check_positive("length L", length)
    rolloff = ROLLOFF_FRACTION * length if rolloff_wavelength is None else rolloff_wavelength
    cutoff = SHORT_CUTOFF_SPACINGS * length / N if short_cutoff_wavelength is None else short_cutoff_wavelength
    if (rolloff_wavelength is not None or short_cutoff_wavelength is not None) \
            and not check_positive("rolloff wavelength", rolloff) > check_positive("short cutoff wavelength", cutoff):
        raise ProblemInputError(f"the roll-off wavelength {rolloff!r} is not longer than the short cutoff wavelength "
                                f"{cutoff!r}: no self-affine range is left for H = {hurst!r}")
    s = spectral_surface(N, hurst, length=length, seed=seed, rolloff_wavelength=rolloff,
                         short_cutoff_wavelength=cutoff)
    s = replace(s, name=f"fourier-H{hurst:g}-N{N}-s{seed}", meta={**s.meta, "family": "fourier"})
    return with_rms_slope(s, rms_slope)


def with_rms_slope(surface: Surface, rms_slope: float) -> Surface:
    """The same surface with its heights (and its levels') multiplied by one factor so that
    ``rms_slope()`` is ``rms_slope``; meta records "rms_slope" and the new "rms_height".
    A flat surface has no slope to scale: ``ProblemInputError``."""
    check_positive("rms slope", rms_slope)
    check_not_flat(surface)
    f = rms_slope / surface.rms_slope()
    levels = tuple(replace(lv, heights=lv.heights * f) for lv in surface.levels)
    meta = {**surface.meta, "rms_slope": rms_slope, "rms_height": surface.rms_height * f}
    return replace(surface, heights=surface.heights * f, levels=levels, meta=meta)


def measured_like_heights(surface: Surface, tilt: float, missing_fraction: float, seed: int = 0,
                          hole_radius: int = 3) -> np.ndarray:
    """The surface's heights as an instrument might deliver them: a mean plane of slope
    ``tilt`` (rise per length, along a random direction) left in, and NaN at about
    ``missing_fraction`` of the points, in discs of ``hole_radius`` points around random
    centres (dropouts).  The NaN are for a file reader's filling rule to fill
    (problems/io.py ``fill_missing``); nothing here fills them."""
    if not (np.isfinite(tilt) and tilt >= 0.0):
        raise ProblemInputError(f"tilt must be a finite slope >= 0, got {tilt!r}")
    if not (0.0 <= missing_fraction < 0.5):
        raise ProblemInputError(f"missing fraction must lie in [0, 0.5), got {missing_fraction!r}")
    if not is_whole(hole_radius, 0):
        raise ProblemInputError(f"hole radius must be an integer >= 0 points, got {hole_radius!r}")
    rng = np.random.default_rng(check_seed(seed))
    n0, n1 = surface.shape
    d0, d1 = surface.spacing
    angle = rng.uniform(0.0, 2.0 * np.pi)
    z = surface.heights + tilt * (np.cos(angle) * (np.arange(n0) * d0)[:, None]
                                  + np.sin(angle) * (np.arange(n1) * d1)[None, :])
    r = int(hole_radius)
    di, dj = np.mgrid[-r:r + 1, -r:r + 1]
    disc = di**2 + dj**2 <= r * r
    holes = round(missing_fraction * n0 * n1 / int(disc.sum()))
    ci, cj = rng.integers(0, n0, holes), rng.integers(0, n1, holes)
    mask = np.zeros((n0, n1), dtype=bool)
    for a, b in zip(di[disc], dj[disc]):
        ii, jj = ci + a, cj + b
        ok = (ii >= 0) & (ii < n0) & (jj >= 0) & (jj < n1)
        mask[ii[ok], jj[ok]] = True
    z[mask] = np.nan
    return z


# ---------------------------------------------------------------------------
# PSD and Hurst fit
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RadialPSD:
    q: np.ndarray  # bin centres (rad/length), geometric means
    C: np.ndarray  # isotropic PSD C(q), length^4
    counts: np.ndarray  # number of FFT modes in each bin


def periodogram(surface: Surface, window: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
    """|q| and the 2-D periodogram C(q) = (d0 d1 / (N0 N1)) |FFT(h)|^2 / (2 pi)^2 (length^4)
    of every FFT mode (N x N, square pixels: delta^2 / N^2).  A Hann window (normalised to unit mean square) is applied to
    non-periodic surfaces unless ``window`` says otherwise."""
    h = surface.heights - surface.heights.mean()
    n0, n1 = surface.shape
    use_window = (not surface.periodic) if window is None else window
    if use_window:
        w = np.outer(np.hanning(n0), np.hanning(n1))
        h = h * w / np.sqrt(np.mean(w**2))
    F = np.fft.fft2(h)
    d0, d1 = surface.spacing
    C2 = (d0 * d1 / (n0 * n1)) * np.abs(F) ** 2 / (2.0 * np.pi) ** 2
    return wavevectors(surface.shape, surface.spacing), C2


def radial_psd(surface: Surface, bins_per_decade: int = 10, window: bool | None = None) -> RadialPSD:
    """Radially averaged 2-D PSD (see ``periodogram``), binned logarithmically."""
    q, C2 = periodogram(surface, window)
    mask = q > 0
    qv, Cv = q[mask], C2[mask]
    lo, hi = np.log10(qv.min()), np.log10(qv.max())
    nb = max(2, int(np.ceil((hi - lo) * bins_per_decade)))
    edges = np.logspace(lo, hi + 1e-12, nb + 1)
    which = np.clip(np.digitize(qv, edges) - 1, 0, nb - 1)
    counts = np.bincount(which, minlength=nb)[:nb]
    sums = np.bincount(which, weights=Cv, minlength=nb)[:nb]
    logq = np.bincount(which, weights=np.log(qv), minlength=nb)[:nb]
    ok = counts > 0
    return RadialPSD(q=np.exp(logq[ok] / counts[ok]), C=sums[ok] / counts[ok], counts=counts[ok])


@dataclass(frozen=True)
class HurstFit:
    hurst: float
    slope: float  # of log C versus log q; H = -slope/2 - 1
    intercept: float  # log C at q = 1 (rad/length)
    q_range: tuple[float, float]
    r2: float  # of the fitted line against the radially averaged PSD bins in q_range
    method: str = "whittle"


#: Default fit window: from FIT_Q_MIN_CYCLES x the fundamental 2 pi/L up to the
#: Nyquist wave number pi/delta divided by FIT_Q_MAX_DIVISOR.
FIT_Q_MIN_CYCLES = 2.0
FIT_Q_MAX_DIVISOR = 3.0


def fit_hurst(
    surface: Surface,
    q_min: float | None = None,
    q_max: float | None = None,
    psd: RadialPSD | None = None,
    method: str = "whittle",
) -> HurstFit:
    """Fit the power law C(q) = c q^s over [q_min, q_max]; H = -s/2 - 1.

    ``method="whittle"`` (default): Whittle's maximum-likelihood fit on the individual
    FFT modes (each periodogram value is C(q) times a unit exponential variable), which
    weights every mode equally and has no log-of-noise bias.  ``method="binned"``:
    least squares of log C on log q over the radially averaged bins, weighted by the
    number of modes per bin (used when ``psd`` is given).

    Default window: 2 x the fundamental (2 pi/L, L the shorter side) to a third of the
    Nyquist wave number (pi / the coarser spacing).
    It leaves out the few, noisy lowest modes and the top of the spectrum, where RMD
    surfaces carry excess power (their interpolation is a poor low-pass) and where
    aliasing lives.  The measured bias per generator is in docs/problems.md.
    """
    check_not_flat(surface)
    q0 = 2.0 * np.pi / min(surface.lengths)
    q_nyq = np.pi / max(surface.spacing)
    lo = FIT_Q_MIN_CYCLES * q0 if q_min is None else float(q_min)
    hi = q_nyq / FIT_Q_MAX_DIVISOR if q_max is None else float(q_max)
    if method not in ("whittle", "binned"):
        raise ProblemInputError(f"unknown Hurst fit method {method!r}; choose 'whittle' or 'binned'")
    binned = radial_psd(surface) if psd is None else psd
    m = (binned.q >= lo) & (binned.q <= hi)
    if m.sum() < 3:
        raise ProblemInputError(f"too few PSD bins in [{lo:.3g}, {hi:.3g}] to fit a Hurst exponent")
    x, y = np.log(binned.q[m]), np.log(binned.C[m])
    if method == "binned" or psd is not None:
        s, a = np.polyfit(x, y, 1, w=np.sqrt(binned.counts[m]))
        method = "binned"
    else:
        s, a = _whittle_power_law(*periodogram(surface), lo, hi)
    resid = y - (a + s * x)
    r2 = 1.0 - float(np.sum(resid**2) / np.sum((y - y.mean()) ** 2))
    return HurstFit(hurst=-s / 2.0 - 1.0, slope=float(s), intercept=float(a), q_range=(lo, hi), r2=r2,
                    method=method)


def _whittle_power_law(q: np.ndarray, C: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """Maximum-likelihood (Whittle) slope s and log-amplitude a of C = e^a q^s over
    the modes with lo <= |q| <= hi.  With I_k ~ C(q_k) Exp(1) the negative
    log-likelihood, minimised over a in closed form, is
    log mean(I_k q_k^-s) + s mean(log q_k)."""
    from scipy.optimize import minimize_scalar

    m = (q >= lo) & (q <= hi)
    lq = np.log(q[m])
    I = C[m]
    lq_mean = float(lq.mean())
    dl = lq - lq_mean  # centred: keeps exp() in range for any slope

    def profile_nll(s: float) -> float:
        return float(np.log(np.mean(I * np.exp(-s * dl))))

    res = minimize_scalar(profile_nll, bounds=(-8.0, 0.0), method="bounded", options={"xatol": 1e-10})
    s = float(res.x)
    a = float(np.log(np.mean(I * np.exp(-s * dl)))) - s * lq_mean
    return s, a
