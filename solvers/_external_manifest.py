"""The manifest of external solvers (``contactbench.solvers.external``): reading it and checking it.

A manifest is a TOML file of ``[[solver]]`` tables (docs/external-solvers.md); nothing else
may stand at its top level.  Every entry is checked when the file is read, before anything
runs: a bad entry, or a file that cannot be read (missing, a folder, a dangling link, not
UTF-8 text, not TOML), is a ``ProblemInputError`` of one line naming the file, the entry and
the key.

A command template is split into words as a POSIX shell would (``shlex``; no shell runs
it).  In each word ``{problem}`` and ``{solution}`` (``PLACEHOLDERS``) are replaced by the
folders of one solve; a literal brace is written twice, ``{{`` or ``}}``, as in Python's
``str.format``.  Any other ``{...}``, and a lone brace, is refused.  The ``version``
command has no placeholders: it runs as written.
"""

from __future__ import annotations

import os
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from string import Formatter
from typing import Any, Mapping

from contactbench.problems.errors import ProblemInputError

from .base import Promise, check_promise

#: Environment variable naming manifest files (os.pathsep-separated).
MANIFEST_ENV = "CONTACTBENCH_EXTERNAL_SOLVERS"
#: The manifest read from the current directory when present.
LOCAL_MANIFEST = "contactbench-solvers.toml"
#: The array of tables a manifest declares its solvers in: its one top-level key.
SOLVER_TABLE = "solver"
INPUTS = ("dense", "kernel")
_KEYS = {"name", "command", "inputs", "warm_start", "version", "description", "exact", "promise", "load_control",
         "bounds"}
#: The manifest's true/false keys.
_FLAGS = ("warm_start", "exact", "load_control", "bounds")
#: The manifest's text keys that are optional.
_TEXTS = ("inputs", "version", "description")

#: What an external solver's name may be: it is a row's label, a ``--solvers`` entry (where
#: ',', '[' and ':' have meanings) and part of a folder's name (no '/').
SOLVER_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+-]*")
#: The most characters an external solver's name may have (it names rows, folders and files).
NAME_MAX_CHARS = 100
#: The placeholders of a command template, each replaced by a folder of the solve.
PLACEHOLDERS = ("problem", "solution")
#: How a command template writes a brace that is no placeholder.
BRACE_RULE = "a literal brace is written twice, {{ or }}"


@dataclass(frozen=True)
class ExternalSpec:
    """One manifest entry (``contactbench.solvers.external``'s module doc), checked when built."""

    name: str
    command: str
    inputs: str = "dense"
    warm_start: bool = False
    version: str | None = None
    description: str = ""
    exact: bool = False
    promise: Promise = "exact"
    load_control: bool = False  # it poses the load equality and may report its multiplier
    bounds: bool = False  # it honours the upper bounds
    workdir: str | None = None  # the folder the command runs in (None: the current one)
    source: str = ""  # the manifest it came from

    def __post_init__(self) -> None:
        where = f" ({self.source})" if self.source else ""
        if len(self.name) > NAME_MAX_CHARS:
            raise ProblemInputError(f"external solver name {self.name[:40]!r}...{where} has {len(self.name)} "
                                    f"characters; at most {NAME_MAX_CHARS}")
        if not SOLVER_NAME.fullmatch(self.name):
            raise ProblemInputError(f"external solver name {self.name!r}{where} must be letters, digits and "
                                    "'.', '_', '+', '-', starting with a letter or digit (it names rows, "
                                    "--solvers entries and folders)")
        who = f"external solver {self.name!r}{where}"
        if self.inputs not in INPUTS:
            raise ProblemInputError(f"{who}: inputs must be 'dense' or 'kernel', got {self.inputs!r}")
        if not split_command(self.command, who):
            raise ProblemInputError(f"{who}: empty command")
        used = template_placeholders(self.command, who)
        if any(field is not None for _, field in _fields(split_command(self.command, who)[0])):
            raise ProblemInputError(f"{who}: the command's first word names the program; it holds a placeholder "
                                    f"in {self.command!r}")
        if not set(PLACEHOLDERS) <= used:
            raise ProblemInputError(f"{who}: the command must contain {{problem}} and {{solution}}, "
                                    f"got {self.command!r}")
        if self.version is not None:
            if not isinstance(self.version, str):
                raise ProblemInputError(f"{who}: version must be a command (a string), got {self.version!r}")
            if not split_command(self.version, who, "version command"):
                raise ProblemInputError(f"{who}: version must be a command to run, got {self.version!r}")


def split_command(template: str, who: str = "external solver", what: str = "command") -> list[str]:
    """The template split into words as a POSIX shell would (no shell runs it); a
    ``ProblemInputError`` naming ``who`` (the solver, its manifest) and ``what`` when it
    cannot be split."""
    try:
        return shlex.split(str(template))
    except ValueError as exc:
        raise ProblemInputError(f"{who}: cannot parse {what} {template!r}: {exc}") from None


def _fields(word: str) -> list[tuple[str, str | None]]:
    """(literal text, placeholder name or None) pieces of one word of a command template
    (module doc); a ``ValueError`` naming what is no placeholder."""
    pieces: list[tuple[str, str | None]] = []
    try:
        parsed = list(Formatter().parse(word))
    except ValueError:
        raise ValueError(f"a lone brace in {word!r}") from None
    for literal, field, spec, conversion in parsed:
        if field is None:
            pieces.append((literal, None))
            continue
        if field not in PLACEHOLDERS or spec or conversion:
            written = field + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "")
            raise ValueError(f"unknown placeholder {{{written}}}")
        pieces.append((literal, field))
    return pieces


