"""Text from the table set in Markdown: a name is text, never markup (report.md is read
by renderers that keep raw HTML)."""

from __future__ import annotations

import re
from typing import Any

__all__ = ["md_code", "md_escape"]


def md_code(text: Any) -> str:
    """``text`` (a name from the table) as one Markdown code span: fenced by more backticks
    than its longest run, so that a backtick in it cannot end the span and let the rest
    be read as markup; a newline as a space."""
    t = str(text).replace("\n", " ")
    fence = "`" * (max((len(r) for r in re.findall("`+", t)), default=0) + 1)
    pad = " " if t.startswith("`") or t.endswith("`") else ""
    return f"{fence}{pad}{t}{pad}{fence}"


#: A "<" that would open an HTML tag, comment or declaration in Markdown.
_TAG_OPEN = re.compile(r"<(?=[A-Za-z/!?])")


def md_escape(text: Any) -> str:
    """``text`` as a Markdown table cell: "|" escaped, a newline a space, and a "<" that
    would open an HTML tag written "&lt;" (a solver or scene name is text, never markup;
    "n <= 10" stays as it is)."""
    return _TAG_OPEN.sub("&lt;", str(text).replace("|", "\\|").replace("\n", " "))
