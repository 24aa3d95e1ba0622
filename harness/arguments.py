"""The command lines' shared rules (``contactbench`` in harness/cli.py and ``contactbench
validate`` in harness/conformance/command.py): the exit status of bad input, the parser
whose usage error is one line, the number types, the items of a comma list, and the check of an
output folder.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from pathlib import Path
from typing import Any, Callable, NoReturn, Sequence

from contactbench.plugins import did_you_mean
from contactbench.problems.atomic_files import not_utf8_text
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.units import plain_float, plain_int

#: Exit status of bad input: refused before anything runs, in one line (its problems joined by "; ").
EXIT_BAD_INPUT = 2
#: A number, negative ones and exponents included: the value of an option, never an
#: option itself (argparse's own pattern misses ``-1e-6``).
NUMBER = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$")


class InputError(ProblemInputError):
    """Bad command-line input found by the command line itself (one line)."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """``--help`` with each option's default, where it has one (None and False defaults
    are "the scene's" / "off" and say so in their own help)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or action.default is False or action.default == argparse.SUPPRESS \
                or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """argparse with the house rules: a usage error is one line on stderr (exit 2), an
    unknown choice names the closest ones, and a negative number (``-1e-6``) is an
    option's value, so ``--length -1e-6`` is refused as not > 0."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NUMBER

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:
        """argparse's, once no option that takes one value is given twice (``given_twice``:
        argparse would keep the last silently, and ``--size 8 --size 16`` runs 16)."""
        tokens = list(sys.argv[1:] if args is None else args)
        twice = given_twice(self, tokens)
        if twice:
            self.error(f"{twice} given twice; give it once")
        return super().parse_known_args(tokens, namespace)

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        if action.choices is not None and value not in action.choices:
            choices = [str(c) for c in action.choices]
            raise argparse.ArgumentError(action, f"invalid choice {value!r}{did_you_mean(str(value), choices)}; "
                                                 f"choose from {', '.join(choices)}")


#: The argparse actions an option may be given more than once for (each use adds).
REPEATABLE_ACTIONS: tuple[type, ...] = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction,
                                        argparse._HelpAction, argparse._VersionAction)


def given_twice(parser: argparse.ArgumentParser, tokens: Sequence[str]) -> str | None:
    """The first option of ``parser`` in ``tokens`` (the command line, up to a bare
    ``--``) that is given a second time -- by the same spelling or another of the same
    option, ``--opt value`` or ``--opt=value``, or a prefix argparse takes for it
    (``option_action``) -- and that is not ``REPEATABLE_ACTIONS``;
    None when there is none.  Tokens that are not this parser's own options (a
    subcommand's, a value) are left to argparse."""
    seen: dict[int, str] = {}
    for token in tokens:
        if token == "--":
            break
        option = token.split("=", 1)[0]
        action = option_action(parser, option) if option.startswith("-") else None
        if action is None or isinstance(action, REPEATABLE_ACTIONS):
            continue
        if id(action) in seen:
            first = seen[id(action)]
            return option if first == option else f"{option} (as {first})"
        seen[id(action)] = option
    return None


def option_action(parser: argparse.ArgumentParser, option: str) -> argparse.Action | None:
    """The action of ``parser`` that argparse gives ``option``: its own spelling, or a
    long option's unambiguous prefix (``--siz`` for ``--size``) where the parser allows
    abbreviations; None for anything else (an ambiguous prefix is argparse's error)."""
    actions = parser._option_string_actions
    if option in actions:
        return actions[option]
    if not (parser.allow_abbrev and option.startswith("--")):
        return None
    found = {id(a): a for name, a in actions.items() if name.startswith(option)}
    return next(iter(found.values())) if len(found) == 1 else None


def plain_number(text: str, kind: type) -> Any:
    """``kind(text)`` for a number written plainly (``problems.units.plain_float``:
    ASCII digits, no underscores -- Python's ``float`` and ``int`` take "1_0" and other
    scripts' digits; a whole number: ``problems.units.plain_int``); a ``ValueError`` otherwise."""
    if kind is int:
        return plain_int(text)
    plain_float(text)
    return kind(text)


