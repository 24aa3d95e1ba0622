"""A foreign reader's own output stays off the terminal (problems/map_readers.py):

* what SurfaceTopography's readers print, log or write at the file-descriptor level while
  they read a map is held (``foreign_output_held``), and file descriptors 1 and 2,
  ``sys.stdout``/``sys.stderr`` and the root logger's handlers are put back whatever
  the reader raised;
* a read that fails is one ``SurfaceFileError`` line naming the file, with the reader's
  reason as printable text, short (``errors.printable_excerpt``);
* a read that succeeds keeps what the reader warned or wrote as the map's own one-line
  warnings (``RawMap.reader_notes``, announced by ``load_surface`` and kept in its
  ``MapPreprocessing.warnings``);
* a map's cleaning warnings come only once the map has passed every check: a map refused
  (flat once its tilt is removed) warns of nothing first;
* x,y,z columns with an infinite coordinate are refused with no NumPy warning first.
"""

from __future__ import annotations

import logging
import os
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import SurfaceTopography.IO

from contactbench.problems.errors import EXCERPT_CHARS, printable_excerpt
from contactbench.problems.io import load_surface
from contactbench.problems.map_files import write_x3p
from contactbench.problems.map_readers import SurfaceFileError, read_height_map
from contactbench.problems.output_streams import foreign_output_held

#: What a noisy reader writes: binary bytes, as a reader that dumps a header does.
JUNK = bytes(range(256)) * 4
N = 16
D = 1e-6


def noisy(real: Any, *, fail: bool) -> Any:
    """``open_topography`` that first says things every way a reader can: a print, a
    write to file descriptor 2, a ``logging`` error and a Python warning; then reads
    with ``real``, or raises a ``ValueError`` whose message holds binary bytes."""

    def open_topography(*args: Any, **kwargs: Any) -> Any:
        print("reader's print")
        os.write(2, JUNK)
        logging.getLogger("igor2.binarywave").error("could not reshape data to %r", JUNK[:64])
        warnings.warn("header field 'ZScale' ignored", UserWarning, stacklevel=2)
        if fail:
            raise ValueError(f"bad magic {JUNK[:40].decode('latin-1')!r}")
        return real(*args, **kwargs)

    return open_topography


def rough_map(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 1e-7, (N, N))


@pytest.fixture
def stderr_logging() -> Any:
    """A root handler writing to file descriptor 2, as the command line's
    ``logging.basicConfig`` on the terminal's stderr."""
    stream = open(2, "w", buffering=1, encoding="utf-8", errors="replace", closefd=False)
    handler = logging.StreamHandler(stream)
    logging.root.addHandler(handler)
    yield handler
    logging.root.removeHandler(handler)
    stream.close()


@pytest.mark.usefixtures("stderr_logging")
def test_a_failed_foreign_read_says_nothing_on_the_terminal_and_one_printable_line(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "m.sur"
    path.write_bytes(JUNK)
    monkeypatch.setattr(SurfaceTopography.IO, "open_topography", noisy(SurfaceTopography.IO.open_topography, fail=True))
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with pytest.raises(SurfaceFileError) as caught:
            read_height_map(path)
    out, err = capfd.readouterr()
    assert out == "" and err == "" and not shown
    message = str(caught.value)
    assert "\n" not in message and str(path) in message and "bad magic" in message
    assert all(0x20 <= ord(ch) < 0x7F for ch in message)
    assert len(message) < len(str(path)) + 2 * EXCERPT_CHARS + 100


@pytest.mark.usefixtures("stderr_logging")
def test_a_garbage_file_is_refused_with_nothing_of_the_readers_on_the_terminal(
        tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "garbage.bin"
    path.write_bytes(bytes(range(256)) * 10)  # (an Igor reader logs the bytes it tried as a shape)
    with pytest.raises(SurfaceFileError) as caught:
        read_height_map(path)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert str(path) in str(caught.value)


def test_a_successful_foreign_read_keeps_what_its_reader_said_as_one_line_warnings(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    path = write_x3p(tmp_path / "m.x3p", rough_map(), D)
    monkeypatch.setattr(SurfaceTopography.IO, "open_topography", noisy(SurfaceTopography.IO.open_topography, fail=False))
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        record = load_surface(path, detrend="none").preprocessing
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert record is not None
    said = [w for w in record.warnings if "its reader" in w]
    assert [str(w.message) for w in shown] == said
    assert any("header field 'ZScale' ignored" in w for w in said)
    assert any("its reader wrote: reader's print" in w for w in said)
    assert all("\n" not in w and all(0x20 <= ord(ch) < 0x7F for ch in w) for w in said)


def test_what_a_reader_says_is_held_and_everything_is_put_back_when_it_raises(
        capfd: pytest.CaptureFixture[str]) -> None:
    streams, handlers = (sys.stdout, sys.stderr), logging.root.handlers[:]
    with pytest.raises(KeyboardInterrupt):
        with foreign_output_held() as said:
            print("to stdout")
            os.write(1, b"fd 1 ")
            os.write(2, b"fd 2 ")
            logging.getLogger("a.reader").error("logged")
            warnings.warn("a reader's warning", UserWarning, stacklevel=1)
            warnings.warn("about its own code", DeprecationWarning, stacklevel=1)
            raise KeyboardInterrupt
    assert (sys.stdout, sys.stderr) == streams and logging.root.handlers == handlers
    assert capfd.readouterr() == ("", "")
    assert all(text in said.written for text in ("to stdout", "fd 1", "fd 2", "logged"))
    assert said.warnings == ["a reader's warning"]
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"


def test_a_printable_excerpt_is_short_printable_text() -> None:
    assert printable_excerpt("magic 'Z8\x93\x00\xc3'\n at offset 0") == "magic 'Z8 ' at offset 0"
    long = printable_excerpt("x" * 1000)
    assert len(long) == EXCERPT_CHARS and long.endswith("...")


@pytest.mark.parametrize("heights", ["plane", "plane-with-a-hole"])
def test_a_map_refused_as_flat_warns_of_nothing_first(tmp_path: Path, heights: str) -> None:
    """A plane (tilt warning) with a missing point (fill warning) is flat once its tilt
    is removed: refused, and no warning before the refusal."""
    z = 1e-7 * np.arange(N)[:, None] + np.zeros((N, N))
    if heights == "plane-with-a-hole":
        z[3, 3] = np.nan
    np.save(tmp_path / "p.npy", z)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with pytest.raises(SurfaceFileError, match="flat"):
            load_surface(tmp_path / "p.npy", N * D)
    assert [str(w.message) for w in shown] == []


def test_xyz_columns_with_an_infinite_coordinate_are_refused_with_no_numpy_warning(tmp_path: Path) -> None:
    x, y = np.meshgrid(np.arange(N) * D, np.arange(N) * D)
    cols = np.column_stack([x.ravel(), y.ravel(), rough_map().ravel()])
    cols[N * 3: N * 3 + 4, 0] = np.inf
    np.savetxt(tmp_path / "xyz.txt", cols)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        with pytest.raises(SurfaceFileError):
            load_surface(tmp_path / "xyz.txt")
    assert [str(w.message) for w in shown] == []
