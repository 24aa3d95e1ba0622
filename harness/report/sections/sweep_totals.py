"""What Fig. 4 (sections/paper.py) sums over a load sweep, per solver label: the steps
it solved out of the sweep's steps, its total solve time where that total covers the
whole sweep, the accuracy its answers bought, and the best solver of each family.

A *step of the sweep* is a distinct (instance, step) of the scene at the profile drawn,
skipped ones included: a solver skipped at a step has no time there, so its sum over
the steps it ran is not a total over the sweep and is never ranked against one.  A solver
with no row at a step (a run appended to the folder for other solvers) was not run there:
its steps solved are counted over the steps it was run on, and say so.
"""

from __future__ import annotations

from typing import Any, Callable

import pandas as pd

from ...table.schema import ANSWERED
from ..core import fmt_err, fmt_num, natural_key, natural_sorted
from ..markdown_text import md_code
from .generic import OWN_REF, REF_CELL

#: The rule ``best_per_family`` applies, as the figure's caption states it.
BEST_RULE = ("the best of a family is its solver that solved the most steps, then the one with the least time "
             "over its solved steps; a family none of whose solvers solved a step has none")
#: Which answers the worst kkt and worst p error of the totals count (the "inaccurate
#: answers" table of Skips and failures counts the same ones).
WORST_RULE = ("worst kkt and worst p err are over the answers the judge read (solved and inaccurate); a timed-out, "
              "failed or crashed solve is counted in the steps but not there; worst p err leaves out the answers "
              "that served as the reference (0 by construction), and is 'ref' where those are a solver's only ones")


def sweep_steps(rows: pd.DataFrame) -> int:
    """The number of steps of the sweep: distinct (instance, step) of ``rows`` (every
    status, skipped included)."""
    return len(rows[["instance", "step"]].drop_duplicates())


def _steps_of(cells: pd.DataFrame) -> pd.Series:
    """Per solver label, its distinct (instance, step)."""
    return cells.drop_duplicates(["solver", "instance", "step"]).groupby("solver", sort=False).size()


def sweep_totals(cells: pd.DataFrame, n_steps: int, every: pd.DataFrame | None = None) -> pd.DataFrame:
    """Per solver label of ``cells`` (``per_cell`` of the attempted rows, one label per
    curve), over a sweep of ``n_steps`` steps: ``steps`` (the sweep's), ``planned`` (the
    steps it has a row at in ``every``, the same cells with the skipped ones: the steps it
    was run on; the sweep's without ``every``), ``run`` (steps with a time), ``solved``
    (steps solved), ``complete`` (every step of the sweep solved),
    ``total_s`` (solve time summed over the steps run), ``solved_s`` (over the steps
    solved), ``worst_kkt`` and ``worst_p_err`` (over the answered cells, schema.ANSWERED,
    the error in p leaving out the answers that served as the reference, ``OWN_REF``; NaN
    when none answered) and ``reference_only`` (``reference_only``)."""
    labels = pd.Index(list(dict.fromkeys(cells["solver"])), name="solver")
    run = _steps_of(cells).reindex(labels, fill_value=0)
    planned = n_steps if every is None else _steps_of(every).reindex(labels, fill_value=0)
    solved = _steps_of(cells[cells["solved"]]).reindex(labels, fill_value=0)
    g = cells.groupby("solver", sort=False)
    answered = cells[cells["status"].isin(ANSWERED)].groupby("solver", sort=False)
    return pd.DataFrame({
        "steps": n_steps, "planned": planned, "run": run, "solved": solved, "complete": solved >= n_steps,
        "total_s": g["solve_time_s"].sum(min_count=1).reindex(labels),
        "solved_s": cells[cells["solved"]].groupby("solver")["solve_time_s"].sum().reindex(labels, fill_value=0.0),
        "worst_kkt": answered["kkt_error"].max().reindex(labels),
        "worst_p_err": measured_p_errors(cells).groupby(cells["solver"], sort=False).max().reindex(labels),
        "reference_only": reference_only(cells).reindex(labels, fill_value=False)}, index=labels)


def measured_p_errors(cells: pd.DataFrame) -> pd.Series:
    """The error in p of each answered cell (schema.ANSWERED) that measures something: NaN
    for the others and for an answer that served as its step's reference (``OWN_REF``: 0
    by construction)."""
    own = cells[OWN_REF] if OWN_REF in cells else pd.Series(False, index=cells.index)
    return cells["p_rel_error"].where(cells["status"].isin(ANSWERED) & ~own.astype(bool))


def reference_only(cells: pd.DataFrame) -> pd.Series:
    """Per solver label: its only answers with an error in p are those that served as the
    reference (the totals table says "ref" there, not a worst error)."""
    if OWN_REF not in cells:
        return pd.Series(False, index=pd.Index(list(dict.fromkeys(cells["solver"]))))
    has_p = cells["status"].isin(ANSWERED) & cells["p_rel_error"].notna()
    g = pd.DataFrame({"solver": cells["solver"], "own": has_p & cells[OWN_REF].astype(bool),
                      "other": has_p & ~cells[OWN_REF].astype(bool)}).groupby("solver", sort=False)
    return g["own"].any() & ~g["other"].any()


