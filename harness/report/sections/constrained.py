"""The sections of the constrained sweeps: ``load-sweep`` (load control) and
``plastic-sweep`` (hardness-bounded pressures).  Per solver, side by side: steps solved,
total solve time, the worst scaled KKT error, and the family's own figure at the top step
-- the approach Delta the answer implies (load control: column ``delta``, the load
equality's multiplier as the judge fits it) or the share of plastic contact elements
(column ``plastic_fraction``).  A page chart draws solve time per step against the load."""

from __future__ import annotations

import pandas as pd

from ..charts import RowChart
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


def constrained_section(scene: str):
    def section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
        title = f"The field's codes on {scene}"
        prof = pick_profile(attempted(rows))
        r = attempted(rows[rows["profile"] == prof])
        if r.empty:
            return Section(title, "Every pair of this scene was skipped.\n", page_charts=TIME_PAGE)
        column, header = TOP_FIGURE[scene]
        body = table_md(ctx, f"Each solver on `{scene}` at profile `{prof}`: steps the judge accepts, their total "
                             "solve time, the worst scaled KKT error (with the load equality's residual and both "
                             "bounds), and the top step's figure.",
                        ["solver", "solved", "total time [s]", "worst kkt_error", header], solver_rows(r, column),
                        "lrrrr", on_page=True)
        return Section(title, body + "\n", page_charts=TIME_PAGE)
    return section


for _order, _scene in enumerate(TOP_FIGURE, start=20):
    register_section(_scene, title=f"The field's codes on {_scene}", group="scenes", order=_order)(
        constrained_section(_scene))
