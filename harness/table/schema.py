"""The tidy table: one row per solve.  Column names here are a public contract
(reports, scripts and users depend on them) -- add columns, never rename.

``COLUMNS`` holds each column's dtype and meaning; ``apply_schema`` gives a frame
exactly these columns and dtypes; ``load_table`` is the one reader of a stored table
(a run directory, or a ``.parquet`` / ``.csv`` file) and applies the schema.

dtypes: ``string`` (missing = ""), ``Int64`` and ``boolean`` (pandas' nullable types,
missing = <NA>), ``float64`` (missing = NaN).

Definitions of the less obvious figures
---------------------------------------
delta            far-field displacement Delta of the step, in the instance's length unit
                 (metres by default); NaN for scenes without one (counterexample).
load             total force P = sum p_ij (N when E is in Pa and lengths in m).
contact_fraction elements in contact, p_i > check_tol x p_s (p_s the problem's force scale,
                 ``problems.kkt``), divided by all N^2 elements (A/A0); docs/report.md.
contact_uncertain elements whose contact state the tolerance leaves open (p_i within a
                 decade of that floor, or counted in contact with an open gap: w_i / u_s >=
                 p_i / p_s or w_i > sqrt(check_tol) u_s), divided by all N^2 elements: the
                 flag of contact_fraction (A/A0 is uncertain by about this).
plastic_uncertain elements in contact whose plastic state the tolerance leaves open (a finite
                 bound u_i with u_i - p_i within a decade of plastic_fraction's floor
                 check_tol x p_s, or counted elastic while u_i - p_i <= sqrt(check_tol) p_s),
                 divided by the elements in contact (plastic_fraction's denominator, not
                 N^2): the flag of plastic_fraction; NaN without a hardness.
solved_hash      sha256 of the measured map's heights as solved (metres, after unit, fill,
                 detrend and crop; surface_hash's hash), first 16 hex digits: the same
                 file prepared by other cleaning code gives another; '' for a generated
                 surface (and in rows written before it was kept).
kkt_error        the scaled figure of ``contactbench.problems.kkt``.
p_rel_error      ||p - p_ref||_inf / ||p_ref||_inf against the scene's reference.
load_rel_error   |P - P_ref| / |P_ref| against the reference solve (or the analytic
                 load where the scene has one and no reference solve ran).
status           the harness's verdict, one of STATUSES (never the solver's own claim,
                 which is in solver_status / solver_converged).
verdict          the judge's conformance reading (harness/judging.py), one of VERDICTS,
                 "" where no answer was judged (skipped, failed, timeout, crashed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import pandas as pd

from contactbench.problems.errors import COUNT_MAX

STATUSES: Final = ("solved", "inaccurate", "failed", "timeout", "crashed", "skipped")
#: The statuses of a solve that returned an answer the judge read (a time to compare).
ANSWERED: Final = ("solved", "inaccurate")
#: The judge's readings of an answer (harness/judging.py), the values of column ``verdict``
#: besides "" (not judged).
VERDICTS: Final = ("pass", "wrong", "unconverged")
#: The kinds of run a row belongs to (column ``history``): warm starts along the load
#: history (the default), or every step from a cold start (``--cold``).
HISTORIES: Final = ("warm", "cold")
DTYPES: Final = ("string", "Int64", "boolean", "float64")
#: What identifies a cell: one solve of one step by one solver variant at one profile,
#: given one operator (``--operator``: the same problem's H as FFTs or dense, which a
#: folder may hold both of through ``--append``), in one kind of run (``history``: warm
#: starts along the load history, or ``--cold``).  Repeats of a cell (column ``repeat``)
#: fold into it.  The one definition, used by the plan's cell ids, the stored table's
#: repeat statistics, the aggregates and the report.
CELL_COLUMNS: Final = ("scene", "instance", "step", "solver", "base_solver", "params", "profile", "operator",
                       "warm_start", "history")
#: The columns of a measured map's preparation (``problems.preprocessing.MapPreprocessing``).
MAP_COLUMNS: Final = ("surface_source", "surface_hash", "height_unit", "nan_rule", "nan_filled", "detrend",
                      "removed_mean", "removed_slope0", "removed_slope1", "crop", "channel_index", "solved_hash")
#: The instance parameters the table carries as columns (read from the instance's
#: recipe, ``InstanceSpec.params``, and the built instance), so no report parses a name.
#: With ``E``, ``control``, ``hardness``, ``delta`` (or ``dim_load`` under load control) and,
#: for a measured map, its file, they rebuild the problem: docs/columns.md.
INSTANCE_COLUMNS: Final = ("surface_family", "hurst", "N", "seed", "kernel", "periodic", "N0", "N1", "delta0",
                           "delta1", "thickness", "nu", "interface", *MAP_COLUMNS)


_COUNTS = ("step", "n", "repeat", "iterations", "matvecs", "N", "N0", "N1", "seed", "nan_filled", "channel_index")
_SHARES = ("contact_fraction", "contact_uncertain", "plastic_fraction", "plastic_uncertain")
_FIGURES = ("primal_residual", "dual_residual", "complementarity", "complementarity_sum", "load_rel_error", "p_rel_error", "analytic_load_rel_error", "load_residual")
_POSITIVE = ("E", "nominal_area", "hardness", "thickness")
_FINITE = ("delta0", "delta1", "removed_mean", "removed_slope0", "removed_slope1")
#: The numbers a column may hold where it has a rule (``check_numbers``; missing, NaN, is
#: always allowed): (low, high, whether low itself is allowed).  What the harness writes never
#: leaves these; a stored entry outside them is a hand edit or a forgery, and is refused.
RANGES: Final[dict[str, tuple[float, float, bool]]] = {
    **{c: (0.0, math.inf, True) for c in _COUNTS + _FIGURES},
    **{c: (0.0, 1.0, True) for c in _SHARES},
    **{c: (0.0, math.inf, False) for c in _POSITIVE},
    **{c: (-math.inf, math.inf, False) for c in _FINITE},
    "hurst": (0.0, 1.0, False),
    "nu": (-1.0, 0.5, False),
}
#: The loosest ``check_tol`` a row may carry: a scaled KKT error of 1 is an answer as far off
#: as the problem's own scales (``problems.kkt``), so no check is looser.
MAX_CHECK_TOL: Final = 1.0
#: The longest duration a ``_s`` column may hold: beyond any run (its longest time limit is a week).
MAX_DURATION_S: Final = 1e9


@dataclass(frozen=True)
class Column:
    """One column of the tidy table."""

    name: str
    dtype: str  # one of DTYPES
    doc: str
    required: bool = False  # a stored table must have it (check_table)


def _columns(required: bool, *spec: tuple[str, str, str]) -> tuple[Column, ...]:
    return tuple(Column(name, dtype, doc, required) for name, dtype, doc in spec)


_REQUIRED = _columns(
    True,
    ("scene", "string", "scene name"),
    ("instance", "string", "instance name within the scene"),
    ("step", "Int64", "load step (0-based)"),
    ("delta", "float64", "far-field displacement Delta of the step (under load control: the answer's approach, "
                         "the multiplier of the load equality as the judge fits it)"),
    ("n", "Int64", "trial-set size"),
    ("solver", "string", "the solver's label (a labelled variant, e.g. 'nnls-gp[K=50]')"),
    ("profile", "string", "accuracy profile (harness/profiles.py)"),
    ("repeat", "Int64", "repeat index of the timed solve"),
    ("warm_start", "boolean", "the solve was given a warm start"),
    ("status", "string", "the harness's verdict, one of STATUSES"),
    ("skip_reason", "string", "why a skipped pair was skipped"),
    ("build_time_s", "float64", "seconds to build the instance"),
    ("solve_time_s", "float64", "seconds of the solve (wall clock)"),
    ("iterations", "Int64", "the solver's iteration count"),
    ("primal_residual", "float64", "KKT figure: primal infeasibility"),
    ("dual_residual", "float64", "KKT figure: dual infeasibility"),
    ("complementarity", "float64", "KKT figure: complementarity"),
    ("kkt_error", "float64", "the scaled KKT error"),
    ("load", "float64", "total force P"),
    ("load_rel_error", "float64", "load error against the reference or closed form"),
    ("p_rel_error", "float64", "error in p against the reference"),
    ("contact_fraction", "float64", "A/A0"),
    ("peak_mem_mb", "float64", "peak memory of the solve, MiB"),
)

_EXTRA = _columns(
    False,
    ("cell_id", "string", "stable hash of (scene, instance, step, solver, profile, repeat, params)"),
    ("base_solver", "string", "registry name (``solver`` may be a labelled variant)"),
    ("params", "string", "JSON of the variant's solver parameters, e.g. {\"K\": 50}"),
    ("family", "string", "solver family: paper, qp, fast, wrapper, reference"),
    ("solver_status", "string", "the solver's own status string"),
    ("solver_converged", "boolean", "the solver's own claim"),
    ("solver_message", "string", "the solver's own message"),
    ("correct_claim", "boolean", "solver_converged == (status == 'solved')"),
    ("check_tol", "float64", "the profile's KKT tolerance used for the verdict"),
    ("solve_time_min_s", "float64", "min solve time over the repeats of this cell's group"),
    ("solve_time_median_s", "float64", "median solve time over the repeats of this cell's group"),
    ("solver_internal_time_s", "float64", "the solver's own timing"),
    ("setup_time_s", "float64", "set-up part of the solve (factorisations, ...)"),
    ("matvecs", "Int64", "products with H"),
    ("complementarity_sum", "float64", "sum of p_i w_i"),
    ("objective", "float64", "1/2 p'Hp - ubar'p"),
    ("dim_load", "float64", "P / (E A)"),
    ("E", "float64", "composite Young's modulus"),
    ("nominal_area", "float64", "nominal area A0"),
    ("N", "Int64", "grid points per side; on a rectangular grid the points along axis 0 (= N0; see N1)"),
    ("kernel", "string", "influence-coefficient kernel"),
    ("periodic", "boolean", "periodic kernel"),
    ("operator", "string", "'fft' or 'dense': what the solver was given (a skipped row, or one whose planning failed: "
                           "what it would have been given)"),
    ("reference_solver", "string", "the solver of the reference solution"),
    ("analytic_load", "float64", "closed-form load, where the scene has one"),
    ("analytic_load_rel_error", "float64", "load error against the closed form"),
    ("time_limit_s", "float64", "the solve's time limit"),
    ("error", "string", "exception text for failed / crashed rows"),
    ("trace", "string", "JSON list of [iteration, elapsed_s, residual], possibly thinned"),
    ("host", "string", "machine that ran the solve"),
    ("timestamp", "string", "when the row was written"),
    ("history", "string", "one of HISTORIES: 'warm', warm starts along load histories (default); 'cold': --cold"),
    ("verdict", "string", "the judge's reading: pass / wrong / unconverged; '' when not judged"),
    ("warmup", "string", "'' (an untimed warm-up ran first, or --no-warmup) or why it was dropped "
                         "(a big solve: the timed solve includes one-time costs)"),
    ("contact_uncertain", "float64", "share of the N^2 elements whose contact state check_tol leaves open (force "
                                     "within a decade of the floor, or a contact with an open gap): the flag of "
                                     "contact_fraction"),
    ("surface_family", "string", "the instance's generated surface family: an RMD family (problems/surfaces.py RMD_FAMILIES, e.g. "
                                 "'saupe', 'periodic'), or cmr-cutoff's spectral 'rolloff' or 'power-law' "
                                 "(problems/scenes/cmr.py); '' for other instances"),
    ("hurst", "float64", "the instance's Hurst exponent H; NaN where the surface has none (a measured map)"),
    ("seed", "Int64", "the instance's random seed; <NA> for deterministic instances and measured maps"),
    ("control", "string", "one of CONTROLS: 'displacement' (Delta given, the default) or 'load' (total force P "
                          "given; delta is then the answer's approach, the load equality's multiplier)"),
    ("hardness", "float64", "the pressure bound H_A in Pa (0 <= p_i <= H_A x element area); NaN: none"),
    ("load_residual", "float64", "KKT figure under load control: |sum p - P| / P; NaN under displacement control"),
    ("plastic_fraction", "float64", "share of the contact elements at the hardness bound; NaN without a hardness"),
    ("variant", "string", "the recipe's named variant of its scene's problem (e.g. greedy-kernels' operator: 'bcc', "
                          "'love', 'thin-layer', 'hardness'); '' where the scene has none"),
    ("N0", "Int64", "grid points along axis 0 (rows) of the problem as solved; <NA> without a grid"),
    ("N1", "Int64", "grid points along axis 1 (columns); N0 = N1 = N on a square grid"),
    ("delta0", "float64", "grid spacing along axis 0 (element side, the instance's length unit); NaN without a grid"),
    ("delta1", "float64", "grid spacing along axis 1 (delta0 = delta1: square elements)"),
    ("thickness", "float64", "the elastic layer's thickness on its rigid base; NaN: the half-space"),
    ("nu", "float64", "the elastic layer's Poisson ratio; NaN: the half-space (E is then the composite modulus)"),
    ("interface", "string", "the layer's interface with its base, 'bonded' or 'frictionless'; '' for the half-space"),
    ("surface_source", "string", "a measured surface's file, base name; '' for a generated surface"),
    ("surface_hash", "string", "sha256 of the measured map's raw heights as read (shape, float64, C order; first 16 "
                               "hex digits): the same file by any path; ''"),
    ("height_unit", "string", "the unit of the measured file's height numbers (the file's own, or the one given; 'm' "
                              "by default); ''"),
    ("nan_rule", "string", "how missing points of the measured map were filled (problems/io.py NAN_RULES); ''"),
    ("nan_filled", "Int64", "missing points of the measured map filled by nan_rule that lie in the map as solved "
                            "(a crop may leave others out: meta.json); <NA> for a generated surface"),
    ("detrend", "string", "what was removed from the measured map: 'plane', 'mean' or 'none'; ''"),
    ("removed_mean", "float64", "height removed at the map's centre (the mean, or the plane's height there); NaN: "
                                "nothing removed"),
    ("removed_slope0", "float64", "slope of the removed plane along axis 0, rise per length; NaN: no plane removed"),
    ("removed_slope1", "float64", "slope of the removed plane along axis 1, rise per length; NaN: no plane removed"),
    ("crop", "string", "the crop rule applied to the measured map: 'none', 'square' or 'pad-square'; ''"),
    ("channel_index", "Int64", "the index of the channel read from the measured file (--channel INDEX, "
                               "load_surface's channel=; its name is in meta.json's surface_preprocessing record); "
                               "<NA> for a file of no channels (.npy, text) and a generated surface"),
    ("plastic_uncertain", "float64", "share of the contact elements whose plastic state check_tol leaves open (slack "
                                     "u_i - p_i within a decade of the plastic floor, or counted elastic within "
                                     "sqrt(check_tol) p_s of the bound): the flag of plastic_fraction; NaN without "
                                     "a hardness"),
    ("solved_hash", "string", "sha256 of the measured map's heights as solved (metres, after unit, fill, detrend "
                              "and crop; shape, float64, C order; first 16 hex digits); ''"),
)

#: Every column, by name, in table order.
COLUMNS: Final[dict[str, Column]] = {c.name: c for c in (*_REQUIRED, *_EXTRA)}
#: The columns a stored table must have (check_table), in this order.
REQUIRED_COLUMNS: Final = tuple(c.name for c in _REQUIRED)
#: Further columns every row carries ("" / NaN / <NA> where not applicable).
EXTRA_COLUMNS: Final = tuple(c.name for c in _EXTRA)
ALL_COLUMNS: Final = REQUIRED_COLUMNS + EXTRA_COLUMNS
#: The columns ``check_table`` reads (the required ones, every number and true/false column,
#: and ``verdict``); the others it never checks.
CHECKED_COLUMNS: Final = tuple(c.name for c in COLUMNS.values()
                               if c.required or c.dtype in ("float64", "Int64", "boolean") or c.name == "verdict")


def columns_of(dtype: str) -> tuple[str, ...]:
    """The names of the columns of one dtype, in table order."""
    if dtype not in DTYPES:
        raise ValueError(f"unknown dtype {dtype!r}; the schema uses {', '.join(DTYPES)}")
    return tuple(c.name for c in COLUMNS.values() if c.dtype == dtype)


class TableError(ValueError):
    """A stored table is missing or breaks the contract (columns, status values)."""


class MissingTableError(TableError, FileNotFoundError):
    """No stored table where one was expected."""


def _missing(v: Any) -> bool:
    return v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))


def as_text(v: Any) -> str:
    return "" if _missing(v) else str(v)


def text_values(col: pd.Series) -> np.ndarray:
    """``as_text`` of every entry of ``col``, as an array; a column of text dtype is read at
    once (its entries are text or missing)."""
    if isinstance(col.dtype, pd.StringDtype):
        return col.fillna("").to_numpy(dtype=object)
    return col.map(as_text).to_numpy(dtype=object)


def as_finite(v: Any) -> float | None:
    """A table cell as a finite float, else None (a null, NaN, inf, or text that is no number)."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def as_bool(v: Any) -> Any:
    """True / False / <NA> from a bool, a number or CSV text ("True", "0", "yes", ...)."""
    if _missing(v):
        return pd.NA
    if isinstance(v, str):
        low = v.strip().lower()
        return True if low in ("true", "1", "yes") else False if low in ("false", "0", "no") else pd.NA
    return bool(v)


