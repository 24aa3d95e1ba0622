"""The paper sections under several conditions, and their readings against the claims
ledger (harness/report/sections/paper.py, paper_conditions.py, counterexample.py).

A ``paper-claims`` table holds the paper's methods on the dense H at profile ``paper`` and
the FFT solvers at ``default``: each paper section draws and reads both, never dropping
one condition's solvers for the other's.  Where a reading gives a verdict on a claim of
the paper it is the ledger's (``claims.ledger`` on the same rows); where the section
pools otherwise it gives its number without one.

The tables are small fabricated sweeps; a section is called directly on a report context
over the written table (figures not kept).
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from contactbench.harness.report import claims as cl
from contactbench.harness.report import core as rp
from contactbench.harness.report.view import read_table
from contactbench.harness.report.claim_rules import CLAIMS
from contactbench.harness.report.sections import counterexample as rce
from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.table.schema import ALL_COLUMNS
from contactbench.solvers.admm import PAPER_PARAMS
from tests.helpers import META, report_row, write_out

#: The label paper-claims gives ADMM as the paper states it.
ADMM_PRINTED = "admm[rho=1.0,rho_relative=False,stop=printed]"
#: The readings' words of each ledger verdict (Example 1: ``share_verdict``).
SHARE_WORDS = {"holds": "agrees with", "partly": "is close to", "fails": ("is below", "is above")}


def section(tmp_path: Path, df: pd.DataFrame, scene: str) -> rp.Section:
    """The paper section of ``scene`` over the table ``df`` (figures named, not saved)."""
    out = write_out(tmp_path, df)
    ctx = rp.ReportContext(out, read_table(out), META)

    def keep(fig: Any, name: str, on_page: bool = False) -> str:
        return f"figures/{name}.png"

    ctx.save_figure = keep  # type: ignore[method-assign]
    fn = {"paper-sweep": rpp.fig4_section, "greedy-linear-solvers": rpp.fig5_section, "gp-k-sweep": rpp.fig6_section,
          "counterexample": rce.counterexample_section}[scene]
    sec = fn(ctx, ctx.rows(scene))
    assert sec is not None
    return sec


def rows_of(scene: str, operator: str, times: dict[str, list[float]], N: int = 64, repeats: int = 1,
            drift: dict[str, float] | None = None, instance: str | None = None, **kw: Any) -> list[dict]:
    """A sweep of ``scene`` under the paper-claims condition of ``operator`` (dense: profile
    ``paper``; fft: ``default``): solver -> its time per step, every step solved, each
    timed ``repeats`` times (repeat r: times x (1 + r drift[solver]))."""
    out = []
    prof = "paper" if operator == "dense" else "default"
    for s, ts in times.items():
        for k, t in enumerate(ts):
            for r in range(repeats):
                out.append(report_row(scene=scene, instance=instance or f"saupe-H0.7-N{N}-bcc-np-s5", seed=5, step=k,
                                      n=150 * (k + 1), N=N, solver=s, profile=prof, operator=operator, repeat=r,
                                      solve_time_s=t * (1 + r * (drift or {}).get(s, 0.0)), dim_load=1e-4 * (k + 1),
                                      verdict="pass", **kw))
    return out


def table(rows: list[dict]) -> pd.DataFrame:
    df = pd.DataFrame(rows, columns=list(ALL_COLUMNS))
    admm = df["solver"] == ADMM_PRINTED
    df.loc[admm, "base_solver"] = "admm"
    df.loc[admm, "params"] = json.dumps({k: PAPER_PARAMS[k] for k in ("rho", "rho_relative", "stop")})
    return df


def ledger_row(df: pd.DataFrame, claim: str, condition: str, size: str = "") -> pd.Series:
    led = cl.ledger(df)
    hit = led[(led["claim"] == claim) & (led["condition"] == condition) & led["n_or_size"].str.startswith(size)]
    assert len(hit) == 1, hit
    return hit.iloc[0]


# ---------------------------------------------------------------------------
# The tightest profile: "paper" is one
# ---------------------------------------------------------------------------


def test_the_paper_profile_is_tighter_than_default_and_looser_than_high() -> None:
    def pick(*profiles: str) -> str:
        return rp.pick_profile(pd.DataFrame({"profile": list(profiles)}))

    assert pick("default", "paper") == "paper" and pick("paper", "mid") == "paper"
    assert pick("paper", "high") == "high" and pick("low", "default") == "default"


def test_each_operator_gets_its_own_tightest_profile() -> None:
    from contactbench.harness.report.sections import paper_conditions as pc

    df = table(rows_of("paper-sweep", "dense", {"nnls-gp": [1.0], "pk": [0.5]})
               + rows_of("paper-sweep", "fft", {"nnls-gp": [0.3], "fast-dual-pccg": [0.1]}))
    blocks = pc.condition_blocks(df)
    assert [(b.profile, b.operators) for b in blocks] == [("paper", ("dense",)), ("default", ("fft",))]
    assert [sorted(set(b.rows["solver"])) for b in blocks] == [["nnls-gp", "pk"], ["fast-dual-pccg", "nnls-gp"]]
    one = pc.condition_blocks(df[df["operator"] == "fft"])
    assert len(one) == 1 and one[0].alone and one[0].name("fig4-paper-sweep") == "fig4-paper-sweep"


# ---------------------------------------------------------------------------
# Fig. 4: every solver of every condition is drawn and read
# ---------------------------------------------------------------------------


def claims_sweep() -> pd.DataFrame:
    """The paper-claims shape of paper-sweep: the paper's methods and ADMM as printed on the
    dense H (profile paper), NNLS+GP, P&K and an FFT solver at default."""
    return table(rows_of("paper-sweep", "dense", {"nnls-gp": [1.0, 1.0], "pk": [0.6, 0.6], ADMM_PRINTED: [40.0, 40.0]})
                 + rows_of("paper-sweep", "fft", {"nnls-gp": [0.3, 0.3], "pk": [0.2, 0.2],
                                                   "fast-dual-pccg": [0.1, 0.1]}))


def test_fig4_draws_the_dense_rows_beside_the_fft_rows(tmp_path: Path) -> None:
    """Before: the default profile was taken as the tightest, and the paper's methods on the
    dense H (profile paper) left the figure and the reading ("ADMM is not in this table")."""
    sec = section(tmp_path, claims_sweep(), "paper-sweep")
    figures = re.findall(r"\]\((figures/[^)]+)\)", sec.body)
    assert figures == ["figures/fig4-paper-sweep-paper.png", "figures/fig4-paper-sweep-default.png"]
    assert sec.body.count("Every solver of the scene under this condition") == 2
    assert f"| {ADMM_PRINTED} |" in sec.body and "ADMM is not in this table" not in sec.body
    dense, fft = sec.body.split("**Condition: operator `fft`")
    assert "**Condition: operator `dense`, profile `paper`.**" in dense and "fast-dual-pccg" not in dense
    assert "ADMM did not run under this condition" in fft
    assert [(c.profile, c.title) for c in sec.page_charts] == [
        ("paper", "Fig. 4: solve time against load (operator dense, profile paper)"),
        ("default", "Fig. 4: solve time against load (operator fft, profile default)")]


def test_fig4_leaves_the_papers_admm_to_the_ledger(tmp_path: Path) -> None:
    """ADMM as printed 40x NNLS+GP: the ratio is read, the verdict is the ledger's row."""
    reading = section(tmp_path, claims_sweep(), "paper-sweep").body.split("**Reading.**")[1]
    admm = reading.split("ADMM / NNLS+GP: ", 1)[1].split(". ", 1)[0]
    assert admm.startswith("measured 40x against the paper's ~100x") and "no verdict here" in admm
    assert "agrees" not in admm and "`fig4-admm-over-nnlsgp`" in admm


