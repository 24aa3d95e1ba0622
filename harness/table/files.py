"""The one home of how the harness writes files and names them.

* ``replace_atomically(path, write)``: ``write(tmp)`` to a unique temporary file beside
  ``path`` (process id and a random suffix: two writers never share one), ``fsync`` it,
  then rename it over ``path``.  A reader sees the old file or the new one, never a
  part; the temporary file is removed if anything fails.
* ``write_text_atomic`` / ``write_npz_atomic``: the same for text and numpy archives.
* ``safe_name(text)``: a file name with only letters, digits and ``._-[]=+``.
* ``canonical_json(obj)``: a JSON text with sorted keys (non-JSON values as ``str``),
  so two dicts with the same items give the same text -- the key of parameters in cell
  identities, stored rows and study variants.
"""

from __future__ import annotations

import contextlib
import json
import errno
import os
import uuid
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: Characters a file name keeps; every other one becomes "_".
SAFE_CHARACTERS = "._-[]=+"


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


def safe_name(text: str) -> str:
    """``text`` with every character but letters, digits and ``SAFE_CHARACTERS`` as "_"."""
    return "".join(c if c.isalnum() or c in SAFE_CHARACTERS else "_" for c in text)


def canonical_json(obj: Any) -> str:
    """JSON with sorted keys, non-JSON values as ``str``: equal dicts, equal texts."""
    return json.dumps(obj, sort_keys=True, default=str)


def pid_exists(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (one of another user's included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError as exc:  # pragma: no cover - EINVAL and the like
        return exc.errno != errno.ESRCH
    return True
