"""The sections of the constrained sweeps: ``load-sweep`` (load control) and
``plastic-sweep`` (hardness-bounded pressures).  Per solver, side by side: steps solved,
total solve time, the worst scaled KKT error, and the family's own figure at the top step
-- the approach Delta the answer implies (load control: column ``delta``, the load
equality's multiplier as the judge fits it) or the share of plastic contact elements
(column ``plastic_fraction``).  A page chart draws solve time per step against the load."""

from __future__ import annotations

import pandas as pd

from ..charts import RowChart
from ..markdown_text import md_escape
from ..core import (
    ReportContext,
    Section,
    attempted,
    fmt_err,
    fmt_num,
    natural_sorted,
    per_cell,
    pick_profile,
    register_section,
    table_md,
)

#: The top-step figure each constrained scene reports: (column, header).
TOP_FIGURE = {"load-sweep": ("delta", "top-step Delta [m]"),
              "plastic-sweep": ("plastic_fraction", "top-step plastic share")}
#: What the scaled KKT error of each constrained scene counts besides p >= 0 and the gaps
#: (``problems.kkt``'s module doc).
KKT_COUNTS = {"load-sweep": "the load equality's residual and the load share carried across open gaps",
              "plastic-sweep": "the hardness bound p <= H_A delta^2 on every element"}
#: The section's title for each constrained scene.
TITLES = {scene: f"Every solver on {scene}" for scene in TOP_FIGURE}
TIME_PAGE = (RowChart("solve time per step against the load"),)


def solver_rows(rows: pd.DataFrame, figure: str) -> list[tuple[str, ...]]:
    """One table row per solver: steps solved / steps, total time of the solved steps,
    worst kkt_error, and ``figure`` at the top step (its median over the solver's rows)."""
    cells = per_cell(rows)
    top = int(cells["step"].max())
    out = []
    for solver in natural_sorted(cells["solver"].unique()):
        c = cells[cells["solver"] == solver]
        at_top = c.loc[c["step"] == top, figure].dropna()
        out.append((solver, f"{int(c['solved'].sum())}/{len(c)}", fmt_num(c.loc[c["solved"], "solve_time_s"].sum()),
                    fmt_err(c["kkt_error"].max()), fmt_num(at_top.median()) if len(at_top) else "-"))
    return out


def skipped_text(rows: pd.DataFrame) -> str:
    """One sentence naming each solver every cell of which was skipped, with its first
    reason; "" when there is none."""
    skipped = rows[rows["status"] == "skipped"]
    ran = set(attempted(rows)["solver"])
    named = [(solver, str(skipped.loc[skipped["solver"] == solver, "skip_reason"].iloc[0]))
             for solver in natural_sorted(skipped["solver"].unique()) if solver not in ran]
    if not named:
        return ""
    return "Not run: " + "; ".join(f"`{solver}` ({md_escape(why) or 'no reason recorded'})" for solver, why in named) \
        + ".\n"


def constrained_section(scene: str):
    def section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
        title = TITLES[scene]
        prof = pick_profile(attempted(rows))
        r = attempted(rows[rows["profile"] == prof])
        if r.empty:
            return Section(title, "Every pair of this scene was skipped.\n" + skipped_text(rows),
                           page_charts=TIME_PAGE)
        column, header = TOP_FIGURE[scene]
        body = table_md(ctx, f"Each solver on `{scene}` at profile `{prof}`: steps the judge accepts, their total "
                             f"solve time, the worst scaled KKT error (which counts {KKT_COUNTS[scene]}), and the "
                             "top step's figure.",
                        ["solver", "solved", "total time [s]", "worst kkt_error", header], solver_rows(r, column),
                        "lrrrr", on_page=True)
        return Section(title, body + "\n" + skipped_text(rows[rows["profile"] == prof]), page_charts=TIME_PAGE)
    return section


for _order, _scene in enumerate(TOP_FIGURE, start=20):
    register_section(_scene, title=TITLES[_scene], group="scenes", order=_order)(constrained_section(_scene))
