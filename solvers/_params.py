"""The error of a solver parameter and the words for its kind (not a solver module: the
registry skips "_" names): the one line that says a parameter is given a value of the
wrong kind, which ``Param.check`` (solvers/base.py: a value given through the API or
``--params``) and ``param_from_text`` (solvers/registry.py: a value written in
``NAME[k=v]``) both raise.  ``ParamError`` is imported from solvers/base.py as well.
"""

from __future__ import annotations

from typing import Any


class ParamError(ValueError):
    """An unknown, ill-typed or out-of-range solver parameter."""


#: What a parameter of each declarable kind takes, in words.
KIND_WORDS: dict[type, str] = {bool: "true or false", int: "a whole number", float: "a number", str: "text",
                               tuple: "a tuple", dict: "a dict"}


def kind_word(kind: type) -> str:
    """What a parameter of ``kind`` takes, in words (``KIND_WORDS``; another kind, which
    the registry's declaration check refuses, is named by its class)."""
    return KIND_WORDS.get(kind, f"a value of kind {getattr(kind, '__name__', repr(kind))}")


def wrong_kind(name: str, kind: type, got: Any) -> ParamError:
    """The ``ParamError`` of parameter ``name``, of ``kind``, given ``got`` (one line)."""
    return ParamError(f"parameter {name!r} takes {kind_word(kind)}, got {got!r}")
