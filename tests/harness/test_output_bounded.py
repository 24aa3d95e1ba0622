"""A handler that prints without end does not fill the disk while its parent waits for
the reply (``isolation.bound_output``): the output file is cut back to its head whenever it
takes more than the cap, its size still counts every byte printed, and the head and the
tail of what was printed are what the log and a failed reply's detail read."""

from __future__ import annotations

import os
import time
from functools import partial
from pathlib import Path
from typing import Any

from contactbench.harness.run.isolation import OUTPUT_NAME, ChildProcess, bound_output

MIB = 1024 * 1024


class Printer:
    """Writes ``chunks`` MiB to descriptor 1 (or to ``path``), one each 10 ms, then the line
    "END"; replies 0."""

    def __init__(self, chunks: int, path: str | None = None) -> None:
        self.chunks, self.path = chunks, path

    def __call__(self, msg: Any) -> int:
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600) if self.path else 1
        block = b"HEAD\n" + b"x" * (MIB - 5)
        for _ in range(self.chunks):
            os.write(fd, block)
            time.sleep(0.01)
        os.write(fd, b"\nEND\n")
        return 0


def test_the_worker_s_own_output_file_stays_under_the_cap(tmp_path: Path) -> None:
    cap = 4 * MIB
    child = ChildProcess(partial(Printer, 120), capture_output=True, output_cap=cap)
    try:
        child.start()
        reply = child.call("go", timeout=60.0)
        assert reply.kind == "ok", reply
        path = os.path.join(child.scratch or "", OUTPUT_NAME)
        st = os.stat(path)
        assert st.st_size >= 120 * MIB  # every byte printed is counted
        assert st.st_blocks * 512 <= cap + 40 * MIB  # (at most a check's worth written since the last cut)
        with open(path, "rb") as fh:
            assert fh.read(5) == b"HEAD\n"
        assert child.output_tail().rstrip().endswith("END")
    finally:
        child.kill()


def test_a_file_the_handler_names_is_bounded_too(tmp_path: Path) -> None:
    cap = 4 * MIB
    out = tmp_path / "worker.txt"
    child = ChildProcess(partial(Printer, 120, str(out)), output_files=(str(out),), output_cap=cap)
    try:
        child.start()
        assert child.call("go", timeout=60.0).kind == "ok"
        st = out.stat()
        assert st.st_size >= 120 * MIB and st.st_blocks * 512 <= cap + 40 * MIB
    finally:
        child.kill()


def test_a_file_under_the_cap_or_gone_is_left_as_it_is(tmp_path: Path) -> None:
    small = tmp_path / "small.txt"
    small.write_bytes(b"a" * 1000)
    bound_output(str(small), cap=MIB)
    assert small.read_bytes() == b"a" * 1000
    bound_output(str(tmp_path / "gone.txt"), cap=MIB)
    big = tmp_path / "big.txt"
    big.write_bytes(b"b" * (3 * MIB))
    bound_output(str(big), cap=MIB, head=10)
    assert big.read_bytes() == b"b" * 10
