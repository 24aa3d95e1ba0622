"""``--allow-any-E`` and ``--allow-implausible`` lift plausibility, not float64: a value
whose kernel table, nominal area, E* A, hardness bound or load-step force a float64 cannot
hold is refused by
the plan in one line, exit 2, before the results folder is made
(``scenes.core.check_float_range``, ``Surface``'s area), for ``run`` as for ``export``."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.surfaces import Surface
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")

BASE = ["paper-sweep", "--size", "33", "--seeds", "0"]
CASES = {
    "E-1e308": (["--steps", "2", "--E", "1e308", "--allow-any-E"], "influence coefficients float64 cannot hold"),
    "loads-1e308": (["--control", "load", "--loads", "1e308", "--allow-implausible"], "a force float64 cannot hold"),
    "length-1e308": (["--steps", "2", "--length", "1e308", "--allow-implausible"], "nominal area"),
    "length-1e-300": (["--steps", "2", "--length", "1e-300", "--allow-implausible"], "nominal area"),
    "hardness-1e-316": (["--steps", "2", "--hardness", "1e-316", "--allow-implausible"],
                        "times the element area"),
    "E-A-underflow": (["--steps", "2", "--length", "1e-150", "--E", "1e-100", "--allow-any-E", "--allow-implausible"],
                      "E* A"),
    "E-A-overflow": (["--steps", "2", "--length", "1e150", "--allow-implausible"], "E* A"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_run_refuses_values_float64_cannot_hold_before_anything_is_made(
        case: str, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    extra, words = CASES[case]
    out = in_tmp / "s1"
    rc, _, err = run_cli(["run", *BASE, *extra, "--solvers", "pk", "--reference", "none", "--no-progress",
                          "--out", str(out)], capsys)
    assert rc == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and words in err, err
    assert not out.exists()


@pytest.mark.parametrize("case", ["length-1e-300", "loads-1e308"])
def test_export_refuses_them_too(case: str, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    extra, words = CASES[case]
    out = in_tmp / "x"
    rc, _, err = run_cli(["export", *BASE, *extra, "--format", "problem-dir", "--out", str(out)], capsys)
    assert rc == 2 and err.count("\n") == 1 and words in err, err
    assert not out.exists()


def test_a_surface_whose_area_float64_cannot_hold_is_refused() -> None:
    z = [[0.0, 1.0], [1.0, 0.0]]
    for delta in (1e-300, 1e200):
        with pytest.raises(ProblemInputError, match="nominal area"):
            Surface(z, delta)  # type: ignore[arg-type]
    assert Surface(z, 1e-150).area > 0  # (small, but a normal float64)


def test_a_plausible_recipe_builds_no_kernel_table_at_planning(monkeypatch: pytest.MonkeyPatch) -> None:
    """The check builds a kernel table (seconds and gigabytes at 4096^2): only a recipe with
    a value outside its plausible range, or a measured map, pays for it."""
    from contactbench.problems.scenes import SceneConfig, core, get_scene

    called: list[str] = []
    monkeypatch.setattr(core, "check_float_range", lambda params, surface, seen: called.append(surface.name))
    scene = get_scene("paper-sweep")
    scene.validate_sizes(scene.config(SceneConfig(size=33, steps=2, seeds=(0,))))
    assert called == []
    scene.validate_sizes(scene.config(SceneConfig(size=33, steps=2, seeds=(0,), E=1e14)))  # (above the plausible 1e13 Pa)
    assert len(called) == 1
