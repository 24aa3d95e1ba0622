"""The elastic layer on a rigid base (problems/layers.py): its compliance factor against the
published thin-layer limits and ContactMechanics' layer, the periodic and non-periodic
tables, and the loads of thick layers against the half-space."""

from __future__ import annotations

import numpy as np
import pytest
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.kernels import kernel_table
from contactbench.problems.layers import Layer, compliance_factor
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operators import FFTOperator, KernelTransform
from contactbench.problems.surfaces import Surface, rmd_surface_n, spectral_surface

E = 1.0e9


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45])
def test_bonded_thin_limit_is_the_confined_modulus(nu: float) -> None:
    """f(s) ~ s (1 - 2 nu) / (2 (1 - nu)^2) as s -> 0: u = p T / M, M = E (1 - nu) / ((1 + nu)(1 - 2 nu))."""
    s = np.array([1e-6, 1e-4])
    slope = (1 - 2 * nu) / (2 * (1 - nu) ** 2)
    np.testing.assert_allclose(compliance_factor(s, nu, "bonded") / s, slope, rtol=1e-3)
    E_young = E * (1 - nu**2)
    M = E_young * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    assert Layer(2e-6, nu).mean_compliance(E) == pytest.approx(2e-6 / M, rel=1e-12)


def test_incompressible_bonded_thin_limit_is_the_lubrication_limit() -> None:
    """nu = 1/2: f ~ 2 s^3 / 3, i.e. u = q^2 T^3 p / (3 G)."""
    s = np.array([1e-3, 1e-2])
    np.testing.assert_allclose(compliance_factor(s, 0.5, "bonded") / s**3, 2.0 / 3.0, rtol=1e-3)


def test_frictionless_base_thin_limit_and_nu_independence() -> None:
    s = np.array([1e-6, 1e-4, 0.5, 3.0])
    np.testing.assert_allclose(compliance_factor(s[:2], 0.3, "frictionless") / s[:2], 0.5, rtol=1e-3)
    np.testing.assert_array_equal(compliance_factor(s, 0.1, "frictionless"), compliance_factor(s, 0.45, "frictionless"))
    printed = (np.cosh(2 * s[2:]) - 1) / (np.sinh(2 * s[2:]) + 2 * s[2:])  # cancels for small s: compared where it does not
    np.testing.assert_allclose(compliance_factor(s[2:], 0.3, "frictionless"), printed, rtol=1e-12)


@pytest.mark.parametrize("interface", ["bonded", "frictionless"])
def test_factor_rises_from_0_to_1_without_overflow(interface: str) -> None:
    s = np.concatenate([[0.0], np.logspace(-8, 3.5, 400)])
    f = compliance_factor(s, 0.3, interface)
    assert np.all(np.isfinite(f)) and f[0] == 0.0
    assert np.all(np.diff(f) >= -1e-15) and abs(f[-1] - 1.0) < 1e-12
    assert 1.0 - compliance_factor(np.array([10.0]), 0.3, interface)[0] < 1e-6  # a layer 10 / q deep: the half-space


def test_bonded_factor_matches_contactmechanics_layer() -> None:
    """ContactMechanics' PeriodicFFTElasticHalfSpace(thickness=, poisson=) (Carbone &
    Mangialardi 2008, eq. A.30) on a 16 x 12 grid of 1 x 1.5: its Green's function at
    q != 0 against ours, 2 f(qT) / (E* q) (young = E* (1 - nu^2))."""
    cm = pytest.importorskip("ContactMechanics")
    nu, T, shape, sizes = 0.3, 0.3, (16, 12), (1.0, 1.5)
    hs = cm.PeriodicFFTElasticHalfSpace(shape, E * (1 - nu**2), physical_sizes=sizes, thickness=T, poisson=nu)
    theirs = np.asarray(hs.greens_function)  # rfft layout along axis 0
    q0 = 2 * np.pi * np.fft.rfftfreq(shape[0], d=sizes[0] / shape[0])
    q1 = 2 * np.pi * np.fft.fftfreq(shape[1], d=sizes[1] / shape[1])
    q = np.hypot(q0[:, None], q1[None, :])
    ours = 2.0 * Layer(T, nu).factor(q * T) / (E * np.where(q > 0, q, 1.0))
    mask = q > 0
    np.testing.assert_allclose(ours[mask], theirs[mask], rtol=1e-10)
    assert theirs[0, 0] == pytest.approx(Layer(T, nu).mean_compliance(E), rel=1e-10)  # the q = 0 mode we leave out


