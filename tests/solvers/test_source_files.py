"""A solver's source digest (``registry.source_digest``) covers the modules its file
imports from its own source tree (``_source_files.class_source_files``): an edit of a
helper module re-pins it as an edit of the solver's own file does, and an edit of a file it
does not import, or of an installed package, does not."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from contactbench.solvers._source_files import absolute_from, class_source_files, imported_modules
from contactbench.solvers.registry import source_digest, unregister

SOLVER = """
import numpy as np
from contactbench.solvers import Outcome, Solver
from . import near
from .deep.inner import scale
import sibling

class Mine(Solver):
    name = "test-source-files-mine"
    family = "test"
    def iterate(self, ctx):
        import late
        return Outcome(np.zeros(ctx.n) * scale() * near.K * sibling.K * late.K, 1, True)
"""

FILES = {
    "pkg/__init__.py": "",
    "pkg/solver.py": SOLVER,
    "pkg/near.py": "K = 1.0\n",
    "pkg/deep/__init__.py": "",
    "pkg/deep/inner.py": "from ..near import K\ndef scale():\n    return K\n",
    "pkg/unused.py": "K = 2.0\n",
    "sibling.py": "K = 1.0\n",
    "late.py": "K = 1.0\n",
    "unrelated.py": "K = 3.0\n",
}


@pytest.fixture
def tree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A user's source tree on ``sys.path``; its modules and solver are gone afterwards."""
    for rel, text in FILES.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in [m for m in sys.modules if m.split(".")[0] in ("pkg", "sibling", "late", "unrelated")]:
        del sys.modules[name]
    unregister("test-source-files-mine", missing_ok=True)


def digest(tree: Path) -> str | None:
    module = importlib.import_module("pkg.solver")
    return source_digest(module.Mine())


def test_the_files_are_the_solver_s_and_those_it_imports_from_its_tree(tree: Path) -> None:
    module = importlib.import_module("pkg.solver")
    files = [f.relative for f in class_source_files(module.Mine) or []]
    assert files == ["late.py", "pkg/__init__.py", "pkg/deep/__init__.py", "pkg/deep/inner.py",
                     "pkg/near.py", "pkg/solver.py", "sibling.py"]


@pytest.mark.parametrize("helper", ["pkg/near.py", "pkg/deep/inner.py", "sibling.py", "late.py", "pkg/__init__.py"])
def test_an_edited_helper_changes_the_digest(tree: Path, helper: str) -> None:
    first = digest(tree)
    with (tree / helper).open("a", encoding="utf-8") as f:
        f.write("# edited\n")
    assert first is not None and digest(tree) not in (None, first)


@pytest.mark.parametrize("other", ["pkg/unused.py", "unrelated.py"])
def test_a_file_the_solver_does_not_import_leaves_the_digest(tree: Path, other: str) -> None:
    first = digest(tree)
    (tree / other).write_text("K = 4.0\n", encoding="utf-8")
    assert digest(tree) == first


def test_a_moved_tree_keeps_its_digest(tree: Path, tmp_path_factory: pytest.TempPathFactory) -> None:
    first = digest(tree)
    for name in [m for m in sys.modules if m.split(".")[0] in ("pkg", "sibling", "late")]:
        del sys.modules[name]
    moved = tmp_path_factory.mktemp("moved")
    for rel, text in FILES.items():
        (moved / rel).parent.mkdir(parents=True, exist_ok=True)
        (moved / rel).write_text(text, encoding="utf-8")
    sys.path.insert(0, str(moved))
    try:
        assert digest(moved) == first
    finally:
        sys.path.remove(str(moved))


def test_a_file_that_does_not_parse_is_hashed_and_imports_nothing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text("import sibling\ndef (:\n", encoding="utf-8")
    assert imported_modules(bad, "bad", tmp_path) == []


@pytest.mark.parametrize(("module", "level", "package", "expected"), [
    ("x", 0, "a.b", "x"),
    ("x", 1, "a.b", "a.b.x"),
    ("x", 2, "a.b", "a.x"),
    (None, 1, "a.b", "a.b"),
    (None, 3, "a.b", ""),
    ("x", 4, "a.b", None),
])
def test_relative_imports_resolve_against_the_package(module: str | None, level: int, package: str,
                                                      expected: str | None) -> None:
    assert absolute_from(module, level, package) == expected


def test_a_helper_linked_into_the_tree_is_read_through_its_link(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A helper module that is a link to a file elsewhere is part of the tree where it is
    imported: an edit of its target changes the digest."""
    (tmp_path / "linkpkg").mkdir()
    (tmp_path / "linkpkg" / "__init__.py").write_text("", encoding="utf-8")
    (tmp_path / "linkpkg" / "solver.py").write_text(SOLVER.replace("from . import near\n", "from . import linked\n")
                                                    .replace("from .deep.inner import scale\n", "")
                                                    .replace("import sibling\n", "")
                                                    .replace("* scale() * near.K * sibling.K * late.K", "* linked.K")
                                                    .replace("        import late\n", ""), encoding="utf-8")
    target = tmp_path / "elsewhere" / "target.py"
    target.parent.mkdir()
    target.write_text("K = 1.0\n", encoding="utf-8")
    (tmp_path / "linkpkg" / "linked.py").symlink_to(target)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        module = importlib.import_module("linkpkg.solver")
        first = source_digest(module.Mine())
        assert "linked.py" in [f.relative.split("/")[-1] for f in class_source_files(module.Mine) or []]
        target.write_text("K = 2.0\n", encoding="utf-8")
        assert source_digest(module.Mine()) not in (None, first)
    finally:
        for name in [m for m in sys.modules if m.split(".")[0] == "linkpkg"]:
            del sys.modules[name]
        unregister("test-source-files-mine", missing_ok=True)
