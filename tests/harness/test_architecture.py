"""The import contract of the installed packages, read from the source with ``ast``.

Every ``import`` and ``from ... import`` statement counts, wherever it stands (inside a
function, a class, an ``if TYPE_CHECKING`` block): an import inside a function that
dodges a cycle is still a cycle.  The rules (docs/architecture.md):

* no cycle among the project's modules;
* ``contactbench.problems`` imports neither ``solvers`` nor ``harness``;
* ``contactbench.solvers`` does not import ``harness``;
* ``contactbench.harness.table`` imports nothing else from ``harness``;
* ``contactbench.harness.report`` never imports ``contactbench.harness.run``;
* at most 12 modules directly in ``harness/``.

A package's ``__init__`` counts as a module: ``from pkg import name`` depends on
``pkg/__init__.py`` and, when ``name`` is a sub-module, on that sub-module too.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Installed package -> source folder (pyproject's package-dir).
PACKAGES = {"contactbench.problems": "problems", "contactbench.solvers": "solvers",
            "contactbench.harness": "harness", "contactbench": "contactbench"}
#: (importer prefix, forbidden imported prefix, why).
FORBIDDEN = (
    ("contactbench.problems", "contactbench.solvers", "problems is the floor: it imports no solver"),
    ("contactbench.problems", "contactbench.harness", "problems is the floor: it imports no harness"),
    ("contactbench.solvers", "contactbench.harness", "solvers import problems only"),
    ("contactbench.harness.report", "contactbench.harness.run", "the report reads the table, never the runner"),
)
#: The table reads and writes files; it imports nothing else from the harness.
TABLE = "contactbench.harness.table"
MAX_TOP_LEVEL_HARNESS_MODULES = 12


@dataclass(frozen=True)
class Module:
    name: str        # dotted, e.g. contactbench.harness.run.plan
    is_package: bool  # an __init__.py
    source: str


def module_name(rel: Path, root_pkg: str) -> tuple[str, bool]:
    """Dotted name of the file ``rel`` (relative to the package folder of ``root_pkg``)."""
    parts = list(rel.with_suffix("").parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts = parts[:-1]
    return ".".join([root_pkg, *parts]), is_pkg


def project_modules(root: Path = ROOT) -> dict[str, Module]:
    """Every module of the installed packages, by dotted name."""
    out: dict[str, Module] = {}
    for pkg, folder in PACKAGES.items():
        base = root / folder
        files = [base / "__init__.py"] if pkg == "contactbench" else sorted(base.rglob("*.py"))
        files += sorted(base.glob("*.py")) if pkg == "contactbench" else []
        for f in files:
            name, is_pkg = module_name(f.relative_to(base), pkg)
            out[name] = Module(name, is_pkg, f.read_text())
    return out


def resolve_relative(importer: Module, level: int, module: str | None) -> str:
    """The absolute name of ``from <level dots><module> import ...`` in ``importer``."""
    parts = importer.name.split(".")
    base = parts if importer.is_package else parts[:-1]
    if level - 1 > len(base):
        raise ValueError(f"{importer.name}: relative import beyond the top package")
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def imported_names(mod: Module) -> set[str]:
    """Every dotted name ``mod`` imports, anywhere in its body (``from a import b`` gives
    both ``a`` and ``a.b``: ``b`` may be a sub-module)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(mod.source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = resolve_relative(mod, node.level, node.module) if node.level else (node.module or "")
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
    return names


def owner(name: str, modules: dict[str, Module]) -> str | None:
    """The project module a dotted name lands in (the longest known prefix), if any."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in modules:
            return cand
    return None


def import_graph(modules: dict[str, Module]) -> dict[str, set[str]]:
    """Module -> the project modules it imports (itself excluded).  Importing
    ``a.b.c`` also runs ``a/__init__`` and ``a.b/__init__``; those edges are left out
    (they are how Python works, not a dependency the importer chose), except the
    package a name lands in."""
    graph: dict[str, set[str]] = {}
    for name, mod in modules.items():
        deps = {o for n in imported_names(mod) if (o := owner(n, modules)) is not None}
        graph[name] = deps - {name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle (its modules, the first repeated at the end), or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m):] + [m]
            if m not in state and (c := visit(m)) is not None:
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)) is not None:
            return c
    return None


def within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def violations(graph: dict[str, set[str]]) -> list[str]:
    """Each forbidden import, as 'importer -> imported (why)'."""
    bad: list[str] = []
    for src, deps in sorted(graph.items()):
        for dst in sorted(deps):
            for a, b, why in FORBIDDEN:
                if within(src, a) and within(dst, b):
                    bad.append(f"{src} -> {dst} ({why})")
            if (within(src, TABLE) and within(dst, "contactbench.harness") and not within(dst, TABLE)
                    and dst != "contactbench.harness"):
                bad.append(f"{src} -> {dst} (the table imports nothing else from the harness)")
    return bad


# ---------------------------------------------------------------------------
# The contract on this checkout
# ---------------------------------------------------------------------------


def test_no_import_cycle() -> None:
    cycle = find_cycle(import_graph(project_modules()))
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_layers_import_one_way() -> None:
    assert violations(import_graph(project_modules())) == []


def test_harness_holds_at_most_twelve_top_level_modules() -> None:
    top = sorted(p.name for p in (ROOT / "harness").glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL_HARNESS_MODULES, top


def test_the_isolated_worker_imports_no_report_code() -> None:
    """The solve runs in a child process: it must not pull in matplotlib's report."""
    graph = import_graph(project_modules())
    seen, todo = set(), ["contactbench.harness.run.worker"]
    while todo:
        n = todo.pop()
        if n not in seen:
            seen.add(n)
            todo.extend(graph.get(n, ()))
    assert not [n for n in seen if within(n, "contactbench.harness.report")]


def test_the_checker_sees_every_package() -> None:
    mods = project_modules()
    for pkg in ("contactbench.harness.table", "contactbench.harness.run", "contactbench.harness.report",
                "contactbench.harness.conformance", "contactbench.problems.scenes", "contactbench.plugins"):
        assert pkg in mods


# ---------------------------------------------------------------------------
# Inputs that would fool a careless checker
# ---------------------------------------------------------------------------


def _mods(**sources: str) -> dict[str, Module]:
    """Fake modules: keyword ``a__b__c`` is module a.b.c; ``a__b__init`` the package a.b."""
    out = {}
    for key, src in sources.items():
        parts = key.split("__")
        is_pkg = parts[-1] == "init"
        name = ".".join(parts[:-1] if is_pkg else parts)
        out[name] = Module(name, is_pkg, src)
    return out


def test_checker_sees_an_import_inside_a_function() -> None:
    mods = _mods(p__init="", p__a="def f():\n    from p import b\n", p__b="import p.a\n")
    assert find_cycle(import_graph(mods)) is not None


def test_checker_resolves_relative_imports() -> None:
    mods = _mods(p__init="", p__q__init="", p__q__a="from ..b import x\n", p__b="from .q.a import y\n")
    assert import_graph(mods)["p.q.a"] == {"p.b"}
    assert import_graph(mods)["p.b"] == {"p.q.a"}
    assert find_cycle(import_graph(mods)) == ["p.b", "p.q.a", "p.b"]


def test_checker_resolves_relative_imports_in_a_package_init() -> None:
    mods = _mods(p__init="from .a import x\n", p__a="")
    assert import_graph(mods)["p"] == {"p.a"}


def test_checker_sees_import_as_and_from_package_import_module() -> None:
    mods = _mods(p__init="", p__a="import p.b as c\n", p__b="from p import a\n")
    assert import_graph(mods)["p.a"] == {"p.b"}
    assert import_graph(mods)["p.b"] == {"p", "p.a"}
    assert find_cycle(import_graph(mods)) is not None


def test_checker_sees_imports_under_type_checking_and_in_classes() -> None:
    src = "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import p.b\nclass C:\n    import p.c\n"
    mods = _mods(p__init="", p__a=src, p__b="", p__c="")
    assert import_graph(mods)["p.a"] == {"p.b", "p.c"}


def test_checker_flags_each_forbidden_direction() -> None:
    graph = {
        "contactbench.problems.x": {"contactbench.solvers.base"},
        "contactbench.solvers.y": {"contactbench.harness.judging"},
        "contactbench.harness.report.core": {"contactbench.harness.run.plan"},
        "contactbench.harness.table.store": {"contactbench.harness.profiles"},
        "contactbench.harness.run.plan": {"contactbench.harness.table.store"},  # allowed
        "contactbench.harness.reporting": {"contactbench.harness.run.plan"},    # not report/: allowed
    }
    bad = violations(graph)
    assert len(bad) == 4, bad
    assert not [b for b in bad if b.startswith("contactbench.harness.run.plan")]
    assert not [b for b in bad if b.startswith("contactbench.harness.reporting")]


def test_checker_ignores_third_party_and_stdlib() -> None:
    mods = _mods(p__init="", p__a="import numpy as np\nfrom os import path\n")
    assert import_graph(mods)["p.a"] == set()


def test_relative_import_beyond_the_top_is_an_error() -> None:
    mods = _mods(p__a="from ... import x\n")
    with pytest.raises(ValueError):
        import_graph(mods)
