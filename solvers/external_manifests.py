"""Registers the external solvers of the manifests (``contactbench.solvers.external``).

Imported by the solver registry's discovery: every entry of the files named by
``CONTACTBENCH_EXTERNAL_SOLVERS`` and of ``./contactbench-solvers.toml`` becomes a
registered solver.  A broken manifest makes this module fail to import, which
``contactbench list solvers`` reports as an import error naming the file, the entry and
the key; the good manifests are registered first.
"""

from __future__ import annotations

from .external import register_manifests

REGISTERED = register_manifests()
