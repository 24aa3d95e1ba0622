"""Reading what a solver answers (not a solver module: the registry skips "_" names): the
error a contract breach raises (``SolverReturnError``), the readers of the hooks' answers
(``HOOK_READERS``) and the rules of the solve's own account -- its iteration and product
counts and its times (``account_problems``), which the lifecycle (solvers/base.py) and the
harness's worker (a solver that overrides ``solve``) both apply, so that every number a
row takes from a solver is one the results table can hold.  Imported from solvers/base.py
as well.
"""

from __future__ import annotations

import functools
import math
import numbers
import reprlib
from typing import Any, Callable

import numpy as np

from contactbench.problems.errors import COUNT_MAX, is_count

from ._loading import one_line


class SolverReturnError(TypeError):
    """A solver's method answered what its contract does not allow (``read_availability``,
    ``read_reason``, ``read_max_iter``, ``read_outcome``, ``account_problems``): one line
    naming the solver, the method and the answer.  Raised where the answer is read, it
    fails that solver's rows."""


def read_availability(name: str, method: str, answer: Any) -> tuple[bool, str]:
    """``availability()``'s ``answer`` as (available, reason on one line) if it is a pair
    of a bool and a str, else ``SolverReturnError``."""
    if (isinstance(answer, tuple) and len(answer) == 2 and isinstance(answer[0], (bool, np.bool_))
            and isinstance(answer[1], str)):
        return bool(answer[0]), one_line(answer[1])
    raise SolverReturnError(f"solver {name!r}: {method}() returned {reprlib.repr(answer)}, not a pair "
                            "(available, reason) of a bool and a str")


def read_reason(name: str, method: str, answer: Any) -> str | None:
    """A reason not to run as ``skip`` or ``skip_params`` answers it: a str, on one line; None
    (run it) for None, False or a blank str; anything else is ``SolverReturnError``."""
    if isinstance(answer, str):
        return one_line(answer) or None
    if answer is None or (isinstance(answer, (bool, np.bool_)) and not answer):
        return None
    raise SolverReturnError(f"solver {name!r}: {method}() returned {reprlib.repr(answer)}, not a reason "
                            "(a str) or None")


def read_max_iter(name: str, n: int, answer: Any) -> int | None:
    """``default_max_iter(n)``'s ``answer`` if it is None or an integer >= 0, the rule of
    ``SolverSettings.max_iter``; else ``SolverReturnError``."""
    if answer is None:
        return None
    if isinstance(answer, (bool, np.bool_)) or not isinstance(answer, (int, np.integer)) or answer < 0:
        raise SolverReturnError(f"solver {name!r}: default_max_iter({n}) returned {reprlib.repr(answer)}, not an "
                                "integer >= 0 or None")
    return int(answer)


def is_real(value: Any) -> bool:
    """A real number: not a bool, not a complex, not text."""
    return isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_))


#: What a count of the solve's account is, in words.
COUNT_RULE = f"an integer from 0 to {COUNT_MAX}"


def is_plain_count(value: Any) -> bool:
    """An integer (not a bool, not a float however whole, not a subclass of int whose
    conversion may say another number) from 0 to ``COUNT_MAX``: a table's int64."""
    return (type(value) is int or isinstance(value, np.integer)) and is_count(value)


def is_seconds(value: Any, most: float = math.inf) -> bool:
    """A real number of seconds, finite, from 0 to ``most`` (NaN, a negative or infinite
    time, and an int too large for a float are not)."""
    if not is_real(value):
        return False
    try:
        x = float(value)
    except OverflowError:
        return False
    return math.isfinite(x) and 0.0 <= x <= most


def account_problems(iterations: Any, matvecs: Any, setup_time: Any, solve_time: Any,
                     unreported: bool = False) -> list[str]:
    """What is wrong with a solve's own account (none: []): its iterations and matvecs each
    an integer from 0 to ``COUNT_MAX``, its solve_time finite seconds >= 0 and its
    setup_time finite seconds from 0 to solve_time (the part of it before the first
    iteration).  With ``unreported`` a time may be NaN, not reported (a ``SolveResult``'s
    default, which a table reads as missing): the harness's reading of a result; the
    lifecycle, which measures both times, allows none."""
    def seconds(value: Any, most: float = math.inf) -> bool:
        return is_seconds(value, most) or (unreported and isinstance(value, (float, np.floating)) and math.isnan(value))

    timed = is_seconds(solve_time)
    checks = (
        ("iterations", iterations, is_plain_count(iterations), COUNT_RULE),
        ("matvecs", matvecs, is_plain_count(matvecs), COUNT_RULE),
        ("solve_time", solve_time, seconds(solve_time), "a finite number of seconds >= 0"),
        ("setup_time", setup_time, seconds(setup_time, float(solve_time) if timed else math.inf),
         "a finite number of seconds from 0 to the solve_time"),
    )
    return [f"{name} is {reprlib.repr(value)}, not {rule}" for name, value, ok, rule in checks if not ok]


#: The methods a subclass may define whose every answer is read by the reader beside it,
#: whoever asks (``Solver.__init_subclass__``).
HOOK_READERS: dict[str, Callable[[str, str, Any], Any]] = {
    "availability": read_availability, "skip": read_reason, "skip_params": read_reason}


def read_through(attr: str, method: Callable[..., Any], read: Callable[[str, str, Any], Any]) -> Callable[..., Any]:
    """``method`` (the solver's ``attr``), its answer read by ``read`` (a ``SolverReturnError``
    if it is not one)."""

    @functools.wraps(method)
    def hook(self: Any, *args: Any, **kwargs: Any) -> Any:
        return read(self.name, attr, method(self, *args, **kwargs))

    return hook
