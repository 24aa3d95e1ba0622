"""Errors raised for bad input.  Each message names what is wrong."""

from __future__ import annotations

import re

import numpy as np

#: The most characters of another program's words (a foreign reader's error or warning)
#: that one of our lines quotes (``printable_excerpt``).
EXCERPT_CHARS = 160
#: A run of characters that are no printable ASCII (binary bytes a reader decoded, control
#: characters, line ends): each run is written as one space.
_NOT_PRINTABLE = re.compile(r"[^\x20-\x7e]+")


class ProblemInputError(ValueError):
    """Invalid input to a problem builder (surface, material, load, file)."""


class MemoryBudgetError(MemoryError):
    """Building the requested object would exceed the memory budget.

    The message carries the estimate so callers can record it as a skip reason.
    """

    def __init__(self, what: str, needed_bytes: float, budget_bytes: float) -> None:
        self.what = what
        self.needed_bytes = float(needed_bytes)
        self.budget_bytes = float(budget_bytes)
        super().__init__(
            f"{what} needs about {needed_bytes / 2**30:.3g} GiB, "
            f"over the memory budget of {budget_bytes / 2**30:.3g} GiB"
        )


def real_number(name: str, value: object, rule: str) -> float:
    """``value`` as a float if it is a real number (not a bool, a string or None), else a
    ``ProblemInputError`` naming ``name`` and ``rule``."""
    if isinstance(value, (bool, str, bytes)) or value is None:
        raise ProblemInputError(f"{name} must be {rule}, got {value!r}")
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ProblemInputError(f"{name} must be {rule}, got {value!r}") from None


def check_positive(name: str, value: float) -> float:
    """Return ``value`` as float if it is a finite real number > 0, else raise a clear error."""
    v = real_number(name, value, "a finite positive number")
    if not (v > 0.0) or v != v or v == float("inf"):
        raise ProblemInputError(f"{name} must be a finite positive number, got {value!r}")
    return v


def check_nonnegative(name: str, value: float) -> float:
    v = real_number(name, value, "a finite number >= 0")
    if not (v >= 0.0) or v == float("inf"):
        raise ProblemInputError(f"{name} must be a finite number >= 0, got {value!r}")
    return v


def is_whole(value: object, minimum: int) -> bool:
    """Whether ``value`` is a whole number >= ``minimum``: an int, or a finite float with an
    integer value; not a bool."""
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, (int, np.integer)):  # (however many digits: no float holds every int)
        return bool(value >= minimum)
    return isinstance(value, (float, np.floating)) and bool(np.isfinite(value)) and int(value) == value \
        and value >= minimum


#: The largest count a table's integer column holds (int64): an iteration or product count
#: beyond it is no count a solver can have made.
COUNT_MAX = 2**63 - 1


def is_count(value: object) -> bool:
    """Whether ``value`` is a whole number from 0 to ``COUNT_MAX`` (``is_whole``)."""
    return is_whole(value, 0) and int(value) <= COUNT_MAX  # type: ignore[call-overload]


def check_whole(name: str, value: object, minimum: int) -> int:
    """``value`` as an int when it is a whole number >= ``minimum`` (``is_whole``), else a
    one-line ``ProblemInputError`` naming ``name``."""
    if not is_whole(value, minimum):
        rule = "a positive integer" if minimum == 1 else f"a whole number >= {minimum}"
        raise ProblemInputError(f"{name} must be {rule}, got {value!r}")
    return int(value)  # type: ignore[arg-type]


def printable_excerpt(text: str, limit: int = EXCERPT_CHARS) -> str:
    """``text`` fit to quote in a one-line message: every run of characters that are not
    printable ASCII (binary junk, control characters, line ends) one space, white space
    collapsed, at most ``limit`` characters (cut with "...")."""
    plain = " ".join(_NOT_PRINTABLE.sub(" ", text).split())
    return plain if len(plain) <= limit else plain[: max(limit - 3, 0)].rstrip() + "..."


def check_hurst(hurst: object) -> float:
    """``hurst`` as a float when it is a real number in (0, 1) (not a bool, not text), else
    a one-line ``ProblemInputError``."""
    if isinstance(hurst, (bool, np.bool_)) or not isinstance(hurst, (int, float, np.integer, np.floating)) \
            or not 0.0 < float(hurst) < 1.0:
        raise ProblemInputError(f"Hurst exponent must lie in (0, 1), got {hurst!r}")
    return float(hurst)
