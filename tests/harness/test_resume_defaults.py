"""A scene option of ``SceneConfig.extra`` written out at the value in effect without it
(``--surface-family saupe`` on a non-periodic scene, ``--surface-family periodic`` with
``--periodic``) is the same configuration: it resumes the folder a run without it wrote,
and the other way round; another value is still another configuration
(harness/run/runner.py, ``given_apart``)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import pytest

from contactbench.harness import cli
from contactbench.harness.run.runner import given_apart
from contactbench.harness.table.store import load_table
from contactbench.problems.scenes import SceneConfig

COMMON = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "test-exact", "--reference", "none",
          "--no-progress"]


def cli_run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = cli.main([*COMMON, *args])
    return code, capsys.readouterr().err


@pytest.mark.parametrize("first, second", [((), ("--surface-family", "saupe")),
                                           (("--surface-family", "saupe"), ())],
                         ids=["spelled-out-second", "spelled-out-first"])
def test_the_family_in_effect_written_out_resumes(first: tuple[str, ...], second: tuple[str, ...], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "run")
    assert cli_run(capsys, *first, "--out", out)[0] == 0
    rows = len(load_table(out))
    code, err = cli_run(capsys, *second, "--out", out)
    assert code == 0, err
    assert len(load_table(out)) == rows  # nothing new was solved
    code, err = cli_run(capsys, "--surface-family", "periodic", "--out", out)
    assert code == 2 and err.count("\n") == 1 and "scene_config.extra.family" in err and "--append" in err


def test_the_family_in_effect_follows_the_other_options() -> None:
    def extra(**given: object) -> dict[str, object]:
        cfg = SceneConfig(size=8, steps=2, periodic=bool(given.pop("periodic", False)) or None, extra=dict(given))
        return dict(given_apart(asdict(cfg), ["paper-sweep"])["extra"])

    assert extra(family="saupe") == {}
    assert extra(family="periodic") == {"family": "periodic"}
    assert extra(family="periodic", periodic=True) == {}
    assert extra(family="saupe", periodic=True) == {"family": "saupe"}
    assert extra(family="saupe", allow_implausible=True) == {}  # a switch that changes no recipe
