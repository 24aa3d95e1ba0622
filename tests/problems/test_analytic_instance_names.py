"""An instance's name tells apart the problems a run can pose: hertz, flat-punch and
cmr-cutoff at another lateral size or modulus than the scene's own are other instances
("-L<metres>", "-E<Pa>"), so a run appended into a folder at another E is not folded into
the first run's cells as its repeats; at the scene's own values the names are as before."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from contactbench.problems.scenes import SceneConfig, get_scene
from tests.helpers import run_cli


@pytest.mark.parametrize("scene", ["hertz", "flat-punch", "cmr-cutoff"])
def test_another_size_or_modulus_is_another_instance(scene: str) -> None:
    s = get_scene(scene)
    own = [spec.instance for spec in s.instances(s.config(SceneConfig()))]
    stiffer = [spec.instance for spec in s.instances(s.config(SceneConfig(E=2 * float(s.defaults.E))))]
    wider = [spec.instance for spec in s.instances(s.config(SceneConfig(length=3 * float(s.defaults.length))))]
    assert not set(own) & set(stiffer) and not set(own) & set(wider) and not set(stiffer) & set(wider)
    assert all("-E" not in name and "-L" not in name for name in own)


def test_an_appended_run_at_another_modulus_keeps_its_own_cells(in_tmp: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["run", "hertz", "--size", "16", "--solvers", "pk", "--reference", "none", "--no-progress", "--out", "o"]
    assert run_cli(argv, capsys)[0] == 0
    assert run_cli([*argv, "--E", "2e9", "--append"], capsys)[0] == 0
    rows = pd.read_csv(in_tmp / "o" / "results.csv")
    assert rows.groupby("instance")["E"].nunique().max() == 1 and rows["instance"].nunique() == 2