def test_fig4_gives_no_verdict_where_the_ledger_reads_cold_solves(tmp_path: Path) -> None:
    """P&K's cold solves in greedy-linear-solvers are the ledger's measurement of the 26x:
    the sweep's own ratio is given without a verdict (the ledger's may differ)."""
    df = pd.concat([claims_sweep(), table(rows_of("greedy-linear-solvers", "dense", {"pk": [26.0, 26.0]}))])
    pk = section(tmp_path, df, "paper-sweep").body.split("P&K 1999 / NNLS+GP: ", 1)[1].split(". ", 1)[0]
    assert pk.startswith("measured 0.6x") and "no verdict here" in pk and "cold solves" in pk
    assert ledger_row(df, "fig4-pk-cold-over-nnlsgp", "dense")["verdict"] == "holds"  # 26x: the ledger's own


def test_fig4_caption_gives_the_grid_size_of_the_drawn_instance(tmp_path: Path) -> None:
    """The drawn instance (the first) is at N = 64; the sweep's other instance at N = 256."""
    df = table(rows_of("paper-sweep", "fft", {"nnls-gp": [1.0], "pk": [0.5]}, N=64, instance="a-N64")
               + rows_of("paper-sweep", "fft", {"nnls-gp": [4.0], "pk": [2.0]}, N=256, instance="b-N256"))
    caption = section(tmp_path, df, "paper-sweep").body.split("*Figure ", 1)[1]
    assert "instance a-N64 (N = 64;" in caption


