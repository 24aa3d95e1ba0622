"""Solver registry (in the manner of qpsolvers: it knows what is importable).

Every module in the ``solvers`` package (and every module under ``solvers/``
sub-packages; modules named ``_*`` are helpers, not solvers) is imported once on first
use; modules register their solvers with the ``@register`` decorator.  External
packages can add solvers through the entry-point group ``contactbench.solvers`` (each
entry point names a module to import), and tests may register throw-away solvers with
``register(..., replace=True)`` / ``unregister``.  The registry itself is a
``contactbench.plugins.PluginRegistry``.

Solvers declared outside any Python module (the external-solver manifests,
``solvers/external_manifests.py``) come from a *late source*: a loader registered with
``add_late_source`` and run once, the first time a name is not among the discovered
solvers or every solver is listed -- never on import or discovery, so a broken
``./contactbench-solvers.toml`` in the user's folder cannot break an import or a
built-in solver.  A loader that fails is recorded: ``import_errors`` lists it, and a
name that stays unknown is reported with that error.

A solver *spec* on the command line (``run --solvers``, ``validate``) is one of

* a registry name, ``fast-dual-pccg``;
* an import path ``module:NAME`` (a Solver subclass, instance or factory); a module in
  the current folder loads as with ``python -m`` (``load_solver``); one that does not load
  is one line whatever its module raised (``load_named_solver``, solvers/_loading.py);
* either with fixed parameters, ``fast-dual-pccg[precision=double]`` or
  ``name[k=v,k2=v2]``: each value is read as the declared ``Param``'s type and checked
  by ``Solver.resolve_params`` (``parse_solver_spec``);
* either with the word ``grid`` among its brackets, ``nnls-gp[grid]`` or
  ``name[grid,k=v]``: one variant per point of the solver's declared ``grid`` (the
  cross product of its values, fixed keys left out; ``expand_solver_spec``), each a
  spec ``name[k=v,...]`` as if written out, at most ``MAX_GRID_VARIANTS`` of them.

``split_solver_list`` splits a comma list of specs (commas inside ``[...]`` belong to
the spec); a spec's text is read in ``solvers/_spec_text.py``, its solver loaded here.

Every solver the registry takes (``register``) or loads by import path (``load_solver``)
passes ``check_declaration`` first: a declaration it cannot use (a parameter of a kind
outside ``PARAM_KINDS``, choices or a grid value its own ``Param.check`` refuses, a grid
key that names no parameter, a parameter name, choice or grid value that a label
``name[k=v]`` cannot carry so that it reads back, ...) is refused in one line.

The variants one command names are one each (``refuse_same_variants``): a label named
twice, or two labels of one solver with the same parameters once defaults are filled in,
is refused before anything runs.
"""

from __future__ import annotations

import hashlib
import importlib
import itertools
import math
import os
import sys
import traceback
from dataclasses import dataclass
from typing import Any, Callable, Sequence, TypeVar

from contactbench.plugins import PluginRegistry, UnknownPluginError

from ._loading import SolverLoadError, availability_failure, file_path_hint, load_failure, user_code
from ._source_files import PROJECT_PACKAGE, class_source_files
from ._spec_text import (GRID_WORD, MAX_GRID_VARIANTS, WRITTEN_RULE, SolverSpec, SolverSpecError, SpecText,
                         is_import_path, param_from_text, reads_back, reads_back_as_key, split_solver_list,
                         split_solver_spec, value_label)
from .base import Capabilities, Param, ParamError, Solver, SolverReturnError, read_availability

S = TypeVar("S")


class UnknownSolverError(UnknownPluginError):
    """``get_solver`` of a name nobody registered (a ``KeyError``)."""


def _same_class(old: Solver, new: Solver) -> bool:
    return type(old) is type(new)


_SOLVERS: PluginRegistry[Solver] = PluginRegistry(
    "solver", package="contactbench.solvers", entry_point_group="contactbench.solvers", recursive=True,
    include=lambda short: short not in ("base", "registry"), same=_same_class, error=UnknownSolverError)


