"""The one home of how the harness writes files and names them.

* ``replace_atomically``, ``write_text_atomic``, ``write_npz_atomic``: files written whole
  or not at all (their home is ``contactbench.problems.atomic_files``).
* ``safe_name(text)``: a file name with only letters, digits and ``._-[]=+``.
* ``canonical_json(obj)``: a JSON text with sorted keys (non-JSON values as ``str``),
  so two dicts with the same items give the same text -- the key of parameters in cell
  identities, stored rows and study variants.
* ``begins_with(path, start)``: whether a file is one a writer of the harness wrote, by
  how every such file begins: a plain file (never a link, a folder or a special file)
  whose first bytes are ``start``.  A writer writes over an existing file of its name
  only when it is its own by this rule.
"""

from __future__ import annotations

import json
import errno
import os
from typing import Any

from contactbench.problems.atomic_files import replace_atomically, write_npz_atomic, write_text_atomic

#: Characters a file name keeps; every other one becomes "_".
SAFE_CHARACTERS = "._-[]=+"


def safe_name(text: str) -> str:
    """``text`` with every character but letters, digits and ``SAFE_CHARACTERS`` as "_"."""
    return "".join(c if c.isalnum() or c in SAFE_CHARACTERS else "_" for c in text)


def canonical_json(obj: Any) -> str:
    """JSON with sorted keys, non-JSON values as ``str``: equal dicts, equal texts."""
    return json.dumps(obj, sort_keys=True, default=str)


def begins_with(path: str | os.PathLike[str], start: bytes) -> bool:
    """Whether ``path`` is a plain file, not a link, whose first bytes are ``start`` (module
    doc); False for anything else, a file that cannot be read included."""
    if os.path.islink(path) or not os.path.isfile(path):
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(len(start)) == start
    except OSError:
        return False


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


__all__ = ["SAFE_CHARACTERS", "begins_with", "canonical_json", "pid_exists", "replace_atomically", "safe_name", "write_npz_atomic",
           "write_text_atomic"]
