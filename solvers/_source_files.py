"""The source files a solver from outside this package is made of: the file that defines
its class and the files of the modules it imports from its own source tree, read without
importing anything (``registry.source_digest`` hashes them so that a results folder pins
them).

The source tree is the folder that holds the class's top-level package or module.  A
module counts when an ``import`` statement anywhere in a counted file (a function's body
too; a relative import against the file's package) names it and it is found in that
folder: its file and the ``__init__.py`` of each package on its way.  Modules found
elsewhere -- the standard library, installed packages, this package -- are not read: the
interpreter's and the environment's versions stand for them.  A module imported by a name
computed at run time (``importlib.import_module(name)``) is not seen."""

from __future__ import annotations

import ast
import inspect
import sys
from dataclasses import dataclass
from importlib.machinery import PathFinder
from pathlib import Path

__all__ = ["PROJECT_PACKAGE", "SourceFile", "class_source_files"]

#: The top-level name of this package, whose modules a solver's source never counts.
PROJECT_PACKAGE = "contactbench"


@dataclass(frozen=True)
class SourceFile:
    """One file of a solver's source: its path relative to the source tree, and its bytes."""

    relative: str
    data: bytes


def class_source_files(cls: type) -> list[SourceFile] | None:
    """The source files of ``cls`` (module doc), sorted by relative path; None when the
    file that defines it cannot be read (a class made at an interactive prompt)."""
    try:
        path = inspect.getsourcefile(cls)
    except TypeError:
        return None
    if not path:
        return None
    origin = Path(path).resolve()
    if not origin.is_file():
        return None
    root = source_tree(origin, cls.__module__).resolve()
    found: dict[Path, str] = {}
    pending = [(origin, cls.__module__)]
    while pending:
        file, name = pending.pop()
        if file in found:
            continue
        found[file] = name
        if file.suffix == ".py":
            pending.extend((f, n) for n, f in imported_modules(file, name, root) if f not in found)
    return sorted((SourceFile(file.relative_to(root).as_posix(), readable_bytes(file)) for file in found),
                  key=lambda f: f.relative)


def readable_bytes(file: Path) -> bytes:
    """The bytes of ``file``; none when it cannot be read (removed since it was found)."""
    try:
        return file.read_bytes()
    except OSError:
        return b""


def source_tree(origin: Path, module: str) -> Path:
    """The folder holding the top-level package or module of ``module`` (defined in
    ``origin``); the file's own folder for a script (``__main__``)."""
    depth = module.count(".") + (1 if origin.name == "__init__.py" else 0)
    if module == "__main__" or depth >= len(origin.parents):
        return origin.parent
    return origin.parents[depth]


def imported_modules(file: Path, name: str, root: Path) -> list[tuple[str, Path]]:
    """(module name, file) of each module ``file`` (module ``name``) imports that is found
    in ``root``, with the packages on its way; what cannot be parsed imports nothing."""
    try:
        tree = ast.parse(file.read_bytes(), filename=str(file))
    except (OSError, SyntaxError, ValueError):
        return []
    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    out: list[tuple[str, Path]] = []
    for wanted in imported_names(tree, package):
        out.extend(module_chain(wanted, root))
    return out


def imported_names(tree: ast.AST, package: str) -> list[str]:
    """The absolute names an AST's import statements may load: each ``import a.b``, and
    for ``from m import x`` both ``m`` and ``m.x`` (``x`` may be a submodule), relative
    ``m`` resolved against ``package``."""
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = absolute_from(node.module, node.level, package)
            if base is None:
                continue
            names.extend([base] if base else [])
            names.extend(f"{base}.{alias.name}" if base else alias.name for alias in node.names if alias.name != "*")
    return names


def absolute_from(module: str | None, level: int, package: str) -> str | None:
    """The absolute name of ``from <level dots><module> import ...`` in ``package``; ""
    for the top of a relative import that leaves no name; None when it climbs above the
    top-level package."""
    if level == 0:
        return module or ""
    parts = package.split(".") if package else []
    if level - 1 > len(parts):
        return None
    head = parts[: len(parts) - (level - 1)]
    return ".".join([*head, module] if module else head)


def module_chain(name: str, root: Path) -> list[tuple[str, Path]]:
    """The files of module ``name`` and of the packages on its way, found in ``root`` only
    (nothing is imported; a name of this package or one not found there gives none)."""
    if not name or name.split(".")[0] == PROJECT_PACKAGE:
        return []
    chain: list[tuple[str, Path]] = []
    search = [str(root)]
    parts = name.split(".")
    for i, part in enumerate(parts):
        spec = PathFinder.find_spec(part, search)
        if spec is None:
            break
        if spec.has_location and spec.origin:  # (a namespace package has no file of its own)
            file = Path(spec.origin).absolute()  # (as found in the tree: a link's target is read through it)
            if not file.is_relative_to(root) or installed(file):
                break
            chain.append((".".join(parts[: i + 1]), file))
        search = list(spec.submodule_search_locations or [])
        if not search:
            break
    return chain


def installed(file: Path) -> bool:
    """Whether ``file`` belongs to the interpreter or an environment's installed packages."""
    prefixes = {Path(p).resolve() for p in (sys.prefix, sys.base_prefix, sys.exec_prefix)}
    return any(file.is_relative_to(p) for p in prefixes) or "site-packages" in file.parts