class _LateSources:
    """Loaders of solvers declared outside the package, by name; each runs at most once
    (marked first: a loader may read the registry), its failure kept as a traceback."""

    def __init__(self) -> None:
        self._loaders: dict[str, Callable[[], object]] = {}
        self._loaded: set[str] = set()
        self._errors: dict[str, str] = {}
        self._messages: dict[str, str] = {}

    def add(self, name: str, load: Callable[[], object]) -> None:
        self._loaders.setdefault(name, load)

    def load(self) -> None:
        _SOLVERS.discover()  # the loaders are registered by discovered modules
        for name, load in list(self._loaders.items()):
            if name in self._loaded:
                continue
            self._loaded.add(name)
            try:
                load()
            except Exception as exc:  # kept for import_errors and the unknown-name message
                self._errors[name] = traceback.format_exc(limit=-4)
                self._messages[name] = str(exc) or type(exc).__name__

    def errors(self) -> dict[str, str]:
        """Loader name -> traceback of each loader that failed."""
        return dict(self._errors)

    def messages(self) -> list[str]:
        """The one-line error of each loader that failed."""
        return list(self._messages.values())


_LATE = _LateSources()


def add_late_source(name: str, load: Callable[[], object]) -> None:
    """Register ``load``, which registers solvers read from outside the package (module
    doc); it runs once, when a name is not found or every solver is listed.  ``name``
    (the registering module) labels its failure in ``import_errors``."""
    _LATE.add(name, load)


class SolverDeclarationError(ValueError):
    """A solver whose declaration cannot be used (``check_declaration``; one line)."""


#: The kinds a ``Param`` may declare: the scalars a spec's text is read as
#: (``param_from_text``) and two structured kinds, given as values through the API or
#: ``validate --params`` JSON.  A sequence is a ``tuple``, never a ``list``: a default
#: is one object shared by every solve, and ``Param.check`` takes only its own kind.
SCALAR_KINDS: tuple[type, ...] = (bool, int, float, str)
PARAM_KINDS: tuple[type, ...] = (*SCALAR_KINDS, tuple, dict)
#: The kinds a declared range (``low``, ``high``) applies to.
NUMBER_KINDS: tuple[type, ...] = (int, float)
#: The ends a range may leave out (``Param.open``).
OPEN_ENDS: tuple[str, ...] = ("", "low", "high", "both")


def check_declaration(solver: Solver) -> Solver:
    """``solver`` if its declaration can be used, else a ``SolverDeclarationError`` naming
    the solver and everything that is wrong, in one line: its ``name`` is a non-empty
    string that ``--solvers`` reads back (``reads_back_as_name``), its ``capabilities`` a
    ``Capabilities``, its ``params`` a tuple (or list) of ``Param`` (each as
    ``param_problems`` requires, names distinct), its other attributes as
    ``attribute_problems`` requires and its ``grid`` as ``grid_problems`` requires."""
    name = getattr(solver, "name", None)
    if not isinstance(name, str) or not name.strip():
        raise SolverDeclarationError(f"solver class {type(solver).__name__} has no name (its `name` is {name!r}; "
                                     "a solver is named by a non-empty string)")
    if not reads_back_as_name(name):
        raise SolverDeclarationError(f"solver class {type(solver).__name__}: its `name` {name!r} cannot be named in "
                                     f"--solvers and read back ({NAME_RULE})")
    caps = getattr(solver, "capabilities", None)
    if not isinstance(caps, Capabilities):
        raise SolverDeclarationError(f"solver {name!r}: its `capabilities` is {caps!r}, not a Capabilities(...)")
    params = getattr(solver, "params", None)
    if not isinstance(params, (tuple, list)) or not all(isinstance(q, Param) for q in params):
        raise SolverDeclarationError(f"solver {name!r}: its `params` is {params!r}, not a tuple of "
                                     "Param(name, type, default, ...)")
    problems = attribute_problems(solver)
    problems += [line for q in params for line in param_problems(q)]
    names = [q.name for q in params]
    problems += [f"parameter {k!r} is declared twice" for k in dict.fromkeys(names) if names.count(k) > 1]
    problems += grid_problems(getattr(solver, "grid", None), params)
    if problems:
        raise SolverDeclarationError(f"solver {name!r}: " + "; ".join(problems))
    return solver