# ---------------------------------------------------------------------------
# Fig. 5: the ledger's ratio per grid size
# ---------------------------------------------------------------------------


def test_fig5_reads_greedy_cholesky_under_the_dense_condition(tmp_path: Path) -> None:
    """Greedy Cholesky ran on the dense H only: its ratio is read in the dense block, and
    the FFT block says where it ran instead of "not in this table"."""
    df = table(rows_of("greedy-linear-solvers", "dense", {"greedy-cg": [1.0] * 3, "greedy-chol": [0.65] * 3})
               + rows_of("greedy-linear-solvers", "fft", {"greedy-cg": [1.0] * 3, "greedy-gs": [3.0] * 3}))
    body = section(tmp_path, df, "greedy-linear-solvers").body
    assert "is not in this table" not in body
    dense, fft = body.split("**Condition: operator `fft`")
    assert "greedy Cholesky / greedy CG time" in dense and "measured 0.65x" in dense
    assert "greedy Cholesky did not run under this condition" in fft


def test_fig5_verdicts_are_the_ledgers_per_grid_size(tmp_path: Path) -> None:
    """Gauss-Seidel 3x CG at N = 32 and 5.5x at N = 64, three repeats: the reading gives the
    ledger's measurement and verdict at each size (holds, partly), and none on the pooled
    median."""
    df = table(rows_of("greedy-linear-solvers", "fft", {"greedy-cg": [1.0] * 3, "greedy-gs": [3.0] * 3}, N=32,
                       repeats=3, drift={"greedy-gs": 0.01})
               + rows_of("greedy-linear-solvers", "fft", {"greedy-cg": [1.0] * 3, "greedy-gs": [5.5] * 3}, N=64,
                         repeats=3, drift={"greedy-gs": 0.01}))
    gs = section(tmp_path, df, "greedy-linear-solvers").body.split("greedy Gauss-Seidel / greedy CG time", 1)[1]
    pooled, per_size = gs.split("the claims ledger's measurement", 1)
    assert "no verdict on it" in pooled and not re.search(r"agrees|close|holds|partly|fails", pooled)
    for N in (32, 64):
        row = ledger_row(df, "fig5-gs-over-cg", "fft", f"{N}^2")
        said = per_size.split(f"N = {N}: ", 1)[1].split(";")[0]
        assert said.startswith(f"{row['measured']:.3g}x") and f"-- {row['verdict']}:" in said, (said, row)
    assert [ledger_row(df, "fig5-gs-over-cg", "fft", f"{N}^2")["verdict"] for N in (32, 64)] == ["holds", "partly"]


def test_the_ledger_and_the_sections_read_one_fig5_threshold() -> None:
    from contactbench.harness.report import claim_measures as cm

    assert rpp.FIG5_MIN_N is cl.FIG5_MIN_N is cm.FIG5_MIN_N


