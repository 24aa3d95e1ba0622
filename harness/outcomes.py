"""A judged answer as a pytest outcome (``settle``): the one rule of the plugin's fixtures
(harness/pytest_plugin.py) and of judged benchmarks (harness/judged_benchmark.py).
Imports nothing beyond pytest (the plugin is loaded in every pytest session)."""

from __future__ import annotations

from typing import Any

import pytest


def settle(verdict: Any, what: str, solver_message: str = "") -> None:
    """The pytest outcome of a judged answer (``harness.judging.Verdict``), as in
    ``contactbench validate``: reading "wrong" (a failing answer claimed as converged,
    or a solver that wrote into its problem or left threads running, claimed or not: the
    message then says which, in the verdict's words) fails the test;
    "unconverged" (the solver said it did not converge) is an xfail; "pass" returns."""
    figures = ", ".join(f"{k} {float(verdict.figures[k]):.3e}" for k in
                        ("kkt_error", "primal_residual", "dual_residual", "complementarity", "p_rel_error",
                         "load_rel_error") if k in verdict.figures) or f"kkt_error {verdict.kkt_error:.3e}"
    if verdict.reading == "wrong":  # (unclaimed: the verdict's own message says why -- a write, threads left)
        who = "the solver claims convergence but " if verdict.claimed else ""
        pytest.fail(f"{what}: {who}the judge reads the answer as wrong: {verdict.message()}; KKT figures: {figures}",
                    pytrace=False)
    if verdict.reading == "unconverged":
        pytest.xfail(f"{what}: not converged, as the solver says ({solver_message or 'no message'}): "
                     f"{'; '.join(verdict.problems)}; KKT figures: {figures}")


__all__ = ["settle"]