#: What a solver's name is, to be named in ``--solvers`` and read back (``reads_back_as_name``).
NAME_RULE = "a name is one word: no space, no control character, none of ',', '[', ']', ':'"
#: The methods a solver's class provides, each a method (a subclass overrides them as methods).
METHODS: tuple[str, ...] = ("availability", "skip", "skip_params", "default_max_iter", "memory_estimate",
                            "time_estimate", "iterate")


def reads_back_as_name(name: str) -> bool:
    """Whether a solver called ``name`` is named by it in ``--solvers``: the comma list
    (``split_solver_list``) and a spec (``split_solver_spec``) read it back as itself, and
    it is not an import path ``module:NAME`` (``is_import_path``) -- one word (``NAME_RULE``)."""
    if not name.isprintable() or any(c.isspace() for c in name) or is_import_path(name):
        return False
    try:
        return split_solver_list(name) == [name] and split_solver_spec(name) == SpecText(name)
    except SolverSpecError:
        return False


def one_line_text(value: Any, empty: bool) -> bool:
    """Whether ``value`` is a str on one line (no control character), non-empty unless ``empty``."""
    return isinstance(value, str) and value.isprintable() and (empty or bool(value.strip()))


def attribute_problems(solver: Solver) -> list[str]:
    """What is wrong with a solver's attributes besides its name, capabilities and params
    (none: []): its ``family`` a non-empty str on one line and its ``description`` a str on
    one line (``one_line_text``); its ``default_tol`` None or a finite number > 0; its
    ``refuted_on`` a frozenset of non-empty str; ``time_scales_with_grid`` a bool; each of
    ``METHODS`` a method."""
    problems: list[str] = []
    family, description = getattr(solver, "family", None), getattr(solver, "description", None)
    if not one_line_text(family, empty=False):
        problems.append(f"its `family` is {family!r}, not a non-empty str on one line")
    if not one_line_text(description, empty=True):
        problems.append(f"its `description` is {description!r}, not a str on one line")
    tol = getattr(solver, "default_tol", None)
    if tol is not None and not (isinstance(tol, (int, float)) and not isinstance(tol, bool)
                                and math.isfinite(tol) and tol > 0):
        problems.append(f"its `default_tol` is {tol!r}, not None or a finite number > 0")
    refuted = getattr(solver, "refuted_on", None)
    if not isinstance(refuted, frozenset) or not all(one_line_text(f, empty=False) for f in refuted):
        problems.append(f"its `refuted_on` is {refuted!r}, not a frozenset of problem families (str)")
    if not isinstance(scales := getattr(solver, "time_scales_with_grid", None), bool):
        problems.append(f"its `time_scales_with_grid` is {scales!r}, not a bool")
    problems += [f"its `{m}` is {getattr(solver, m, None)!r}, not a method" for m in METHODS
                 if not callable(getattr(solver, m, None))]
    return problems


def param_problems(param: Param) -> list[str]:
    """What is wrong with one declared parameter (none: []): its name is a non-empty
    string that a spec's brackets read back as a key (``reads_back_as_key``); its kind one
    of ``PARAM_KINDS``; a range (``low``, ``high``) only on a number kind, its ends numbers
    with low <= high and ``open`` one of ``OPEN_ENDS``; its ``choices`` a non-empty tuple
    of distinct values that each pass ``Param.check`` and, for a kind a spec's text is read
    as (``SCALAR_KINDS``), read back from a label (``reads_back``); its default None (the
    solver works it out) or a value ``Param.check`` accepts."""
    if not isinstance(param.name, str) or not param.name.strip():
        return [f"a declared parameter has no name (its name is {param.name!r})"]
    what = f"parameter {param.name!r}"
    if not reads_back_as_key(param.name):
        return [f"{what}: its name cannot be written as the key of name[key=value] and read back "
                f"({WRITTEN_RULE})"]
    if param.kind not in PARAM_KINDS:
        kind = getattr(param.kind, "__name__", repr(param.kind))
        return [f"{what} is of kind {kind}, not one of {', '.join(k.__name__ for k in PARAM_KINDS)} "
                "(a sequence is a tuple)"]
    problems = range_problems(param)
    if param.choices is not None:
        problems += value_list_problems(param, param.choices, f"{what}: its choices",
                                        labelled=param.kind in SCALAR_KINDS)
    if param.default is not None and not problems:
        try:
            param.check(param.default)
        except ParamError as exc:
            problems.append(f"the default of a declared parameter does not pass its own declaration: {exc}")
    return problems


