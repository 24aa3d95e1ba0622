"""The seal's rules (problems/operator_state.py) belong to the classes that declare them, not
to their names: a subclass is sealed by its bases' rules and its own, an unrelated class of
the same name by content, a renamed class by its rules; operator_state.py names no class and
imports none of the modules that declare rules."""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import ClassVar, Iterator

import numpy as np
import pytest

from contactbench.harness.judging import ProblemSeal
from contactbench.problems import operator_state
from contactbench.problems.fft_transform import _DuccWork
from contactbench.problems.instances import QP
from contactbench.problems.kernels import kernel_table
from contactbench.problems.operator_state import SealRule, seal_rule
from contactbench.problems.operators import ContactOperator, DenseOperator, FFTOperator, KernelTransform

N = 32  # grid side: a set of 40 points on it switches to the dense block at its first product


class WithUnitResponse(FFTOperator):
    """An FFT operator that keeps H 1 (built on first use) in a cache its own rule declares."""

    SEAL_RULE: ClassVar[SealRule] = SealRule(caches={"_unit": lambda op, key, current: op.fresh_unit_response()})

    def unit_response(self) -> np.ndarray:
        if getattr(self, "_unit", None) is None:
            self._unit = self.fresh_unit_response()
        return self._unit

    def fresh_unit_response(self) -> np.ndarray:
        return self.partial_product(np.arange(self.n), np.arange(self.n), np.ones(self.n))


def fft_problem(cls: type[FFTOperator] = FFTOperator) -> QP:
    """A QP on 40 points of an N x N grid, its operator of class ``cls``."""
    transform = KernelTransform(kernel_table("bcc", (N, N), 1e-6, 1e9, False), (N, N))
    H = cls(transform, np.arange(0, 4 * 40, 4))
    return QP(H, np.linspace(-1e-7, 1e-7, H.n))


def honest_products(qp: QP) -> None:
    """Products enough for the dense switch, in both precisions."""
    x = np.linspace(0.5, 1.5, qp.n)
    for _ in range(6):
        qp.H.matvec(x)
    qp.H.with_precision(np.float32).matvec(x)


def test_a_subclass_is_sealed_by_its_bases_rules_and_its_own() -> None:
    """An honest solve on a subclass of the FFT operator (another name) builds its bases'
    caches (the dense block) and its own (declared on the subclass) and leaves the seal
    whole; a write into the subclass's cache breaks it, and ``mend`` drops that cache."""
    qp = fft_problem(WithUnitResponse)
    H = qp.H
    assert isinstance(H, WithUnitResponse)
    seal = ProblemSeal.of(qp)
    honest_products(qp)
    H.unit_response()
    assert H.uses_dense and seal.broken(qp) == ""
    seal.mend(qp)
    seal = ProblemSeal.of(qp)
    H.unit_response()[0] *= 2.0
    assert "H._unit" in seal.broken(qp)
    seal.mend(qp)
    assert getattr(H, "_unit", None) is None
    assert np.allclose(H.unit_response(), H.matvec(np.ones(H.n)), rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("named_as, name", [(ContactOperator, "matvec_count"), (KernelTransform, "fft_count"),
                                            (_DuccWork, "rows"), (_DuccWork, "_field")],
                         ids=["counter-ContactOperator", "counter-KernelTransform", "work-rows", "work-field"])
def test_a_class_named_as_one_with_rules_is_sealed_by_content(named_as: type, name: str) -> None:
    """An object of an unrelated class that bears the name of a class with rules (where that
    class holds a counter or a work buffer) is sealed by content: a write into its array is
    a write into the problem."""
    namesake = type(named_as.__qualname__, (), {})()
    setattr(namesake, name, np.arange(4.0))
    qp = QP(DenseOperator(np.eye(4)), np.zeros(4))
    qp.H.helper = namesake
    seal = ProblemSeal.of(qp)
    getattr(namesake, name)[0] = 7.0
    assert f"H.helper.{name}" in seal.broken(qp)


@pytest.fixture
def renamed_fft_operator() -> Iterator[None]:
    """``FFTOperator`` under another name for the test (the rules read afresh)."""
    names = FFTOperator.__name__, FFTOperator.__qualname__
    FFTOperator.__name__ = FFTOperator.__qualname__ = "RenamedOperator"
    seal_rule.cache_clear()
    try:
        yield
    finally:
        FFTOperator.__name__, FFTOperator.__qualname__ = names
        seal_rule.cache_clear()


def test_a_renamed_class_keeps_its_rules(renamed_fft_operator: None) -> None:
    """The rules follow the class, whatever its name: an honest solve that builds the dense
    block of a renamed FFT operator leaves the seal whole."""
    qp = fft_problem()
    seal = ProblemSeal.of(qp)
    honest_products(qp)
    assert qp.H.uses_dense and seal.broken(qp) == ""


def problem_class_names(folder: Path) -> set[str]:
    """The names of the classes the modules under ``folder`` define."""
    return {node.name for path in folder.rglob("*.py") for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.ClassDef)}


def strings_besides_docstrings(tree: ast.Module) -> list[str]:
    """The string constants of ``tree`` that are not docstrings."""
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef)) and node.body
                  and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings]


def test_operator_state_names_no_class_and_imports_no_module_that_declares_rules() -> None:
    """operator_state.py reads the rules from the classes: no string in its code names a
    class of problems/ (its own aside), and it imports no module of the package."""
    source = Path(operator_state.__file__)
    tree = ast.parse(source.read_text())
    own = {node.name for node in ast.walk(tree) if isinstance(node, ast.ClassDef)}
    others = problem_class_names(source.parent) - own
    assert {"ContactOperator", "FFTOperator", "KernelTransform"} <= others
    named = {word for text in strings_besides_docstrings(tree) for word in re.findall(r"[A-Za-z_]\w*", text)}
    assert named & others == set()
    imports = [node for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))]
    assert [ast.unparse(node) for node in imports if isinstance(node, ast.ImportFrom) and node.level > 0] == []
    assert [ast.unparse(node) for node in imports if "contactbench" in ast.unparse(node)] == []


class SlowCount(int):
    """A count that acts when counted (it would slow or break the next solve's products)."""

    def __add__(self, other: object) -> "SlowCount":
        return SlowCount(int(self) + int(other))  # type: ignore[call-overload]


@pytest.mark.parametrize("left", [SlowCount(3), None, 2.0], ids=["int-subclass", "none", "float"])
def test_a_counter_is_any_count_but_only_a_plain_int(left: object) -> None:
    """Products add to an operator's counters and leave the seal whole; a counter left as
    anything but a plain int -- a value that acts when the next solve counts -- breaks it."""
    qp = fft_problem()
    seal = ProblemSeal.of(qp)
    honest_products(qp)
    assert qp.H.matvec_count > 0 and seal.broken(qp) == ""
    qp.H.matvec_count = left  # type: ignore[assignment]
    assert "matvec_count" in seal.broken(qp)