def positive_number(text: str, kind: type, what: str) -> Any:
    """``text`` as a finite number of ``kind`` that is > 0, written plainly
    (``plain_number``), else an argparse error naming it."""
    try:
        v = plain_number(text, kind)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not {what}: {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def positive_float(text: str) -> float:
    return float(positive_number(text, float, "a number"))


#: The longest time limit of one solve, seconds (``run --timeout`` and
#: ``--reference-timeout``, ``RunConfig``, ``validate --timeout``): a week; beyond it a
#: value is a slip (a unit, an exponent), not a limit.
MAX_TIMEOUT_S = 7 * 24 * 3600.0


def check_time_limit(seconds: float, what: str, flag: str = "") -> float:
    """``seconds`` if it is a finite number of seconds in (0, ``MAX_TIMEOUT_S``], else a
    ``ValueError`` naming the setting ``what`` (and its command-line ``flag``)."""
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
            or not (math.isfinite(seconds) and 0 < seconds <= MAX_TIMEOUT_S):
        raise ValueError(f"{what} must be a finite number of seconds > 0 and at most {MAX_TIMEOUT_S:g} (a week), "
                         f"got {seconds!r}" + (f" ({flag})" if flag else ""))
    return float(seconds)


def time_limit(text: str) -> float:
    """An option's time limit, seconds: a finite number > 0 and at most ``MAX_TIMEOUT_S``,
    else an argparse error naming it."""
    seconds = positive_float(text)
    if seconds > MAX_TIMEOUT_S:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 and at most {MAX_TIMEOUT_S:g} s (a week), "
                                         f"got {text}")
    return seconds


def comma_items(text: str, split: Callable[[str], list[str]] | None = None, repeats: bool = False) -> list[str]:
    """The items of the comma list ``text``, stripped, in order; [] when it names none
    ("", ",", " , ": each option says what that means).  An empty item ("a,,b", "a,") is
    an ``argparse.ArgumentTypeError`` naming the list, and so is an item given twice,
    unless ``repeats`` (a list whose positions mean something, e.g. L0,L1).  ``split``
    splits a list whose items hold commas of their own (``--solvers`` name[k=v,...]);
    the empty items it drops are found in the text.  Default: at every comma."""
    bare = "".join(text.split())
    if not bare.strip(","):
        return []
    if ",," in bare or bare.startswith(",") or bare.endswith(","):
        raise argparse.ArgumentTypeError(f"empty item in {text!r}")
    items = split(text) if split is not None else [item.strip() for item in text.split(",")]
    seen: set[str] = set()
    for item in items:
        if item in seen and not repeats:
            raise argparse.ArgumentTypeError(f"{item!r} twice in {text!r}")
        seen.add(item)
    return items


def check_out_dir(path: str, option: str = "--out") -> Path:
    """``path`` if it is, or can be made, a folder we may write: else one ``InputError``
    naming it (a name that is not UTF-8 text, which the table's writer cannot take; one
    holding a control character, which would break the lines that name it; an
    existing file, a path under a file, a path through a symbolic link that leads to
    nothing, where no folder can be made, a folder we may not write).  A ``path`` that is
    itself a link to a folder is that folder.  Creates nothing."""
    check_utf8_path(path, option)
    if any(ord(c) < 32 or ord(c) == 127 for c in path):  # (each line the command prints names it on one line)
        raise InputError(f"{option} {path!r}: the name holds a control character (a newline, a tab); choose another")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option} {path}: exists and is not a folder")
    probe = p
    while not probe.exists():
        if probe.is_symlink():
            raise InputError(f"{option} {path}: {probe} is a symbolic link to {os.readlink(probe)!r}, which leads "
                             f"to no file or folder; remove the link or choose another {option}")
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(f"{option} {path}: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(f"{option} {path}: cannot write in {probe} (permission denied)")
    return p


def check_utf8_path(path: str, option: str) -> None:
    """One ``InputError`` naming ``path`` (its undecodable bytes escaped) unless it is UTF-8
    text: a name the system gave as bytes that are not UTF-8 (``os.fsdecode``'s surrogate
    escapes) cannot be written into the table's files (``atomic_files.not_utf8_text``)."""
    shown = not_utf8_text(path)
    if shown is not None:
        raise InputError(f"{option} {shown}: the name is not UTF-8 text; choose a name in UTF-8")


def os_error_line(exc: OSError) -> str:
    """The one line of a path that cannot be read or written: the path, and what is
    wrong in our words where the system's are unclear (``FileExistsError``: something --
    a file, a link, a link to nothing -- is where a folder or file was to be made)."""
    where = f"{exc.filename}: " if exc.filename else ""
    if isinstance(exc, FileExistsError) and exc.filename:
        kind = "a symbolic link" if os.path.islink(exc.filename) else "a file" if os.path.isfile(exc.filename) \
            else "something"
        return f"{where}{kind} is in the way of what the command makes there; move it away"
    return f"{where}{exc.strerror or exc}"
