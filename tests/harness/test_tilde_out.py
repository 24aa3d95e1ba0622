"""A "~" that reaches ``--out`` (the shell leaves the one of ``--out=~/x`` as it is) names a
folder of that name under the current folder, for every reader and writer alike
(``atomic_files.literal_path``): pandas and pyarrow expand a leading "~" of a relative path,
so the table's temporary file went to the home folder, the run failed to write its table on
every try, and a file was left among the user's own."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import run_cli


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A home folder of its own, and a working folder beside it as the current one."""
    home, work = tmp_path / "home", tmp_path / "work"
    (home / "mine").mkdir(parents=True)
    work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    return home


def test_a_run_writes_its_table_under_a_folder_named_tilde(home: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["run", "counterexample", "--size", "6", "--seeds", "0", "--reference", "none", "--no-progress",
            "--no-warmup", "--solvers", "nnls", "--out", "~/mine"]
    rc, _, err = run_cli(args, capsys)
    assert rc == 0, err
    assert (Path("~") / "mine" / "results.csv").is_file()
    assert list((home / "mine").iterdir()) == []
    rc, out, err = run_cli(["report", "~/mine"], capsys)
    assert rc == 0, err
    assert (Path("~") / "mine" / "report.md").is_file() and list((home / "mine").iterdir()) == []


def test_an_export_writes_under_a_folder_named_tilde(home: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, _, err = run_cli(["export", "hertz", "--size", "16", "--format", "qpbenchmark", "--out", "~/mine/qps"],
                         capsys)
    assert rc == 0, err
    assert any((Path("~") / "mine" / "qps").iterdir())
    assert list((home / "mine").iterdir()) == []


def test_a_path_through_a_link_and_up_is_read_as_the_system_reads_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """"lnk/../out" is "far/out" when lnk points at far/deep: every file of the run goes
    there (removing ".." as text put the table in ./out and the journal in far/out)."""
    (tmp_path / "far" / "deep").mkdir(parents=True)
    (tmp_path / "lnk").symlink_to(tmp_path / "far" / "deep")
    monkeypatch.chdir(tmp_path)
    args = ["run", "counterexample", "--size", "6", "--seeds", "0", "--reference", "none", "--no-progress",
            "--no-warmup", "--solvers", "nnls", "--out", "lnk/../out"]
    rc, _, err = run_cli(args, capsys)
    assert rc == 0, err
    assert (tmp_path / "far" / "out" / "results.csv").is_file() and (tmp_path / "far" / "out" / "rows.jsonl").is_file()
    assert not (tmp_path / "out").exists()