def bool_series(s: pd.Series) -> pd.Series:
    """``as_bool`` over a column, as pandas' nullable boolean."""
    return s.map(as_bool).astype("boolean")


def apply_schema(df: pd.DataFrame) -> pd.DataFrame:
    """A copy with every schema column (added empty where absent), schema columns first
    in table order, then any others, each schema column cast to its dtype."""
    d = df.copy()
    for name in ALL_COLUMNS:
        if name not in d.columns:
            d[name] = None
    d = d[list(ALL_COLUMNS) + [c for c in d.columns if c not in COLUMNS]]
    for c in COLUMNS.values():
        col = d[c.name]
        if c.dtype == "string":
            d[c.name] = col.map(as_text).astype("string")
        elif c.dtype == "boolean":
            d[c.name] = bool_series(col)
        elif c.dtype == "Int64":
            d[c.name] = pd.to_numeric(col.map(lambda v: None if _missing(v) else v), errors="coerce").round() \
                .astype("Int64")
        else:
            d[c.name] = pd.to_numeric(col, errors="coerce").astype("float64")
    return d


#: The columns that name what a row is (``check_table``): ``status`` on every row; the
#: others on every row of a table that names them on any (a run writes them on each).
NAMING_COLUMNS: Final = ("status", "scene", "instance", "solver", "profile")


