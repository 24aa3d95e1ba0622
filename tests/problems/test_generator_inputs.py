"""The generators' inputs: a Hurst exponent is a number in (0, 1) (``surfaces.check_hurst``,
text and bools refused in one line, not a raw TypeError); a roll-off wavelength not longer
than the short cutoff leaves no self-affine range and is refused (the surface would be white
noise named "H0.7"); a refusal prints Delta as a number, not a NumPy repr."""

from __future__ import annotations

import numpy as np
import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.surfaces import fourier_synthesis, rmd_surface_n, spectral_surface


@pytest.mark.parametrize("hurst", ["0.7", True, None, 1.0, 0.0, float("nan"), np.bool_(True)])
def test_a_hurst_exponent_that_is_no_number_in_the_open_interval_is_refused(hurst: object) -> None:
    for make in (lambda: rmd_surface_n(16, hurst), lambda: spectral_surface(16, hurst)):  # type: ignore[arg-type]
        with pytest.raises(ProblemInputError, match=r"Hurst exponent must lie in \(0, 1\)"):
            make()
    with pytest.raises(ProblemInputError, match=r"Hurst exponent must lie in \(0, 1\)"):
        get_scene("population").instances(SceneConfig(size=16, extra={"hursts": (hurst,)}))


@pytest.mark.parametrize("hurst", [np.float32(0.7), 0.3, np.float64(0.9)])
def test_a_hurst_exponent_in_the_open_interval_is_taken(hurst: float) -> None:
    assert rmd_surface_n(16, hurst).meta["hurst"] == pytest.approx(float(hurst))


def test_a_rolloff_shorter_than_the_cutoff_is_refused() -> None:
    with pytest.raises(ProblemInputError, match="no self-affine range"):
        fourier_synthesis(64, 0.7, 0.1, rolloff_wavelength=1e-6, short_cutoff_wavelength=50e-6)
    fourier_synthesis(64, 0.7, 0.1, rolloff_wavelength=50e-6, short_cutoff_wavelength=1e-5)  # the right way round


def test_a_refusal_prints_delta_as_a_number() -> None:
    s = rmd_surface_n(16, 0.7, length=1e-4, seed=0, family="periodic")
    b = InstanceBuilder(s, 1e9, "spectral", periodic=True, operator="fft")
    with pytest.raises(ProblemInputError) as caught:
        b.build(np.float64(2.0) * float(np.ptp(s.heights)))
    assert "np.float64" not in str(caught.value) and "Delta = " in str(caught.value)
