"""Loading a solver named by import path ``module:NAME`` (not a solver module: the registry
skips "_" names): the user's code, which the harness imports in its own process (``run``)
or in a child (``validate``).

Whatever that code raises while its module is imported, ``NAME`` is read from it or the
solver is built (``user_code``) is the module's failure, never the end of the harness's
process: a ``SystemExit``, a ``GeneratorExit``, a ``KeyboardInterrupt`` that no Ctrl-C
raised, or any other ``BaseException`` comes out as an ``ImportAborted`` naming the module
and what it raised.  A ``KeyboardInterrupt`` raised by a SIGINT or SIGTERM that arrived
while the code ran is the user's and passes as it is.  (A module that ends the process
itself, ``os._exit``, or crashes it, a segfault, cannot be caught here.)

``load_failure`` is the one line a command prints for a solver named by import path
that does not load: the module not found (or one it imports), ``NAME`` missing, a file
path where a module name goes, a declaration the registry refuses, or whatever else was
raised -- ``SolverLoadError``, a bad-input error (``ProblemInputError``).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from contactbench.problems.errors import ProblemInputError
from contactbench.stops import raise_noted, signals_noted


class SolverLoadError(ProblemInputError):
    """A solver named by import path that cannot be loaded (``load_failure``; one line)."""


class ImportAborted(Exception):
    """A user module raised something other than an ``Exception`` (``SystemExit``, its own
    ``KeyboardInterrupt``, a ``BaseException`` subclass) while it was imported or its solver
    was built (``user_code``); the original is its ``__cause__``."""




def one_line(text: str) -> str:
    """``text`` on one line: its non-blank lines, stripped, joined by " / "."""
    return " / ".join(line.strip() for line in text.splitlines() if line.strip())


def exception_message(exc: BaseException) -> str:
    """``str(exc)``, or a note naming its type where its ``__str__`` raises (a solver's
    own exception class): reading a solver's error never fails."""
    try:
        return str(exc)
    except KeyboardInterrupt:  # (the user's: stops as anywhere)
        raise
    except BaseException:  # (a __str__ that raises anything else, SystemExit included)
        return f"<the message of {type(exc).__name__} cannot be read: its __str__ raised>"


def exception_text(exc: BaseException) -> str:
    """``Type: message`` of ``exc`` (``exception_message``), the type alone when the
    message is empty."""
    text = exception_message(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def availability_failure(exc: BaseException) -> str:
    """The words for a solver whose ``availability()`` raised ``exc`` (the registry's load
    check and the harness's skip policy, listing and ``validate`` say it alike)."""
    return f"its availability() failed: {exception_text(exc)}"


def exception_line(exc: BaseException) -> str:
    """``exception_text`` of ``exc`` on one line (``one_line``)."""
    return one_line(exception_text(exc))


@contextmanager
def user_code(spec: str, doing: str) -> Iterator[None]:
    """Run the block, user code of the solver ``spec`` (``doing``: what it does, e.g.
    "importing module 'm'"): an ``Exception`` it raises passes as it is; anything else
    is raised as an ``ImportAborted`` (module doc), except a ``KeyboardInterrupt`` while a
    ``USER_STOP_SIGNALS`` signal arrived, the user's, which passes; and a user's stop the
    block swallowed is raised after it (``stops.raise_noted``)."""
    with signals_noted() as arrived:
        try:
            yield
        except Exception:
            raise
        except BaseException as exc:
            if isinstance(exc, KeyboardInterrupt) and arrived:
                raise
            raise ImportAborted(f"{doing} raised {exception_line(exc)}") from exc
    raise_noted(arrived)


def file_path_hint(module: str, attr: str) -> str:
    """How to name a solver whose module part is empty (``:NAME``), a file path (``x.py``,
    ``./x``, ``/abs/dir/x.py``) or a relative module name (``.x``), or whose ``NAME`` is
    empty (``module:``), by its import path instead; "" when ``module:attr`` names a
    module and a name in it."""
    if not module.strip() or not attr.strip():
        part = "module name before" if not module.strip() else "NAME after"
        return (f"the {part} ':' is empty; name a solver by import path as module:NAME (e.g. my_solver:MySolver, "
                "run from the folder that holds my_solver.py)")
    if not (module.endswith(".py") or "/" in module or os.sep in module or module.startswith(".")):
        return ""
    path = Path(module)
    if "/" not in module and os.sep not in module and not module.endswith(".py"):
        return f"{module!r} is a relative module name; give the module's full name, package.module:{attr}"
    stem = path.name[:-3] if path.name.endswith(".py") else path.name
    there = "" if path.is_file() or path.with_name(stem + ".py").is_file() else " (there is no such file)"
    return (f"{module!r} is a file path, not a module name{there}; name it {stem}:{attr} and run from "
            f"{path.parent.resolve()} (or put that folder on PYTHONPATH)")


def load_failure(spec: str, exc: BaseException, module: Any = None) -> SolverLoadError:
    """The one-line error of the solver ``spec`` (``module:NAME``) that did not load,
    having raised ``exc``; ``module`` is the module imported, where it was.  A module not
    found names the folder to run from, a module it imports that is not installed is named,
    a missing ``NAME`` is said so; anything else is ``cannot load solver 'spec': Type:
    message`` (a declaration the registry refuses is the registry's to word)."""
    mod_name, attr = spec.split(":", 1)
    if isinstance(exc, ModuleNotFoundError):
        missing = exc.name or ""
        if missing and mod_name != missing and not mod_name.startswith(missing + "."):  # not the module: its import
            return SolverLoadError(f"cannot load solver {spec!r}: module {mod_name!r} imports {missing!r}, which is "
                                   "not installed here")
        return SolverLoadError(f"cannot import {mod_name!r} for solver {spec!r}: {one_line(str(exc))}; run from the "
                               "folder that holds it or put that folder on PYTHONPATH")
    if isinstance(exc, AttributeError) and module is not None and not any(k in vars(module)
                                                                          for k in (attr, "__getattr__")):
        return SolverLoadError(f"module {mod_name!r} has no attribute {attr!r} (solver {spec!r})")
    if isinstance(exc, ImportAborted):  # (it names what it was doing and what was raised)
        return SolverLoadError(f"cannot load solver {spec!r}: {one_line(str(exc))}")
    return SolverLoadError(f"cannot load solver {spec!r}: {exception_line(exc)}")
