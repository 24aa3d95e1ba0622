"""Why a CMR answer fails the check, from what the table carries: the CMR solve counts the
contact points its pruning (step 1.2 of Algorithm 6) left out, the points outside the fine
projected set whose gap is negative (``info["left_out"]``), and begins its message with them;
the report's failures section prints, beside the inaccurate answers, each solver's own words
for the answers it did not claim (``own_accounts``: columns ``solver_converged`` and
``solver_message``, whatever the solver's name)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from contactbench.harness.report import core as rp
from contactbench.harness.report.sections.generic import skips_section
from contactbench.harness.table.schema import ALL_COLUMNS
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.surfaces import rmd_surface_n
from contactbench.solvers import SolverSettings
from contactbench.solvers.cmr import CMRSolver, left_out_text
from tests.helpers import META, report_row

#: A cascade that prunes contacts the fine answer needs: h = 1 on a 64^2 surface of H = 0.5.
PRUNING = {"h": 1.0, "coarsest": 16}


def pruning_instance():  # noqa: ANN201 - a ContactInstance
    s = rmd_surface_n(64, 0.5, seed=2)
    return InstanceBuilder(s, 1e9, "bcc").build(paper_max_displacement(s))


def overlapping_unloaded(inst, p: np.ndarray) -> int:  # noqa: ANN001
    """The trial-set points with no force and a gap below -1e-9 max|ubar|: the judge's
    negative gaps, counted from the harness's own H and ubar."""
    w = inst.qp.H.matvec(p) - inst.qp.ubar
    return int(np.count_nonzero((p == 0) & (w < -1e-9 * np.max(np.abs(inst.qp.ubar)))))


def test_a_pruning_cascade_counts_the_contacts_it_left_out_and_says_so_first() -> None:
    inst = pruning_instance()
    res = CMRSolver("nnls").solve(inst.qp, SolverSettings(tol=1e-9, params=dict(PRUNING)))
    k = res.info["left_out"]
    assert k > 0 and not res.converged
    assert k == overlapping_unloaded(inst, np.asarray(res.p))
    assert res.message.startswith(left_out_text(k, repair=False))
    assert "step 1.2 of Algorithm 6" in res.message and "repair=True re-admits them" in res.message
    repaired = CMRSolver("nnls").solve(inst.qp, SolverSettings(tol=1e-9, params={**PRUNING, "repair": True}))
    assert repaired.info["left_out"] == 0 and repaired.converged and "left out" not in repaired.message


def failures_body(tmp: Path, rows: list[dict]) -> str:
    ctx = rp.ReportContext(tmp, pd.DataFrame(rows, columns=list(ALL_COLUMNS)), dict(META))
    return skips_section(ctx, ctx.table).body


def test_the_failures_section_prints_a_solvers_own_words_for_the_answers_it_did_not_claim(tmp_path: Path) -> None:
    """Any solver (the name is never read): its unclaimed inaccurate answers are counted and
    the message of the worst is printed; an answer claimed as converged (a false claim) is
    not explained by its own message, and a solved one is no failure."""
    why = left_out_text(57, repair=False)
    rows = [report_row(scene="paper-sweep", step=k, n=100, solver="wrap", profile="high", status="inaccurate",
                       kkt_error=kkt, solver_converged=False, solver_status="stalled",
                       solver_message=f"{why}; levels 16->32" if k == 1 else "left out 3 contact points")
            for k, kkt in enumerate((0.1, 0.5))]
    rows.append(report_row(scene="paper-sweep", step=0, n=100, solver="greedy", profile="high", status="inaccurate",
                           kkt_error=0.02, solver_converged=True, solver_message="no negative p after 7 passes"))
    rows.append(report_row(scene="paper-sweep", step=0, n=100, solver="pk", profile="high"))
    body = failures_body(tmp_path, rows)
    note = body[body.index("In the solvers' own words"):]
    assert "`wrap` (paper-sweep, profile `high`): 2 of its answers; at the worst (instance i0, step 1)" in note
    assert why in note
    assert "greedy" not in note and "`pk`" not in note



def test_a_long_message_keeps_its_first_and_last_words() -> None:
    """A solver's message names what it did first and its verdict last: past the limit
    its middle is left out, not its end."""
    from contactbench.harness.report.sections.generic import ends_of

    line = "CMR 16->32 " + "x" * 400 + " the cascade pruned points (repair=True makes it exact)"
    cut = ends_of(line, 200)
    assert len(cut) <= 200 and cut.startswith("CMR 16->32") and cut.endswith("(repair=True makes it exact)")
    assert " ... " in cut and ends_of("short", 200) == "short"
