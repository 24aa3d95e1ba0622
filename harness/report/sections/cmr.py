"""Report sections of the cascade multi-resolution scenes (Bemporad & Paggi 2015, sec. 5.2):
``cmr`` (Fig. 8), ``cmr-h-sweep`` (Fig. 9) and ``cmr-cutoff`` (Figs. 10-11).

Section 5 is reported as distributions over seeds: every figure draws the
median with a 10-90 % band (``BAND``), and every table gives the same numbers, per
surface family that ran, per base solver and per coarse reading.

Pairing.  Each CMR row ("cmr+<base>" in ``base_solver``) is paired with the direct solve
of its base (``base_solver`` == <base>) on the same instance, step and history; only
solves that returned an answer (solved or inaccurate) are paired (a failed or timed-out
solve has no load), so the tables' seed counts say how many pairs each figure rests on.  The
direct time of a base given the dense H (``operator`` "dense", e.g. ``scipy-nnls``)
includes the assembly of that H (its row's ``build_time_s`` less the step's build, which
the CMR row of the step carries), as the CMR time includes the assembly of every level's
matrix.  A variant's time ratio is its CMR time summed over the paired steps of an
instance (the 10-step history of ``cmr``, the top step of ``cmr-h-sweep``) over the
direct time summed over the same steps; the load error is (P_CMR - P_direct) / P_direct
at the top step (negative: CMR misses load).  n_p/n is the fine level's projected share
of the trial set, from the column ``projected_n`` when the table has one, else from the
CMR solver's message (``NP_RE``).  The variant's h, coarse reading and first level are read from ``params`` (absent
keys: the wrapper's declared defaults).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Iterable, Sequence

import numpy as np
import pandas as pd
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.solvers.cmr import CMRSolver

from ..core import (
    ReportContext,
    attempted,
    fmt_num,
    natural_key,
    natural_sorted,
    parse_json,
    per_cell,
    pick_profile,
    table_md,
)
from ...table.schema import ANSWERED
from ..markdown_text import md_code
from .paper import family_name

#: The study's area-of-influence factor and first level: the cmr solver's declared
#: defaults (solvers/cmr.py), the values the cmr study runs at.
CMR_H: float = next(p.default for p in CMRSolver.params if p.name == "h")
CMR_COARSEST: int = next(p.default for p in CMRSolver.params if p.name == "coarsest")

NP_RE = re.compile(r"n_p/n=([0-9.eE+-]+)")
#: The registry names of the CMR wrappers: "cmr+<base solver>" (solvers/cmr.py).
CMR_PREFIX = "cmr+"
#: The paper's accuracy claim: the error in the maximum load under 2 % (for H > 0.5).
ERROR_TOL = 0.02
#: The Hurst exponents the paper's accuracy claim is about: H > PAPER_H_MIN.
PAPER_H_MIN = 0.5
#: The paper's time claim: about 50 % of the time saved at h = 2 (CMR / direct ~ 0.5).
PAPER_TIME_RATIO = 0.5
#: The share of seeds under ERROR_TOL at which the claim is read as robust.
ROBUST_SHARE = 0.8
#: The claims ledger's rows that judge Fig. 8's claims (claim_rules.py ``CLAIMS``), as the
#: readings name them.
LEDGER_ROWS = "`fig8-cmr-error` (the largest |error| for H > 0.5) and `fig8-cmr-time`"
#: The quantiles of the bands drawn and tabled around the median.
BAND = (0.10, 0.90)
#: The surface of paper Fig. 9 (and of the first-level figure when several H ran).
FIG9_H = 0.7
#: What each base solver stands for in the figures and readings.
BASE_TEXT = {"scipy-nnls": "dense Cholesky + NNLS (the paper's base)", "nnls": "incremental NNLS",
             "fast-dual-pccg": "FFT base fast-dual-pccg"}
#: The surface-family key of instances that are not generated rough surfaces.
NO_FAMILY = ""


def family_label(family: str) -> str:
    """A surface family as a caption names it: "all surfaces" where the table names none."""
    return family or "all surfaces"


def wrapped_solver(base_solver: str) -> str | None:
    """The base solver a CMR wrapper runs ("cmr+nnls" -> "nnls"), None for other solvers."""
    return base_solver[len(CMR_PREFIX):] if base_solver.startswith(CMR_PREFIX) else None


# ---------------------------------------------------------------------------
# Distributions
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Band:
    """Median and the BAND quantiles of the finite values, and how many there were."""

    median: float
    lo: float
    hi: float
    count: int


def finite(values: Iterable[Any]) -> np.ndarray:
    """The finite numbers among ``values`` (missing values of any kind dropped)."""
    v = pd.to_numeric(pd.Series(list(values), dtype=object), errors="coerce").to_numpy(dtype=float, na_value=np.nan)
    return v[np.isfinite(v)]


def band(values: Iterable[float]) -> Band:
    v = finite(values)
    if not len(v):
        return Band(np.nan, np.nan, np.nan, 0)
    lo, med, hi = np.quantile(v, [BAND[0], 0.5, BAND[1]])
    return Band(float(med), float(lo), float(hi), len(v))


def share_under(errors: Iterable[float], tol: float = ERROR_TOL) -> float:
    """The share of the finite errors with |error| < tol (NaN when there is none)."""
    e = finite(errors)
    return float(np.mean(np.abs(e) < tol)) if len(e) else np.nan


def worst(errors: Iterable[float]) -> float:
    """The error of largest magnitude, with its sign."""
    e = finite(errors)
    return float(e[np.argmax(np.abs(e))]) if len(e) else np.nan


def fmt_band(b: Band, pct: bool = False) -> str:
    """"median [lo, hi]" (in % with ``pct``)."""
    if not b.count:
        return "-"
    f = _pct if pct else fmt_num
    return f"{f(b.median)} [{f(b.lo)}, {f(b.hi)}]" + (" %" if pct else "")


def _pct(v: float) -> str:
    x = round(100 * v, 1)
    return f"{x if x != 0 else 0.0:.1f}"


def fmt_pct1(v: float) -> str:
    """A fraction in per cent, one decimal ("-" for NaN, never "-0.0")."""
    return "-" if not np.isfinite(v) else f"{_pct(v)} %"


# ---------------------------------------------------------------------------
# Pairing CMR rows with the direct solves
# ---------------------------------------------------------------------------


@lru_cache(maxsize=None)
def wrapper_defaults(base_solver: str) -> dict[str, Any]:
    """The declared defaults of a CMR wrapper's parameters ({} when it is not registered)."""
    from contactbench.solvers.registry import load_solver

    try:
        return load_solver(base_solver).param_defaults()
    except Exception:
        return {}


