"""A solver spec as text (``registry`` module doc): ``name``, ``module:NAME``,
``name[k=v,...]`` and ``name[grid,...]``, split into their parts and their values read as
the declared ``Param``'s kind; and whether a name, key or value written in a spec reads
back as itself.  Text only: nothing here loads a solver."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from contactbench.problems.units import plain_float

from ._params import Param, ParamError, wrong_kind


def value_label(value: Any) -> str:
    """A parameter's value as a variant's label writes it (``SolverSpec.label``)."""
    return f"{value}"


def reads_back_as_key(name: str) -> bool:
    """Whether a parameter called ``name``, written as the key of a spec's brackets
    ``x[name=1]``, reads back as that key (``split_solver_spec``)."""
    try:
        return split_solver_spec(f"x[{name}=1]").raw == {name: "1"}
    except SolverSpecError:
        return False


def reads_back(param: Param, value: Any) -> bool:
    """Whether ``value`` (as ``param.check`` reads it), written in a label
    ``x[key=text]`` (``value_label``), reads back as itself: the brackets give the same
    text (``split_solver_spec``) and the text reads as ``param``'s kind to an equal value
    (``param_from_text``)."""
    text = value_label(value)
    try:
        return split_solver_spec(f"x[k={text}]").raw == {"k": text} and param_from_text(param, text) == value
    except (SolverSpecError, ParamError):
        return False


def is_import_path(name: str) -> bool:
    """Whether a solver's name (a spec's part before any ``[...]``) is an import path
    ``module:NAME`` -- user code the harness imports -- rather than a registry name."""
    return ":" in name


class SolverSpecError(ValueError):
    """A malformed solver spec or an unusable parameter in it (one line)."""


#: The item of a spec's brackets that asks for every point of the solver's declared
#: grid: ``name[grid]``, ``name[grid,key=value]`` (``expand_solver_spec``).
GRID_WORD = "grid"
#: The most variants one ``name[grid]`` entry may stand for (the product of its grid's
#: value counts, fixed keys left out); beyond it the entry is refused.
MAX_GRID_VARIANTS = 100


@dataclass(frozen=True)
class SolverSpec:
    """A solver named on the command line: ``name`` (registry name or ``module:NAME``)
    and the parameters fixed for it (checked values, as the user gave the keys)."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """The table's name of the variant: ``name[k=v,...]`` with the keys sorted (the
        scheme of the study sweeps' ``{solver}[{param}={value}]``), or ``name``."""
        if not self.params:
            return self.name
        return f"{self.name}[{','.join(f'{k}={value_label(v)}' for k, v in sorted(self.params.items()))}]"


def split_solver_list(text: str) -> list[str]:
    """The specs of a comma list, e.g. ``"a,b[k=1,j=2],c"`` -> ``["a", "b[k=1,j=2]", "c"]``;
    empty entries are dropped; an unbalanced bracket is a ``SolverSpecError``."""
    parts: list[str] = []
    depth, start = 0, 0
    for i, c in enumerate(text):
        if c == "[":
            depth += 1
        elif c == "]":
            depth -= 1
            if depth < 0:
                raise SolverSpecError(f"unbalanced ']' in solver list {text!r}")
        elif c == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    if depth:
        raise SolverSpecError(f"unclosed '[' in solver list {text!r}")
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


@dataclass(frozen=True)
class SpecText:
    """One spec as written (``split_solver_spec``): the solver's ``name``, the parameters'
    texts by key (``raw``) and whether its brackets ask for the solver's grid (``grid``)."""

    name: str
    raw: dict[str, str] = field(default_factory=dict)
    grid: bool = False


def split_solver_spec(text: str) -> SpecText:
    """``"name[k=v,k2=v2]"`` -> ``SpecText("name", {"k": "v", "k2": "v2"})`` (values as
    text); the item ``GRID_WORD`` among the brackets (``"name[grid,k=v]"``) sets ``grid``."""
    text = text.strip()
    if "[" not in text:
        if "]" in text:
            raise SolverSpecError(f"unbalanced ']' in solver {text!r}")
        return SpecText(text)
    name, _, rest = text.partition("[")
    if rest.strip() == "]":
        raise SolverSpecError(f"empty parameter list in solver {text!r}: write name[key=value] or just name")
    if not rest.endswith("]") or "[" in rest[:-1] or "]" in rest[:-1]:
        raise SolverSpecError(f"bad solver spec {text!r}: write name[key=value,key2=value2]")
    raw: dict[str, str] = {}
    grid = False
    for item in rest[:-1].split(","):
        if item.strip() == GRID_WORD:
            if grid:
                raise SolverSpecError(f"{GRID_WORD!r} given twice in solver {text!r}")
            grid = True
            continue
        key, eq, value = (s.strip() for s in item.partition("="))
        if not eq or not key or not value:
            raise SolverSpecError(f"bad parameter {item.strip()!r} in solver {text!r}: write key=value "
                                  f"(or {GRID_WORD}: every point of the solver's grid)")
        if key in raw:
            raise SolverSpecError(f"parameter {key!r} given twice in solver {text!r}")
        raw[key] = value
    if not name.strip() or not (raw or grid):
        raise SolverSpecError(f"bad solver spec {text!r}: write name[key=value,key2=value2]")
    return SpecText(name.strip(), raw, grid)


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def param_from_text(param: Param, text: str) -> Any:
    """``text`` read as ``param``'s type (bool: true/false, yes/no, on/off, 1/0; a number
    written plainly, ``problems.units.plain_float``: "1_0" is none), then checked by
    ``Param.check``; a ``ParamError`` names the parameter."""
    bad = wrong_kind(param.name, param.kind, text)
    value: Any = text
    if param.kind is bool:
        if text.lower() not in _TRUE + _FALSE:
            raise bad
        value = text.lower() in _TRUE
    elif param.kind is int:
        try:
            plain_float(text)
            value = int(text)
        except ValueError:
            raise bad from None
    elif param.kind is float:
        try:
            value = plain_float(text)
        except ValueError:
            raise bad from None
        if not math.isfinite(value):
            raise bad
    return param.check(value)


#: What a key or value written in a spec's brackets ``name[key=value]`` is, to read back.
WRITTEN_RULE = ("a key or value written in name[key=value] is not empty, holds no ',', '[' or ']', has no space "
                "at either end, and a value reads as its parameter's kind")
