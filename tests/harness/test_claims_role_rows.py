"""The Example 1 readings and the Cholesky limit read the rows that play the paper's role
(``claim_tables.playing``): a variant of greedy CG with other parameters, in the same table,
never stands for greedy CG, and params that are not a JSON object play no role."""

from __future__ import annotations

import json

import pandas as pd

from contactbench.harness.report import claims as cl
from contactbench.harness.report.claim_tables import playing, plays


def greedy_rows(scene: str, params: str, solver: str, bad: bool) -> list[dict]:
    """greedy-cg rows of ``scene`` at n = 25, seeds 0-9, all rejected (unconverged) or all passed."""
    variant = {"counterexample-2delta": "spacing-2"}.get(scene, "")
    return [{"scene": scene, "instance": f"n25-s{s}-{variant}", "seed": s, "step": 0, "solver": solver,
             "base_solver": "greedy-cg", "params": params, "profile": cl.CONDITION_PROFILES["dense"],
             "history": "warm", "repeat": 0, "status": "inaccurate" if bad else "solved",
             "verdict": "unconverged" if bad else "pass", "solver_converged": not bad, "n": 25,
             "N": 9 if variant else 5, "operator": "dense", "variant": variant, "solve_time_s": 0.01,
             "p_rel_error": 0.5 if bad else 0.0, "check_tol": 1e-6} for s in range(10)]


def test_a_greedy_variant_never_stands_for_greedy_cg_in_example_1_and_its_variants() -> None:
    for scene, claim in (("counterexample", "ex1-greedy-fails"), ("counterexample-2delta", "greedy-spacing-2delta")):
        rows = (greedy_rows(scene, "{}", "greedy-cg", bad=False)
                + greedy_rows(scene, json.dumps({"max_passes": 1}), "greedy-cg[max_passes=1]", bad=True))
        led = cl.ledger(pd.DataFrame(rows))
        mine = led[(led["claim"] == claim) & (led["condition"] == "dense")]
        assert len(mine) == 1, mine[["claim", "measured", "verdict", "evidence"]]  # one row for n = 25, not two
        assert mine.iloc[0]["measured"] == 0.0, mine.iloc[0]["evidence"]


def test_params_that_are_not_an_object_play_no_role() -> None:
    assert plays("greedy-cg", "") and plays("greedy-cg", float("nan")) and plays("greedy-cg", "{}")
    assert not plays("greedy-cg", "{bad") and not plays("greedy-cg", 5) and not plays("greedy-cg", "[1]")
    rows = pd.DataFrame({"base_solver": ["greedy-cg"] * 3, "params": ["", "{bad", json.dumps({"max_passes": 1})]})
    assert list(playing(rows, "greedy-cg").index) == [0]
