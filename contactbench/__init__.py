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
``harness/``; ``pyproject.toml`` maps them under this package.
"""

from __future__ import annotations

import os as _os

__version__ = "0.2.0"

# Editable installs and in-tree use: the floors live beside this folder, not inside it.
_ROOT = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if all(_os.path.isdir(_os.path.join(_ROOT, d)) for d in ("problems", "solvers", "harness")):
    if _ROOT not in __path__:
        __path__.append(_ROOT)