def range_problems(param: Param) -> list[str]:
    """What is wrong with ``param``'s declared range (none: [], also where it has none)."""
    what = f"parameter {param.name!r}"
    if param.open not in OPEN_ENDS:
        return [f"{what}: its open ends are {param.open!r}, not one of {', '.join(map(repr, OPEN_ENDS))}"]
    if param.low is None and param.high is None:
        return []
    if param.kind not in NUMBER_KINDS:
        return [f"{what} declares a range, but is a {param.kind.__name__}: a range is a number's (int or float)"]
    ends = [e for e in (param.low, param.high) if e is not None]
    if any(isinstance(e, bool) or not isinstance(e, (int, float)) or math.isnan(e) for e in ends):
        return [f"{what}: its range ends low={param.low!r}, high={param.high!r} are not numbers"]
    if param.low is not None and param.high is not None and param.low > param.high:
        return [f"{what}: its range is empty (low={param.low!r} > high={param.high!r})"]
    return []


def value_list_problems(param: Param, values: Any, what: str, labelled: bool = True) -> list[str]:
    """What is wrong with a list of values of ``param`` (its choices, or a grid's values):
    it is a non-empty tuple or list, each value passes ``param.check``, none twice (as
    checked: 1 and 1.0 of a float are one value) and, where ``labelled``, each reads back
    from a label ``name[key=value]`` as itself (``reads_back``)."""
    if not isinstance(values, (tuple, list)) or not values:
        return [f"{what} are {values!r}, not a non-empty tuple of values"]
    problems: list[str] = []
    seen: list[Any] = []  # (dicts are values too: a list, not a set)
    for v in values:
        try:
            checked = param.check(v)
        except ParamError as exc:
            problems.append(f"{what}: {exc}")
            continue
        if checked in seen:
            problems.append(f"{what} list {v!r} twice")
        seen.append(checked)
        if labelled and not reads_back(param, checked):
            written = f"{param.name}={value_label(checked)}"
            problems.append(f"{what}: {v!r} does not read back from a label, written {written!r} ({WRITTEN_RULE})")
    return problems


def grid_problems(grid: Any, params: Sequence[Param]) -> list[str]:
    """What is wrong with a solver's ``grid`` (none: []): a dict whose every key names a
    declared parameter and whose every value is a list of that parameter's values
    (``value_list_problems``)."""
    if not isinstance(grid, dict):
        return [f"its `grid` is {grid!r}, not a dict of parameter name -> tuple of values"]
    declared = {q.name: q for q in params}
    problems: list[str] = []
    for key, values in grid.items():
        if key not in declared:
            problems.append(f"its grid names {key!r}, which is not a declared parameter (declared: "
                            f"{', '.join(map(repr, declared)) or 'none'})")
            continue
        problems += value_list_problems(declared[key], values, f"its grid values of {key!r}")
    return problems


def register(obj: S | None = None, *, replace: bool = False) -> S | Callable[[S], S]:
    """Register a Solver subclass (instantiated with no arguments) or instance whose
    declaration passes ``check_declaration``.

    Usable as ``@register`` on a class or ``register(instance)``.
    """

    def _do(o: S) -> S:
        inst = o() if isinstance(o, type) else o
        if not isinstance(inst, Solver):
            raise TypeError(f"{o!r} is not a Solver")
        check_declaration(inst)
        _SOLVERS.add(inst.name, inst, replace=replace)
        return o

    if obj is None:
        return _do
    return _do(obj)


def unregister(name: str, *, missing_ok: bool = False) -> None:
    """Remove the solver registered as ``name`` (a test's throw-away solver, say): a later
    ``get_solver(name)`` is an ``UnknownSolverError`` until it is registered again.  A name
    that is not registered is a ``KeyError`` naming it, or nothing when ``missing_ok``."""
    if name not in _SOLVERS:
        if missing_ok:
            return
        raise UnknownSolverError(f"cannot unregister solver {name!r}: no solver of that name is registered")
    _SOLVERS.remove(name)