def template_placeholders(template: str, who: str) -> set[str]:
    """The placeholders a command template uses; a ``ProblemInputError`` of one line, naming
    ``who`` (the solver), the template and the known placeholders, for any other ``{...}``
    or a lone brace (module doc)."""
    used: set[str] = set()
    for word in shlex.split(template):
        try:
            used |= {field for _, field in _fields(word) if field is not None}
        except ValueError as exc:
            known = ", ".join(f"{{{p}}}" for p in PLACEHOLDERS)
            raise ProblemInputError(f"{who}: {exc} in the command {template!r}; the placeholders are {known} "
                                    f"({BRACE_RULE})") from None
    return used


def filled_words(template: str, values: Mapping[str, str]) -> list[str]:
    """The words of a checked command template (``ExternalSpec``), each placeholder replaced
    by its value in ``values`` and each doubled brace by one."""
    return ["".join(literal + (values[field] if field is not None else "") for literal, field in _fields(word))
            for word in shlex.split(template)]


# ---------------------------------------------------------------------------
# Reading a manifest
# ---------------------------------------------------------------------------


def _load_toml(path: Path) -> dict[str, Any]:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ModuleNotFoundError:
            raise ProblemInputError(f"reading {path} needs Python >= 3.11 (tomllib) or the tomli package") from None
    what = f"external solver manifest {path}"
    if path.is_symlink() and not path.exists():
        raise ProblemInputError(f"{what} is a link to {os.readlink(path)}, which does not exist")
    if path.is_dir():
        raise ProblemInputError(f"{what} is a folder, not a file")
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ProblemInputError(f"{what} does not exist") from None
    except UnicodeDecodeError as exc:
        raise ProblemInputError(f"{what} is not UTF-8 text: {exc}") from None
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ProblemInputError(f"{what} is unreadable: {exc}") from None


def _spec_of(entry: Any, path: Path, k: int) -> ExternalSpec:
    where = f"{path} entry {k + 1}"
    if not isinstance(entry, dict):
        raise ProblemInputError(f"{where}: each [[solver]] must be a table")
    unknown = sorted(set(entry) - _KEYS)
    if unknown:
        raise ProblemInputError(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(_KEYS))}")
    for key in ("name", "command"):
        if not isinstance(entry.get(key), str):
            raise ProblemInputError(f"{where}: {key!r} is required and must be a string")
    for key in _TEXTS:
        if key in entry and not isinstance(entry[key], str):
            raise ProblemInputError(f"{where}: {key!r} must be a string, got {entry[key]!r}")
    for key in _FLAGS:
        if key in entry and not isinstance(entry[key], bool):
            raise ProblemInputError(f"{where}: {key!r} must be true or false, got {entry[key]!r}")
    try:
        promise = check_promise(entry.get("promise", "exact"))
    except ValueError as exc:
        raise ProblemInputError(f"{where}: {exc}") from None
    return ExternalSpec(name=entry["name"], command=entry["command"], inputs=entry.get("inputs", "dense"),
                        warm_start=bool(entry.get("warm_start", False)), version=entry.get("version"),
                        description=entry.get("description", ""), exact=bool(entry.get("exact", False)),
                        promise=promise, load_control=bool(entry.get("load_control", False)),
                        bounds=bool(entry.get("bounds", False)), workdir=str(path.resolve().parent), source=str(path))


def load_manifest(path: str | os.PathLike[str]) -> list[ExternalSpec]:
    """The entries of one manifest (``[[solver]]`` tables); a file that cannot be read, a
    top-level key other than ``solver`` or bad content is a ``ProblemInputError`` naming
    the file (and the entry and the key)."""
    p = Path(path)
    doc = _load_toml(p)
    unknown = sorted(set(doc) - {SOLVER_TABLE})
    if unknown:
        raise ProblemInputError(f"{p}: unknown top-level key(s) {', '.join(unknown)}; a manifest declares its "
                                f"solvers as [[{SOLVER_TABLE}]] tables")
    entries = doc.get(SOLVER_TABLE, [])
    if not isinstance(entries, list):
        raise ProblemInputError(f"{p}: {SOLVER_TABLE!r} must be an array of tables ([[{SOLVER_TABLE}]])")
    specs = [_spec_of(e, p, k) for k, e in enumerate(entries)]
    names = [s.name for s in specs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ProblemInputError(f"{p}: solver name(s) {', '.join(dup)} declared twice")
    return specs


def manifest_paths(environ: Mapping[str, str] | None = None, cwd: str | None = None) -> list[Path]:
    """The manifests to read: those of ``CONTACTBENCH_EXTERNAL_SOLVERS``, then
    ./contactbench-solvers.toml when there is anything by that name -- a folder or a
    dangling link too, which ``load_manifest`` then refuses (each once)."""
    env = os.environ if environ is None else environ
    paths = [Path(s) for s in env.get(MANIFEST_ENV, "").split(os.pathsep) if s.strip()]
    local = Path(cwd or os.getcwd()) / LOCAL_MANIFEST
    if os.path.lexists(local):
        paths.append(local)
    seen: dict[Path, Path] = {}
    for p in paths:
        seen.setdefault(p.resolve(), p)
    return list(seen.values())