def ranked_labels(tot: pd.DataFrame) -> list[str]:
    """The labels of ``sweep_totals`` in reading order: those that solved the whole sweep
    by total time, then the others by steps solved (most first), then by name."""
    return sorted(tot.index, key=lambda s: (not tot.loc[s, "complete"],
                                            float(tot.loc[s, "total_s"]) if tot.loc[s, "complete"] else 0.0,
                                            -int(tot.loc[s, "solved"]), natural_key(s)))


def total_text(t: pd.Series) -> str:
    """The "total [s]" cell of a ``sweep_totals`` row: the total over the whole sweep, or,
    for a solver that did not solve every step, "-" with its time over the steps it ran
    in parentheses (a partial sum, not comparable to a total)."""
    if t["complete"]:
        return fmt_num(t["total_s"])
    if not t["run"]:
        return "-"
    if t["planned"] < t["steps"]:
        over = "" if t["run"] == t["planned"] else f"{int(t['run'])} of "
        return (f"- ({fmt_num(t['total_s'])} over {over}the {int(t['planned'])} steps it was run on, of the sweep's "
                f"{int(t['steps'])})")
    return f"- ({fmt_num(t['total_s'])} over {int(t['run'])} of {int(t['steps'])} steps)"


def totals_rows(tot: pd.DataFrame, family_of: Callable[[str], str]) -> list[tuple[Any, ...]]:
    """The rows of Fig. 4's totals table, in ``ranked_labels`` order: solver, family,
    steps solved (of the steps it was run on, ``planned``), total [s] (``total_text``), worst
    kkt, worst p err."""
    return [(s, family_of(s), f"{int(tot.loc[s, 'solved'])} of {int(tot.loc[s, 'planned'])}",
             total_text(tot.loc[s]), fmt_err(tot.loc[s, "worst_kkt"]),
             REF_CELL if tot.loc[s, "reference_only"] else fmt_err(tot.loc[s, "worst_p_err"]))
            for s in ranked_labels(tot)]


def best_per_family(tot: pd.DataFrame, family_of: Callable[[str], str]) -> dict[str, str]:
    """Family -> its best label in ``sweep_totals`` (``BEST_RULE``): most steps solved,
    then the least time over the solved steps, then the natural order of the labels.  A
    label that solved no step is never a family's best."""
    best: dict[str, str] = {}
    ranked: dict[str, tuple[int, float]] = {}
    for lab in natural_sorted(tot.index):
        solved = int(tot.loc[lab, "solved"])
        if solved == 0:
            continue
        key = (-solved, float(tot.loc[lab, "solved_s"]))
        f = family_of(lab)
        if f not in ranked or key < ranked[f]:
            ranked[f], best[f] = key, lab
    return best


def skipped_note(tot: pd.DataFrame) -> str:
    """Caption text naming, per drawn label, the steps of the sweep it has no time at
    (skipped, or not run), which leave no mark on the figure; "" when none."""
    short = [(s, int(tot.loc[s, "planned"]) - int(tot.loc[s, "run"])) for s in natural_sorted(tot.index)]
    short = [(s, k) for s, k in short if k > 0]
    if not short:
        return ""
    steps = int(tot["steps"].iloc[0])
    return (f" Steps a solver skipped leave no mark (Skips and failures says why); skipped of the sweep's {steps}: "
            + ", ".join(f"{md_code(s)} {k}" for s, k in short) + ".")


def total_ratio(tot: pd.DataFrame, a: str | None, b: str | None) -> float:
    """Total time of ``a`` over ``b``; NaN unless both solved the whole sweep."""
    if a is None or b is None or a not in tot.index or b not in tot.index:
        return float("nan")
    if not (tot.loc[a, "complete"] and tot.loc[b, "complete"]):
        return float("nan")
    return float(tot.loc[a, "total_s"] / tot.loc[b, "total_s"])


#: The accuracy levels at which the Fig. 4 reading names the fastest solver.
ACCURACY_LEVELS = (1e-6, 1e-8, 1e-10, 1e-12)


def time_at(tot: pd.DataFrame, s: str) -> str:
    """"`s` (12.3 s, kkt <= 4.0e-09)": a time always comes with the accuracy it bought."""
    return f"{md_code(s)} ({fmt_num(tot.loc[s, 'total_s'])} s, worst kkt {fmt_err(tot.loc[s, 'worst_kkt'])})"


def fastest_at_accuracy(tot: pd.DataFrame) -> list[tuple[float, str]]:
    """(level, solver): per accuracy level, the fastest solver whose every step is
    solved with kkt_error <= level (levels no solver reaches are left out, and a level
    is kept only when its winner differs from the next looser level's)."""
    complete = tot[tot["complete"] & tot["worst_kkt"].notna()]
    out: list[tuple[float, str]] = []
    for level in ACCURACY_LEVELS:
        ok = complete[complete["worst_kkt"] <= level]
        if ok.empty:
            break
        best = str(ok["total_s"].idxmin())
        if not out or out[-1][1] != best:
            out.append((level, best))
        else:
            out[-1] = (level, best)
    return out