def all_solvers() -> dict[str, Solver]:
    """Every registered solver, available or not, by name (sorted); the late sources
    (external manifests) are loaded first."""
    _LATE.load()
    return _SOLVERS.all()


def available_solvers() -> dict[str, Solver]:
    """The registered solvers (``all_solvers``, late sources loaded first) whose
    ``availability()`` answers available on this machine now, by name (sorted); a solver
    whose check fails (a missing package, no GPU) is left out -- ``all_solvers`` lists it,
    ``availability()`` gives its reason; an ``availability()`` that raises raises here."""
    return {k: s for k, s in all_solvers().items() if s.availability()[0]}


def check_late_sources() -> None:
    """A one-line ``SolverLoadError`` when a late source (an external manifest: the
    ``CONTACTBENCH_EXTERNAL_SOLVERS`` files, ./contactbench-solvers.toml) failed to load,
    whichever solvers a run names: a bad manifest is refused before anything runs, never
    left out in silence (its good entries, registered first, would run beside it)."""
    _LATE.load()
    failed = _LATE.messages()
    if failed:
        raise SolverLoadError(f"external solvers could not be read: {'; '.join(failed)}")


def import_errors() -> dict[str, str]:
    """Module -> traceback of every solver module that failed to import, and of every
    late source (an external manifest) that failed to load."""
    _LATE.load()
    return {**_SOLVERS.import_errors(), **_LATE.errors()}


def get_solver(name: str) -> Solver:
    """The solver called ``name``: a discovered one, else one of the late sources
    (external manifests, read now); else ``UnknownSolverError`` listing the known ones
    and, first, the error of any late source that failed to load."""
    if not isinstance(name, str):
        raise UnknownSolverError(f"a solver is named by a string (contactbench list solvers), got {name!r}")
    if name in _SOLVERS:
        return _SOLVERS.get(name)
    _LATE.load()
    failed = "; ".join(_LATE.messages())
    if failed and name not in _SOLVERS:
        raise UnknownSolverError(f"unknown solver {name!r}: external solvers could not be read: {failed}; "
                                 f"known solvers: {', '.join(_SOLVERS.all()) or '(none)'}")
    return _SOLVERS.get(name)


