"""Another load program is another problem, so another instance: a run at another number
of steps or with other ``--loads`` (e.g. appended into the same folder) never shares an
instance name with the scene's own program, whose name carries no suffix
(``scenes.core.program_suffix``, ``steps_suffix``, ``departure_suffix``)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from contactbench.problems.constraints import CONTROLS
from contactbench.problems.scenes import SceneConfig, get_scene
from tests.helpers import run_cli


def names(scene: str, **options: object) -> list[str]:
    sc = get_scene(scene)
    extra = options.pop("extra", {})
    return [s.instance for s in sc.instances(sc.config(SceneConfig(extra=extra, **options)))]  # type: ignore[arg-type]


@pytest.mark.parametrize("scene,size", [("paper-sweep", 17), ("plastic-sweep", 17), ("cmr", 17), ("hertz", 16),
                                        ("flat-punch", 16), ("population", 16), ("cmr-cutoff", 16)])
def test_each_step_count_is_its_own_instance_and_the_scene_s_own_has_no_suffix(scene: str, size: int) -> None:
    own = get_scene(scene).config(None).steps
    other, another = [k for k in (2, 3, 4) if k != own][:2]
    plain, fewer, more = (names(scene, size=size, seeds=(0,), steps=k) for k in (own, other, another))
    assert not set(plain) & set(fewer) and not set(fewer) & set(more) and not set(plain) & set(more)
    assert all("-K" not in n for n in plain) and all(n.endswith(f"-K{other}") for n in fewer)


def test_two_load_programs_of_one_count_are_two_instances() -> None:
    load = {"control": CONTROLS[1]}
    a = names("paper-sweep", size=17, extra={**load, "loads": (1e-3, 2e-3)})
    b = names("paper-sweep", size=17, extra={**load, "loads": (1e-3, 3e-3)})
    assert a != b and all("-load-K2-P" in n for n in a + b)


def test_the_load_sweep_s_own_loads_have_no_suffix_and_its_other_counts_have_one() -> None:
    (own,) = names("load-sweep", size=17)
    (fewer,) = names("load-sweep", size=17, steps=4)
    assert own.endswith("-load") and fewer.startswith(own + "-K4-P")


def test_a_population_on_another_kernel_or_size_is_another_instance() -> None:
    plain = names("population", size=16, seeds=(0,))
    assert plain == ["pop-H0.5-N16-s0", "pop-H0.7-N16-s0", "pop-H0.9-N16-s0"]
    for other in (names("population", size=16, seeds=(0,), kernel="love"),
                  names("population", size=16, seeds=(0,), periodic=False),
                  names("population", size=16, seeds=(0,), length=50e-6),
                  names("population", size=16, seeds=(0,), E=2e9)):
        assert not set(other) & set(plain)


def test_an_appended_run_at_another_step_count_keeps_each_cell_its_own(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    for steps in ("2", "3"):
        rc, _, err = run_cli(["run", "paper-sweep", "--size", "9", "--steps", steps, "--solvers", "pk",
                              "--out", str(out), "--append", "--no-warmup"], capsys)
        assert rc == 0, err
    table = pd.read_csv(out / "results.csv")
    assert len(table) == 5 and not table.duplicated(["instance", "step", "solver", "repeat"]).any()
    assert table.groupby(["instance", "step"])["delta"].nunique().max() == 1
