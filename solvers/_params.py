"""A declared solver parameter (``Param``), its error and the words for its kind (not a
solver module: the registry skips "_" names): the one line that says a parameter is given
a value of the wrong kind, which ``Param.check`` (a value given through the API or
``--params``) and ``param_from_text`` (solvers/registry.py: a value written in
``NAME[k=v]``) both raise.  ``Param`` and ``ParamError`` are imported from
solvers/base.py as well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


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


@dataclass(frozen=True)
class Param:
    """One declared solver parameter: name, type, default, and its allowed values
    (``choices``) or range from ``low`` to ``high``, each end included unless it is
    ``open`` there ("low", "high" or "both": ADMM's penalty is > 0, not >= 0)."""

    name: str
    kind: type
    default: Any
    doc: str = ""
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] | None = None
    open: str = ""  # "", "low", "high" or "both": the ends the range leaves out

    def check(self, value: Any) -> Any:
        """``value`` converted to ``kind`` if it is acceptable, else ``ParamError``."""
        v = self._coerce(value)
        if self.choices is not None and v not in self.choices:
            raise ParamError(f"parameter {self.name!r} must be one of {', '.join(map(repr, self.choices))}, "
                             f"got {value!r}")
        if not self.in_range(v):
            raise ParamError(f"parameter {self.name!r} must lie in {self.range_text()}, got {value!r}")
        return v

    def in_range(self, v: Any) -> bool:
        """Whether ``v`` lies in the declared range (its open ends left out)."""
        low_out = self.open in ("low", "both")
        high_out = self.open in ("high", "both")
        if self.low is not None and (v < self.low or low_out and v == self.low):
            return False
        return not (self.high is not None and (v > self.high or high_out and v == self.high))

    def range_text(self) -> str:
        """The range as an interval: "[1, inf)", "(0, 2)"."""
        left = "(" if self.low is None or self.open in ("low", "both") else "["
        right = ")" if self.high is None or self.open in ("high", "both") else "]"
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"{left}{lo}, {hi}{right}"

    def _coerce(self, value: Any) -> Any:
        bad = wrong_kind(self.name, self.kind, value)
        if self.kind is bool:
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            raise bad
        if self.kind is int:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise bad
            return int(value)
        if self.kind is float:
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise bad
            if not math.isfinite(float(value)):
                raise bad
            return float(value)
        if not isinstance(value, self.kind):
            raise bad
        return value

    def describe(self) -> str:
        allowed = (f" one of {'|'.join(map(str, self.choices))}" if self.choices is not None else
                   f" in {self.range_text()}" if self.low is not None or self.high is not None else "")
        return f"{self.name}: {self.kind.__name__} = {self.default!r}{allowed}" + (f"  ({self.doc})" if self.doc else "")