# ---------------------------------------------------------------------------
# Fig. 6: the ledger's rule, not a band of the section's own
# ---------------------------------------------------------------------------


def k_sweep(totals: dict[int, tuple[float, ...]], scene: str = "gp-k-sweep", operator: str = "fft",
            n: int = 6000) -> pd.DataFrame:
    """A K sweep of NNLS+GP, two steps: K -> each timed repeat's total time."""
    rows = []
    for K, reps in totals.items():
        for r, total in enumerate(reps):
            for k in range(2):
                rows.append(report_row(scene=scene, instance="saupe-H0.7-N128-bcc-np-s5", seed=5, step=k,
                                       n=n // (2 - k), N=128, solver=f"nnls-gp[K={K}]", base_solver="nnls-gp",
                                       params=json.dumps({"K": K}), operator=operator, repeat=r,
                                       profile="paper" if operator == "dense" else "default", solve_time_s=total / 2,
                                       dim_load=1e-4 * (k + 1), verdict="pass"))
    return table(rows)


def test_fig6_least_at_k50_is_partly_as_the_ledger_reads_it(tmp_path: Path) -> None:
    """Before: a least at K = 50 "agrees with the paper" (a band of 50-150 of the section's
    own); the ledger's rule reads K = 50 as partly."""
    df = k_sweep({0: (5.0,), 50: (1.0,), 100: (2.0,), 200: (4.0,)})
    reading = section(tmp_path, df, "gp-k-sweep").body.split("**Reading.**")[1]
    assert "agrees" not in reading and "this is close to the paper (the claims ledger's partly band" in reading
    assert ledger_row(df, "fig6-best-k", "fft")["verdict"] == "partly"


@pytest.mark.parametrize("totals", [
    {0: (9.0, 9.1, 9.2), 50: (3.0, 3.1, 3.2), 100: (1.0, 1.01, 1.02), 150: (2.0, 2.1, 2.2)},  # holds
    {0: (1.0, 1.01, 1.02), 50: (3.0, 3.1, 3.2), 100: (4.0, 4.1, 4.2), 150: (5.0, 5.1, 5.2)},  # fails
    {0: (10.0, 10.0, 10.0), 50: (5.05, 4.0, 6.0), 100: (6.0, 5.0, 4.0), 150: (4.0, 5.1, 6.1)},  # repeats disagree
    {0: (9.0, 9.0, 9.0), 50: (3.0, 3.0, 3.9), 100: (1.0, 1.0, 1.3), 150: (1.05, 1.05, 1.4)},  # tied with 150
    {0: (3.0,), 25: (1.0,), 100: (1.03,), 200: (2.0,)},  # one repeat: 25 (fails) tied with 100 (holds)
])
def test_fig6_ledger_measurement_is_the_ledgers(totals: dict[int, tuple[float, ...]]) -> None:
    from contactbench.harness.report.sections import paper_conditions as pc

    df = k_sweep(totals)
    (mine,) = pc.fig6_ledger(df)
    row = ledger_row(df, "fig6-best-k", "fft")
    assert (mine.measured, mine.verdict) == (row["measured"], row["verdict"])


def test_fig6_gives_no_verdict_where_the_ledger_reads_the_cold_k_sweep(tmp_path: Path) -> None:
    warm = k_sweep({0: (5.0,), 50: (1.0,), 100: (2.0,)}, operator="dense")
    cold = k_sweep({0: (5.0,), 50: (3.0,), 100: (1.0,)}, scene="greedy-linear-solvers", operator="dense")
    reading = section(tmp_path, pd.concat([warm, cold]), "gp-k-sweep").body.split("**Reading.**")[1]
    assert "no verdict here: the claims ledger reads this claim on the cold K sweep" in reading
    assert not re.search(r"agrees|is close to|does not agree", reading.split(". ")[0])
    assert ledger_row(pd.concat([warm, cold]), "fig6-best-k", "dense")["verdict"] == "holds"


