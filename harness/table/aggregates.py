"""Fair aggregates over a tidy results table (harness/table/schema.py): per solver success
rate, correct rate, shifted geometric mean of solve time relative to the best, and
Dolan-More performance profiles.

Definitions (the report states them next to every number):

* A *problem* is one (scene, instance, step, profile, history): each profile is its own
  accuracy target, so the same instance at two profiles is two problems; a step solved
  along a warm-started load history and the same step of a ``--cold`` run start from
  different points, so they are two problems too.
* A *cell* is one (problem, solver) (schema.CELL_COLUMNS: the solver's label names its
  base and parameters).  Repeats are folded into the cell: it is solved
  when every repeat is ``status == "solved"`` (the harness's KKT verdict at the
  profile's ``check_tol``), and its time is the minimum ``solve_time_s`` over repeats.
* *Solved share*: solved cells / problems -- every problem of the table, so a skipped
  cell and a cell not run count as not solved.  *Success rate*: solved cells / attempted
  cells (skipped cells are not attempted; they are counted separately).  A report shows
  the success rate only beside the solved share and the problem count: on its own, 100 %
  of 3 attempted reads as 100 % of 10 problems.  (``SolverSummary`` computes both.)
* *Correct rate*: attempted rows on which the solver's own claim ``solver_converged``
  agrees with the verdict ``status == "solved"``.  A *false claim* is a row where the
  solver claims convergence and the check says otherwise.
* A cell is *planned* when the table has a row of the solver for the problem, whatever
  its status (a skipped row was planned and not run); a problem with no row of the solver
  is a cell never planned (``CellTable``'s ``planned``).
* *Shifted geometric mean* (Mittelmann's benchmarks): ``exp(mean(log(t + s))) - s``
  with shift ``s`` seconds, over the cells the solver was planned to run (their count is
  ``SolverSummary.sgm_cells``): a planned cell that is not solved -- failed, inaccurate,
  timeout, crashed or skipped -- counts at the *penalty* of the part aggregated (one scene
  at one profile, ``profile_parts``): the largest ``time_limit_s`` of its rows, never less
  than its largest solved time (else, with no limit recorded, the largest observed time),
  so an unsolved cell never counts cheaper than any solve of the part, whatever limit its
  own row ran under (``run --append`` may add rows with another ``--timeout``); one home:
  ``penalty_time``.  A cell never planned is not counted.  An SGM within rounding of 0
  (every counted time 0) reads 0.  Reported relative to the best (1.00 = best): the solver's SGM over the
  smallest SGM over the same cells among the solvers planned on every one of them that
  solved at least one cell (so 1 is the best on the solver's own problems; one that
  solved nothing is never the best).  A solver skipped on every problem has no SGM (the
  limit it would count at is no measurement), and where no solver solved a cell every
  cell counts at the limit and the figure measures nothing: no solver gets an SGM (NaN,
  "-" in the report), rather than a tie of everyone at "1 = best".
* *Own reference*: a row whose answer served as its step's reference solution
  (``reference_solver`` is ``served_name`` of the row itself, "<solver>@<profile>": the
  name the runner gives a run's own answer that serves).  Its
  ``p_rel_error`` is 0 by construction and measures nothing; reports show it as the
  reference, not as an exact answer (``own_reference``).
* *Performance profile* (Dolan & More, Math. Program. 91, 2002):
  ``rho_s(tau) = |{p : t_ps <= tau * min_s' t_ps'}| / n_p`` with ``t_ps = inf`` for
  cells that are not solved; problems no solver solves stay in ``n_p``, and so do the
  problems a solver was never planned on (its curve ends at its solved share).
* *Within one profile*: the SGM and the performance profile compare solvers on the same
  problems, and a problem is one profile's; a scene whose rows ran at several profiles is
  aggregated once per profile (``profile_parts``), never across them (two solvers that ran
  only at different profiles never met).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np
import pandas as pd

from .schema import bool_series

#: The default shift of the shifted geometric mean, in seconds.  Damps the relative
#: weight of sub-10-ms solves, whose ratios are timer noise.
DEFAULT_SHIFT_S: float = 0.01

#: The columns that identify a problem.
PROBLEM_KEYS: tuple[str, ...] = ("scene", "instance", "step", "profile", "history")

#: Floor applied to measured times before taking ratios (a 0.0 s timer reading).
TIME_FLOOR_S: float = 1e-9

def served_name(label: str, profile: str) -> str:
    """``reference_solver`` of a row whose own answer served as its step's reference: the
    solver's label and the profile it ran at, "<solver>@<profile>"."""
    return f"{label}@{profile}"


