"""A surface path that is not a regular file (a named pipe, a device, a socket) is refused
in one line before any of it is read, and a .npy file whose header declares more values
than the file holds is refused before NumPy allocates them (problems/io.py,
``check_surface_file``)."""

from __future__ import annotations

import os
import socket
import threading
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
from contactbench.problems.io import SurfaceFileError, load_surface
from tests.helpers import run_cli


@pytest.fixture
def fifo(tmp_path: Path) -> Iterator[Path]:
    """A named pipe; a helper opens and closes its writing end whenever a reader waits on
    it, so a reader sees its end at once instead of waiting for ever."""
    path = tmp_path / "pipe.txt"
    os.mkfifo(path)
    done = threading.Event()

    def release_readers() -> None:
        while not done.wait(0.05):
            try:
                os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:  # no reader waits
                pass

    helper = threading.Thread(target=release_readers, daemon=True)
    helper.start()
    yield path
    done.set()
    helper.join()


def lying_npy(path: Path, shape: tuple[int, ...], data_bytes: int) -> Path:
    """A .npy file whose header declares ``shape`` of float64, followed by ``data_bytes``
    bytes of data."""
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": shape})
        f.write(b"\0" * data_bytes)
    return path


def test_a_named_pipe_is_refused_before_it_is_read(fifo: Path) -> None:
    with pytest.raises(SurfaceFileError, match="it is a named pipe"):
        load_surface(fifo, length=1e-5)


def test_a_device_is_refused_before_it_is_read() -> None:
    with pytest.raises(SurfaceFileError, match="it is a character device"):
        load_surface(os.devnull, length=1e-5)


def test_a_socket_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(path))
        with pytest.raises(SurfaceFileError, match="it is a socket"):
            load_surface(path, length=1e-5)


def test_a_npy_header_declaring_more_than_the_file_holds_is_refused_before_allocating(tmp_path: Path) -> None:
    path = lying_npy(tmp_path / "huge.npy", (10**6, 10**6), 2048)
    with pytest.raises(SurfaceFileError) as caught:
        load_surface(path, length=1e-5)
    line = str(caught.value)
    assert "1000000 x 1000000" in line and "2,048 bytes" in line and len(line.splitlines()) == 1


def test_a_npy_file_holding_what_its_header_declares_loads(tmp_path: Path) -> None:
    path = tmp_path / "ok.npy"
    np.save(path, np.random.default_rng(0).standard_normal((16, 16)) * 1e-6)
    assert load_surface(path, length=1e-5).heights.shape == (16, 16)


def test_run_refuses_a_lying_npy_header_in_one_line_exit_2(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = lying_npy(in_tmp / "huge.npy", (10**6, 10**6), 2048)
    rc, _, err = run_cli(["run", "paper-sweep", "--steps", "2", "--solvers", "pk", "--reference", "none",
                          "--no-progress", "--surface", str(path), "--length", "1e-5", "--out", "o"], capsys)
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, (rc, err)
    assert "header declares 1000000 x 1000000" in err and not (in_tmp / "o").exists()
