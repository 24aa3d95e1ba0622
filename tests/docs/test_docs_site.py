"""The user's guide (mkdocs.yml, docs/) builds and says true things.

* ``mkdocs build --strict`` passes: every page in the nav, no broken link, the API reference
  collected from the code;
* the tutorial notebook is stored without outputs and the build executes it: the page shows
  its outputs (the conformance tables, the caught solver, the figures);
* every column of the committed results table is in the column glossary, and every schema
  column has a unit;
* the Python in the pages is checked against the code: every ``python`` block parses, its
  ``contactbench`` imports exist and its calls of them bind to their signatures; the blocks
  run (page by page, in order); and call-shaped inline code naming a public function uses
  its real parameter names (a ``rmd_surface(k, H, ...)`` listing, or ``H=0.7``, fails).
"""

from __future__ import annotations

import ast
import functools
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import nbformat
import pandas as pd
import pytest

from tests.helpers import REPO

DOCS = REPO / "docs"
NOTEBOOK = DOCS / "tutorial.ipynb"
HOOK = DOCS / "hooks" / "contactbench_docs.py"
#: Pages whose python blocks are checked but not run here, and why.
NOT_RUN = {
    "adding-a-solver.md": "its blocks are tests/example_solver.py and a pytest file, run by tests/docs/test_docs.py",
    "distributed.md": "its blocks start a SLURM or local Dask cluster",
}
#: ipykernel's note, when the build executes the tutorial, that its kernel talks to the build
#: over local TCP: the kernel's log, not a warning of the build.
KERNEL_TRANSPORT_NOTE = "[IPKernelApp] WARNING | Kernel is running over TCP without encryption."
#: The modules whose public functions and classes inline code may name.
PUBLIC_PACKAGES = ("contactbench.problems", "contactbench.solvers", "contactbench.harness")


def load_hook() -> ModuleType:
    spec = importlib.util.spec_from_file_location("contactbench_docs_hook", HOOK)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def pages() -> list[Path]:
    return sorted(DOCS.glob("*.md"))


def python_blocks(text: str) -> list[tuple[int, str]]:
    """(first line number, source) of every ```python fenced block."""
    out, lines = [], text.splitlines()
    i = 0
    while i < len(lines):
        if re.match(r"^```python\s*$", lines[i]):
            start, body = i + 2, []
            i += 1
            while i < len(lines) and not lines[i].startswith("```"):
                body.append(lines[i])
                i += 1
            out.append((start, "\n".join(body) + "\n"))
        i += 1
    return out


# ---------------------------------------------------------------------------
# The strict build
# ---------------------------------------------------------------------------


@pytest.mark.slow
def test_the_site_builds_in_strict_mode(tmp_path: Path) -> None:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
                          check=False, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mkdocs build --strict failed (install the docs extra: make setup):\n{log}"
    warnings = [ln for ln in log.splitlines() if "WARNING" in ln and not ln.startswith(KERNEL_TRANSPORT_NOTE)]
    assert warnings == [], log
    site = tmp_path / "site"
    columns = (site / "columns.html").read_text()
    assert "kkt_error" in columns and "glossary: generated" not in columns
    tutorial = (site / "tutorial.html").read_text()
    assert "CONFORMS" in tutorial, "the tutorial's own solver should conform, on the page"
    assert "caught:" in tutorial and "WRONG" in tutorial, "the tutorial's impatient solver should be caught"
    assert "same heights: True" in tutorial, "the read-back of a stored map keeps its heights"
    assert "data:image/png" in tutorial, "the tutorial draws the pressure field and the load-area curve"
    api = (site / "api" / "solvers.html").read_text()
    assert "SolverSettings" in api and "get_solver" in api
    hook = load_hook()
    shown = re.findall(r'src="(report-figures/[^"]+)"', (site / "figures.html").read_text())
    assert shown, "docs/figures.md shows no report figure"
    for rel in shown:
        assert (site / rel).is_file(), f"figures page shows {rel}, which the build did not copy"
        assert rel in hook.figure_sources(), rel


# ---------------------------------------------------------------------------
# The notebook
# ---------------------------------------------------------------------------


def test_the_notebook_is_stored_without_outputs() -> None:
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert len(code) >= 8
    for c in code:
        assert not c.outputs and c.execution_count is None, f"stored with outputs: {c.source[:60]!r}"