def import_user_module(name: str) -> Any:
    """Import module ``name``; a module that is not importable otherwise is looked for in
    the current folder too (as ``python -m`` does: the folder goes on ``sys.path``)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        top = name.split(".", 1)[0]
        if exc.name != top or os.getcwd() in sys.path:
            raise
    sys.path.insert(0, os.getcwd())
    return importlib.import_module(name)


def load_solver(spec: str | Solver) -> Solver:
    """A solver by registry name or by import path ``module:NAME`` (a Solver subclass,
    instance or factory; ``import_user_module`` finds the module), its declaration
    checked (``check_declaration``) and, for an import path, its ``availability()`` asked once
    (``check_availability``); a ``Solver`` handed in is returned as it is.  An
    import path's code runs under ``solvers._loading.user_code``: an ``Exception`` it
    raises passes as it is (a missing ``NAME``: ``AttributeError``; not a solver:
    ``TypeError``), anything else but the user's Ctrl-C comes out as an ``ImportAborted``
    (``load_named_solver`` words each in one line)."""
    if isinstance(spec, Solver):
        return spec
    if not is_import_path(spec):
        return get_solver(spec)
    mod_name, attr = spec.split(":", 1)
    with user_code(spec, f"importing module {mod_name!r}"):
        module = import_user_module(mod_name)
    with user_code(spec, f"reading {attr!r} from module {mod_name!r}"):
        obj = getattr(module, attr)
    with user_code(spec, f"building solver {spec!r}"):
        solver = _built(obj)
    if solver is None:
        raise TypeError(f"{spec} is not a Solver subclass, instance or factory")
    check_declaration(solver)
    with user_code(spec, f"asking solver {solver.name!r} its availability()"):
        check_availability(solver)
    return solver


#: Hex digits of a solver's source digest in a run's configuration (``source_digest``).
SOURCE_DIGEST_DIGITS = 16
#: The module prefix of the project's own solvers, which a source digest leaves out.
PROJECT_MODULES = PROJECT_PACKAGE + "."


def source_digest(solver: Solver) -> str | None:
    """The SHA-256 (``SOURCE_DIGEST_DIGITS`` hex digits) of the source of ``solver``, for a
    solver from outside this package (a user's module named by import path or registered by
    a plugin): the file that defines its class and the modules it imports from its own source
    tree (``_source_files.class_source_files``), each with its path in that tree; or of what
    it pins itself (``Solver.pinned_source``: an outside program's manifest entry and files).
    A results folder pins it, so that an edited solver is never resumed as the code whose
    rows the folder holds.  None for the project's own solvers (the package's version pins
    them) and for a class whose file cannot be read (defined at an interactive prompt)."""
    data = solver.pinned_source()
    cls = type(solver)
    if data is None and not cls.__module__.startswith(PROJECT_MODULES):
        files = class_source_files(cls)
        data = None if files is None else b"".join(
            f"{f.relative}\0{len(f.data)}\0".encode() + f.data for f in files)
    return None if data is None else hashlib.sha256(data).hexdigest()[:SOURCE_DIGEST_DIGITS]


def check_availability(solver: Solver) -> None:
    """A ``SolverDeclarationError`` naming the solver when its ``availability()`` raises an
    ``Exception`` or answers what is not a pair (available, reason) (``base.read_availability``)."""
    try:
        read_availability(solver.name, "availability", solver.availability())
    except SolverReturnError as exc:
        raise SolverDeclarationError(str(exc)) from None
    except Exception as exc:
        raise SolverDeclarationError(f"solver {solver.name!r}: {availability_failure(exc)}") from None


def _built(obj: Any) -> Solver | None:
    """The solver ``obj`` (a Solver subclass, instance or factory) gives, else None."""
    if isinstance(obj, type) and issubclass(obj, Solver):
        return obj()
    if isinstance(obj, Solver):
        return obj
    if callable(obj):
        out = obj()
        if isinstance(out, Solver):
            return out
    return None


def load_named_solver(spec: str | Solver) -> Solver:
    """``load_solver``, where a solver named by import path that does not load is one
    ``SolverLoadError`` line (``solvers._loading.load_failure``; a file path where a module
    name goes, ``file_path_hint``) whatever its module raised, and the user's Ctrl-C still
    interrupts; a registry name that is unknown is ``load_solver``'s ``KeyError``."""
    if isinstance(spec, Solver) or not is_import_path(spec):
        return load_solver(spec)
    mod_name, attr = spec.split(":", 1)
    hint = file_path_hint(mod_name, attr)
    if hint:
        raise SolverLoadError(f"cannot load solver {spec!r}: {hint}")
    try:
        return load_solver(spec)
    except SolverDeclarationError as exc:  # it names the solver and what is wrong
        raise SolverLoadError(f"cannot load solver {spec!r}: {exc}") from None
    except Exception as exc:
        raise load_failure(spec, exc, sys.modules.get(mod_name)) from None


# ---------------------------------------------------------------------------
# Specs with parameters: name[k=v,k2=v2]
# ---------------------------------------------------------------------------


def parse_solver_spec(text: str) -> tuple[SolverSpec, Solver]:
    """The spec of one ``--solvers`` entry naming one variant and its solver (loaded by
    ``load_named_solver``).  Parameters are read against the solver's declared ``Param``s and
    checked by ``resolve_params``, the check ``validate --params`` makes; a bad one is a
    ``ParamError`` naming the allowed keys, a malformed spec (or ``name[grid]``, which
    names several: ``expand_solver_spec``) a ``SolverSpecError``."""
    parts = split_solver_spec(text)
    if parts.grid:
        raise SolverSpecError(f"solver {text.strip()!r} names every point of a grid, not one variant")
    return fixed_spec(parts, text)


