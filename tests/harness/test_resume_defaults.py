"""A scene option of ``SceneConfig.extra`` written out at the value in effect without it
(``--surface-family saupe`` on a non-periodic scene, ``--surface-family periodic`` with
``--periodic``) is the same configuration: it resumes the folder a run without it wrote,
and the other way round; another value is still another configuration
(harness/run/spelled_out.py, ``given_apart``)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli
from contactbench.harness.run.runner import given_apart
from contactbench.harness.run.spelled_out import left_out
from contactbench.harness.table.store import load_table
from contactbench.problems.scenes import SceneConfig

COMMON = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "test-exact", "--reference", "none",
          "--no-progress"]


def cli_run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """``run`` with ``COMMON`` and ``args``; ``args`` giving ``--reference`` replaces COMMON's
    (an option is given once)."""
    common = COMMON
    if "--reference" in args:
        k = COMMON.index("--reference")
        common = COMMON[:k] + COMMON[k + 2:]
    code = cli.main([*common, *args])
    return code, capsys.readouterr().err


def assert_resumes(capsys: pytest.CaptureFixture[str], first: tuple[str, ...], second: tuple[str, ...],
                   out: str) -> None:
    """A run with the options ``first`` into ``out``, then one with ``second``: the second
    resumes the folder and solves nothing new."""
    assert cli_run(capsys, *first, "--out", out)[0] == 0
    rows = len(load_table(out))
    code, err = cli_run(capsys, *second, "--out", out)
    assert code == 0, err
    assert len(load_table(out)) == rows  # nothing new was solved


@pytest.mark.parametrize("first, second", [((), ("--surface-family", "saupe")),
                                           (("--surface-family", "saupe"), ())],
                         ids=["spelled-out-second", "spelled-out-first"])
def test_the_family_in_effect_written_out_resumes(first: tuple[str, ...], second: tuple[str, ...], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = str(tmp_path / "run")
    assert_resumes(capsys, first, second, out)
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


SPELLED_OUT = {
    "control": (("--control", "displacement"), ()),
    "layer": (("--thickness", "2e-4", "--nu", "0.3", "--interface", "bonded"), ("--thickness", "2e-4")),
    "map": (("--detrend", "plane", "--nan", "fill-mean", "--crop", "none"), ()),
}


@pytest.mark.parametrize("which", sorted(SPELLED_OUT))
@pytest.mark.parametrize("first_spelled", [True, False], ids=["spelled-out-first", "spelled-out-second"])
def test_an_option_at_the_value_its_recipe_reads_without_it_resumes(which: str, first_spelled: bool, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """``--control displacement``, a layer's ``--nu 0.3 --interface bonded``, a map's
    ``--detrend plane --nan fill-mean --crop none``: the same cells as the run without
    them, so either resumes the folder the other wrote and solves nothing new; the
    options are checked as given, and another value is another configuration."""
    spelled, plain = SPELLED_OUT[which]
    base = COMMON
    if which == "map":
        np.save(tmp_path / "map.npy", np.random.default_rng(0).normal(size=(8, 8)) * 1e-7)
        base = [a for a in COMMON if a not in ("--size", "8")] + ["--surface", str(tmp_path / "map.npy"),
                                                                  "--length", "1e-4"]
    out = str(tmp_path / "run")
    first, second = (spelled, plain) if first_spelled else (plain, spelled)
    assert cli.main([*base, *first, "--out", out]) == 0, capsys.readouterr().err
    ids = sorted(load_table(out)["cell_id"])
    assert cli.main([*base, *second, "--out", out]) == 0, capsys.readouterr().err
    assert sorted(load_table(out)["cell_id"]) == ids  # the same cells: nothing new was solved
    if which == "layer":  # checked as given (no layer: refused), and another value is another configuration
        assert cli.main([*base, "--nu", "0.3", "--out", out]) == 2
        assert "--nu describes an elastic layer" in capsys.readouterr().err
        assert cli.main([*base, "--thickness", "2e-4", "--nu", "0.4", "--out", out]) == 2
        assert "scene_config.extra.nu" in capsys.readouterr().err


def test_an_option_overriding_its_scene_s_own_default_is_kept(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """``--control displacement`` is the reader's default but not the load sweep's: there
    it is the user's choice, and the run is under displacement control."""
    def extra(scene: str) -> dict[str, object]:
        return dict(given_apart(asdict(SceneConfig(extra={"control": "displacement"})), [scene])["extra"])

    assert extra("paper-sweep") == {}
    assert extra("load-sweep") == {"control": "displacement"}
    out = str(tmp_path / "run")
    args = ["run", "load-sweep", "--size", "8", "--steps", "2", "--solvers", "test-exact", "--reference", "none",
            "--no-progress", "--control", "displacement", "--out", out]
    assert cli.main(args) == 0, capsys.readouterr().err
    assert not any(str(name).endswith("-load") for name in load_table(out)["instance"])


def xyz_map(path: Path) -> Path:
    """An 8 x 8 map as x,y,z columns of a regular 3 um grid written to 6 digits, so the
    lateral size the file states (24 um) is 8 times the coordinates' step only within the
    reader's tolerance; heights of about 0.3 um, in no unit of its own."""
    n, step = 8, 3e-6
    z = np.random.default_rng(0).normal(size=(n, n)) * 3e-7
    y, x = np.meshgrid(np.arange(n) * step, np.arange(n) * step, indexing="ij")
    np.savetxt(path, np.c_[x.ravel(), y.ravel(), z.ravel()], fmt="%.6g")
    return path


STATED_BY_THE_FILE = {
    "length": ("--length", "2.4e-5"),
    "length-per-axis": ("--length", "2.4e-5,2.4e-5"),
    "height-unit": ("--height-unit", "m"),
    "both": ("--length", "2.4e-5", "--height-unit", "m"),
}