def variant_params(base_solver: str, params_text: str) -> tuple[float, str, int]:
    """(h, coarse, coarsest) of a CMR row: its ``params``, else the wrapper's defaults."""
    p = parse_json(params_text, {})
    p = {**wrapper_defaults(base_solver), **(p if isinstance(p, dict) else {})}
    h = float(p["h"]) if p.get("h") is not None else np.nan
    coarsest = int(p["coarsest"]) if p.get("coarsest") is not None else -1
    return h, str(p.get("coarse") or "subsample"), coarsest


#: The column that would hold the fine level's projected trial-set size (not in the
#: schema yet: read when present, else n_p/n is parsed from the message).
PROJECTED_N = "projected_n"


def n_p_over_n(message: str) -> float:
    m = NP_RE.search(str(message))
    return float(m.group(1)) if m else np.nan


def projected_share(cells: pd.DataFrame) -> pd.Series:
    """n_p/n of CMR cells: ``PROJECTED_N`` / n where the table has it, else the message's."""
    parsed = cells["solver_message"].map(n_p_over_n)
    if PROJECTED_N not in cells.columns:
        return parsed
    stored = pd.to_numeric(cells[PROJECTED_N], errors="coerce") / cells["n"]
    return stored.where(stored.notna(), parsed)


def cmr_pairs(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per (instance, step, CMR variant) where both the CMR solve and its direct
    solve returned an answer (``ANSWERED``) under the same profile -- each base at the
    tightest profile it ran under (``pick_profile``), so a study that ran the dense base
    under the paper's profile and the FFT base under another shows both: the CMR solve's
    time, load and n_p/n beside its direct base solve's, the load error, the variant's
    base / coarse / h / coarsest and the surface's family / H / seed.  Empty when no CMR
    row has its direct solve."""
    done = attempted(rows)
    if done.empty:
        return pd.DataFrame()
    base_of = done["base_solver"].map(wrapped_solver).fillna(done["base_solver"]).to_numpy()
    tightest = done.groupby(base_of)["profile"].transform(lambda s: pick_profile(pd.DataFrame({"profile": s})))
    cells = per_cell(done[(done["profile"] == tightest).to_numpy()])
    if cells.empty:
        return pd.DataFrame()
    cells = cells[cells["status"].isin(ANSWERED)]
    inner = cells["base_solver"].map(wrapped_solver)
    is_cmr = inner.notna()
    cmr, direct = cells[is_cmr].copy(), cells[~is_cmr]
    if cmr.empty or direct.empty:
        return pd.DataFrame()
    cmr["base"] = inner[is_cmr]
    h, coarse, coarsest = zip(*(variant_params(b, p) for b, p in zip(cmr["base_solver"], cmr["params"])))
    cmr = cmr.assign(h=h, coarse=coarse, coarsest=coarsest, n_p_over_n=projected_share(cmr))
    keys = ["instance", "step", "history", "profile"]
    d = direct[[*keys, "base_solver", "solve_time_s", "load", "build_time_s", "operator", "warm_start"]].rename(
        columns={"base_solver": "base", "solve_time_s": "direct_solve_s", "load": "direct_load",
                 "build_time_s": "direct_build_s", "operator": "direct_operator", "warm_start": "direct_warm"})
    out = cmr.merge(d, on=[*keys, "base"], how="inner")
    if out.empty:
        return out
    dense = (out["direct_operator"] == "dense") & (out["operator"] != "dense")
    assembly = (out["direct_build_s"] - out["build_time_s"]).clip(lower=0.0).fillna(0.0)
    out["direct_assembly_s"] = np.where(dense, assembly, 0.0)
    out["direct_assembled"] = dense.to_numpy(dtype=bool)
    out["direct_time_s"] = out["direct_solve_s"] + out["direct_assembly_s"]
    out["err"] = (out["load"] - out["direct_load"]) / out["direct_load"]
    out["N"] = out["N"].fillna(0).astype(int)
    fams = out["surface_family"] if "surface_family" in out.columns else pd.Series("", index=out.index)
    out["surface"] = [family_name(f) or NO_FAMILY for f in fams]
    absent = pd.Series(np.nan, index=out.index)  # a table written before the instance columns
    out["H"] = pd.to_numeric(out.get("hurst", absent), errors="coerce").astype(float)
    out["seed"] = pd.to_numeric(out.get("seed", absent), errors="coerce").fillna(-1).astype(int)
    return out


def instance_totals(pairs: pd.DataFrame) -> pd.DataFrame:
    """One row per (instance, CMR variant): the time ratio over the paired steps, and the
    error, n_p/n and n at the top paired step."""
    keys = ["surface", "instance", "solver", *VARIANT, "h", "coarsest", "H", "seed"]
    g = pairs.groupby(keys, dropna=False)
    tot = g.agg(cmr_s=("solve_time_s", "sum"), direct_s=("direct_time_s", "sum"),
                assembly_s=("direct_assembly_s", "sum"), steps=("step", "size"))
    tot["ratio"] = tot["cmr_s"] / tot["direct_s"]
    # the top step's row of each group, by position (a join on the keys would miss a key
    # holding NaN: a table without the Hurst exponent)
    top = pairs.loc[g["step"].idxmax().to_numpy(), ["err", "n_p_over_n", "n", "step"]]
    return pd.concat([tot.reset_index(), top.reset_index(drop=True)], axis=1)


#: What tells the CMR runs of a scene apart in every table and figure: the base, the
#: coarse reading and the grid size (the dense base may run at a smaller N than the fast).
VARIANT = ["base", "coarse", "N"]
Variant = tuple[str, str, int]


def variant_order(frame: pd.DataFrame) -> list[Variant]:
    """The (base, coarse, N) present: dense base first, larger N first, subsample first."""
    found = {(str(b), str(c), int(n)) for b, c, n in zip(frame["base"], frame["coarse"], frame["N"].fillna(0))}
    rank = {"scipy-nnls": 0, "nnls": 1}
    return sorted(found, key=lambda v: (rank.get(v[0], 2), natural_key(v[0]), -v[2], v[1] != "subsample", v[1]))


def of_variant(frame: pd.DataFrame, v: Variant) -> pd.DataFrame:
    return frame[(frame["base"] == v[0]) & (frame["coarse"] == v[1]) & (frame["N"].fillna(0) == v[2])]


def variant_title(v: Variant) -> str:
    return f"{BASE_TEXT.get(v[0], v[0])}, coarse={v[1]}, N = {v[2]}"


@dataclass(frozen=True)
class BaseRun:
    """How one base ran in a scene's pairs, read from the table's columns only: ``base`` (the
    direct solve's ``base_solver``), its ``operator``, how many of its distinct direct
    solves were warm started (``warm_start``) of how many, how many of them count the
    assembly of a dense H in their time (``cmr_pairs``: a dense direct solve against a CMR
    run that is not), and how many of the CMR solves over it were warm started, of how many."""

    base: str
    operator: str
    direct_warm: int
    direct: int
    assembled: int
    cmr_warm: int
    cmr: int


def base_runs(pairs: pd.DataFrame) -> dict[str, BaseRun]:
    """Base -> its ``BaseRun`` in ``pairs`` (``cmr_pairs``), in ``variant_order``.  A direct
    solve paired with several CMR variants counts once."""
    out: dict[str, BaseRun] = {}
    if pairs.empty:
        return out
    keys = ["instance", "step", "history", "profile"]
    for base in dict.fromkeys(v[0] for v in variant_order(pairs)):
        p = pairs[pairs["base"] == base]
        direct = p.drop_duplicates([*keys, "base"])
        ops = natural_sorted(set(direct["direct_operator"].fillna("").astype(str)) - {""})
        cmr = p.drop_duplicates([*keys, "solver"])
        out[base] = BaseRun(base, "/".join(ops) or "-", int(direct["direct_warm"].astype(bool).sum()), len(direct),
                            int(direct["direct_assembled"].astype(bool).sum()), int(cmr["warm_start"].astype(bool).sum()),
                            len(cmr))
    return out


def warm_short(warm: int, total: int) -> str:
    """A panel title's words on the warm starts of ``total`` solves: "cold" (none), "warm"
    (all), else "warm on k of n"."""
    return "cold" if warm == 0 else "warm" if warm == total else f"warm on {warm} of {total}"


def panel_title(v: Variant, runs: dict[str, BaseRun]) -> str:
    """A CMR panel's title: the base as the table names it, its operator and whether its
    direct solves were warm started (``runs``: ``base_runs`` of the panel's pairs), then the
    coarse reading and N."""
    r = runs.get(v[0])
    how = f" ({r.operator})\ndirect solves {warm_short(r.direct_warm, r.direct)}" if r else ""
    return f"{v[0]} base{how}\ncoarse={v[1]}, N = {v[2]}"


#: What each coarse reading of the CMR levels is, for the design note.
COARSE_TEXT = {"subsample": "exact subsamples (`coarse=subsample`)", "mean": "block means (`coarse=mean`)"}


def _warm_words(warm: int, total: int, what: str) -> str:
    if warm == 0:
        return f"never warm started: each of its {total} {what} from scratch"
    if warm == total:
        return f"warm started from the previous step's answer on all {total} {what}"
    return f"warm started from the previous step's answer on {warm} of its {total} {what}, the other {total - warm} from scratch"


def design_note(pairs: pd.DataFrame) -> str:
    """What the direct solves and the CMR runs of ``pairs`` (``cmr_pairs``) were, read from
    the table: each base's ``base_solver``, operator and ``warm_start`` count, whether its
    time includes a dense H's assembly, the coarse readings that ran, and the CMR runs' own
    warm starts ("" for no pairs)."""
    runs = base_runs(pairs)
    if not runs:
        return ""
    bases = []
    for r in runs.values():
        what = BASE_TEXT.get(r.base, "")
        text = f"{md_code(r.base)} ({what + ', ' if what and r.base not in what else ''}operator {r.operator}), " \
               f"{_warm_words(r.direct_warm, r.direct, 'direct solves')}"
        if r.assembled:
            some = "" if r.assembled == r.direct else f" on {r.assembled} of its {r.direct} solves"
            text += f"; its time includes the assembly of its dense H{some}"
        bases.append(text)
    coarse = [COARSE_TEXT.get(c, f"`coarse={c}`") for c in natural_sorted(set(pairs["coarse"].astype(str)))]
    cmr = "; ".join(f"over {md_code(r.base)}, {_warm_words(r.cmr_warm, r.cmr, 'CMR solves')}" for r in runs.values())
    return (f"**Direct solves and bases** (from the table's `base_solver`, `operator` and `warm_start`): "
            f"{'; '.join(bases)}. CMR runs over each base, with the coarse levels as {' or '.join(coarse)}; "
            f"CMR's fine level, {cmr}.\n")


# ---------------------------------------------------------------------------
# Summaries: the one place each table's numbers are computed
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Summary:
    """The distribution of one group of instances (one variant at one H, or h, ...)."""

    ratio: Band
    err: Band
    np_n: Band
    share: float  # of |err| < ERROR_TOL
    worst: float

    @classmethod
    def of(cls, tot: pd.DataFrame) -> Summary:
        return cls(band(tot["ratio"]), band(tot["err"]), band(tot["n_p_over_n"]), share_under(tot["err"]),
                   worst(tot["err"]))


def summaries(tot: pd.DataFrame, by: Sequence[str]) -> dict[tuple, Summary]:
    """Summary per group of ``by`` (keys as tuples; the variants in ``variant_order``,
    numbers ascending)."""
    rank = {v: i for i, v in enumerate(variant_order(tot))}
    pos = {c: i for i, c in enumerate(by)}

    def key(k: tuple) -> tuple:
        head = rank.get(tuple(k[pos[c]] for c in VARIANT), -1) if set(VARIANT) <= set(pos) else 0
        return (head, *(natural_key(str(x)) if isinstance(x, str) else ((0, float(x), ""),) for x in k))

    groups = {(k if isinstance(k, tuple) else (k,)): g for k, g in tot.groupby(list(by), dropna=False)}
    return {k: Summary.of(groups[k]) for k in sorted(groups, key=key)}


@dataclass(frozen=True)
class Table:
    """A report table: caption, headers, cells, alignment -- rendered in Markdown by
    ``table_md`` (which also records it for the HTML page)."""

    caption: str
    headers: tuple[str, ...]
    rows: list[tuple[str, ...]]
    align: str

    def md(self, ctx: ReportContext) -> str:
        return table_md(ctx, self.caption, self.headers, self.rows, self.align, on_page=True)


def fig8_table(tot: pd.DataFrame, family: str) -> Table:
    s = summaries(tot, [*VARIANT, "H"])
    rows = [(BASE_TEXT.get(b, b), c, str(N), fmt_num(H), str(v.err.count), fmt_band(v.ratio),
             fmt_band(v.err, pct=True), fmt_pct1(v.worst), fmt_pct1(v.share), fmt_band(v.np_n))
            for (b, c, N, H), v in s.items()]
    return Table(f"Fig. 8 ({family_label(family)}): per base, coarse reading and H over the seeds -- time "
                 f"CMR / direct summed over the load history, error in the load at the top step, its worst "
                 f"case, the share of seeds with |error| < {100 * ERROR_TOL:g} %, and n_p/n at the top step; "
                 f"median [{100 * BAND[0]:g} %, {100 * BAND[1]:g} %].",
                 ("base", "coarse", "N", "H", "seeds", "time ratio", "load error", "worst", "share < 2 %",
                  "n_p/n"), rows, "llrrrrrrrr")


def history_bands(pairs: pd.DataFrame) -> dict[tuple, Band]:
    """Band of the load error per (base, coarse, N, H, step) over the seeds."""
    return {(str(b), str(c), int(N), float(H), int(k)): band(g["err"])
            for (b, c, N, H, k), g in pairs.groupby([*VARIANT, "H", "step"], dropna=False)}


def history_table(pairs: pd.DataFrame, family: str) -> Table:
    hb = history_bands(pairs)
    steps = sorted({k[4] for k in hb})
    order = variant_order(pairs)
    groups = sorted({k[:4] for k in hb}, key=lambda k: (order.index(k[:3]), k[3]))
    rows = [(BASE_TEXT.get(g[0], g[0]), g[1], str(g[2]), fmt_num(g[3]),
             *(fmt_band(hb[(*g, k)], pct=True) if (*g, k) in hb else "-" for k in steps)) for g in groups]
    return Table(f"Load error along the load history ({family_label(family)}): median [{100 * BAND[0]:g} %, "
                 f"{100 * BAND[1]:g} %] over the seeds at each step (step 1: the lowest load).",
                 ("base", "coarse", "N", "H", *(f"step {k + 1}" for k in steps)), rows, "llrr" + "r" * len(steps))


def h_table(tot: pd.DataFrame, family: str) -> Table:
    s = summaries(tot, [*VARIANT, "h"])
    rows = [(BASE_TEXT.get(b, b), c, str(N), fmt_num(h), str(v.err.count), fmt_band(v.np_n), fmt_band(v.ratio),
             fmt_band(v.err, pct=True), fmt_pct1(v.worst), fmt_pct1(v.share)) for (b, c, N, h), v in s.items()]
    return Table(f"Fig. 9 ({family_label(family)}): against h, first level {CMR_COARSEST} -- n_p/n, time "
                 f"CMR / direct and load error at the top step over the seeds; median "
                 f"[{100 * BAND[0]:g} %, {100 * BAND[1]:g} %].",
                 ("base", "coarse", "N", "h", "seeds", "n_p/n", "time ratio", "load error", "worst",
                  "share < 2 %"), rows, "llrrrrrrrr")


def coarsest_table(tot: pd.DataFrame, family: str) -> Table:
    s = summaries(tot, [*VARIANT, "H", "coarsest"])
    rows = [(BASE_TEXT.get(b, b), c, str(N), fmt_num(H), str(k), str(v.err.count), fmt_band(v.err, pct=True),
             fmt_pct1(v.worst), fmt_pct1(v.share), fmt_band(v.ratio), fmt_band(v.np_n))
            for (b, c, N, H, k), v in s.items()]
    return Table(f"Where the cascade starts ({family_label(family)}), h = {CMR_H:g}: load error (worst case "
                 f"over the seeds), share under {100 * ERROR_TOL:g} %, time ratio and n_p/n per first level.",
                 ("base", "coarse", "N", "H", "first level", "seeds", "load error", "worst", "share < 2 %",
                  "time ratio", "n_p/n"), rows, "llrrrrrrrrr")


# ---------------------------------------------------------------------------
# Readings: where the paper's claim holds, in numbers from the rows
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ClaimCheck:
    """The paper's claims read on one variant: accuracy for H > PAPER_H_MIN (typical:
    the median; robust: ROBUST_SHARE of the surfaces and the worst one under ERROR_TOL)
    and time (the median ratio under 1)."""

    variant: Variant
    accuracy: Summary | None
    ratio: Band

    @property
    def typical(self) -> bool:
        return self.accuracy is not None and abs(self.accuracy.err.median) < ERROR_TOL

    @property
    def robust(self) -> bool:
        a = self.accuracy
        return a is not None and a.share >= ROBUST_SHARE and abs(a.worst) < ERROR_TOL

    @property
    def saves_time(self) -> bool:
        return self.ratio.count > 0 and self.ratio.median < 1.0

    def line(self) -> str:
        """The variant's numbers, with no verdict word: the verdicts on the paper's Fig. 8
        claims are the claims ledger's (rows ``LEDGER_ROWS``, per operator at the largest
        size, the largest |error| included), which this line names."""
        a = self.accuracy
        acc = ("no surface with H > 0.5" if a is None else
               f"median error {fmt_pct1(a.err.median)}, {fmt_pct1(a.share)} of {a.err.count} surfaces under "
               f"{100 * ERROR_TOL:g} %, worst {fmt_pct1(a.worst)}")
        r = self.ratio
        saving = (f"saves {100 * (1 - r.median):.0f} % of the time" if self.saves_time else "saves no time")
        return (f"- {variant_title(self.variant)}: {acc}; time CMR / direct {fmt_num(r.median)} "
                f"[{fmt_num(r.lo)}, {fmt_num(r.hi)}] -- {saving}.")


def claim_checks(tot: pd.DataFrame) -> list[ClaimCheck]:
    out = []
    for v in variant_order(tot):
        sub = of_variant(tot, v)
        high = sub[sub["H"] > PAPER_H_MIN]
        out.append(ClaimCheck(v, Summary.of(high) if len(high) else None, band(sub["ratio"])))
    return out


def low_load_line(pairs: pd.DataFrame) -> str:
    """The error at the lowest against the top step of the history, H > PAPER_H_MIN,
    over every variant."""
    sub = pairs[pairs["H"] > PAPER_H_MIN]
    if sub.empty or sub["step"].nunique() < 2:
        return ""
    first, top = sub[sub["step"] == sub["step"].min()], sub[sub["step"] == sub["step"].max()]
    s_first, s_top = share_under(first["err"]), share_under(top["err"])
    verdict = "fewer" if s_first < s_top else "as many or more"
    return (f"- Low loads (H > {PAPER_H_MIN:g}, every variant): at the first step {fmt_pct1(s_first)} of the "
            f"solves are under {100 * ERROR_TOL:g} % (median {fmt_pct1(band(first['err']).median)}, worst "
            f"{fmt_pct1(worst(first['err']))}), at the top step {fmt_pct1(s_top)} (median "
            f"{fmt_pct1(band(top['err']).median)}, worst {fmt_pct1(worst(top['err']))}): {verdict} under "
            f"{100 * ERROR_TOL:g} % at low loads.")


def verdict_line(checks: Sequence[ClaimCheck]) -> str:
    """The variants grouped by their numbers (median |error| under ERROR_TOL, every surface
    under it, median time ratio under 1), with no verdict word; the rows of the claims ledger
    that judge the paper's Fig. 8 claims (``LEDGER_ROWS``) named."""
    def names(cs: Iterable[ClaimCheck]) -> str:
        return "; ".join(variant_title(c.variant) for c in cs) or "none"

    both = [c for c in checks if c.typical and c.saves_time]
    not_robust = [c for c in checks if c.typical and not c.robust]
    slow = [c for c in checks if not c.saves_time]
    inaccurate = [c for c in checks if not c.typical]
    tol = f"{100 * ERROR_TOL:g} %"
    return (f"- **In short.** Median |error| under {tol} and median time ratio under 1: {names(both)}. Median "
            f"|error| under {tol} but some surface over it: {names(not_robust)}. Median |error| over {tol}: "
            f"{names(inaccurate)}. No time saved: {names(slow)}. No verdict here: the claims ledger judges the "
            f"paper's Fig. 8 claims per operator at the largest size, rows {LEDGER_ROWS} (claims.md).")


def fig8_reading(tot: pd.DataFrame, pairs: pd.DataFrame) -> str:
    checks = claim_checks(tot)
    lines = [c.line() for c in checks] + [low_load_line(pairs), verdict_line(checks)]
    return ("**Reading** (computed from the rows). The paper: error in the maximum load under 2 % for H > 0.5, "
            "about 50 % of the time saved at h = 2 (a dense NNLS base, one surface per H). Here, per base and "
            "coarse reading, over the seeds (time summed over the load history):\n\n"
            + "\n".join(x for x in lines if x) + "\n")


def fig9_reading(tot: pd.DataFrame) -> str:
    parts = []
    at = tot[(tot["coarsest"] == CMR_COARSEST)]
    for v in variant_order(at):
        sub = of_variant(at, v)
        s = summaries(sub, ["h"])
        if len(s) < 2:
            continue
        (h0, v0), (h1, v1) = next(iter(s.items())), list(s.items())[-1]
        parts.append(f"{variant_title(v)}: n_p/n {fmt_num(v0.np_n.median)} -> {fmt_num(v1.np_n.median)} and "
                     f"time ratio {fmt_num(v0.ratio.median)} -> {fmt_num(v1.ratio.median)}, median error "
                     f"{fmt_pct1(v0.err.median)} -> {fmt_pct1(v1.err.median)} for h {h0[0]:g} -> {h1[0]:g}.")
    at2 = tot[np.isclose(tot["h"], CMR_H)]
    starts = summaries(at2, [*VARIANT, "coarsest"])
    for (*var, k), x in starts.items():
        if len({kk[3] for kk in starts if list(kk[:3]) == var}) > 1:
            parts.append(f"{variant_title(tuple(var))}, h = {CMR_H:g}, first level {k}: worst error "
                         f"{fmt_pct1(x.worst)}, {fmt_pct1(x.share)} under {100 * ERROR_TOL:g} %.")
    return ("**Reading** (computed from the rows; paper, H = 0.7: n_p/n from 0.4 to 0.8 as h goes 1.25 -> 3.0, "
            "the time ratio tends to 0.6 and the error falls under 1 %). " + " ".join(parts) + "\n")


# ---------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------


def by_family(pairs: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    return [(f, g) for f, g in sorted(pairs.groupby("surface"), key=lambda kv: kv[0])]


def recorded_families(rows: pd.DataFrame) -> pd.Series:
    """Each row's ``surface_family``; where a table written before ``cmr-cutoff`` recorded
    its surfaces' families leaves it empty, the family of the scene's own recipe of that
    instance name at the row's N, H and seed (``recipe_family``): the recipe, not the name,
    says which surface it is."""
    fam = rows["surface_family"].fillna("").astype(str) if "surface_family" in rows else pd.Series("", index=rows.index)
    missing = (fam == "") & (rows["scene"] == "cmr-cutoff")
    for i in rows.index[missing]:
        r = rows.loc[i]
        fam.loc[i] = recipe_family(str(r["instance"]), int(r["N"]), float(r["hurst"]), int(r["seed"])) \
            if pd.notna(r["N"]) and pd.notna(r["hurst"]) and pd.notna(r["seed"]) else ""
    return fam


@lru_cache(maxsize=64)
def recipe_family(instance: str, N: int, hurst: float, seed: int) -> str:
    """The ``family`` of the cmr-cutoff recipe called ``instance`` at size N, Hurst exponent
    and seed (the scene's other settings its own); "" when the scene names none so."""
    scene = get_scene("cmr-cutoff")
    try:
        specs = scene.instances(scene.config(SceneConfig(size=N, seeds=(seed,), extra={"hurst": hurst})))
    except ProblemInputError:  # (a row no recipe of the scene could have written: N 0, seed -1)
        return ""
    return next((str(s.params.get("family", "")) for s in specs if s.instance == instance), "")