#: How many units in the last place of the shift an SGM may be off 0 and still read 0: the
#: rounding of ``exp(log(shift)) - shift`` (all times 0), not a time.
SGM_ZERO_ULPS: int = 8


def shifted_geometric_mean(times: Iterable[float], shift: float = DEFAULT_SHIFT_S) -> float:
    """``exp(mean(log(t_i + shift))) - shift``, clipped at 0; NaN for an empty input.  A
    result within ``SGM_ZERO_ULPS`` ulps of ``shift`` of 0 is rounding and reads exactly 0
    (so every time 0 gives 0, and a ratio over it is undefined, not 1e15).

    ``shift`` must be >= 0 and every time >= 0 and finite (count failures at the time
    limit before calling)."""
    t = np.asarray(list(times), dtype=float)
    if shift < 0 or not math.isfinite(shift):
        raise ValueError(f"shift must be a finite number >= 0, got {shift!r}")
    if t.size == 0:
        return float("nan")
    if not np.all(np.isfinite(t)) or np.any(t < 0):
        raise ValueError("shifted geometric mean needs finite times >= 0 (count failures at the time limit)")
    if shift == 0 and np.any(t == 0):
        raise ValueError("a zero time needs a positive shift")
    sgm = float(np.exp(np.mean(np.log(t + shift))) - shift)
    if abs(sgm) <= SGM_ZERO_ULPS * float(np.spacing(shift)):
        return 0.0
    return max(0.0, sgm)


@dataclass(frozen=True)
class CellTable:
    """One row per (problem, solver): ``solved`` (bool), ``time_s`` (min over repeats,
    NaN when never timed), ``penalty_s`` (the time counted for an unsolved cell:
    ``penalty_time`` of the whole table, the same for every cell),
    ``attempted`` (not skipped), ``planned`` (the table has a row of the solver for the
    problem, whatever its status; False for a pair filled in as absent)."""

    frame: pd.DataFrame
    solvers: tuple[str, ...]
    problems: tuple[tuple, ...]


