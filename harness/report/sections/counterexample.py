"""Report section of Example 1 (Bemporad & Paggi 2015, sec. 3, Fig. 2): the greedy
counterexample (scene ``counterexample``).

The counts are the judge's: a seed "violates the LCP" when the judge does not accept the
answer (``status`` is not "solved": the scaled KKT error exceeds the profile's
``check_tol``, or no answer came back), and the table's ``verdict`` splits those into
"wrong" (the solver claimed convergence: the paper's failure mode), "unconverged" (it
said it had not) and no answer (failed / timeout / crashed).  This section never applies
a threshold of its own.  How far an accepted answer lies from the exact one
(``p_rel_error``) is shown apart, as "distance from the exact LCP answer", never as a
violation.  One rejected case is plotted from the stored answer
(``OUT/arrays/counterexample-<instance>-<solver>.npz``, see docs/report.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from contactbench.problems.instances import CONTACT_TOL, counterexample
from matplotlib.figure import Figure

from ..charts import RowChart
from ..claim_rules import CLAIMS
from ..claim_tables import with_numbers
from ..markdown_text import md_code
from ..core import (
    ReportContext,
    ReportInputError,
    Section,
    attempted,
    fmt_err,
    fmt_pct,
    legend_outside,
    natural_key,
    natural_sorted,
    new_figure,
    register_section,
    table_md,
)
from ...table.aggregates import own_reference
from .generic import REF_CELL
from .paper import resolve_role
from .paper_conditions import Block, condition_blocks, operators_of

#: The share of seeds on which the paper saw greedy CG violate the LCP (sec. 3: "about 40 %"),
#: in percent, and its legend name: the dashed line of both Example 1 charts.
PAPER_GREEDY_SHARE = (40.0, "paper: ~40 % (greedy CG)")
#: The page chart of Example 1: the share of seeds not solved, per solver and n.
EXAMPLE1_PAGE = (RowChart("seeds violating the LCP (counterexample)", drawer="unsolved-share", x="n",
                          x_title="problem size", reference=PAPER_GREEDY_SHARE),)

#: The judge's reading of one seed, worst first: what a cell of several repeats reads as.
READINGS = ("no answer", "wrong", "unconverged", "accepted")
#: The cell of one seed and solver (repeats folded).
CELL_KEYS = ["scene", "instance", "step", "solver", "profile"]


def judge_reading(rows: pd.DataFrame) -> pd.Series:
    """Per row, the judge's reading from the table's own ``status`` and ``verdict``:
    "accepted" (status "solved" and verdict "pass" or not judged), "wrong" / "unconverged"
    (the judge's verdict on an answer it did not accept; where a table has no verdict,
    the judge's rule: "wrong" when the solver claimed convergence), else "no answer"
    (failed, timeout, crashed)."""
    status = rows["status"].astype(str)
    verdict = rows["verdict"].astype(str) if "verdict" in rows.columns else pd.Series("", index=rows.index)
    verdict = verdict.where(verdict.isin(["pass", "wrong", "unconverged"]), "")
    if "solver_converged" in rows.columns:  # a table without the verdict: the judge's rule from the claim
        claimed = rows["solver_converged"].astype("boolean").fillna(False).astype(bool)
        verdict = verdict.where((verdict != "") | (status != "inaccurate"), np.where(claimed, "wrong", "unconverged"))
    accepted = (status == "solved") & verdict.isin(["pass", ""])
    out = np.where(accepted, "accepted",
                   np.where(verdict == "wrong", "wrong",
                            np.where((verdict == "unconverged") | (status == "inaccurate"), "unconverged", "no answer")))
    return pd.Series(out, index=rows.index, dtype=object)


def seed_readings(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per (instance, solver, profile) cell: its worst reading over the repeats
    (column ``reading``), ``violates`` (reading not "accepted"), the cell's first ``n``,
    ``base_solver`` and ``params``, and its largest ``p_rel_error``."""
    keys = [k for k in CELL_KEYS if k in rows.columns]
    rank = {r: i for i, r in enumerate(READINGS)}
    r = rows.assign(_rank=judge_reading(rows).map(rank))
    g = r.groupby(keys, sort=True, dropna=False)
    carried = {c: (c, "first") for c in ("n", "base_solver", "params", "check_tol") if c in r.columns}
    cells = g.agg(**carried, _rank=("_rank", "min"), p_rel_error=("p_rel_error", "max")).reset_index()
    cells["reading"] = cells["_rank"].map(dict(enumerate(READINGS)))
    cells["violates"] = cells["reading"] != "accepted"
    return cells.drop(columns=["_rank"])


def violation_counts(cells: pd.DataFrame) -> pd.DataFrame:
    """Per (solver, n): seeds, seeds the judge rejects (``violations``), their split by
    reading, and ``fraction`` = violations / seeds."""
    g = cells.groupby(["solver", "n"])
    frac = pd.DataFrame({"seeds": g.size(), "violations": g["violates"].sum()})
    for reading in READINGS[:-1]:
        frac[reading] = g["reading"].agg(lambda s, x=reading: int((s == x).sum()))
    frac = frac.reset_index()
    frac["fraction"] = frac["violations"] / frac["seeds"]
    return frac


#: The fractions the paper (~40 %, any n) and an independent re-implementation
#: (``default_rng(seed).random(n)``, seeds 0-99) measured for greedy CG.
COUNTEREXAMPLE_REFERENCE = {25: 0.14, 100: 0.36, 400: 0.52}


@register_section("counterexample", title="Example 1: the greedy counterexample", group="paper", order=40)
def counterexample_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    title = "Example 1: the greedy counterexample (counterexample)"
    parts = [_counterexample_block(ctx, b) for b in condition_blocks(rows)]
    return Section(title, "\n".join(parts), page_charts=EXAMPLE1_PAGE)


def _counterexample_block(ctx: ReportContext, block: Block) -> str:
    """The chart, tables, reading and failing case of one block (condition) of the scene."""
    prof = block.profile
    r = attempted(block.rows)
    if r.empty:
        return "Every pair of this scene was skipped.\n"
    cells = seed_readings(r)
    frac = violation_counts(cells)
    ns = sorted(frac["n"].unique())
    solvers = natural_sorted(frac["solver"].unique())
    fig, (ax,) = new_figure(width=6.4, height=3.8)
    width = 0.8 / max(len(solvers), 1)
    for i, s in enumerate(solvers):
        f = frac[frac["solver"] == s].set_index("n").reindex(ns)
        bars = ax.bar(np.arange(len(ns)) + (i - (len(solvers) - 1) / 2) * width, 100 * f["fraction"].fillna(0),
                      width, color=ctx.color(s), label=s)
        ax.bar_label(bars, labels=[("-" if pd.isna(v) else f"{100 * v:.0f}") for v in f["fraction"]], fontsize=7,
                     padding=1)
    ax.axhline(PAPER_GREEDY_SHARE[0], color="gray", ls="--", lw=1, label=PAPER_GREEDY_SHARE[1])
    ax.set_xticks(np.arange(len(ns)), [f"n = {int(n)}" for n in ns])
    ax.set_ylabel("seeds violating the LCP  [%]\n(judge: not solved)")
    ax.set_xlabel("problem size (all n points in the trial set)")
    ax.set_ylim(0, 105)
    ax.grid(True, axis="y", alpha=0.3)
    legend_outside(ax, "solver")
    rel = ctx.save_figure(fig, block.name("counterexample-violations"))
    tol = _check_tol_text(r)
    body = [block.lead() + ctx.figure_md(
        rel, f"fraction of seeds on which each solver violates the LCP: the judge does not accept the answer "
             f"(status not `solved`: scaled KKT error above the profile's check_tol{tol}, or no answer) at "
             f"{block.profile_text}.")]
    rows_t = [(s, *[_frac_cell(frac, s, n) for n in ns]) for s in solvers]
    body.append(table_md(ctx, f"LCP violations by solver and n, as the judge reads them: rejected seeds / seeds "
                              f"(of which wrong = claimed convergence, unconverged, no answer), profile `{prof}`.",
                         ["solver", *[f"n = {int(n)}" for n in ns]], rows_t, "l" + "r" * len(ns)))
    body.append(_distance_table(ctx, cells, ns, solvers, prof, set(r.loc[own_reference(r), "solver"])))
    body.append(_counterexample_reading(frac, cells, r))
    body.append(_counterexample_case(ctx, cells, block))
    return "\n".join(body)


def _check_tol_text(rows: pd.DataFrame) -> str:
    if "check_tol" not in rows.columns:
        return ""
    tols = sorted({float(t) for t in rows["check_tol"].dropna()})
    return f" = {', '.join(f'{t:g}' for t in tols)}" if tols else ""


def _frac_cell(frac: pd.DataFrame, s: str, n: float) -> str:
    f = frac[(frac["solver"] == s) & (frac["n"] == n)]
    if f.empty:
        return "-"
    row = f.iloc[0]
    split = ", ".join(f"{int(row[k])} {k}" for k in READINGS[:-1] if int(row[k]) > 0)
    return (f"{fmt_pct(float(row['fraction']))} ({int(row['violations'])}/{int(row['seeds'])}"
            + (f": {split}" if split else "") + ")")


def _distance_table(ctx: ReportContext, cells: pd.DataFrame, ns: list, solvers: list[str], prof: str,
                    references: set[str]) -> str:
    """Median and largest p_rel_error of the accepted seeds: a distance, not a verdict;
    ``REF_CELL`` for the solvers whose answers are the reference (``references``)."""
    ok = cells[~cells["violates"] & cells["p_rel_error"].notna()]
    if ok.empty:
        return "No accepted answer has a distance from the exact answer in this table (no reference).\n"

    def cell(s: str, n: float) -> str:
        e = ok[(ok["solver"] == s) & (ok["n"] == n)]["p_rel_error"]
        if s in references and not e.empty:
            return REF_CELL
        return "-" if e.empty else f"{fmt_err(float(e.median()))} / {fmt_err(float(e.max()))}"

    rows_t = [(s, *[cell(s, n) for n in ns]) for s in solvers]
    own = (f" {md_code(REF_CELL)}: the reference's own answers (distance 0 by construction)."
           if references & set(ok["solver"]) else "")
    return table_md(ctx, f"Distance from the exact LCP answer (not a verdict): median / largest "
                         f"||p - p_exact||_inf / ||p_exact||_inf over the seeds the judge accepts, profile `{prof}`. "
                         f"An accepted answer is exact to the judge's tolerance; this shows how close its forces are."
                         + own,
                    ["solver", *[f"n = {int(n)}" for n in ns]], rows_t, "l" + "r" * len(ns))


def share_verdict(share: float) -> str:
    """Words for greedy CG's share of rejected seeds against the paper's ~40 %, read by the
    claims ledger's row ``ex1-greedy-fails`` (its holds and partly bands)."""
    rule = CLAIMS["ex1-greedy-fails"].rule
    verdict = rule.at(share)
    side = "below" if share < rule.lo else "above"
    paper = f"the paper's ~{fmt_pct(rule.lo)}"
    if verdict == "holds":
        return f"agrees with {paper} (the claims ledger's holds band, +-{fmt_pct(rule.holds)})"
    if verdict == "partly":
        return f"is close to {paper}, {side} it (the claims ledger's partly band, +-{fmt_pct(rule.partly)})"
    return f"is {side} {paper}"


def ledger_shares(rows: pd.DataFrame) -> pd.DataFrame:
    """The claims ledger's measurement of ``ex1-greedy-fails`` (claims.py ``example1_rows``
    reads it here) over the attempted ``rows``: per operator, solver and n, the
    ``violation_counts`` columns, the seeds answered (``answered``: a crash or a timeout is
    no answer), and ``share``, those on which the answer is wrong (claimed converged,
    rejected by the judge) over ``answered`` (NaN where none was answered)."""
    parts = []
    for op, g in rows.groupby(operators_of(rows), sort=True):
        f = violation_counts(seed_readings(g))
        parts.append(f.assign(operator=str(op), answered=f["seeds"] - (f["violations"] - f["wrong"])))
    if not parts:
        return pd.DataFrame(columns=["operator", "n", "wrong", "answered", "share"])
    out = pd.concat(parts, ignore_index=True)
    return out.assign(share=out["wrong"] / out["answered"].where(out["answered"] > 0))


def _counterexample_reading(frac: pd.DataFrame, cells: pd.DataFrame, rows: pd.DataFrame) -> str:
    """Example 1's reading: each greedy solver's share of rejected seeds per n; greedy CG's
    verdict is the claims ledger's, per n on the ledger's measurement (``ledger_shares``,
    ``share_verdict``): the paper says "any n", so a share pooled over the sizes is given
    without one."""
    cg = resolve_role(cells, "greedy-cg")
    greedy = [s for s in (resolve_role(cells, k) for k in ("greedy-cg", "greedy-gs", "greedy-chol")) if s]
    measured = [f"{fmt_pct(f)} at n = {n}" for n, f in COUNTEREXAMPLE_REFERENCE.items()]
    parts = [("**Reading.** The paper reports that greedy CG violates the LCP in about 40 % of 100 seeds "
              f"for any n (an independent re-implementation measured {', '.join(measured[:-1])} and "
              f"{measured[-1]}). Here a seed violates it when the judge rejects the answer.")]
    for s in greedy:
        f = frac[frac["solver"] == s]
        desc = ", ".join(f"{fmt_pct(x)} at n = {int(n)}" for n, x in zip(f["n"], f["fraction"]))
        total = float(f["violations"].sum() / f["seeds"].sum())
        pooled = (f" ({fmt_pct(total)} pooled over the sizes, given no verdict: the claims ledger reads each n apart)"
                  if len(f) > 1 else "")
        if s != cg:
            parts.append(f"{md_code(s)} violates it in {desc}{pooled}; the paper's ~40 % and the claims ledger's row "
                         f"`ex1-greedy-fails` are greedy CG's, so no verdict is read on it.")
            continue
        sh = ledger_shares(with_numbers(rows[rows["solver"] == s]))  # (the rows as the ledger reads them)
        op = sh["operator"].nunique() > 1
        each = "; ".join(f"n = {int(x.n)}" + (f" ({x.operator})" if op else "")
                         + f": {int(x.wrong)} of {int(x.answered)} ({fmt_pct(x.share)}), which "
                         + (share_verdict(float(x.share)) if x.answered > 0 else "cannot be read: no answer")
                         for x in sh.itertuples())
        parts.append(f"{md_code(s)} violates it in {desc}{pooled}. As the claims ledger reads it (row "
                     f"`ex1-greedy-fails`: per n, the seeds whose answer is wrong -- claimed converged, rejected by "
                     f"the judge -- of the seeds it answered): {each}.")
    if not greedy:
        parts.append("No greedy solver is in this table.")
    others = frac[~frac["solver"].isin(greedy)]
    clean = natural_sorted(others.groupby("solver")["violations"].sum().loc[lambda v: v == 0].index)
    bad = natural_sorted(others.groupby("solver")["violations"].sum().loc[lambda v: v > 0].index)
    if clean:
        parts.append(f"Never violating (as the paper proves for NNLS): {', '.join(md_code(s) for s in clean)}.")
    if bad:
        parts.append(f"Non-greedy solvers the judge rejects on some seed (a finding): "
                     f"{', '.join(md_code(s) for s in bad)}.")
    return " ".join(parts) + "\n"


COUNTEREXAMPLE_ARRAY_RE = re.compile(r"^counterexample-(n\d+-s\d+)-(.+)\.npz$")


def find_counterexample_arrays(out_dir: Path) -> dict[tuple[str, str], Path]:
    """(instance, solver) -> npz path for OUT/arrays/ and OUT/_cache/ files named
    ``counterexample-<instance>-<solver>.npz`` (instance like ``n100-s1``)."""
    found: dict[tuple[str, str], Path] = {}
    for d in (out_dir / "arrays", out_dir / "_cache"):
        if d.is_dir():
            for p in sorted(d.rglob("counterexample-*.npz")):
                m = COUNTEREXAMPLE_ARRAY_RE.match(p.name)
                if m:
                    found.setdefault((m.group(1), m.group(2)), p)
    return found


@dataclass
class CounterexampleCase:
    """One stored answer with the judge's per-element floors at the row's check_tol:
    a gap w_i < -gap_floor violates w >= 0 beyond the tolerance, and p_i > contact_floor
    is a contact (``ContactInstance.contact_mask``)."""

    instance: str
    solver: str
    ubar: np.ndarray
    w: np.ndarray
    p: np.ndarray
    p_ref: np.ndarray
    E: float
    gap_floor: float
    contact_floor: float


def load_counterexample_case(path: Path, instance: str, solver: str, check_tol: float = CONTACT_TOL
                             ) -> CounterexampleCase:
    """Read the npz (keys p, p_ref, and ubar, w if stored) and rebuild the problem from
    its name (``problems.instances.counterexample(n, seed)``: no solve) for its scales;
    missing ubar / w come from it."""
    with np.load(path, allow_pickle=False) as z:
        data = {k: np.asarray(z[k], dtype=float) for k in z.files if k in ("p", "p_ref", "ubar", "w", "E")}
    if "p" not in data or "p_ref" not in data:
        raise ReportInputError(f"{path} lacks arrays 'p' and/or 'p_ref' (has {sorted(data)})")
    m = re.fullmatch(r"n(\d+)-s(\d+)", instance)
    if not m:
        raise ReportInputError(f"cannot rebuild counterexample {instance!r}: name is not n<N>-s<seed>")
    inst = counterexample(int(m.group(1)), int(m.group(2)))
    if data["p"].shape != (inst.n,) or data["p_ref"].shape != (inst.n,):
        raise ReportInputError(f"{path}: arrays of shape {data['p'].shape} / {data['p_ref'].shape} for n = {inst.n}")
    data.setdefault("ubar", np.asarray(inst.qp.ubar, dtype=float))
    data.setdefault("w", np.asarray(inst.qp.H.matvec(data["p"]), dtype=float) - data["ubar"])
    tol = float(check_tol) if np.isfinite(check_tol) and check_tol > 0 else CONTACT_TOL
    gap_floor = tol * float(np.max(np.abs(inst.qp.ubar), initial=0.0))
    return CounterexampleCase(instance, solver, data["ubar"], data["w"], data["p"], data["p_ref"], float(inst.E),
                              gap_floor, inst.contact_floor(tol))


def _counterexample_case(ctx: ReportContext, cells: pd.DataFrame, block: Block | None = None) -> str:
    """One rejected case of ``cells`` plotted from its stored answer (its figure named for
    ``block`` in a scene of several), or why none can be."""
    bad = cells[cells["violates"]].copy()
    if bad.empty:
        return "The judge rejected no answer, so there is no failing case to plot.\n"
    arrays = find_counterexample_arrays(ctx.out_dir)
    greedy_first = [resolve_role(cells, "greedy-cg")]
    bad["_pref"] = [(0 if s in greedy_first else 1, 0 if n == 100 else 1, natural_key(i))
                    for s, n, i in zip(bad["solver"], bad["n"], bad["instance"])]
    bad = bad.sort_values("_pref")
    tols = bad["check_tol"] if "check_tol" in bad.columns else pd.Series(CONTACT_TOL, index=bad.index)
    pick = next(((i, s, t) for i, s, t in zip(bad["instance"], bad["solver"], tols) if (i, s) in arrays), None)
    if pick is None:
        i0, s0 = bad["instance"].iloc[0], bad["solver"].iloc[0]
        return (f"A failing case (e.g. `{s0}` on `{i0}`) cannot be plotted: no array file "
                f"`arrays/counterexample-{i0}-{s0}.npz` (keys p, p_ref, ubar, w) was stored with this table.\n")
    case = load_counterexample_case(arrays[pick[:2]], pick[0], pick[1], float(pick[2]))
    fig = Figure(figsize=(7.0, 7.5))
    axs = [fig.add_subplot(3, 1, k + 1) for k in range(3)]
    fig.subplots_adjust(hspace=0.3)
    idx = np.arange(1, len(case.ubar) + 1)
    axs[0].plot(idx, case.ubar, "o", ms=3, color="tab:blue", label="ubar")
    axs[0].set_ylabel("ubar  [a.u. of length]")
    neg = case.w < -case.gap_floor  # w >= 0 violated beyond the judge's tolerance
    axs[1].plot(idx, case.w, "o", ms=3, color="tab:blue", label="w = H p - ubar")
    if neg.any():
        axs[1].plot(idx[neg], case.w[neg], "o", ms=6, color="red", label="w < 0 (LCP violated)")
    axs[1].axhline(0, color="black", lw=0.8)
    axs[1].set_ylabel("gap w  [a.u. of length]")
    axs[2].plot(idx, case.p / case.E, "o", ms=4, color="tab:blue", label=f"{case.solver}")
    axs[2].plot(idx, case.p_ref / case.E, ".", ms=5, color="green", label="exact (reference)")
    axs[2].set_ylabel("p / E  [a.u. of area]")
    axs[2].set_xlabel("boundary element index")
    for a in axs:
        a.grid(True, alpha=0.3)
        legend_outside(a)
    axs[0].set_title(f"counterexample {case.instance}, solver {case.solver}", fontsize=9)
    rel = ctx.save_figure(fig, (block.name if block else str)(f"counterexample-case-{case.instance}-{case.solver}"),
                          on_page=True)
    n_neg = int(neg.sum())
    dp = np.abs(case.p - case.p_ref)
    on, on_ref = case.p > case.contact_floor, case.p_ref > case.contact_floor
    false_contact = int(np.sum(on & ~on_ref))
    missed = int(np.sum(~on & on_ref))
    return ctx.figure_md(rel, f"one failing case, `{case.solver}` on `{case.instance}` (as paper Fig. 2: delta = 1, "
                              f"E = {case.E:g}): ubar, the computed gap w ({n_neg} negative entries), and p/E "
                              f"against the exact solution; {false_contact} false contacts, {missed} missed "
                              f"contacts, max |p - p_exact| / max p_exact = "
                              f"{fmt_err(dp.max() / max(float(np.max(np.abs(case.p_ref))), 1e-300))}.")
