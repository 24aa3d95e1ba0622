"""The stress battery's reports.

* ``contactbench report``: the summary section "Stress battery" counts, per solver, the
  judge's verdicts (column ``verdict``) on the rows of the ``stress`` scenes of the table.
* ``write_stress_report``: reads what ``benchmarks/bench_stress.py`` writes into a results
  directory (``conditioning.csv``, ``survival-fast.csv`` and/or ``survival-full.csv`` -- the
  verdict rows of ``harness.conformance.battery``), renders survival table, cond(H) vs n and
  unit-scaling table, and saves them as ``README.md`` beside the tables, plus
  ``survival_matrix-<mode>.csv`` (case x solver).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from contactbench.problems.atomic_files import literal_path

from ..core import ReportContext, Section, markdown_table, natural_key, register_section, table_md
from ..markdown_text import md_code
from ..owned_files import refuse_foreign_page, title_line
from ...table.files import write_text_atomic
from ...table.schema import VERDICTS

#: The battery's scenes: "stress" and its parts "stress-<group>".
STRESS_SCENE = "stress"
#: The battery's README.md title (its first line: how a report knows the page as its own).
STRESS_TITLE = "Numerical stability stress battery"


def is_stress_scene(scene: str) -> bool:
    return scene == STRESS_SCENE or scene.startswith(f"{STRESS_SCENE}-")


@register_section("stress-verdicts", title="Stress battery", group="summary", order=25)
def stress_section(ctx: ReportContext, table: pd.DataFrame) -> Section | None:
    """Per solver: the judge's verdicts on the stress rows, and the rows not judged."""
    rows = table[table["scene"].map(is_stress_scene)]
    if rows.empty:
        return None
    body = []
    lines = []
    for solver, g in sorted(rows.groupby("solver"), key=lambda kv: natural_key(kv[0])):
        counts = g["verdict"].value_counts()
        lines.append((solver, len(g), *[int(counts.get(v, 0)) for v in VERDICTS], int((g["verdict"] == "").sum())))
    body.append(table_md(ctx, "the judge's verdicts on the stress scenes' rows: pass; wrong = a wrong answer "
                              "claimed as converged; unconverged = not solved, and the solver said so; not judged = "
                              "skipped, failed, timed out or crashed (or a table without verdicts).",
                         ["solver", "rows", *VERDICTS, "not judged"], lines, "lrrrrr"))
    wrong = [md_code(s) for s, _n, _p, w, *_ in lines if w]
    body.append("**Reading.** " + (f"Wrong answers claimed as converged: {', '.join(wrong)}." if wrong else
                                   "No solver claimed convergence on a wrong answer.") + "\n")
    return Section("Stress battery", "\n".join(body))

GOOD = ("pass", "refused", "skipped")


def load_survival(results: Path) -> list[tuple[pd.DataFrame, str]]:
    """The verdict rows of each battery mode present ("fast", "full")."""
    return [(pd.read_csv(literal_path(results / f"survival-{m}.csv")), m) for m in ("fast", "full")
            if (results / f"survival-{m}.csv").exists()]


def survival_summary(rows: pd.DataFrame) -> pd.DataFrame:
    """solver x group: 'passed/solves' with the count of wrong claims, plus a verdict."""
    solves = rows[rows["step"] >= 0]
    out = {}
    for (solver, group), g in solves.groupby(["solver", "group"]):
        wrong = int((g["status"] == "WRONG").sum())
        other = int((~g["status"].isin(GOOD + ("WRONG",))).sum())
        refused = int((g["status"] == "refused").sum())
        cell = f"{int((g['status'] == 'pass').sum())}/{len(g)}"
        if wrong:
            cell += f" W{wrong}"
        if other:
            cell += f" x{other}"
        if refused:
            cell += f" r{refused}"
        out.setdefault(solver, {})[group] = cell
    table = pd.DataFrame(out).T.sort_index()
    table.index.name = "solver"
    flagged = rows[rows["step"] < 0].groupby("solver")["status"].apply(lambda s: int((s == "flagged").sum()))
    table["flagged"] = flagged.reindex(table.index).fillna(0).astype(int)
    wrong = solves.groupby("solver")["status"].apply(lambda s: int((s == "WRONG").sum()))
    table["verdict"] = ["CONFORMS" if wrong.get(s, 0) == 0 else "FAILS" for s in table.index]
    return table


def survival_matrix(rows: pd.DataFrame) -> pd.DataFrame:
    return rows.pivot_table(index="label", columns="solver", values="status", aggfunc="first")


