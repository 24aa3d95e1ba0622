"""Reading a results table for the claims ledger (``harness.report.claims``) and for the
report's readings that state its verdicts: which label plays each of the paper's methods
(``PAPER_ROLES``, ``LEDGER_ROLES``, ``by_role``), the rows the ledger reads
(``ledger_rows``), the seeds a measurement rests on, a condition's rows, and each solver
label's totals over the steps (``totals``) and their ratios (``ratio``).

A condition is an operator and the profile the study runs it at (``CONDITION_PROFILES``,
read from the study itself): every reader takes its rows through ``of_condition`` or
``under``, so a row of another profile never stands for the paper's condition.

This module and claim_measures.py are the one home of these measurements: claims.py and
the report's sections import them; they import no section."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from contactbench.solvers.admm import PAPER_PARAMS
from contactbench.solvers.registry import get_solver

from ..profiles import CLAIMS_DENSE_PROFILE, CLAIMS_FFT_PROFILE
from ..table.schema import ANSWERED, CELL_COLUMNS, bool_series
from .claim_rules import Timing, relative_range
from .core import natural_key, parse_json, per_cell

# ---------------------------------------------------------------------------
# The paper's algorithms: found by base_solver and params, never by label
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PaperRole:
    """How to find one of the paper's algorithms in a table: its registry name, the
    paper's parameter values (a row plays the role when its ``params``, read with the
    registry's defaults, are those values with every other parameter at its default:
    ``plays``), and whether the role is the warm-started run.
    ``warm=False``: cold runs first, a warm-started one only when there is no cold one;
    ``warm=True``: warm-started runs only."""

    label: str
    base_solver: str
    params: dict[str, Any] = field(default_factory=dict)
    warm: bool = False


PAPER_ROLES: dict[str, PaperRole] = {
    "nnls-gp": PaperRole("NNLS+GP", "nnls-gp", {"K": 100}),
    "nnls": PaperRole("NNLS", "nnls"),
    "pk": PaperRole("P&K 1999", "pk"),
    "pk-printed": PaperRole("P&K as printed (the paper's Algorithm 2)", "pk-printed"),
    "pk-warm": PaperRole("P&K 1999 + warm start", "pk", warm=True),
    "greedy-cg": PaperRole("greedy CG", "greedy-cg"),
    "greedy-gs": PaperRole("greedy Gauss-Seidel", "greedy-gs"),
    "greedy-chol": PaperRole("greedy Cholesky", "greedy-chol"),
    # ADMM as section 4 states it (tex 1028-1029: alpha 1.5, rho 1, eps 1e-8 with the printed
    # stop): ``solvers.admm.PAPER_PARAMS``; the registry's default ADMM is another method
    "admm": PaperRole("ADMM", "admm", dict(PAPER_PARAMS)),
}


def _defaults(base_solver: str) -> dict[str, Any] | None:
    try:
        return dict(get_solver(base_solver).param_defaults())
    except KeyError:  # (a base solver the registry does not know: its params as given)
        return None


def _params_match(params: Any, wanted: dict[str, Any], base_solver: str = "") -> bool:
    """Whether ``params`` (a row's JSON; blank or missing: none given) are ``wanted`` read with
    the registry's defaults of ``base_solver``; params that are not a JSON object match nothing."""
    blank = params is None or (isinstance(params, float) and math.isnan(params)) or (
        isinstance(params, str) and not params.strip())
    p = {} if blank else parse_json(params, None)
    if not isinstance(p, dict):
        return False
    default = _defaults(base_solver) if base_solver else None
    if default is None:
        return all(p.get(k, v) == v for k, v in wanted.items())
    return {**default, **p} == {**default, **wanted}


def plays(role: str | PaperRole, params: Any) -> bool:
    """Whether a row with ``params`` (its JSON) plays ``role`` (a key of PAPER_ROLES, or a
    role): read with the registry's defaults of the role's base solver, its parameters are
    the paper's (``PaperRole.params``) and every other one is at the registry's default."""
    r = PAPER_ROLES[role] if isinstance(role, str) else role
    return _params_match(params, r.params, r.base_solver)


def playing(rows: pd.DataFrame, role: str | PaperRole) -> pd.DataFrame:
    """The rows of ``rows`` that play ``role``: its base solver with the paper's parameters
    (``plays``), so that a variant of the same solver (other parameters) never stands for it."""
    r = PAPER_ROLES[role] if isinstance(role, str) else role
    mine = rows[rows["base_solver"] == r.base_solver]
    if "params" not in mine.columns:
        return mine
    return mine[np.array([plays(r, p) for p in mine["params"]], dtype=bool)]


def resolve_role(curves: pd.DataFrame, role: str | PaperRole) -> str | None:
    """The ``solver`` label that plays ``role`` (a key of PAPER_ROLES, or a role), or None.

    ``curves`` has one row per label (or more; duplicates are ignored) with columns
    ``solver``, ``base_solver``, ``params`` and, optionally, ``warm`` (the label is a
    warm-started run).  Among the role's base solver's labels the one with the paper's
    parameters wins, then the natural order of the labels."""
    r = PAPER_ROLES[role] if isinstance(role, str) else role
    c = curves[curves["base_solver"] == r.base_solver]
    warm = c["warm"].astype(bool) if "warm" in c.columns else pd.Series(False, index=c.index)
    if r.warm:
        c, warm = c[warm], warm[warm]
    ranked = sorted(((bool(w) != r.warm, not plays(r, p), natural_key(s), s)
                     for s, p, w in zip(c["solver"], c["params"], warm)))
    return ranked[0][-1] if ranked else None


def paper_roles(curves: pd.DataFrame) -> dict[str, str | None]:
    """Every role of PAPER_ROLES resolved in ``curves`` (see resolve_role)."""
    return {k: resolve_role(curves, k) for k in PAPER_ROLES}


#: The paper's methods as the claims ledger compares them: its algorithms (PAPER_ROLES but
#: the warm-started P&K) and pure accelerated GP; each key is the method's registry name.
LEDGER_ROLES: dict[str, PaperRole] = {**{k: r for k, r in PAPER_ROLES.items() if not r.warm},
                                      "gp": PaperRole("accelerated GP", "gp")}


def by_role(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with, in each scene, the label of each of the paper's methods (``LEDGER_ROLES``,
    found by ``base_solver`` and ``params``: ``resolve_role``, with the paper's parameter
    values only, never another variant) replaced by the role's key, and any other label
    that spells a key marked with its base solver (``"pk (bvls)"``): a label is never taken
    for the method it names.  Roles are found per scene and grid size (``N``): a size's
    own run of the method plays it there."""
    parts = []
    keys = [c for c in ("scene", "N") if c in rows.columns]
    for _, r in rows.groupby(keys, sort=False, dropna=False):
        curves = r.drop_duplicates("solver")
        params = dict(zip(curves["solver"], curves["params"]))
        players = {s: k for k, role in LEDGER_ROLES.items()
                   if (s := resolve_role(curves, role)) is not None and plays(role, params[s])}
        bases = dict(zip(curves["solver"], curves["base_solver"]))
        name = {s: players.get(s, f"{s} ({bases[s]})" if s in LEDGER_ROLES else s) for s in curves["solver"]}
        parts.append(r.assign(solver=r["solver"].map(name)))
    return pd.concat(parts) if parts else rows


#: The numbers of an answer a claim rests on (``with_numbers``).
MEASURED_COLUMNS: tuple[str, ...] = ("solve_time_s", "iterations", "load", "contact_fraction")


def with_numbers(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with each answered row lacking a finite ``MEASURED_COLUMNS`` number, or whose
    time is not in (0, its ``time_limit_s``] (no limit where the column is absent or
    blank), read as failed: a sum or median over the rest would be a verdict."""
    cols = [c for c in MEASURED_COLUMNS if c in rows.columns]
    values = rows[cols].apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    times = values[:, cols.index("solve_time_s")] if "solve_time_s" in cols else np.ones(len(rows))
    limit = (pd.to_numeric(rows["time_limit_s"], errors="coerce").fillna(math.inf).to_numpy(dtype=float)
             if "time_limit_s" in rows.columns else np.full(len(rows), math.inf))
    with np.errstate(invalid="ignore"):
        lacking = ~np.isfinite(values).all(axis=1) | ~(times > 0) | (times > limit)
    bad = rows["status"].isin(ANSWERED).to_numpy() & lacking
    return rows.assign(status=rows["status"].mask(bad, "failed"))


def one_row_per_cell(rows: pd.DataFrame) -> pd.DataFrame:
    """``rows`` with one row per cell and repeat, the first (the cell of
    ``table.schema.CELL_COLUMNS``, as ``table.reading.first_rows`` tells two rows of one
    cell without their ``cell_id``): a cell written twice under a fresh id is one
    measurement, never two in a sum."""
    keys = [c for c in (*CELL_COLUMNS, "repeat") if c in rows.columns]
    if not keys or rows.empty:
        return rows
    return rows[~rows[keys].astype(str).duplicated(keep="first")]


def ledger_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows as the claims ledger reads them: ``one_row_per_cell``, ``with_numbers``,
    then ``by_role`` (the paper's methods under their registry names, never by label)."""
    return by_role(with_numbers(one_row_per_cell(rows)))


# ---------------------------------------------------------------------------
# Seeds, conditions, totals and ratios
# ---------------------------------------------------------------------------


def seeds_text(seeds: Iterable[int]) -> str:
    """"5", "0-99" or "0,3,7": the seeds a measurement rests on."""
    s = sorted({int(x) for x in seeds})
    if not s:
        return ""
    if len(s) > 2 and s == list(range(s[0], s[-1] + 1)):
        return f"{s[0]}-{s[-1]}"
    return ",".join(map(str, s))


def seeds_of(rows: pd.DataFrame) -> str:
    """``seeds_text`` of the rows' ``seed`` column (the instance's recipe; "" where the table
    has none)."""
    if "seed" not in rows.columns:
        return ""
    return seeds_text(pd.to_numeric(rows["seed"], errors="coerce").dropna().astype(int))


#: Each condition of the ledger (the table's ``operator``) and the profile the study runs it
#: at (``harness.profiles``, where the study, harness.run.studies, reads them too): dense at
#: ``paper`` (eps = 1e-8), fft at ``default``.
CONDITION_PROFILES: dict[str, str] = {"dense": CLAIMS_DENSE_PROFILE, "fft": CLAIMS_FFT_PROFILE}


def condition_words(condition: str) -> str:
    """"operator dense, profile paper": the condition in an evidence string."""
    return f"operator {condition}, profile {CONDITION_PROFILES.get(condition, '?')}"


def under(rows: pd.DataFrame, condition: str) -> pd.DataFrame:
    """The rows of ``condition``: its operator and its profile (``CONDITION_PROFILES``); a
    table without a ``profile`` column has none of the condition's rows."""
    if "profile" not in rows.columns or condition not in CONDITION_PROFILES:
        return rows.iloc[0:0]
    return rows[(rows["operator"] == condition) & (rows["profile"] == CONDITION_PROFILES[condition])]


def of_condition(rows: pd.DataFrame, scene: str, condition: str) -> pd.DataFrame:
    """The attempted rows of ``scene`` under ``condition`` (``under``: operator and profile)."""
    r = under(rows, condition)
    r = r[r["scene"] == scene]
    return r[r["status"] != "skipped"]


#: The paper's methods (registry names): "fastest" and "the same load" compare these only.
PAPER_METHODS: frozenset[str] = frozenset(r.base_solver for r in LEDGER_ROLES.values())
#: The scene of the independent (cold, from p = 0) solves: the ledger reads Fig. 4's P&K, P&K
#: as printed and greedy CG on it, and Fig. 6's K sweep where it has one.
COLD_SCENE = "greedy-linear-solvers"
#: The suffix of a label read from the independent (cold) solves of ``COLD_SCENE``.
COLD = " cold"


def repeat_totals(rows: pd.DataFrame) -> pd.Series:
    """Per (solver, repeat) of the rows: the repeat's total solve time over the steps, each
    cell counted once (``one_row_per_cell``); NaN where a step has no time, and NaN for a
    repeat that lacks a row of any of the label's cells (the cells of
    ``table.schema.CELL_COLUMNS`` any repeat of the label has): a repeat short of a step
    is no total, never a smaller one.  A table without ``repeat`` is one repeat, 0."""
    rows = one_row_per_cell(rows)
    rep = rows.assign(repeat=rows["repeat"] if "repeat" in rows.columns else 0)
    keys = [c for c in CELL_COLUMNS if c in rep.columns and c != "solver"]
    cells = rep.groupby(keys, dropna=False, sort=False).ngroup() if keys else pd.Series(0, index=rep.index)
    g = rep.assign(_cell=cells).groupby(["solver", "repeat"])
    total = g["solve_time_s"].agg(lambda v: v.sum(skipna=False))
    per_label = rep.assign(_cell=cells).groupby("solver")["_cell"].nunique()
    complete = g["_cell"].nunique() == per_label.reindex(total.index.get_level_values(0)).to_numpy()
    return total.where(complete)


def spent_seconds(rows: pd.DataFrame) -> pd.Series:
    """Per solver label of the (unfolded) rows: a lower bound of its total solve time over the
    steps -- per cell (its repeats), the least time of a repeat that answered, else the most
    time a repeat ran before it stopped (a timeout's limit; a row with no time counts 0)."""
    keys = [c for c in CELL_COLUMNS if c in rows.columns]
    t = pd.to_numeric(rows["solve_time_s"], errors="coerce").fillna(0.0)
    r = rows.assign(_t=t, _answered=t.where(rows["status"].isin(ANSWERED)))
    g = r.groupby(keys, sort=False, dropna=False)
    cell = g["_answered"].min().fillna(g["_t"].max())
    return cell.groupby(level="solver").sum()


def totals(rows: pd.DataFrame) -> pd.DataFrame:
    """Per solver label of the (unfolded) rows: the total solve time over the steps, as the
    median over the timed repeats of each complete repeat's sum (``repeat_totals``;
    ``repeats``, ``spread``: their count and relative range); operator products and
    iterations (``matvecs``, ``iterations``: the time's load-independent witnesses), steps,
    steps answered and steps solved; ``uncounted``: ``uncounted_steps``.  A total is
    ``comparable`` when every step of the largest count returned an answer and some repeat
    is complete; ``spent_s`` is ``spent_seconds``, a lower bound of the total of a solver
    that stopped."""
    cols = ["total_s", "spent_s", "repeats", "spread", "matvecs", "iterations", "steps", "answered", "solved",
            "comparable", "uncounted"]
    if rows.empty:
        return pd.DataFrame(columns=cols)
    cells = per_cell(rows)
    g = cells.groupby("solver")
    nan = pd.Series(math.nan, index=g.size().index)
    out = pd.DataFrame({"matvecs": g["matvecs"].sum(min_count=1) if "matvecs" in cells.columns else nan,
                        "iterations": g["iterations"].agg(lambda v: v.sum(skipna=False))
                        if "iterations" in cells.columns else nan,
                        "steps": g.size(), "answered": g["status"].agg(lambda s: int(s.isin(ANSWERED).sum())),
                        "solved": g["solved"].sum()})
    per = repeat_totals(rows).dropna().groupby(level=0)  # (the complete repeats only)
    out["total_s"], out["repeats"], out["spread"] = per.median(), per.size(), per.agg(relative_range)
    out["repeats"] = out["repeats"].fillna(0).astype(int)
    out["spent_s"] = spent_seconds(rows)
    out["comparable"] = ((out["answered"] == out["steps"]) & (out["steps"] == out["steps"].max())
                         & (out["repeats"] > 0))
    out["uncounted"] = uncounted_steps(cells)
    return out[cols]


def uncounted_steps(cells: pd.DataFrame) -> pd.Series:
    """Per solver label of ``per_cell`` rows: the answered solves from p = 0 (``warm_start``
    not True) of a problem with n > 0 whose iteration count is not positive -- a cold solve
    of a non-empty problem that reports no iteration counted none, so no iteration claim
    reads it (``ratio`` with ``of="iterations"``)."""
    labels = cells["solver"].drop_duplicates()
    if "iterations" not in cells.columns:
        return pd.Series(0, index=labels.to_numpy())
    warm = (bool_series(cells["warm_start"]).fillna(False).astype(bool) if "warm_start" in cells.columns
            else pd.Series(False, index=cells.index))
    n = pd.to_numeric(cells["n"], errors="coerce") if "n" in cells.columns else pd.Series(1.0, index=cells.index)
    its = pd.to_numeric(cells["iterations"], errors="coerce")
    bad = cells["status"].isin(ANSWERED) & ~warm & (n > 0) & ~(its > 0)
    return bad.groupby(cells["solver"]).sum().astype(int)


#: The project's reading of "the same normal force P" (tex 1039-1044: every method, once it
#: has converged) for a method a claim reads as printed, inexact by design (``ratio``'s
#: ``inexact``): its load at every step within this share of the other side's answer there --
#: the paper's own bound on an approximate answer's load (tex 1349-1350: "relative errors
#: less than 2 %").  Further off, or without its own stop, the answer is not the paper's.
INEXACT_LOAD_TOL = 0.02


def as_printed_refusal(rows: pd.DataFrame, label: str, ref: str) -> str:
    """Why the answers of ``label`` among ``rows`` (the unfolded rows its totals come from)
    are no measurement even read as printed, "" where they are one: every answer claims the
    method's own stop (``solver_converged`` True, in every repeat) and its load at each
    (instance, step) is within ``INEXACT_LOAD_TOL`` of the median load of ``ref``'s answers
    there (a step ``ref`` did not answer, or a load that is not a number, is off)."""
    mine = rows[(rows["solver"] == label) & rows["status"].isin(ANSWERED)]
    if mine.empty:
        return f"no answer of {label}"
    why = []
    stop = (bool_series(mine["solver_converged"]).fillna(False).astype(bool) if "solver_converged" in mine.columns
            else pd.Series(False, index=mine.index))
    if not stop.all():
        why.append(f"{int((~stop).sum())} of its {len(mine)} answers did not reach its own stop "
                   "(solver_converged False)")
    theirs = rows[(rows["solver"] == ref) & rows["status"].isin(ANSWERED)]
    ref_load = pd.to_numeric(theirs["load"], errors="coerce").groupby([theirs["instance"], theirs["step"]]).median()
    at = ref_load.reindex(pd.MultiIndex.from_arrays([mine["instance"], mine["step"]])).to_numpy(dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        gap = np.abs(pd.to_numeric(mine["load"], errors="coerce").to_numpy(dtype=float) / at - 1.0)
    off = ~(gap <= INEXACT_LOAD_TOL)
    if off.any():
        worst = float(np.nanmax(gap)) if np.isfinite(gap).any() else math.nan
        why.append(f"its load is off {ref}'s by more than {INEXACT_LOAD_TOL:g} (INEXACT_LOAD_TOL) on {int(off.sum())} "
                   f"of {len(mine)} answers (at most {worst:.3g} where compared)")
    return "; ".join(why)


def fmt_count(v: float) -> str:
    """A count as an integer, "?" where the table has none."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "?"
    return f"{int(x)}" if math.isfinite(x) else "?"


def ratio(tot: pd.DataFrame, a: str, b: str, of: str = "total_s", inexact: Iterable[str] = (),
          rows: pd.DataFrame | None = None) -> tuple[float, str, Timing]:
    """a / b of column ``of`` (the median total time; or ``iterations``) with the words saying
    what it rests on and its timing (NaN where either is missing or incomplete, or b is not
    positive).  The spread of a time ratio is the sum of the two totals' spreads.  A side
    whose answers did not all pass the KKT check (solved < steps) did not converge: NaN,
    the words say which, unless its label is in ``inexact`` (a method the claim names as
    inexact by design, read as printed: the paper's own stop; the words say so) and its
    answers among ``rows`` (the unfolded rows ``tot`` comes from) pass
    ``as_printed_refusal`` against the other side; ``rows`` None reads them unchecked, for a
    method approximate by design whose load the ledger judges in claims of its own (CMR's
    cascade: fig8-cmr-error), never for one of Fig. 4's methods.
    An iteration ratio with a side that has ``uncounted`` steps (``uncounted_steps``) is NaN."""
    missing = [s for s in (a, b) if s not in tot.index]
    if missing:
        return math.nan, f"no rows of {', '.join(missing)}", Timing()
    ta, tb = tot.loc[a], tot.loc[b]

    def one(label: str, t: pd.Series) -> str:
        return (f"{label} {t['total_s']:.4g} s (median of {int(t['repeats'])}), {fmt_count(t.get('matvecs'))} "
                f"matvecs, {fmt_count(t.get('iterations'))} iterations ({int(t['solved'])}/{int(t['steps'])} steps "
                f"pass the KKT check)")

    words = f"{one(a, ta)}, {one(b, tb)}"
    timing = Timing(int(min(ta["repeats"], tb["repeats"])),
                    float(ta["spread"] + tb["spread"]) if of == "total_s" else 0.0)
    if not (ta["comparable"] and tb["comparable"]) or not tb[of] > 0 or not np.isfinite([ta[of], tb[of]]).all():
        return math.nan, words + "; not every step answered", timing
    uncounted = [f"{s} ({int(t.get('uncounted', 0))})" for s, t in ((a, ta), (b, tb)) if t.get("uncounted", 0) > 0]
    if of == "iterations" and uncounted:
        return math.nan, words + (f"; a solve from p = 0 of n > 0 reporting no iteration: {', '.join(uncounted)} "
                                  "steps, no iteration count"), timing
    short = [(s, t) for s, t in ((a, ta), (b, tb)) if int(t["solved"]) < int(t["steps"])]
    as_printed = [s for s, _ in short if s in set(inexact)]
    for s in as_printed if rows is not None else ():
        why = as_printed_refusal(rows, s, b if s == a else a)
        if why:
            return math.nan, words + (f"; {s} read as printed is no measurement: {why} -- a time to an answer that is "
                                      "not the paper's 'same normal force' (tex 1039-1044)"), timing
    if as_printed:
        words += (f"; {', '.join(as_printed)} read as printed, inexact by design (its own stop, not the KKT "
                  "check" + (f"; every answer at its own stop, its load within {INEXACT_LOAD_TOL:g} of the other "
                             "side's)" if rows is not None else ")"))
    unconverged = [f"{s} ({int(t['solved'])}/{int(t['steps'])})" for s, t in short if s not in as_printed]
    if unconverged:
        return math.nan, words + (f"; not every answer converged: {', '.join(unconverged)} steps pass the KKT "
                                  "check, a time to an unconverged answer is no measurement"), timing
    return float(ta[of] / tb[of]), words, timing


def paper_labels(tot: pd.DataFrame) -> list[str]:
    """The labels of ``tot`` that play one of the paper's methods (``by_role``: the keys of
    ``LEDGER_ROLES``, warm or cold), other variants of theirs left out."""
    return [s for s in tot.index if s.removesuffix(COLD) in LEDGER_ROLES]


def nnlsgp_cold(tot: pd.DataFrame) -> str | None:
    """The label of NNLS+GP (K = 100) from p = 0 (the cold solves of ``COLD_SCENE``), None
    where the table has none (never the warm one: the claim reads the cold)."""
    return "nnls-gp" + COLD if "nnls-gp" + COLD in tot.index else None
