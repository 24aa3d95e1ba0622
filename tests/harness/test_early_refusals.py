"""Bad input to ``run`` and ``validate`` is one line and exit 2, before anything runs or
is written, and nothing that is not the project's is touched:

* ``validate --csv PATH`` writes only a new file or a CSV file validate wrote (its first
  line the verdict table's header); a link (dangling or not) or any other file is
  refused before the battery runs, and left as it is;
* ``run --scheduler ADDRESS`` checks the address's form before the plan, and contacts the
  scheduler before the results folder is written: one it cannot reach leaves nothing;
* ``run --out ''`` and ``--out ' '`` name no folder (as for ``export``), nor does
  ``report ''`` (it would read the current folder);
* an ``--out`` whose name is not UTF-8 text (bytes the table's writer cannot take) is
  refused before the run, for ``run``, ``export`` and ``report``;
* an ``--out`` that is a link to a folder is that folder."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from contactbench.harness import cli
from contactbench.harness.conformance import command
from contactbench.harness.conformance.command import csv_header, is_verdict_csv
from contactbench.harness.run import distributed

pytestmark = pytest.mark.usefixtures("in_tmp")

VALIDATE = ["pk", "--cases", "edge/single*", "--quiet"]
RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "pk", "--reference", "none", "--no-progress"]


def one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


@pytest.fixture
def no_battery(monkeypatch: pytest.MonkeyPatch) -> None:
    """The battery may not run (a refusal comes before it)."""
    def ran(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("the battery ran")

    monkeypatch.setattr(command, "validate", ran)


@pytest.mark.usefixtures("no_battery")
@pytest.mark.parametrize("kind", ["link-to-a-file", "dangling-link", "link-to-a-verdict-csv"])
def test_validate_refuses_a_csv_path_that_is_a_link_before_the_battery_runs(
        in_tmp: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    theirs = in_tmp / "notes.txt"
    theirs.write_text(f"{csv_header()}\n" if kind == "link-to-a-verdict-csv" else "someone's notes\n")
    path = in_tmp / "verdicts.csv"
    path.symlink_to(in_tmp / "nowhere.csv" if kind == "dangling-link" else theirs)
    before = theirs.read_bytes()
    assert command.main([*VALIDATE, "--csv", str(path)]) == 2
    err = one_line_error(capsys)
    assert "--csv" in err and str(path) in err
    assert theirs.read_bytes() == before and sorted(p.name for p in in_tmp.iterdir()) == sorted(
        {theirs.name, path.name})


def test_validate_writes_a_new_csv_over_its_own_and_over_no_other_file(
        in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = in_tmp / "v.csv"
    path.write_text("someone's notes\n")
    assert command.main([*VALIDATE, "--csv", str(path)]) == 2
    assert "was not written by validate" in one_line_error(capsys) and path.read_text() == "someone's notes\n"
    path.unlink()
    assert command.main([*VALIDATE, "--csv", str(path)]) == 0
    assert is_verdict_csv(path) and path.read_text().startswith(csv_header() + "\n")
    path.write_text(f"{csv_header()}\nan,older,table\n")
    assert command.main([*VALIDATE, "--csv", str(path)]) == 0
    assert "an,older,table" not in path.read_text() and is_verdict_csv(path)


@pytest.mark.parametrize("address", ["garbage", "", "tcp://host", "tcp://host:0", "nosuch://host:8786",
                                     "127.0.0.1:port"])
def test_a_scheduler_address_of_the_wrong_form_is_refused_before_anything_is_written(
        in_tmp: Path, capsys: pytest.CaptureFixture[str], address: str) -> None:
    assert cli.main([*RUN, "--out", "out", "--scheduler", address]) == 2
    assert "--scheduler" in one_line_error(capsys)
    assert list(in_tmp.iterdir()) == []


def test_a_scheduler_that_cannot_be_reached_leaves_no_folder(in_tmp: Path, capsys: pytest.CaptureFixture[str],
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    def unreachable(address: Any) -> Any:
        raise OSError(f"Timed out trying to connect to {address} after 30 s")

    monkeypatch.setattr(distributed, "connect", unreachable)
    assert cli.main([*RUN, "--out", "out", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "tcp://127.0.0.1:1" in one_line_error(capsys)
    assert list(in_tmp.iterdir()) == []


@pytest.mark.parametrize("out", ["", " "])
def test_an_empty_or_blank_out_names_no_folder(in_tmp: Path, capsys: pytest.CaptureFixture[str], out: str) -> None:
    assert cli.main([*RUN, "--out", out]) == 2
    assert "must be named" in one_line_error(capsys)
    assert list(in_tmp.iterdir()) == [] and not os.path.lexists(in_tmp / "results")


@pytest.mark.parametrize("out", ["", " "])
def test_report_of_an_empty_name_reads_no_folder(in_tmp: Path, capsys: pytest.CaptureFixture[str], out: str) -> None:
    assert cli.main(["report", out]) == 2
    assert "must be named" in one_line_error(capsys)
    assert list(in_tmp.iterdir()) == []


NOT_UTF8 = os.fsdecode(b"o_bad\xff")


@pytest.mark.parametrize("argv", [[*RUN, "--out", NOT_UTF8],
                                  ["export", "hertz", "--size", "8", "--format", "problem-dir", "--out", NOT_UTF8],
                                  ["report", NOT_UTF8]])
def test_a_name_that_is_not_utf8_is_refused_before_anything_runs(in_tmp: Path, capsys: pytest.CaptureFixture[str],
                                                                 argv: list[str]) -> None:
    if argv[0] == "report":
        os.mkdir(NOT_UTF8)
    before = sorted(os.listdir(in_tmp))
    assert cli.main(argv) == 2
    err = one_line_error(capsys)
    assert "o_bad\\xff" in err and "UTF-8" in err, err
    assert sorted(os.listdir(in_tmp)) == before


def test_an_out_that_is_a_link_to_a_folder_is_that_folder(in_tmp: Path) -> None:
    (in_tmp / "kept").mkdir()
    (in_tmp / "link").symlink_to(in_tmp / "kept", target_is_directory=True)
    assert cli.main([*RUN, "--out", "link"]) == 0
    assert (in_tmp / "link").is_symlink() and (in_tmp / "kept" / "results.parquet").is_file()


@pytest.mark.parametrize("command", ["run", "export"])
def test_a_surface_file_named_in_no_utf8_is_refused_naming_it(in_tmp: Path, capsys: pytest.CaptureFixture[str],
                                                              command: str) -> None:
    import numpy as np

    name = os.fsdecode(b"map\xfe.npy")
    np.save(name, np.random.default_rng(0).normal(size=(17, 17)) * 1e-7)
    tail = ["--solvers", "pk", "--reference", "none", "--no-progress"] if command == "run" else ["--format",
                                                                                                  "problem-dir"]
    argv = [command, "paper-sweep", "--steps", "2", "--surface", name, "--length", "1e-4", *tail, "--out", "out"]
    assert cli.main(argv) == 2
    err = one_line_error(capsys)
    assert "map\\\\xfe.npy" in err and "UTF-8" in err, err  # (the name as repr shows it)
    assert sorted(os.listdir(in_tmp)) == [name]
