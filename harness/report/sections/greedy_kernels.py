"""The greedy-across-kernels section (scene ``greedy-kernels``): the share of Example 1's
seeds on which each greedy variant's answer is rejected by the judge, per operator variant
(column ``variant``) and n -- the paper's open question on other forms of H, with numbers.
A chart (backend-neutral, ``charts.Chart``) draws the shares against n, one series per
(solver, variant)."""

from __future__ import annotations

import pandas as pd

from ..charts import Chart, Series
from ..core import ReportContext, Section, attempted, natural_sorted, pick_profile, register_section, table_md
from .counterexample import COUNTEREXAMPLE_REFERENCE, seed_readings

TITLE = "Greedy on other forms of H (greedy-kernels)"


def rejected_shares(rows: pd.DataFrame) -> pd.DataFrame:
    """Per (solver, variant, n): seeds, seeds the judge rejects, and their share."""
    cells = seed_readings(rows).merge(
        rows[["instance", "variant"]].drop_duplicates("instance"), on="instance", how="left")
    g = cells.groupby(["solver", "variant", "n"])
    out = pd.DataFrame({"seeds": g.size(), "rejected": g["violates"].sum()}).reset_index()
    out["share"] = out["rejected"] / out["seeds"]
    return out


@register_section("greedy-kernels", title=TITLE, group="scenes", order=10)
def greedy_kernels_section(ctx: ReportContext, rows: pd.DataFrame) -> Section | None:
    prof = pick_profile(attempted(rows))
    r = attempted(rows[rows["profile"] == prof])
    if r.empty:
        return Section(TITLE, "Every pair of this scene was skipped.\n")
    shares = rejected_shares(r)
    ns = sorted(int(n) for n in shares["n"].unique())
    variants = natural_sorted(shares["variant"].unique())
    body = [f"Example 1's draw (ubar ~ U(0,1), every element in the trial set) on each operator; a seed counts "
            f"as a failure when the judge does not accept the answer (profile `{prof}`). On the BCC operator the "
            f"paper reports about 40 % for any n; the counterexample scene measures, over seeds 0-99, {', '.join(f'n = {n}: {v:.0%}' for n, v in COUNTEREXAMPLE_REFERENCE.items())}.\n"]
    table_rows = []
    for solver in natural_sorted(shares["solver"].unique()):
        for variant in variants:
            s = shares[(shares["solver"] == solver) & (shares["variant"] == variant)].set_index("n")
            table_rows.append((solver, variant, *[
                f"{int(s.at[n, 'rejected'])}/{int(s.at[n, 'seeds'])} ({s.at[n, 'share']:.0%})" if n in s.index
                else "-" for n in ns]))
    body.append(table_md(ctx, f"Seeds the judge rejects / seeds, by solver, operator and n (profile `{prof}`).",
                         ["solver", "operator", *[f"n = {n}" for n in ns]], table_rows, "ll" + "r" * len(ns),
                         on_page=True))
    series = tuple(
        Series(f"{solver} {variant}", tuple(float(n) for n in s["n"]), tuple(100.0 * float(v) for v in s["share"]))
        for (solver, variant), s in shares.sort_values("n").groupby(["solver", "variant"]))
    chart = Chart("greedy-kernels-rejected", "Example 1 on other forms of H: seeds rejected by the judge",
                  "n (all points in the trial set)", "seeds rejected [%]", series)
    return Section(TITLE, "\n".join(body), charts=(chart,))