def fixed_spec(parts: SpecText, text: str) -> tuple[SolverSpec, Solver]:
    """The solver of ``parts`` and the spec of its fixed parameters (``parts.raw``), each
    read as its declared ``Param`` (``param_from_text``) and checked (``resolve_params``)."""
    solver = load_named_solver(parts.name)
    declared = {p.name: p for p in solver.params}
    try:
        params = {k: param_from_text(declared[k], v) if k in declared else v for k, v in parts.raw.items()}
    except ParamError as exc:
        raise ParamError(f"solver {text.strip()!r}: {exc}") from None
    solver.resolve_params(params)  # an unknown key: the allowed ones, in one line
    return SolverSpec(parts.name, params), solver


def expand_solver_spec(text: str) -> tuple[list[SolverSpec], Solver]:
    """The specs one ``--solvers`` entry stands for, and its solver: one
    (``parse_solver_spec``), or, with ``GRID_WORD`` among its brackets, one per point of
    the solver's declared grid (``grid_points``) with the entry's fixed parameters in each
    (a fixed key leaves the grid).  A solver that declares no grid, or a grid of more than
    ``MAX_GRID_VARIANTS`` points, is a ``SolverSpecError`` (one line)."""
    parts = split_solver_spec(text)
    spec, solver = fixed_spec(parts, text)
    if not parts.grid:
        return [spec], solver
    if not solver.grid:
        raise SolverSpecError(f"solver {text.strip()!r}: {solver.name!r} declares no grid to expand "
                              "(contactbench list solvers --params)")
    free = {k: tuple(v) for k, v in solver.grid.items() if k not in spec.params}
    count = math.prod(len(v) for v in free.values())
    if count > MAX_GRID_VARIANTS:
        raise SolverSpecError(f"solver {text.strip()!r}: its grid has {count:,} points, over the limit of "
                              f"{MAX_GRID_VARIANTS} variants of one entry; fix some parameters, "
                              f"{parts.name}[{GRID_WORD},key=value]")
    return [SolverSpec(parts.name, {**spec.params, **point}) for point in grid_points(solver, spec.params)], solver


def grid_points(solver: Solver, fixed: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Every point of ``solver``'s declared grid, the keys of ``fixed`` left out: the
    cross product of the grid's values (each as its ``Param.check`` reads it), keys in the
    grid's order, the last varying fastest.  A grid that is empty once ``fixed`` is left
    out has one point, {}."""
    declared = {p.name: p for p in solver.params}
    axes = [[(k, declared[k].check(v)) for v in values] for k, values in solver.grid.items()
            if k not in (fixed or {})]
    return [dict(point) for point in itertools.product(*axes)]


@dataclass(frozen=True)
class NamedVariant:
    """One variant a command names: its ``label`` (as its rows or lines are labelled), its
    ``solver`` and the parameters given it (None or {}: every default)."""

    label: str
    solver: Solver
    params: dict[str, Any] | None = None


def refuse_same_variants(variants: Sequence[NamedVariant], where: str) -> None:
    """A one-line ``SolverSpecError`` when two of ``variants`` are one variant, before
    anything is solved twice: a label named twice (``nnls-gp[grid],nnls-gp[K=50]`` names
    ``nnls-gp[K=50]`` twice), or two labels of one solver (one name, one class) whose
    parameters are equal once every default is filled in (``Solver.resolve_params``:
    ``nnls-gp`` and ``nnls-gp[K=100]``), both labels named.  ``where`` names what named
    them (``--solvers``); each variant's parameters are ones ``resolve_params`` takes."""
    labels = [v.label for v in variants]
    twice = [k for k in dict.fromkeys(labels) if labels.count(k) > 1]
    if twice:
        raise SolverSpecError(f"{where} names the variant{'s' if len(twice) > 1 else ''} "
                              f"{', '.join(map(repr, twice))} twice; name each variant once")
    full = [(v, v.solver.resolve_params(v.params)) for v in variants]
    for i, (v, params) in enumerate(full):
        for first, first_params in full[:i]:
            if _same_class(first.solver, v.solver) and first.solver.name == v.solver.name and first_params == params:
                raise SolverSpecError(f"{where} names one variant twice, as {first.label!r} and {v.label!r} (solver "
                                      f"{v.solver.name!r} with the same parameters once defaults are filled in); "
                                      "name each variant once")
