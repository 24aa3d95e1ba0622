"""A results folder whose entries a run reads or writes is refused, before anything is
written or locked, when one of them is a symbolic link (a run never reads or writes
through one) or of the wrong kind (a file where the run keeps a folder, or the reverse):
exit 2, one line naming the entry; the folder and whatever a link points to are left as
they are."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable

import pytest

from contactbench.harness import cli
from contactbench.harness.table.meta import META_FILE
from contactbench.harness.table.store import (ARRAYS_DIR, CACHE_DIR, CSV_FILE, LOCK_FILE, MARKER_FILE, PARQUET_FILE,
                                              ROWS_FILE, RUN_ENTRIES, RunFolderError, check_run_entries)

RUN = ["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", "pk", "--reference", "none", "--no-progress"]


def snapshot(folder: Path) -> dict[str, tuple[str, bytes]]:
    """Every entry under ``folder`` (links not followed): its kind and its bytes."""
    out: dict[str, tuple[str, bytes]] = {}
    for path in sorted(folder.rglob("*")):
        rel = str(path.relative_to(folder))
        if path.is_symlink():
            out[rel] = ("link", os.readlink(path).encode())
        elif path.is_dir():
            out[rel] = ("folder", b"")
        else:
            out[rel] = ("file", path.read_bytes())
    return out


@pytest.fixture(scope="module")
def base_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished run folder of two rows (its _cache and arrays folders there)."""
    out = tmp_path_factory.mktemp("base") / "run"
    assert cli.main([*RUN, "--out", str(out)]) == 0
    for name in (CACHE_DIR, ARRAYS_DIR):
        (out / name).mkdir(exist_ok=True)
    return out


def link_to_file(entry: Path, elsewhere: Path) -> None:
    target = elsewhere / entry.name
    if entry.is_file():
        shutil.move(entry, target)
    else:
        target.write_text("someone's file\n")
    entry.symlink_to(target)


def link_to_folder(entry: Path, elsewhere: Path) -> None:
    shutil.rmtree(entry, ignore_errors=True)
    entry.symlink_to(elsewhere, target_is_directory=True)


def file_for_folder(entry: Path, elsewhere: Path) -> None:
    shutil.rmtree(entry, ignore_errors=True)
    entry.write_text("not a folder\n")


def folder_for_file(entry: Path, elsewhere: Path) -> None:
    entry.unlink(missing_ok=True)
    entry.mkdir()


CASES: list[tuple[str, Callable[[Path, Path], None], str]] = [
    *[(name, link_to_file, "is a symbolic link") for name in (ROWS_FILE, META_FILE, MARKER_FILE, CSV_FILE,
                                                              PARQUET_FILE, LOCK_FILE)],
    *[(name, link_to_folder, "is a symbolic link") for name in (CACHE_DIR, ARRAYS_DIR)],
    *[(name, file_for_folder, "is not a folder") for name in (CACHE_DIR, ARRAYS_DIR)],
    *[(name, folder_for_file, "is not a plain file") for name in (ROWS_FILE, META_FILE, CSV_FILE)],
]


@pytest.mark.parametrize(("name", "make", "problem"), CASES, ids=[f"{c[0]}-{c[1].__name__}" for c in CASES])
def test_an_entry_that_is_a_link_or_of_the_wrong_kind_is_refused_and_nothing_is_written(
        base_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str,
        make: Callable[[Path, Path], None], problem: str) -> None:
    out, elsewhere = tmp_path / "o", tmp_path / "elsewhere"
    shutil.copytree(base_run, out, symlinks=True)
    elsewhere.mkdir()
    make(out / name, elsewhere)
    before, theirs = snapshot(out), snapshot(elsewhere)
    capsys.readouterr()
    k = RUN.index("--steps")
    code = cli.main([*RUN[:k], *RUN[k + 2:], "--out", str(out), "--steps", "3", "--append"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and str(out / name) in err and problem in err, err
    assert snapshot(out) == before  # no marker, meta.json, lock or row written
    assert snapshot(elsewhere) == theirs  # nothing written through the link


def test_the_layout_names_every_entry_a_run_reads_or_writes_with_its_kind(tmp_path: Path) -> None:
    assert {n for n, folder in RUN_ENTRIES.items() if folder} == {CACHE_DIR, ARRAYS_DIR}
    assert {ROWS_FILE, META_FILE, MARKER_FILE, CSV_FILE, PARQUET_FILE, LOCK_FILE} <= set(RUN_ENTRIES)
    (tmp_path / CACHE_DIR).symlink_to(tmp_path / "nowhere")  # a dangling link too
    with pytest.raises(RunFolderError, match=rf"{CACHE_DIR} is a symbolic link"):
        check_run_entries(tmp_path)