def profile_parts(df: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    """The rows of ``df`` (one scene, or every scene for a summary across them) by profile,
    in order of the profile's name: each part is aggregated on its own (the module's
    definitions: within one profile), so a solver is counted only at the profiles it ran.
    One part where ``df`` ran at one profile; none for an empty ``df``."""
    if df.empty:
        return []
    prof = df["profile"].astype(str)
    return [(p, df[prof == p]) for p in sorted(prof.unique())]


def penalty_time(df: pd.DataFrame) -> float:
    """The time an unsolved cell of ``df`` counts at in the shifted geometric mean (the
    module's definitions; ``df`` is the part aggregated, one scene at one profile): the
    largest ``time_limit_s`` of its rows, raised to its largest solved ``solve_time_s``,
    whatever limit the unsolved cell's own row ran under -- so a solver that solved nothing
    never gets an SGM below one that solved; with no limit recorded, the largest observed
    solve time; 1 s for a part with neither.  The one home of the rule."""
    limit = pd.to_numeric(df["time_limit_s"], errors="coerce") if "time_limit_s" in df.columns \
        else pd.Series(np.nan, index=df.index)
    times = pd.to_numeric(df["solve_time_s"], errors="coerce")
    solved = times[df["status"].astype(str) == "solved"]
    candidates = [float(v) for v in (limit.max(), solved.max()) if np.isfinite(v)]
    if not candidates:
        candidates = [float(v) for v in (times.max(),) if np.isfinite(v)]
    return max(candidates) if candidates else 1.0


def cell_table(df: pd.DataFrame, solvers: Sequence[str] | None = None) -> CellTable:
    """Fold repeats into cells and fill absent (problem, solver) pairs as unsolved, not
    attempted and not planned.  ``solvers`` restricts / orders the solver set (default: all).
    ``df`` is the part aggregated (one scene at one profile, ``profile_parts``): its unsolved
    cells count at ``penalty_time(df)``."""
    if df.empty:
        return CellTable(pd.DataFrame(columns=[*PROBLEM_KEYS, "solver", "solved", "attempted", "planned", "time_s",
                                               "penalty_s"]), (), ())
    d = df.copy()
    if "history" not in d.columns:  # a frame built by hand, not through the schema
        d["history"] = ""
    d["history"] = d["history"].astype("string").fillna("")
    d["_solved"] = d["status"].astype(str) == "solved"
    d["_attempted"] = d["status"].astype(str) != "skipped"
    d["_time"] = pd.to_numeric(d["solve_time_s"], errors="coerce")
    keys = [*PROBLEM_KEYS, "solver"]
    g = d.groupby(keys, sort=True, dropna=False)
    cells = pd.DataFrame({
        "solved": g["_solved"].all(),
        "attempted": g["_attempted"].any(),
        "planned": g["_solved"].size() > 0,  # a row of the solver, whatever its status
        "time_s": g["_time"].min(),
    }).reset_index()
    all_solvers = tuple(solvers) if solvers is not None else tuple(sorted(d["solver"].astype(str).unique()))
    problems = tuple(sorted({tuple(r) for r in d[list(PROBLEM_KEYS)].itertuples(index=False)}, key=_sort_key))
    full = pd.MultiIndex.from_tuples([(*p, s) for p in problems for s in all_solvers], names=keys)
    cells = cells.set_index(keys).reindex(full)
    for flag in ("solved", "attempted", "planned"):
        cells[flag] = cells[flag].astype("boolean").fillna(False).astype(bool)
    cells["penalty_s"] = penalty_time(d)
    return CellTable(cells.reset_index(), all_solvers, problems)


def _sort_key(t: tuple) -> tuple:
    return tuple((0, v) if isinstance(v, (int, float, np.integer, np.floating)) and not pd.isna(v)
                 else (1, str(v)) for v in t)


def counted_times(cells: CellTable) -> pd.DataFrame:
    """Problems x solvers matrix of the time a cell counts at in the shifted geometric mean
    (which takes only the planned cells: ``time_aggregate``): the measured time where
    solved, the penalty (``penalty_time``) otherwise."""
    f = cells.frame
    t = np.where(f["solved"], f["time_s"].clip(lower=0.0), f["penalty_s"])
    return _matrix(cells, t)


def _matrix(cells: CellTable, values: np.ndarray) -> pd.DataFrame:
    """Problems x solvers matrix of per-cell ``values`` (cells are complete)."""
    f = cells.frame
    m = pd.Series(values, index=pd.MultiIndex.from_frame(f[[*PROBLEM_KEYS, "solver"]])).unstack("solver")
    return m.reindex(columns=list(cells.solvers))


def solved_times(cells: CellTable) -> pd.DataFrame:
    """Problems x solvers matrix of measured times, +inf where the cell is not solved."""
    f = cells.frame
    t = np.where(f["solved"], np.maximum(f["time_s"].fillna(np.inf), TIME_FLOOR_S), np.inf)
    return _matrix(cells, t)


def planned_matrix(cells: CellTable) -> pd.DataFrame:
    """Problems x solvers matrix (as ``counted_times``): was the cell planned (a row of the
    solver for the problem, whatever its status; see the module's definitions)?"""
    return _matrix(cells, cells.frame["planned"].to_numpy(dtype=bool)).astype(bool)


@dataclass(frozen=True)
class PerformanceProfile:
    """Dolan-More profile: ``ratios[s]`` is the sorted vector of r_ps (inf where
    unsolved); ``fraction(s, tau)`` evaluates rho_s(tau)."""

    solvers: tuple[str, ...]
    n_problems: int
    ratios: dict[str, np.ndarray] = field(default_factory=dict)
    left_out: tuple[str, ...] = ()  # ``never_attempted``: not drawn

    def fraction(self, solver: str, tau: float) -> float:
        r = self.ratios[solver]
        return float(np.count_nonzero(r <= tau * (1 + 1e-12)) / self.n_problems) if self.n_problems else float("nan")

    def curve(self, solver: str, taus: np.ndarray) -> np.ndarray:
        return np.array([self.fraction(solver, float(t)) for t in taus])

    def max_finite_ratio(self) -> float:
        vals = [float(np.max(r[np.isfinite(r)])) for r in self.ratios.values() if np.any(np.isfinite(r))]
        return max(vals) if vals else 1.0


def never_attempted(cells: CellTable) -> tuple[str, ...]:
    """The solvers of ``cells`` skipped on every problem (their skip reasons say why)."""
    f = cells.frame
    tried = f.groupby("solver", sort=False)["attempted"].any()
    return tuple(s for s in cells.solvers if not bool(tried.get(s, False)))


def performance_profile(cells: CellTable) -> PerformanceProfile:
    """r_ps = t_ps / min_s t_ps over the solvers of ``cells`` attempted on at least one
    problem (``never_attempted`` would draw a flat zero: left out, the others' ratios
    unchanged); inf for unsolved cells, and for every solver on a problem that none solves."""
    m = solved_times(cells)
    best = m.min(axis=1).to_numpy()
    skipped = never_attempted(cells)
    solvers = tuple(s for s in cells.solvers if s not in skipped)
    ratios: dict[str, np.ndarray] = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for s in solvers:
            r = m[s].to_numpy() / best
            r[~np.isfinite(best)] = np.inf
            ratios[s] = np.sort(r)
    return PerformanceProfile(solvers, len(m.index), ratios, skipped)


@dataclass(frozen=True)
class SolverSummary:
    """One line of the aggregate table."""

    solver: str
    problems: int  # every problem of the table (the solved share's denominator)
    attempted: int
    skipped: int
    solved: int
    solved_share: float  # solved / problems: skipped and not run count as not solved
    success_rate: float  # solved / attempted
    claim_rows: int  # attempted rows with a known solver claim
    correct_rate: float  # claim agrees with verdict, over claim_rows
    false_claims: int  # claimed converged, verdict not solved
    sgm_s: float  # shifted geometric mean of counted time over the planned cells
    sgm_rel: float  # relative to the best solver over the same cells
    sgm_cells: int  # the planned cells sgm_s counts (0 where it has none)


def claim_agreement(df: pd.DataFrame) -> pd.Series:
    """Per row: does ``solver_converged`` agree with ``status == "solved"``?  Uses the
    solver's claim as stored (bool or CSV text), NaN where the claim is unknown."""
    verdict = df["status"].astype(str) == "solved"
    claim = bool_series(df["solver_converged"]) if "solver_converged" in df else pd.Series(pd.NA, index=df.index)
    agree = (claim == verdict).astype("boolean")
    agree[claim.isna()] = pd.NA
    return agree


def summarize(df: pd.DataFrame, shift: float = DEFAULT_SHIFT_S, solvers: Sequence[str] | None = None,
              with_time: bool = True) -> list[SolverSummary]:
    """The aggregate table of ``df`` (usually one scene): one SolverSummary per solver, its
    time aggregate by ``time_aggregate`` (over the cells the solver was planned to run).
    ``with_time=False`` leaves the time aggregate NaN, over 0 cells (for tables mixing
    scenes, where solvers do not all run on the same problems)."""
    cells = cell_table(df, solvers)
    times = time_aggregate(cells, shift) if with_time else {s: NO_TIME for s in cells.solvers}
    attempted_rows = df[df["status"].astype(str) != "skipped"]
    agree = claim_agreement(attempted_rows)
    claim = bool_series(attempted_rows["solver_converged"]) if "solver_converged" in attempted_rows \
        else pd.Series(pd.NA, index=attempted_rows.index, dtype="boolean")
    out: list[SolverSummary] = []
    f = cells.frame
    for s in cells.solvers:
        c = f[f["solver"] == s]
        att = int(c["attempted"].sum())
        solved = int((c["solved"] & c["attempted"]).sum())
        rows = attempted_rows["solver"].astype(str) == s
        a = agree[rows].dropna()
        false_claims = int(((claim[rows] == True) & (attempted_rows.loc[rows, "status"].astype(str) != "solved"))  # noqa: E712
                           .fillna(False).sum())
        out.append(SolverSummary(
            solver=s, problems=len(c), attempted=att,
            skipped=int(((~c["attempted"]) & c["solver"].notna()).sum()),
            solved=solved, solved_share=share(solved, len(c)), success_rate=share(solved, att),
            claim_rows=len(a), correct_rate=float(a.astype(bool).mean()) if len(a) else float("nan"),
            false_claims=false_claims, sgm_s=times[s].sgm_s, sgm_rel=times[s].sgm_rel,
            sgm_cells=times[s].cells))
    return out


def share(part: int, whole: int) -> float:
    """``part / whole``; NaN for an empty ``whole``."""
    return part / whole if whole else float("nan")


def solvers_with_a_solve(cells: CellTable) -> tuple[str, ...]:
    """The solvers of ``cells`` with at least one solved cell."""
    f = cells.frame
    won = f.groupby("solver", sort=False)["solved"].any()
    return tuple(s for s in cells.solvers if bool(won.get(s, False)))


@dataclass(frozen=True)
class TimeAggregate:
    """One solver's time aggregate (the module's definitions): ``sgm_s`` over the ``cells``
    it was planned to run, ``sgm_rel`` that over the best over the same cells."""

    sgm_s: float
    sgm_rel: float
    cells: int


#: No time aggregate: NaN over no cells.
NO_TIME = TimeAggregate(float("nan"), float("nan"), 0)


def time_aggregate(cells: CellTable, shift: float = DEFAULT_SHIFT_S) -> dict[str, TimeAggregate]:
    """Solver -> the SGM the aggregate table shows.  ``sgm_s``: the shifted geometric mean
    of ``counted_times`` over the solver's planned cells (``planned_matrix``); ``sgm_rel``:
    that over the smallest SGM over the same cells among the solvers of
    ``solvers_with_a_solve`` planned on every one of them (NaN where none is, or that
    smallest is 0); ``cells``: how many cells ``sgm_s`` counts.  ``NO_TIME`` for a solver
    skipped on every problem (``never_attempted``: the limit it would count at is no
    measurement) and for every solver where none solved a cell (each would count every
    cell at the limit: a tie that reads as "1 = best")."""
    won = solvers_with_a_solve(cells)
    if not won:
        return {s: NO_TIME for s in cells.solvers}
    counted, planned = counted_times(cells), planned_matrix(cells)
    skipped = set(never_attempted(cells))
    out: dict[str, TimeAggregate] = {}
    for s in cells.solvers:
        mine = planned[s].to_numpy()
        if s in skipped or not mine.any():
            out[s] = NO_TIME
            continue
        sgm = shifted_geometric_mean(counted[s].to_numpy()[mine], shift)
        peers = [shifted_geometric_mean(counted[t].to_numpy()[mine], shift) for t in won
                 if planned[t].to_numpy()[mine].all()]
        best = min(peers) if peers else float("nan")
        out[s] = TimeAggregate(sgm, sgm / best if best > 0 else float("nan"), int(mine.sum()))
    return out


def own_reference(df: pd.DataFrame) -> pd.Series:
    """Per row: did the row's own answer serve as its step's reference solution
    (``reference_solver == "<solver>@<profile>"``, see the module's definitions)?  Such a
    row's ``p_rel_error`` is 0 by construction.  False where the column is absent."""
    if "reference_solver" not in df.columns or df.empty:
        return pd.Series(False, index=df.index, dtype=bool)
    served = pd.Series([served_name(s, prof) for s, prof in zip(df["solver"].astype(str), df["profile"].astype(str))],
                       index=df.index, dtype="string")
    return (df["reference_solver"].astype("string").fillna("") == served).astype(bool)


def reference_steps(df: pd.DataFrame) -> dict[str, tuple[int, ...]]:
    """Reference solver (``reference_solver``, as the rows name it) -> the steps on which it
    served, in order of its first step; rows without a reference are left out."""
    if "reference_solver" not in df.columns:
        return {}
    ref = df["reference_solver"].astype("string").fillna("")
    have = df[ref != ""]
    steps = pd.to_numeric(have["step"], errors="coerce")
    out: dict[str, set[int]] = {}
    for name, k in zip(ref[ref != ""], steps):
        if pd.notna(k):
            out.setdefault(str(name), set()).add(int(k))
    return {name: tuple(sorted(ks)) for name, ks in sorted(out.items(), key=lambda kv: (min(kv[1]), kv[0]))}
