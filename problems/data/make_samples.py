"""Regenerate the sample height maps of problems/data (see PROVENANCE.md).

Run:  python problems/data/make_samples.py   (deterministic: fixed seeds)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactbench.problems.io import write_text, write_x3p
from contactbench.problems.surfaces import spectral_surface

HERE = Path(__file__).resolve().parent


def measured_like(n: int, hurst: float, length: float, rms: float, seed: int, rolloff: float | None,
                  tilt: float, noise: float, dropout: float, ny: int | None = None) -> np.ndarray:
    """A spectral self-affine map with an optional roll-off plateau, plus what an
    instrument adds: a tilt (slope ``tilt``), white noise (rms ``noise``) and missing
    points (a fraction ``dropout``, in small clusters, as NaN).  ``ny`` < n crops rows."""
    s = spectral_surface(n, hurst, length=length, rms_height=rms, seed=seed,
                         rolloff_wavelength=None if rolloff is None else rolloff * length)
    rng = np.random.default_rng(seed + 1000)
    z = s.heights.copy()
    x = np.arange(n) * s.delta
    z += tilt * (x[None, :] + 0.5 * x[:, None])
    z += rng.normal(0.0, noise, z.shape)
    centres = rng.integers(0, n - 1, size=(int(dropout * n * n / 2), 2))
    for i, j in centres:
        z[i:i + 2, j:j + 1] = np.nan
    return z[: (ny or n), :]


def main() -> None:
    # 10x-like: roll-off plateau below q = 2 pi / (L/8); float32 x3p with NaN dropouts.
    z10 = measured_like(128, 0.6, 1.0e-3, 2.0e-6, seed=10, rolloff=1 / 8, tilt=2e-4, noise=2e-8, dropout=0.01)
    # synthetic, measured-like: spectral H=0.6 with roll-off at L/8, tilt, noise, dropouts
    write_x3p(HERE / "solar-10x-like.x3p", z10, 1.0e-3 / 128, data_type="F")
    # 100x-like: pure power law, non-square 96 x 128 (rows x columns), float64 .npy.
    z100 = measured_like(128, 0.6, 1.3e-4, 0.5e-6, seed=100, rolloff=None, tilt=5e-4, noise=5e-9,
                         dropout=0.005, ny=96)
    np.save(HERE / "solar-100x-like.npy", z100, allow_pickle=False)
    # ground-like: 64 x 64 text matrix in micrometres with a roll-off at L/4.
    zg = measured_like(64, 0.8, 5.0e-4, 0.8e-6, seed=7, rolloff=1 / 4, tilt=0.0, noise=1e-8, dropout=0.0)
    write_text(HERE / "ground-like-um.csv", zg * 1e6, delimiter=",")


if __name__ == "__main__":
    main()
