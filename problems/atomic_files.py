"""Files written whole or not at all, the one home of the rule for every writer of the
project (problems' exports and the harness's tables, reports and answers alike).

* ``replace_atomically(path, write)``: ``write(tmp)`` to a unique temporary file beside
  ``path`` (process id and a random suffix: two writers never share one), ``fsync`` it,
  then rename it over ``path``.  A reader sees the old file or the new one, never a
  part; the temporary file is removed if anything fails.
* ``write_text_atomic`` / ``write_npz_atomic``: the same for text and numpy archives.
* ``folder_lock(folder)``: an exclusive, non-blocking ``flock`` on the folder itself for
  the length of a ``with`` block (no lock file: nothing is added to the folder; the
  kernel drops the lock when the process dies); ``FolderLockedError`` at once when
  another process holds it.
* ``literal_path(path)``: the path every reader and writer hands a library (absolute: a
  leading "~" names a folder of that name, never the home folder).
* ``names_nothing(path)``: whether a path a writer is given is empty or blank ("" would
  be the current folder, " " a file of that name): every writer refuses it.
* ``not_utf8_text(path)``: a path whose name is not UTF-8 text (bytes the system gave that
  ``os.fsdecode`` escapes), shown with those bytes escaped; the results record names and
  paths as UTF-8 text (pyarrow takes UTF-8 paths only), so every reader and writer of a
  named path refuses it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import uuid
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np


def names_nothing(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is empty or only blanks (module doc)."""
    return not os.fspath(path).strip()


def not_utf8_text(path: str | os.PathLike[str]) -> str | None:
    """``path`` shown with its undecodable bytes escaped ("o_bad\\xff") where it is not
    UTF-8 text, else None (module doc)."""
    name = os.fspath(path)
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return os.fsencode(name).decode("utf-8", "backslashreplace")
    return None


def literal_path(path: str | os.PathLike[str]) -> Path:
    """``path`` as the file system reads it, made absolute so that no library reads it
    otherwise: pandas and pyarrow expand a leading "~" of a relative path to the home
    folder, where ``open`` and ``os.replace`` read a folder named "~" (a shell leaves the
    "~" of ``--out=~/x`` as it is).  Joined to the current folder as it is, ".." kept: the
    system reads "link/.." past the link's target, where removing it as text would not."""
    return Path(os.fspath(path)).absolute()


def replace_atomically(path: str | os.PathLike[str], write: Callable[[str], Any]) -> None:
    """``write(tmp)`` to a unique temporary file next to ``path`` (``literal_path``: every
    writer, ``write`` too, reads the one path), fsync it, then rename it over ``path``; the
    temporary file is removed if anything fails, and an ``OSError`` that names no file, or
    the temporary one, names ``path`` (a full disk's "No space left on device" names none)."""
    p = literal_path(path)
    tmp = str(p.with_name(f".{p.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp"))  # (umask applies)
    try:
        write(tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename in (None, tmp):
            exc.filename = str(p)
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


class FolderLockedError(BlockingIOError):
    """Another process holds the lock of the folder (``folder_lock``)."""


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike[str]) -> Iterator[None]:
    """Hold an exclusive ``flock`` on the existing folder ``folder`` for the ``with``
    block; ``FolderLockedError`` at once when another process holds it."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FolderLockedError(f"{folder} is locked by another process") from None
        yield
    finally:
        os.close(fd)  # (closing the last descriptor releases the lock)


__all__ = ["FolderLockedError", "folder_lock", "names_nothing", "not_utf8_text", "replace_atomically", "write_npz_atomic",
           "write_text_atomic"]