def check_table(df: pd.DataFrame, source: object = "the table") -> None:
    """Raise TableError when ``df`` lacks a required column, leaves a ``NAMING_COLUMNS``
    entry empty (missing or blank) on a row -- ``status`` on any row, the others on a row
    of a table whose other rows name them (the report would print a scene, solver or
    profile named "") -- or holds a status or verdict outside the contract.  An empty
    entry's message names the column and the first such row (1-based, in table order)."""
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise TableError(f"results table in {source} lacks required column(s): {', '.join(missing)}")
    for name in NAMING_COLUMNS:
        empty = np.array([not str(v).strip() for v in text_values(df[name])], dtype=bool)
        if empty.any() and (name == "status" or not empty.all()):
            first = int(np.flatnonzero(empty)[0])
            raise TableError(f"column {name} of {source} is empty in row {first + 1} ({int(empty.sum())} such "
                             f"row(s)); every row names its {name}")
    bad = sorted(set(text_values(df["status"])) - set(STATUSES))
    if bad:
        raise TableError(f"unknown status value(s) {bad} in {source}; expected one of {', '.join(STATUSES)}")
    if "verdict" in df.columns:
        bad = sorted(set(text_values(df["verdict"])) - {"", *VERDICTS})
        if bad:
            raise TableError(f"unknown verdict value(s) {bad} in {source}; expected one of {', '.join(VERDICTS)} "
                             f"or empty")
    for c in COLUMNS.values():
        if c.name in df.columns and c.dtype in ("float64", "Int64"):
            check_numbers(df[c.name], c.name, source, whole=c.dtype == "Int64")
        elif c.name in df.columns and c.dtype == "boolean":
            check_booleans(df[c.name], c.name, source)
    check_readings(df, source)


