"""contactbench: a benchmark harness for rough-surface normal contact QPs.

The project's three floors are installed under this one namespace, so nothing with a
generic name (``problems``, ``solvers``, ``harness``) lands in a user's environment:

* ``contactbench.problems`` -- surfaces, kernels, operators, QP instances, the QP's own
  mathematics (KKT figures, the exact LCP solution), scenes (data sets);
* ``contactbench.solvers``  -- the solver extension point (``Solver``, ``SolveResult``,
  ``register``) and every registered solver;
* ``contactbench.harness``  -- profiles, studies, the runner, the judge, tables, reports,
  conformance and the command line.

In the source tree the floors are the top-level folders ``problems/``, ``solvers/`` and
``harness/``; ``pyproject.toml`` maps them under this package (``package-dir``), for a
wheel and for the editable install of ``make`` alike.
"""

from __future__ import annotations


def __getattr__(name: str) -> str:
    """``__version__``, read when asked (the one version: pyproject.toml), so that importing
    the package (the ``contactbench`` command's first step) reads no metadata."""
    if name != "__version__":
        raise AttributeError(f"module 'contactbench' has no attribute {name!r}")
    from importlib import metadata

    try:
        return metadata.version("contactbench")
    except metadata.PackageNotFoundError:  # pragma: no cover - not installed
        return "unknown"
