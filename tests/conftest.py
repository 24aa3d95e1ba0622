"""The test suite's shared set-up.

The installed pytest plugin (``contactbench.harness.pytest_plugin``) gives users the
fixtures ``contact_instance``, ``run_harness``, ``contactbench_conformance`` and
``contactbench_settle``; the suite uses them as a user would.  What only the suite needs
is here and in tests/helpers.py (test modules never import each other):

* the throw-away ``test-*`` solvers of tests/helpers.py are registered for every test,
  whichever test modules a session collects (importing helpers registers them);
* ``in_tmp``: the test runs in an empty folder of its own, and ``sys.path`` is restored
  after it (a ``module:NAME`` solver load may add the current folder);
* every test starts with no map warning announced (``problems.io`` announces each once per
  process), so that what a test sees warned does not hang on the tests run before it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from contactbench.problems import io as map_io
from tests import helpers  # noqa: F401 -- importing it registers the test-* solvers


@pytest.fixture(autouse=True)
def no_map_warning_announced(monkeypatch: pytest.MonkeyPatch) -> None:
    """A fresh once-per-process set of announced map warnings for each test."""
    monkeypatch.setattr(map_io, "_ANNOUNCED", set())


@pytest.fixture
def in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Run in ``tmp_path`` (the current folder) with a copy of ``sys.path``."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))
    return tmp_path