def check_booleans(col: pd.Series, name: str, source: object) -> None:
    """Raise TableError for an entry of a true/false column that ``as_bool`` cannot read
    (text such as "maybe": never read as missing).  Only the entries that are neither
    missing nor equal to True or False (text, other objects) are read one by one."""
    if pd.api.types.is_bool_dtype(col):
        return
    plain = (col.isna() | col.isin([True, False])).to_numpy(dtype=bool)
    unread = [int(i) for i in np.flatnonzero(~plain) if as_bool(col.iloc[i]) is pd.NA
              and as_text(col.iloc[i]).strip() != ""]
    if unread:
        raise TableError(f"column {name} of {source} holds {col.iloc[unread[0]]!r}, not true or false "
                         f"(row {unread[0] + 1}; {len(unread)} such row(s))")


def check_readings(df: pd.DataFrame, source: object) -> None:
    """Raise TableError for a row whose reading its own figures contradict (a hand-edited
    or forged row: the judge writes none of these): a negative ``kkt_error``; "solved" with
    a ``kkt_error`` that is not a finite number at most its ``check_tol`` (missing counts as
    above it where the table has the column: every run writes it), or with no finite
    ``solve_time_s``; "inaccurate" with a
    ``kkt_error`` at most its ``check_tol``; the reading "pass" above its ``check_tol``, or on a row that is neither
    "solved" nor "timeout" (a solve judged and finished past the limit); a ``check_tol``
    that is not a number > 0 and at most ``MAX_CHECK_TOL``.  The checks run on the numeric columns already
    checked by ``check_numbers``."""
    status = text_values(df["status"])
    kkt = _numbers(df, "kkt_error")
    tol = _numbers(df, "check_tol")
    seconds = _numbers(df, "solve_time_s")
    solved, inaccurate = status == "solved", status == "inaccurate"
    late = status == "timeout"  # judged, and finished past the time limit: its reading stands
    passed = text_values(df["verdict"]) == "pass" if "verdict" in df.columns else np.zeros(len(df), bool)
    told = "check_tol" in df.columns  # (every run writes it; a table without the column is read as it was)
    with np.errstate(invalid="ignore"):
        within = np.isfinite(kkt) & ((np.isnan(tol) & (not told)) | (kkt <= tol))
        rules = [
            (~np.isnan(tol) & ~((tol > 0) & (tol <= MAX_CHECK_TOL)),
             f"a check_tol {{tol}}, not a number > 0 and at most {MAX_CHECK_TOL:g}"),
            (kkt < 0, "a negative kkt_error {kkt}"),
            (solved & ~within, "status solved with kkt_error {kkt} above its check_tol {tol} (or not a number)"),
            (solved & ~np.isfinite(seconds), "status solved with solve_time_s {seconds}, not a finite time"),
            (inaccurate & (kkt <= tol), "status inaccurate with kkt_error {kkt} within its check_tol {tol}"),
            (passed & ~(solved | late), "the reading pass on a row whose status is neither solved nor timeout"),
            (passed & ~within, "the reading pass with kkt_error {kkt} above its check_tol {tol}"),
        ]
    for rows, what in rules:
        hit = np.flatnonzero(rows)
        if hit.size:
            i = int(hit[0])
            text = what.format(kkt=kkt[i], tol=tol[i], seconds=seconds[i])
            raise TableError(f"row {i + 1} of {source} contradicts its own figures: {text} "
                             f"({hit.size} such row(s)); the judge writes no such row")


