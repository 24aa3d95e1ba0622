"""Adds the external solvers of the manifests (``contactbench.solvers.external``) to the
registry, as a late source (``registry.add_late_source``).

Imported by the solver registry's discovery, this module reads nothing: the files named
by ``CONTACTBENCH_EXTERNAL_SOLVERS`` and ``./contactbench-solvers.toml`` are read when
external solvers are resolved -- a name that is not a built-in solver, or the list of
every solver.  A broken manifest is then reported by ``contactbench list solvers`` as an
import error naming the file, the entry and the key (the good manifests are registered
first), and by the lookup of a name it should have declared.
"""

from __future__ import annotations

from .external import register_manifests
from .registry import add_late_source

add_late_source(__name__, register_manifests)