# ---------------------------------------------------------------------------
# Example 1: per n, as the ledger reads it
# ---------------------------------------------------------------------------


def counterexample(shares: dict[int, float], seeds: int = 20) -> pd.DataFrame:
    """Example 1 on the dense H: greedy CG wrong on ``shares[n]`` of the seeds at each n."""
    rows = []
    for n, share in shares.items():
        for s in range(seeds):
            bad = s < round(share * seeds)
            rows.append(report_row(scene="counterexample", instance=f"n{n}-s{s}", seed=s, n=n, N=n, solver="greedy-cg",
                                   operator="dense", profile="paper", solve_time_s=1e-4, delta=float("nan"),
                                   status="inaccurate" if bad else "solved", verdict="wrong" if bad else "pass",
                                   kkt_error=0.05 if bad else 1e-10, solver_converged=True))
    return table(rows)


def test_example1_reads_each_n_as_the_ledger_does(tmp_path: Path) -> None:
    """Wrong on 10 % at n = 25 and 70 % at n = 100: 40 % pooled, which the paper's "any n"
    does not make a verdict (before: "agrees with the paper's ~40 %"); each n is read as the
    ledger reads it, both outside its bands."""
    df = counterexample({25: 0.1, 100: 0.7})
    reading = section(tmp_path, df, "counterexample").body.split("**Reading.**")[1]
    pooled, per_n = reading.split("As the claims ledger reads it", 1)
    assert "40 % pooled over the sizes, given no verdict" in pooled and "agrees" not in pooled
    led = cl.ledger(df)
    rows = led[led["claim"] == "ex1-greedy-fails"]
    assert len(rows) == 2
    for r in rows.itertuples():
        said = per_n.split(f"{r.n_or_size}: ", 1)[1].split(";")[0]
        words = SHARE_WORDS[r.verdict]
        assert said.startswith(tuple([words] if isinstance(words, str) else words), said.index("which ") + 6), said
    assert set(rows["verdict"]) == {"fails"}


def test_share_verdict_words_follow_the_ledger_rule() -> None:
    rule = CLAIMS["ex1-greedy-fails"].rule
    for share in (0.1, 0.25, 0.36, 0.52, 0.8):
        words = SHARE_WORDS[rule.at(share)]
        assert rce.share_verdict(share).startswith(words if isinstance(words, str) else tuple(words))


# ---------------------------------------------------------------------------
# Imports run one way: the ledger imports the sections
# ---------------------------------------------------------------------------


#: The modules that hold the ledger's measurements (one home each), below the ledger and the sections.
MEASURE_MODULES = ("claim_tables", "claim_measures")
#: The sections that state the ledger's verdicts.
READING_MODULES = ("sections/paper.py", "sections/paper_conditions.py", "sections/paper_readings.py",
                   "sections/counterexample.py")


def _imports_and_functions(path: Path) -> tuple[set[str], set[str]]:
    """The modules a file imports (relative names as written, ".sections.paper") and the
    functions and classes it defines at its top level."""
    tree = ast.parse(path.read_text())
    imported = {"." * n.level + (n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    return imported, defined


def test_the_measurements_have_one_home_below_the_ledger_and_the_sections() -> None:
    """claim_tables.py and claim_measures.py import no section; no paper section defines a
    function or class of theirs again (a copy of a measurement under the same name)."""
    from contactbench.harness.report import claims

    report = Path(claims.__file__).parent
    homes: set[str] = set()
    for mod in MEASURE_MODULES:
        imported, defined = _imports_and_functions(report / f"{mod}.py")
        assert not [m for m in imported if "sections" in m or m.endswith(".claims")], (mod, imported)
        homes |= defined
    for mod in READING_MODULES:
        assert not homes & _imports_and_functions(report / mod)[1], mod


def test_the_paper_sections_do_not_import_the_ledger() -> None:
    code = ("import sys; import contactbench.harness.report.sections.paper, "
            "contactbench.harness.report.sections.counterexample, "
            "contactbench.harness.report.sections.paper_conditions; "
            "print('contactbench.harness.report.claims' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