@pytest.mark.parametrize("which", sorted(STATED_BY_THE_FILE))
@pytest.mark.parametrize("first_spelled", [True, False], ids=["spelled-out-first", "spelled-out-second"])
def test_a_file_option_at_what_the_file_states_resumes(which: str, first_spelled: bool, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """``--length`` at the lateral size an x,y,z map states (within the reader's
    tolerance) and ``--height-unit m`` on a map that states no unit are what the reader
    takes without them: the same cells, so either resumes the folder the other wrote and
    solves nothing new; another unit is another configuration."""
    base = [a for a in COMMON if a not in ("--size", "8")] + ["--surface", str(xyz_map(tmp_path / "map.txt"))]
    spelled = STATED_BY_THE_FILE[which]
    first, second = (spelled, ()) if first_spelled else ((), spelled)
    out = str(tmp_path / "run")
    assert cli.main([*base, *first, "--out", out]) == 0, capsys.readouterr().err
    ids = sorted(load_table(out)["cell_id"])
    assert cli.main([*base, *second, "--out", out]) == 0, capsys.readouterr().err
    assert sorted(load_table(out)["cell_id"]) == ids  # the same cells: nothing new was solved
    assert cli.main([*base, "--height-unit", "mm", "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scene_config.extra.height_unit" in err, err


@pytest.mark.parametrize("first_pair", [True, False], ids=["pair-first", "pair-second"])
def test_one_length_and_the_pair_it_implies_are_one_configuration(first_pair: bool, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """On a square map that states no size, ``--length L`` and ``--length L,L`` read the
    same spacing: either resumes the folder the other wrote and solves nothing new; a pair
    that reads another spacing is another configuration."""
    path = tmp_path / "map.npy"
    np.save(path, np.random.default_rng(0).normal(size=(8, 8)) * 1e-7)
    base = [a for a in COMMON if a not in ("--size", "8")] + ["--surface", str(path), "--height-unit", "m", "--kernel", "love"]
    one, pair = ("--length", "2e-4"), ("--length", "2e-4,2e-4")
    first, second = (pair, one) if first_pair else (one, pair)
    out = str(tmp_path / "run")
    assert cli.main([*base, *first, "--out", out]) == 0, capsys.readouterr().err
    ids = sorted(load_table(out)["cell_id"])
    assert cli.main([*base, *second, "--out", out]) == 0, capsys.readouterr().err
    assert sorted(load_table(out)["cell_id"]) == ids
    assert cli.main([*base, "--length", "2e-4,3e-4", "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scene_config.length" in err, err


def test_a_file_option_is_kept_where_leaving_it_out_reads_otherwise(tmp_path: Path) -> None:
    """The length of a file that states none, a length the scene fills in itself where it
    is left out (the CMR scenes), and a unit other than the one the reader applies are
    the user's choice: kept.  Leaving out what the file states is taken back."""
    xyz = str(xyz_map(tmp_path / "map.txt"))
    np.save(tmp_path / "map.npy", np.random.default_rng(0).normal(size=(8, 8)) * 1e-7)

    def kept(scene: str, path: str, length: object, **extra: object) -> dict[str, object]:
        cfg = SceneConfig(steps=2, surface_path=path, length=length, extra=dict(extra))  # type: ignore[arg-type]
        given = given_apart(asdict(cfg), [scene])
        planned = left_out(cfg, [scene])
        assert (planned.length, dict(planned.extra)) == (given["length"], dict(given["extra"]))
        return {"length": given["length"], **given["extra"]}

    assert kept("paper-sweep", xyz, 2.4e-5, height_unit="m") == {"length": None}
    assert kept("paper-sweep", xyz, (2.4e-5, 2.4e-5)) == {"length": None}
    assert kept("paper-sweep", xyz, None, height_unit="mm") == {"length": None, "height_unit": "mm"}
    assert kept("cmr", xyz, 2.4e-5) == {"length": 2.4e-5}
    assert kept("paper-sweep", str(tmp_path / "map.npy"), 2e-4, height_unit="m") == {"length": 2e-4}
    assert kept("paper-sweep", str(tmp_path / "missing.txt"), 2.4e-5, height_unit="m") == {"length": 2.4e-5,
                                                                                          "height_unit": "m"}


REFERENCE_LIMIT = {"default-timeout": (("--reference", "auto"), "300"),
                   "given-timeout": (("--reference", "auto", "--timeout", "10"), "50")}


@pytest.mark.parametrize("which", sorted(REFERENCE_LIMIT))
@pytest.mark.parametrize("first_spelled", [True, False], ids=["spelled-out-first", "spelled-out-second"])
def test_the_reference_limit_in_effect_written_out_resumes(which: str, first_spelled: bool, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """``--reference-timeout`` at 5 x ``--timeout`` (its default, whether the timeout is
    given or its own default) is the run without it: either resumes the folder the other
    wrote and solves nothing new; another limit is another configuration."""
    timeout, limit = REFERENCE_LIMIT[which]
    spelled = (*timeout, "--reference-timeout", limit)
    first, second = (spelled, timeout) if first_spelled else (timeout, spelled)
    out = str(tmp_path / "run")
    assert_resumes(capsys, first, second, out)
    code, err = cli_run(capsys, *timeout, "--reference-timeout", "7", "--out", out)
    assert code == 2 and err.count("\n") == 1 and "run.reference_timeout" in err, err


def test_a_reference_limit_without_a_reference_resumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With ``--reference none`` no reference is solved: any ``--reference-timeout`` is the
    run without it."""
    assert_resumes(capsys, ("--reference", "none"), ("--reference", "none", "--reference-timeout", "7"),
                   str(tmp_path / "run"))