def _numbers(df: pd.DataFrame, name: str) -> np.ndarray:
    """Column ``name`` as float64 (NaN where absent or missing)."""
    if name not in df.columns:
        return np.full(len(df), np.nan)
    return pd.to_numeric(df[name], errors="coerce").to_numpy(dtype="float64", na_value=np.nan)


def check_numbers(col: pd.Series, name: str, source: object, whole: bool = False) -> None:
    """Raise TableError for an entry of a numeric column that is text but no number, or a
    true/false value (a corrupted or hand-edited table: never read as missing nor as 0 or
    1), a number that is not whole in
    a ``whole`` (count) column (never rounded) or beyond its int64 (``COUNT_MAX``), or a negative or infinite duration (the
    ``_s`` columns: seconds; missing is NaN)."""
    flags = col.map(lambda v: isinstance(v, (bool, np.bool_))) if col.dtype == object or \
        pd.api.types.is_bool_dtype(col) else None
    if flags is not None and flags.any():
        at = int(np.flatnonzero(flags.to_numpy(dtype=bool))[0])
        raise TableError(f"column {name} of {source} holds {col.iloc[at]!r}, a true/false value, not a number "
                         f"(row {at + 1}; {int(flags.sum())} such row(s))")
    if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col):
        values = col.astype("float64")
    else:
        values = pd.to_numeric(col, errors="coerce")  # (missing and blank entries, and text, read NaN)
        suspect = np.flatnonzero(values.isna().to_numpy() & col.notna().to_numpy())  # text, or no number
        unread = np.array([i for i in suspect if as_text(col.iloc[i]).strip() != ""], dtype=np.int64)
        if unread.size:
            raise TableError(f"column {name} of {source} holds {col.iloc[unread[0]]!r}, not a number "
                             f"(row {int(unread[0]) + 1}; {unread.size} such row(s))")
    if whole:
        x = values.to_numpy(dtype="float64", na_value=np.nan)
        with np.errstate(invalid="ignore"):
            hit = np.flatnonzero(np.isfinite(x) & (x != np.round(x)))
        if hit.size:
            raise TableError(f"column {name} of {source} holds {x[hit[0]]}, not a whole number (row {int(hit[0]) + 1})")
        with np.errstate(invalid="ignore"):
            hit = np.flatnonzero(np.isfinite(x) & (np.abs(x) > COUNT_MAX))
        if hit.size:
            raise TableError(f"column {name} of {source} holds {x[hit[0]]:g}, beyond a count's range "
                             f"(|value| <= {COUNT_MAX}; row {int(hit[0]) + 1})")
    if name.endswith("_s"):
        seconds = values.to_numpy(dtype="float64", na_value=np.nan)
        for wrong, what in ((seconds < 0, "a negative"), (np.isinf(seconds), "an infinite"),
                            (seconds > MAX_DURATION_S, f"a longer than {MAX_DURATION_S:g} s")):
            hit = np.flatnonzero(wrong)
            if hit.size:
                raise TableError(f"column {name} of {source} holds {what} duration, {seconds[hit[0]]} s "
                                 f"(row {int(hit[0]) + 1})")
    if name in RANGES:
        check_range(values.to_numpy(dtype="float64", na_value=np.nan), name, source)


def check_range(x: np.ndarray, name: str, source: object) -> None:
    """Raise TableError for an entry of column ``name`` outside its ``RANGES`` (NaN: missing)."""
    low, high, low_allowed = RANGES[name]
    with np.errstate(invalid="ignore"):
        outside = ~np.isnan(x) & ((x < low) | (x > high) | (~np.isfinite(x)) | ((x == low) & (not low_allowed)))
    if math.isinf(high) and name in _FIGURES:  # (a figure of no answer is inf: a failed row's)
        with np.errstate(invalid="ignore"):
            outside &= ~(x == math.inf)
    hit = np.flatnonzero(outside)
    if hit.size:
        bounds = f"{'[' if low_allowed else '('}{low:g}, {high:g}]" if math.isfinite(high) else \
            f"{'>=' if low_allowed else '>'} {low:g}" if math.isfinite(low) else "finite"
        raise TableError(f"column {name} of {source} holds {x[hit[0]]:g}, outside its range ({bounds}; row "
                         f"{int(hit[0]) + 1}; {hit.size} such row(s))")
