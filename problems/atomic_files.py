"""Files written whole or not at all, the one home of the rule for every writer of the
project (problems' exports and the harness's tables, reports and answers alike).

* ``replace_atomically(path, write)``: ``write(tmp)`` to a unique temporary file beside
  ``path`` (process id and a random suffix: two writers never share one), ``fsync`` it,
  then rename it over ``path``.  A reader sees the old file or the new one, never a
  part; the temporary file is removed if anything fails.
* ``write_text_atomic`` / ``write_npz_atomic``: the same for text and numpy archives.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path
from typing import Any, Callable

import numpy as np


def replace_atomically(path: str | os.PathLike[str], write: Callable[[str], Any]) -> None:
    """``write(tmp)`` to a unique temporary file next to ``path``, fsync it, then rename
    it over ``path``; the temporary file is removed if anything fails."""
    p = Path(path)
    tmp = str(p.with_name(f".{p.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp"))  # (umask applies)
    try:
        write(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``replace_atomically``)."""
    replace_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def write_npz_atomic(path: str | os.PathLike[str], compressed: bool = False, **arrays: Any) -> None:
    """Write a numpy archive (no pickles) to ``path`` atomically."""
    save = np.savez_compressed if compressed else np.savez

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            save(fh, **arrays)

    replace_atomically(path, write)


__all__ = ["replace_atomically", "write_npz_atomic", "write_text_atomic"]