def test_periodic_spectral_layer_table_applies_the_factor_to_a_cosine_mode() -> None:
    """A pressure cos(q x) on a rectangular periodic grid is displaced by 2 f(qT) / (E* q) cos(q x)."""
    shape, spacing, T = (24, 16), (1.0e-6, 2.0e-6), 3e-6
    layer = Layer(T, 0.35)
    op = FFTOperator(KernelTransform(kernel_table("spectral", shape, spacing, E, True, layer=layer), shape),
                     np.arange(shape[0] * shape[1]))
    i, j = np.mgrid[0:shape[0], 0:shape[1]]
    for k0, k1 in ((1, 0), (0, 1), (3, 2)):
        phase = 2 * np.pi * (k0 * i / shape[0] + k1 * j / shape[1])
        q = np.hypot(2 * np.pi * k0 / (shape[0] * spacing[0]), 2 * np.pi * k1 / (shape[1] * spacing[1]))
        pressure = np.cos(phase)
        u = op.matvec((pressure * spacing[0] * spacing[1]).ravel()).reshape(shape)
        np.testing.assert_allclose(u, 2 * layer.factor(np.array(q * T)) / (E * q) * pressure, rtol=0, atol=1e-12 * T / E)


def test_non_periodic_bonded_layer_under_a_wide_uniform_pressure_is_confined() -> None:
    """Uniform pressure on a 64 x 64 patch, 16 thicknesses wide: the centre of a bonded layer
    sinks p T / M (uniaxial strain; Johnson, Contact Mechanics, sec. 5.9 thin layers), to 1e-3."""
    N, L = 64, 1e-4
    layer = Layer(L / 16, 0.3)
    d = L / N
    op = FFTOperator(KernelTransform(kernel_table("love", (N, N), d, E, False, layer=layer), (N, N)),
                     np.arange(N * N))
    u = op.matvec(np.full(N * N, d * d)).reshape(N, N)  # unit pressure
    assert u[N // 2, N // 2] == pytest.approx(layer.mean_compliance(E), rel=1e-3)
    half = FFTOperator(KernelTransform(kernel_table("love", (N, N), d, E, False), (N, N)), np.arange(N * N))
    assert half.matvec(np.full(N * N, d * d))[N * N // 2 + N // 2] > 5 * u[N // 2, N // 2]  # the half-space sinks far more


def test_periodic_real_space_layer_agrees_with_the_spectral_layer_away_from_the_element() -> None:
    shape, d, T = (32, 24), 1e-6, 3e-6
    love = kernel_table("love", shape, d, E, True, layer=Layer(T))
    spec = kernel_table("spectral", shape, d, E, True, layer=Layer(T))
    love0 = kernel_table("love", shape, d, E, True)
    spec0 = kernel_table("spectral", shape, d, E, True)
    assert np.abs((love - spec) - (love0 - spec0)).max() <= 2e-3 * love[0, 0]


def _loads(surface: Surface, kernel: str, periodic: bool, layer: Layer | None, fractions: tuple[float, ...]) -> np.ndarray:
    builder = InstanceBuilder(surface, E, kernel=kernel, periodic=periodic, layer=layer)
    out = []
    for frac in fractions:
        D = frac * paper_max_displacement(surface)
        inst = builder.build(D)
        qp = inst.qp.restrict(np.flatnonzero(inst.qp.ubar > -0.5 * D)) if periodic else inst.qp
        out.append(exact_solution(qp.H.to_dense(), qp.ubar).p.sum())
    return np.array(out)


def test_a_periodic_layer_ten_sizes_thick_carries_the_half_space_loads() -> None:
    s = spectral_surface(32, 0.7, length=1e-4, rms_height=1e-6, seed=3)
    fr = (0.2, 0.6, 1.0)
    half = _loads(s, "spectral", True, None, fr)
    np.testing.assert_allclose(_loads(s, "spectral", True, Layer(10 * s.length), fr), half, rtol=1e-6)
    thin = _loads(s, "spectral", True, Layer(0.1 * s.length), fr)
    assert np.all(thin > 1.1 * half)  # a thin layer is stiffer: more load at the same approach


def test_a_non_periodic_layer_tends_to_the_half_space_as_one_over_thickness() -> None:
    """Non-periodic: the layer's excess load at the same approach falls as 1/T; at T = 20 L it
    is within 1 % of the half-space, at T = 10 L within 2 % (32 x 32, bonded, nu = 0.3)."""
    s = rmd_surface_n(32, 0.7, "saupe", length=1e-4, rms_height=1e-6, seed=3)
    fr = (0.2, 1.0)
    half = _loads(s, "love", False, None, fr)
    e10 = _loads(s, "love", False, Layer(10 * s.length), fr) / half - 1
    e20 = _loads(s, "love", False, Layer(20 * s.length), fr) / half - 1
    assert np.all(e20 > 0) and np.all(e20 < 0.01) and np.all(e10 < 0.02)
    np.testing.assert_allclose(e10 / e20, 2.0, rtol=0.05)


@pytest.mark.parametrize("kw,match", [
    ({"thickness": 0.0}, "thickness"), ({"thickness": -1.0}, "thickness"), ({"thickness": float("nan")}, "thickness"),
    ({"thickness": float("inf")}, "thickness"), ({"thickness": 1.0, "nu": 0.6}, "nu"),
    ({"thickness": 1.0, "nu": -1.0}, "nu"), ({"thickness": 1.0, "nu": float("nan")}, "nu"),
    ({"thickness": 1.0, "interface": "glued"}, "interface")])
def test_bad_layers_are_refused(kw: dict, match: str) -> None:
    with pytest.raises(ProblemInputError, match=match):
        Layer(**kw)


def test_a_layer_thinner_than_an_element_needs_the_spectral_kernel() -> None:
    thin = Layer(0.5e-6)
    with pytest.raises(ProblemInputError, match="thinner than a grid element"):
        kernel_table("love", (8, 8), 1e-6, E, False, layer=thin)
    with pytest.raises(ProblemInputError, match="thinner than a grid element"):
        kernel_table("bcc", (8, 8), 1e-6, E, True, layer=thin)
    assert np.isfinite(kernel_table("spectral", (8, 8), 1e-6, E, True, layer=thin)).all()


def test_layer_sweep_scene_runs_the_half_space_and_each_thickness() -> None:
    from contactbench.problems.scenes import SceneConfig, get_scene
    from contactbench.problems.scenes.layers import LAYER_THICKNESSES

    scene = get_scene("layer-sweep")
    with pytest.raises(ProblemInputError, match="too stiff.*--kernel love"):
        scene.validate(scene.config(SceneConfig(size=32, steps=2)))  # bcc: 0.1 L is 3.2 spacings
    cfg = scene.config(SceneConfig(size=32, steps=2, kernel="love"))
    specs = scene.instances(cfg)
    assert len(specs) == 1 + len(LAYER_THICKNESSES) and specs[0].instance == "saupe-H0.7-N32-love-np-s5-K2"
    assert [s.params.get("thickness_over_L") for s in specs] == [None, *LAYER_THICKNESSES]
    scene.validate(cfg)
    half, thin = specs[0].build(), specs[1].build()
    assert half.deltas == thin.deltas  # one ramp per surface: loads compare at equal approach
    assert half.at(1).qp.geometry.layer is None
    layer = thin.at(1).qp.geometry.layer
    assert layer == Layer(0.1 * 1e-4, 0.3, "bonded")
    with pytest.raises(ProblemInputError, match="thinner than a grid element"):
        scene.validate(scene.config(SceneConfig(size=8, steps=2, kernel="love")))  # 0.1 L < L / 8
    with pytest.raises(ProblemInputError, match="thicknesses"):
        scene.instances(scene.config(SceneConfig(size=32, extra={"thicknesses": (0.5, -1.0)})))


def test_paper_sweep_takes_a_layer_from_the_config() -> None:
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("paper-sweep")
    cfg = scene.config(SceneConfig(size=32, steps=2, extra={"thickness": 4e-5, "nu": 0.45}))  # 12.8 spacings
    (spec,) = scene.instances(cfg)
    assert spec.instance.endswith("-T4e-05-nu0.45-K2")
    assert spec.build().at(0).qp.geometry.layer == Layer(4e-5, 0.45)
    with pytest.raises(ProblemInputError, match="nu"):
        scene.instances(scene.config(SceneConfig(size=32, steps=2, extra={"thickness": 2e-5, "nu": 0.7})))[0].build()