# ---------------------------------------------------------------------------
# The column glossary
# ---------------------------------------------------------------------------


def glossary_missing(columns: list[str], glossary: str) -> list[str]:
    return [c for c in columns if f"| `{c}` |" not in glossary]


def test_every_column_of_the_committed_table_is_in_the_glossary() -> None:
    hook = load_hook()
    glossary = hook.glossary_markdown()
    columns = list(pd.read_parquet(REPO / "results" / "default" / "results.parquet").columns)
    assert len(columns) > 20
    assert glossary_missing(columns, glossary) == []
    assert glossary_missing(["not_a_column"], glossary) == ["not_a_column"]  # the check bites
    assert hook.GLOSSARY_MARKER in (DOCS / "columns.md").read_text()


def test_every_schema_column_has_a_unit_and_no_unit_is_stale() -> None:
    from contactbench.harness.table import schema

    hook = load_hook()
    assert set(hook.UNITS) == set(schema.COLUMNS)
    rows = hook.glossary_rows()
    assert [r[0] for r in rows] == list(schema.COLUMNS)
    assert all(r[2] and r[3] for r in rows)


def test_the_schema_definitions_reach_the_glossary() -> None:
    hook = load_hook()
    defs = hook.schema_definitions()
    assert {"delta", "load", "contact_fraction", "kkt_error", "p_rel_error", "load_rel_error", "status",
            "verdict"} <= set(defs)
    assert "check_tol x p_s" in defs["contact_fraction"]
    doc = "x\n\nDefinitions of the less obvious figures\n---\nload   first\n       second\nnoise  not a column\n\nload_rel_error  again\n"
    assert hook.schema_definitions(doc) == {"load": "first second", "load_rel_error": "again"}
    assert hook.schema_definitions("no such section") == {}
    row = {r[0]: r for r in hook.glossary_rows()}
    assert "solved/inaccurate" in row["status"][3] and "STATUSES" not in row["status"][3]


# ---------------------------------------------------------------------------
# The Python in the pages
# ---------------------------------------------------------------------------