def findings(rows: pd.DataFrame) -> pd.DataFrame:
    bad = rows[~rows["status"].isin(("pass", "skipped", "refused"))]
    cols = ["solver", "label", "status", "kkt_error", "p_rel_error", "message"]
    return bad[cols].sort_values(["status", "solver", "label"])


def cond_table(cond: pd.DataFrame) -> pd.DataFrame:
    """n (to the nearest decade) x (kernel, density): cond(H_II), with the exact n."""
    import numpy as np

    t = cond.assign(col=lambda d: d["kernel"] + " d=" + d["target_density"].map("{:g}".format),
                    decade=lambda d: (10.0 ** np.round(np.log10(d["n"]))).astype(int),
                    cell=lambda d: d["cond"].map("{:.3g}".format) + " (n=" + d["n"].astype(str) + ")")
    table = t.pivot_table(index="decade", columns="col", values="cell", aggfunc="first")
    table.index.name = "n ~"
    return table


def units_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Per solver and units recipe: the agreement row (P/(E A) spread, scaled-KKT spread)
    with the worst kkt_error of its steps."""
    u = rows[rows["group"] == "units"]
    agree = u[u["step"] < 0].set_index(["solver", "case"])
    steps = u[u["step"] >= 0].groupby(["solver", "case"])
    out = pd.DataFrame({
        "dimload_spread": agree["p_rel_error"],
        "kkt_spread": agree["kkt_error"],
        "worst_kkt_error": steps["kkt_error"].max(),
        "steps_passed": steps["status"].apply(lambda s: f"{int((s == 'pass').sum())}/{len(s)}"),
        "agreement": agree["status"],
    })
    return out.reset_index()


def _cell(v: object, floatfmt: str) -> str:
    if isinstance(v, float):
        return "" if v != v else format(v, floatfmt)
    return str(v).replace("|", "/").replace("\n", " ")


def _md(df: pd.DataFrame, floatfmt: str = ".3g") -> str:
    """A GitHub markdown table of ``df`` (index included)."""
    d = df.reset_index() if df.index.name or not isinstance(df.index, pd.RangeIndex) else df
    rows = [[_cell(v, floatfmt) for v in row] for row in d.itertuples(index=False)]
    return markdown_table([str(c) for c in d.columns], rows).rstrip("\n")


def render_stress_section(results: Path) -> str:
    results = Path(results)
    parts = [title_line(STRESS_TITLE)]
    for rows, mode in load_survival(results):
        parts += [f"## Which solver survives which case ({mode} battery)", "",
                  "Cells: passed/solves per group; `W` = wrong answers claimed as converged, "
                  "`x` = crashed / timed out / unconverged, `r` = refused (e.g. CMR without a surface).  "
                  "`flagged`: unit systems disagreeing beyond 1e-8 or chaotic perturbation response.  "
                  f"Full case x solver matrix: `survival_matrix-{mode}.csv`.", "",
                  _md(survival_summary(rows)), "",
                  f"## Unit-scaling table ({mode} battery)", "",
                  "Spread over m/Pa, um/MPa, nm/GPa (unit-systems) and E = 1e-3 .. 1e9 Pa (E-range) of "
                  "P/(E A) (relative) and of the scaled KKT figures (absolute); required: <= 1e-8.", "",
                  _md(units_table(rows)), "",
                  f"## Findings ({mode} battery: every verdict other than pass / refused / skipped)", "",
                  _md(findings(rows).reset_index(drop=True)), ""]
    cond_paths = sorted(results.glob("conditioning*.csv"))
    if cond_paths:
        cond = pd.concat([pd.read_csv(literal_path(p)) for p in cond_paths], ignore_index=True)
        parts += ["## cond(H_II) against n (BCC and Love, aperiodic; random trial sets at packing density d)", "",
                  "Dense eigvalsh up to n = 2500, Lanczos (ARPACK eigsh) on the FFT operator beyond.", "",
                  _md(cond_table(cond)), ""]
    return "\n".join(parts)


def write_stress_report(results: Path) -> Path:
    """RESULTS/README.md and the survival matrices; a README.md that is not the battery's
    page stops it before it writes (``owned_files.refuse_foreign_page``)."""
    results = Path(results)
    refuse_foreign_page(results / "README.md", STRESS_TITLE)
    text = render_stress_section(results)
    for rows, mode in load_survival(results):
        survival_matrix(rows).to_csv(literal_path(results / f"survival_matrix-{mode}.csv"))
    path = results / "README.md"
    write_text_atomic(path, text)
    return path
