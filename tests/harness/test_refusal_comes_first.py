"""Bad input to ``run`` and ``export`` is refused in one line, exit 2, with nothing before
it: the warnings the command's checks raise (a map's cleaning) are held until every check
has passed (``cli.held_warnings``) and dropped when the input is refused; a run that goes
ahead shows them.  A refusal names the option or path and what is wrong in our words:

* ``--out`` through a symbolic link that leads nowhere (no folder can be made there);
* a solver named by import path with an empty module name (``:NAME``) or an empty NAME
  (``module:``);
* a file or link in the way of a folder or file the command makes (``FileExistsError``:
  what is in the way, not the system's "File exists")."""

from __future__ import annotations

import errno
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli
from contactbench.harness.arguments import InputError
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")

N = 16
RUN = ["run", "paper-sweep", "--steps", "1", "--reference", "none", "--no-progress"]


def one_line_refusal(args: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    rc, out, err = run_cli(args, capsys)
    assert rc == 2 and out == "" and err.count("\n") == 1 and err.startswith("contactbench: error:"), err
    return err


def tilted_map_with_a_hole(path: Path, rise: float) -> Path:
    """A rough map on a plane of slope ``rise`` per point (the tilt warns) with one missing
    point (the fill warns)."""
    z = np.random.default_rng(1).normal(0.0, rise / 100, (N, N)) + rise * np.arange(N)[:, None]
    z[3, 3] = np.nan
    np.save(path, z)
    return path


def test_a_map_refused_as_too_steep_shows_no_warning_of_its_cleaning_first(
        in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tilted_map_with_a_hole(in_tmp / "steep.npy", 1e-3)
    np.save(path, np.load(path) + np.random.default_rng(2).normal(0.0, 1e-2, (N, N)))
    err = one_line_refusal([*RUN, "--solvers", "pk", "--surface", str(path), "--length", "1e-4", "--out", "o"], capsys)
    assert "rms slope" in err
    assert not (in_tmp / "o").exists()


def test_a_run_folder_refused_shows_no_warning_of_the_map_first(
        in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tilted_map_with_a_hole(in_tmp / "tilted.npy", 1e-7)
    (in_tmp / "o").mkdir()
    (in_tmp / "o" / "_cache").symlink_to(in_tmp / "nowhere")
    err = one_line_refusal([*RUN, "--solvers", "pk", "--surface", str(path), "--length", "1.6e-5", "--out", "o"], capsys)
    assert "o/_cache" in err


def test_held_warnings_are_shown_in_order_once_released_and_dropped_on_bad_input() -> None:
    shown: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = lambda message, *rest: shown.append(str(message))
        with cli.held_warnings() as held:
            warnings.warn("first", UserWarning, stacklevel=1)
            warnings.warn("second", UserWarning, stacklevel=1)
            assert shown == []
            held.release()
            warnings.warn("third", UserWarning, stacklevel=1)
        assert shown == ["first", "second", "third"]
        with pytest.raises(InputError):
            with cli.held_warnings():
                warnings.warn("before a refusal", UserWarning, stacklevel=1)
                raise InputError("bad input")
        with cli.held_warnings():
            warnings.warn("kept to the end", UserWarning, stacklevel=1)
    assert shown == ["first", "second", "third", "kept to the end"]


@pytest.mark.parametrize("command", ["run", "export"])
@pytest.mark.parametrize("where", ["lnk", "lnk/sub"])
def test_out_through_a_link_that_leads_nowhere_is_named_as_such(
        in_tmp: Path, capsys: pytest.CaptureFixture[str], command: str, where: str) -> None:
    (in_tmp / "lnk").symlink_to(in_tmp / "nowhere")
    args = [*RUN, "--size", "8", "--solvers", "pk"] if command == "run" else ["export", "paper-sweep", "--size", "8", "--steps", "1",
                                                           "--format", "problem-dir"]
    err = one_line_refusal([*args, "--out", where], capsys)
    assert f"--out {where}: lnk is a symbolic link to" in err and "File exists" not in err
    assert not (in_tmp / "nowhere").exists()


@pytest.mark.parametrize(("spec", "part"), [(":X", "module name before ':'"), ("json:", "NAME after ':'")])
def test_a_solver_path_with_an_empty_part_says_which_part_is_empty(
        capsys: pytest.CaptureFixture[str], spec: str, part: str) -> None:
    err = one_line_refusal([*RUN, "--size", "8", "--solvers", spec, "--out", "o"], capsys)
    assert f"cannot load solver {spec!r}: the {part} is empty" in err and "Empty module name" not in err


@pytest.mark.parametrize("kind", ["file", "link"])
def test_something_in_the_way_of_a_folder_is_named_in_our_words(
        in_tmp: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, kind: str) -> None:
    (in_tmp / "h").mkdir()
    figures = in_tmp / "h" / "figures"
    if kind == "file":
        figures.write_text("notes\n")
    else:
        figures.symlink_to(in_tmp / "nowhere")

    def makes_figures(out_dir: str) -> int:
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(figures))

    monkeypatch.setattr(cli, "cmd_report", makes_figures)
    err = one_line_refusal(["report", "h"], capsys)
    word = "a file" if kind == "file" else "a symbolic link"
    assert f"{figures}: {word} is in the way" in err and "File exists" not in err