def _binds(fn: Any, n_args: int, keywords: list[str], drop_self: bool = False) -> str | None:
    """None when a call with ``n_args`` positional arguments and these keywords binds to
    ``fn``'s signature, else the reason."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return None
    if drop_self:
        params = list(sig.parameters.values())[1:]
        sig = sig.replace(parameters=params)
    try:
        sig.bind_partial(*([None] * n_args), **{k: None for k in keywords})
    except TypeError as exc:
        return str(exc)
    return None


def imported_names(tree: ast.AST) -> tuple[dict[str, Any], list[str]]:
    """The contactbench names a block imports (local name -> object), and import errors."""
    names: dict[str, Any] = {}
    errors: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("contactbench"):
            try:
                mod = importlib.import_module(node.module)
            except ImportError as exc:
                errors.append(f"line {node.lineno}: from {node.module} import ...: {exc}")
                continue
            for a in node.names:
                if not hasattr(mod, a.name):
                    errors.append(f"line {node.lineno}: {node.module} has no {a.name!r}")
                else:
                    names[a.asname or a.name] = getattr(mod, a.name)
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("contactbench"):
                    try:
                        names[a.asname or a.name] = importlib.import_module(a.name)
                    except ImportError as exc:
                        errors.append(f"line {node.lineno}: import {a.name}: {exc}")
    return names, errors


def check_block(source: str) -> list[str]:
    """What is wrong with a python block against the code (parse, imports, call signatures)."""
    try:
        tree = ast.parse(source)
    except SyntaxError as exc:
        return [f"does not parse: {exc}"]
    names, errors = imported_names(tree)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call) or any(isinstance(a, ast.Starred) for a in node.args) \
                or any(k.arg is None for k in node.keywords):
            continue
        fn = None
        if isinstance(node.func, ast.Name):
            fn = names.get(node.func.id)
        elif isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name):
            owner = names.get(node.func.value.id)
            if isinstance(owner, ModuleType):
                fn = getattr(owner, node.func.attr, None)
        if fn is None or not callable(fn):
            continue
        why = _binds(fn, len(node.args), [k.arg for k in node.keywords if k.arg])
        if why:
            errors.append(f"line {node.lineno}: {ast.unparse(node.func)}(...): {why}")
    return errors


def public_modules() -> list[ModuleType]:
    """The three packages and their public modules (the peers' and the GPU's optional
    back ends left out)."""
    import pkgutil

    out = []
    for pkg_name in PUBLIC_PACKAGES:
        pkg = importlib.import_module(pkg_name)
        out.append(pkg)
        out += [importlib.import_module(f"{pkg_name}.{m.name}") for m in pkgutil.iter_modules(pkg.__path__)
                if not m.name.startswith("_") and m.name not in {"peer_cm", "peer_tamaas", "operators_gpu"}]
    return out


@functools.cache
def public_callables() -> dict[str, Any]:
    """Name -> function or class defined in a public module of the three packages; names
    defined twice with different objects are left out (ambiguous)."""
    found: dict[str, Any] = {}
    ambiguous: set[str] = set()
    for mod in public_modules():
        for name, obj in vars(mod).items():
            if name.startswith("_") or not (inspect.isfunction(obj) or inspect.isclass(obj)):
                continue
            if getattr(obj, "__module__", "").split(".")[0] != "contactbench":
                continue
            if name in found and found[name] is not obj:
                ambiguous.add(name)
            found.setdefault(name, obj)
    return {k: v for k, v in found.items() if k not in ambiguous}


@functools.cache
def module_names() -> frozenset[str]:
    return frozenset(m.__name__.rsplit(".", 1)[-1] for m in public_modules())


_CALL_START = re.compile(r"`([A-Za-z_][\w.]*)\(")
_KEYWORD = re.compile(r"^(\w+)\s*=")
_NAME = re.compile(r"^([A-Za-z_]\w*)\b")


def call_items(text: str, start: int) -> list[str] | None:
    """The top-level comma-separated items from ``text[start]`` (just after an opening
    parenthesis) to its matching close, or None when the span ends first."""
    items, depth, cur, quote = [], 0, "", ""
    for ch in text[start:]:
        if ch == "`":
            return None
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            if depth == 0:
                items.append(cur)
                return [" ".join(i.split()) for i in items if i.strip()]
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(cur)
            cur = ""
            continue
        cur += ch
    return None


def _callable_of(dotted: str, table: dict[str, Any]) -> tuple[Any, bool]:
    """The public function or class (or ``Class.method``) an inline call names, and
    whether its first parameter (self / cls) is implicit."""
    parts = dotted.split(".")
    if len(parts) >= 2 and inspect.isclass(table.get(parts[-2])):
        fn = inspect.getattr_static(table[parts[-2]], parts[-1], None)
        if isinstance(fn, staticmethod):
            return fn.__func__, False
        if isinstance(fn, classmethod):
            return fn.__func__, True
        return fn, True
    if len(parts) >= 2 and parts[-2] not in module_names():
        return None, False  # a method of some object (``inst.load(p)``): run, not checked, here
    return table.get(parts[-1]), False


def check_inline_calls(text: str, table: dict[str, Any]) -> list[str]:
    """Inline code shaped like ``f(a, b, c=1)`` where f is a public function or class (or
    ``Class.method``).  Every ``name=`` must be a parameter.  With a keyword present (a
    signature listing, or a keyword call) every bare name must be a parameter too, unless
    it is an upper-case placeholder of three letters or more (``DIR``, not ``H``); without
    one, the count of arguments must fit.  A function taking ``**kwargs`` accepts any
    keyword here (``rmd_surface_n`` passes them on): running the blocks catches those."""
    errors = []
    for m in _CALL_START.finditer(text):
        fn, implicit_first = _callable_of(m.group(1), table)
        items = call_items(text, m.end())
        if fn is None or not callable(fn) or items is None:
            continue
        try:
            sig = inspect.signature(fn)
        except (TypeError, ValueError):
            continue
        params = list(sig.parameters.values())[1 if implicit_first else 0:]
        names = {p.name for p in params}
        open_kw = any(p.kind is p.VAR_KEYWORD for p in params)
        items = [i for i in items if i not in {"...", "*", "/"} and not i.startswith("*")]
        keywords = [k.group(1) for k in map(_KEYWORD.match, items) if k]
        bare = [i for i in items if not _KEYWORD.match(i)]
        where = f"line {text.count(chr(10), 0, m.start()) + 1}: `{m.group(1)}(...)`"
        errors += [f"{where}: no parameter {k!r}" for k in keywords if k not in names and not open_kw]
        if keywords:
            for item in bare:
                n = _NAME.match(item)
                if n and n.group(1) not in names and not (len(n.group(1)) > 2 and n.group(1).isupper()):
                    errors.append(f"{where}: lists {n.group(1)!r}, which is no parameter of {sorted(names)}")
        elif not any(p.kind is p.VAR_POSITIONAL for p in params) and len(bare) > len(params):
            errors.append(f"{where}: {len(bare)} arguments, {len(params)} parameters")
    return errors


def test_the_checks_catch_a_wrong_hurst_name() -> None:
    table = public_callables()
    assert "rmd_surface" in table and "judge" in table
    bad_block = "from contactbench.problems.surfaces import rmd_surface\ns = rmd_surface(6, H=0.7)\n"
    assert any("'H'" in e for e in check_block(bad_block))
    assert check_block("from contactbench.problems.surfaces import rmd_surface\ns = rmd_surface(6, hurst=0.7)\n") == []
    assert check_block("import contactbench.problems.surfaces as s\ns.spectral_surface(8, H=0.5)\n")
    assert check_block("from contactbench.solvers import no_such_name\n")
    assert check_block("def broken(:\n")
    listing = "`rmd_surface(k, H, length, rms_height, seed, periodic=True, min_level=2)`"
    assert any("lists 'H'" in e for e in check_inline_calls(listing, table))
    assert check_inline_calls("`spectral_surface(N, H=0.7)`", table)
    assert check_inline_calls("`build_report(DIR, shift=...)` `rmd_surface(k, hurst, seed=0)`", table) == []
    assert check_inline_calls("`Solver.solve(qp, settings, warm, extra)`", table)
    assert check_inline_calls("`Solver.solve(qp, settings, warm)` and `rmd_surface_n(N, hurst, family=None)`",
                              table) == []


@pytest.mark.parametrize("page", [p.name for p in pages()] + ["../README.md"])
def test_the_python_of_a_page_matches_the_code(page: str) -> None:
    text = (DOCS / page).read_text()
    errors = [f"{page} block at line {line}: {e}" for line, src in python_blocks(text) for e in check_block(src)]
    errors += [f"{page} {e}" for e in check_inline_calls(text, public_callables())]
    assert errors == []


_DOTTED = re.compile(r"`((?:contactbench\.)?(?:problems|solvers|harness)(?:\.[A-Za-z_]\w*)+)")


def unresolved_names(text: str) -> list[str]:
    """Backticked dotted names of the packages (``harness.judging.judge``,
    ``contactbench.problems.kkt``) that name no module or attribute."""
    bad = []
    for m in _DOTTED.finditer(text):
        parts = m.group(1).removeprefix("contactbench.").split(".")
        obj: Any = None
        for i in range(len(parts), 0, -1):
            try:
                obj, rest = importlib.import_module("contactbench." + ".".join(parts[:i])), parts[i:]
                break
            except ImportError:
                continue
        for name in rest if obj is not None else ():
            obj = getattr(obj, name, None)
            if obj is None:
                break
        if obj is None:
            bad.append(m.group(1))
    return bad


def test_dotted_names_in_the_pages_exist() -> None:
    assert unresolved_names("`harness.judging.judge` `contactbench.problems.kkt.kkt_check`") == []
    assert unresolved_names("`harness.judging.no_such` `problems.nowhere`") == ["harness.judging.no_such",
                                                                               "problems.nowhere"]
    bad = {p.name: unresolved_names(p.read_text()) for p in [*pages(), REPO / "README.md"]}
    assert {k: v for k, v in bad.items() if v} == {}


RUN_PAGES = [p.name for p in pages() if python_blocks(p.read_text()) and p.name not in NOT_RUN]


def test_the_pages_with_library_calls_are_run() -> None:
    assert {"getting-started.md", "columns.md"} <= set(RUN_PAGES)


@pytest.mark.parametrize("page", RUN_PAGES)
def test_the_python_blocks_of_a_page_run(page: str, tmp_path: Path) -> None:
    blocks = python_blocks((DOCS / page).read_text())
    script = tmp_path / "page.py"
    script.write_text("".join(f"# {page}, block at line {line}\n{src}\n" for line, src in blocks))
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(script)], check=False, cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, f"{page}: its python blocks fail:\n{proc.stdout}\n{proc.stderr}"
