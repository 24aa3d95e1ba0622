"""Every public name imports as promised: each name in each ``__all__`` of the package,
and each name the docs show in a ``from contactbench... import X`` line (README.md,
docs/*.md, the tutorial notebook), resolves; a name the docs then call, ``X(``, is
callable (not, say, a submodule that shares its name)."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import json
import re
from pathlib import Path

import pytest

from tests.helpers import REPO

#: The installed package's floors and their source folders (pyproject.toml's package-dir).
FLOORS = {"contactbench": REPO / "contactbench", "contactbench.problems": REPO / "problems",
          "contactbench.solvers": REPO / "solvers", "contactbench.harness": REPO / "harness"}
#: Words the docs put where a reader writes a name of their own.
PLACEHOLDERS = {"NAME", "..."}
IMPORT_LINE = re.compile(r"from\s+(contactbench(?:\.\w+)*)\s+import\s+(\([^)]*\)|[^\n`]+)")


def module_files() -> dict[str, Path]:
    """Module name -> source file of every module of the package."""
    out: dict[str, Path] = {}
    for prefix, root in FLOORS.items():
        files = [root / "__init__.py", root / "plugins.py"] if prefix == "contactbench" else sorted(root.rglob("*.py"))
        for f in files:
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([prefix, *parts])] = f
    return out


def has_all(path: Path) -> bool:
    """Whether a module assigns ``__all__`` at its top level (read, not imported)."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            return True
    return False


ALL_MODULES = sorted(m for m, f in module_files().items() if has_all(f))


def doc_texts() -> dict[str, str]:
    """Each doc's text a reader sees: Markdown as is, the notebook's cells' sources."""
    out = {str(p.relative_to(REPO)): p.read_text(encoding="utf-8")
           for p in [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]}
    for nb in sorted((REPO / "docs").rglob("*.ipynb")):
        cells = json.loads(nb.read_text(encoding="utf-8"))["cells"]
        out[str(nb.relative_to(REPO))] = "\n".join("".join(c.get("source", "")) for c in cells)
    return out


def documented_imports() -> list[tuple[str, str, str, bool]]:
    """(doc, module, name, whether the doc calls ``name(``) for every name of every
    ``from contactbench... import`` line of the docs."""
    found = []
    for doc, text in doc_texts().items():
        for module, names in IMPORT_LINE.findall(text):
            for item in names.strip("()").replace("\n", " ").split(","):
                name = item.split(" as ")[-1].strip() if " as " in item else item.strip()
                original = item.split(" as ")[0].strip()
                if not original or original in PLACEHOLDERS or not original.isidentifier():
                    continue
                called = re.search(rf"(?<![\w.]){re.escape(name)}\(", text) is not None
                found.append((doc, module, original, called))
    return sorted(set(found))


@pytest.mark.parametrize("module", ALL_MODULES)
def test_every_name_in_all_imports(module: str) -> None:
    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as exc:  # an optional extra (a peer code, a GPU library) not installed here
        if exc.name and not exc.name.startswith("contactbench"):
            pytest.skip(f"{module} needs {exc.name}")
        raise
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, f"{module}.__all__ names what it does not define: {missing}"


DOCUMENTED = documented_imports()


def test_the_pattern_finds_the_docs_imports() -> None:
    assert len(ALL_MODULES) > 10 and "contactbench.harness" in ALL_MODULES
    assert len(DOCUMENTED) > 20
    assert ("docs/api/harness.md", "contactbench.harness", "judge", True) in DOCUMENTED


@pytest.mark.parametrize(("doc", "module", "name", "called"), DOCUMENTED,
                         ids=[f"{d}:{m}.{n}" for d, m, n, _ in DOCUMENTED])
def test_every_documented_import_works_as_shown(doc: str, module: str, name: str, called: bool) -> None:
    namespace: dict[str, object] = {}
    exec(f"from {module} import {name}", namespace)  # the statement as the docs show it
    obj = namespace[name]
    if called:
        assert callable(obj), f"{doc}: `from {module} import {name}` gives {obj!r}, which {doc} calls"


def test_the_harness_judge_is_the_function_even_after_its_module_is_imported() -> None:
    importlib.import_module("contactbench.harness.judging")
    from contactbench.harness import judge

    assert callable(judge) and judge.__name__ == "judge"


@pytest.mark.parametrize("package", [m for m in ALL_MODULES if module_files()[m].name == "__init__.py"])
def test_no_exported_name_is_shadowed_by_a_submodule(package: str) -> None:
    """A package's exported name that is also a submodule's name resolves to the submodule
    once that is imported (the import system binds it on the package): so an exported
    name either is that submodule or has no submodule of its name."""
    mod = importlib.import_module(package)
    lazy = vars(mod).get("__getattr__")  # PEP 562 exports: what the name is meant to be
    for name in mod.__all__:
        meant = lazy(name) if lazy is not None and name not in vars(mod) else vars(mod).get(name)
        if importlib.util.find_spec(f"{package}.{name}") is not None:
            sub = importlib.import_module(f"{package}.{name}")
            assert meant is sub, f"{package}.{name}: the export and a submodule share a name"
