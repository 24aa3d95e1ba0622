"""Bad input to ``run`` and ``validate`` is one line and exit 2, before anything runs or
is written, and nothing that is not the project's is touched:

* ``validate --csv PATH`` writes only a new file or a CSV file validate wrote (its first
  line the verdict table's header); a link (dangling or not) or any other file is
  refused before the battery runs, and left as it is;
* ``run --scheduler ADDRESS`` checks the address's form before the plan, and contacts the
  scheduler before the results folder is written: one it cannot reach leaves nothing;
* ``run --out ''`` and ``--out ' '`` name no folder (as for ``export``)."""

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
