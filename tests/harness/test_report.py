"""The report (harness/report/core.py and its section modules) built from a fabricated tidy table.

``tests.helpers.fabricate_table`` writes a plausible table with every schema column:
paper-sweep, greedy-linear-solvers, gp-k-sweep, counterexample and hertz rows, with
skips, a timeout, a crash, inaccurate answers, false claims and traces.  Timings follow
simple models (stated there) so the report's computed ratios can be checked against
values recomputed here from the same table.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from contactbench.harness import build_report, load_table
from contactbench.harness.report import core as rp
from contactbench.harness.report.view import read_table
from contactbench.harness.report.sections import counterexample as rce
from contactbench.harness.report.sections import paper as rpp
from contactbench.harness.table.meta import write_meta
from contactbench.harness.table.schema import ALL_COLUMNS, REQUIRED_COLUMNS
from tests.helpers import META, fabricate_table, report_row, trace_json, write_out


def write_counterexample_arrays(out: Path, instance: str = "n100-s1", solver: str = "greedy-cg",
                                full: bool = True) -> Path:
    """A fabricated failing case in the format the report reads."""
    rng = np.random.default_rng(3)
    n = int(instance.split("-")[0][1:])
    p_ref = np.maximum(rng.normal(0.004, 0.004, n), 0.0)
    p = p_ref.copy()
    p[[5, 17]] = [0.0, p_ref[17] + 0.003]
    arrays = {"p": p, "p_ref": p_ref}
    if full:
        ubar = rng.random(n)
        w = rng.random(n) * (p == 0)
        w[5] = -0.02
        arrays.update(ubar=ubar, w=w)
    d = out / "arrays"
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"counterexample-{instance}-{solver}.npz"
    np.savez(path, **arrays)
    return path


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, pd.DataFrame]:
    df = fabricate_table()
    out = write_out(tmp_path_factory.mktemp("rep"), df)
    write_counterexample_arrays(out)
    path = build_report(out)
    return out, path.read_text(), df


def _figure_links(text: str) -> list[str]:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)


def test_fabricated_table_follows_the_schema() -> None:
    df = fabricate_table()
    assert list(df.columns) == list(ALL_COLUMNS)
    assert set(REQUIRED_COLUMNS) <= set(df.columns)


def test_report_has_every_section_and_every_figure_exists(built: tuple[Path, str, pd.DataFrame]) -> None:
    out, text, _ = built
    for heading in ("# contactbench report: synthetic", "Fig. 4", "Fig. 5", "Fig. 6", "Example 1",
                    "Closed-form check (hertz)", "## Run time against error", "## Aggregates across instances",
                    "## Skips and failures", "## Tables per scene"):
        assert heading in text, heading
    links = _figure_links(text)
    assert len(links) >= 12
    for rel in links:
        f = out / rel
        assert f.is_file(), rel
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # every PNG on disk is referenced (no stale figures)
    assert sorted(p.name for p in (out / "figures").glob("*.png")) == sorted(Path(r).name for r in links)
    # header from meta.json
    for v in ("| Git commit | 0123abc |", "| CPU | Synthetic CPU 9000 |", "numpy=2.x", "| Cores | 1 physical, 2 logical |",
              "| Threads (BLAS/FFT) | OMP_NUM_THREADS=1, FFT workers=1, openblas: 1 threads |"):
        assert v in text


def test_fig4_reading_uses_ratios_computed_from_the_table(built: tuple[Path, str, pd.DataFrame]) -> None:
    _, text, df = built
    r = df[(df["scene"] == "paper-sweep") & (df["profile"] == "high")]
    cells = r.groupby(["solver", "step"])["solve_time_s"].min().groupby("solver").sum()
    pk_ratio = cells["pk"] / cells["nnls-gp"]
    assert f"P&K 1999 / NNLS+GP: measured {pk_ratio:.3g}x" in text
    pk_reading = text.split("P&K 1999 / NNLS+GP")[1].split("\n")[0]
    # the ledger reads this claim on P&K's cold solves, not on the sweep's warm ones: no verdict here
    assert "no verdict here" in pk_reading and "fig4-pk-cold-over-nnlsgp" in pk_reading
    best = cells.idxmin()
    warm = bool(r[r["solver"] == best]["warm_start"].any())  # the report labels warm-started runs
    assert f"fastest solver over the whole sweep here is `{best}{' (warm)' if warm else ''}`" in text


def test_fig5_and_fig6_readings(built: tuple[Path, str, pd.DataFrame]) -> None:
    _, text, df = built
    g = df[df["scene"] == "greedy-linear-solvers"].pivot_table(index="n", columns="solver", values="solve_time_s")
    chol = float(np.median((g["greedy-chol"] / g["greedy-cg"]).dropna()))
    assert f"greedy Cholesky / greedy CG time (median over 4 common solved instances): measured {chol:.3g}x" in text
    assert "Cholesky was skipped from n = 25600 on (dense submatrix needs 4.9 GiB" in text
    k = df[df["scene"] == "gp-k-sweep"].groupby("params")["solve_time_s"].sum()
    kbest = json.loads(k.idxmin())["K"]
    assert f"The total time is smallest at K = {kbest} " in text


def test_paper_sections_state_the_surface_family(built: tuple[Path, str, pd.DataFrame]) -> None:
    _, text, _ = built
    fig4 = text[text.index("### Fig. 4"):text.index("### Fig. 5")]
    fig6 = text[text.index("### Fig. 6"):]
    # the fabricated paper-sweep and gp-k-sweep rows carry surface_family "rmd": the periodic family's old name
    assert "**Surface family.** `periodic`" in fig4 and "**Surface family.** `periodic`" in fig6.split("###")[1]
    fig5 = text[text.index("### Fig. 5"):text.index("### Fig. 6")]
    assert "**Surface family.**" not in fig5  # its instances ("n400") are not generated rough surfaces
    assert rpp.surface_families(pd.DataFrame({"surface_family": ["saupe"]})) == ["saupe"]


def test_counterexample_fractions_and_case(built: tuple[Path, str, pd.DataFrame]) -> None:
    out, text, df = built
    ce = df[(df["scene"] == "counterexample") & (df["solver"] == "greedy-cg")]
    v = ce[ce["n"] == 100]
    bad = int((v["status"] != "solved").sum())  # the judge's verdict, never a threshold of the section's own
    assert "| greedy-cg | " in text and f"({bad}/20: {bad} wrong)" in text
    assert "Never violating (as the paper proves for NNLS): `nnls`." in text
    assert "figures/counterexample-case-n100-s1-greedy-cg.png" in text
    assert (out / "figures" / "counterexample-case-n100-s1-greedy-cg.png").is_file()


def test_failures_and_skips_are_listed(built: tuple[Path, str, pd.DataFrame]) -> None:
    _, text, _ = built
    skips = text.split("## Skips and failures")[1].split("## Tables per scene")[0]
    assert "| greedy-linear-solvers | greedy-chol | 1 | 1 | 0 | dense submatrix needs 4.9 GiB" in skips
    assert skips.count("| hertz | broken |") == 4
    assert "crashed" in skips and "timeout" in skips and "SIGABRT" in skips
    assert "inaccurate answers" in skips and "| paper-sweep | admm | default | 1 |" in skips


def test_missing_scenes_get_no_section_and_the_report_is_deterministic(tmp_path: Path) -> None:
    df = fabricate_table()
    out = write_out(tmp_path, df[df["scene"] == "hertz"], meta=None)
    text = build_report(out).read_text()
    assert "Fig. 4" not in text and "Fig. 6" not in text and "Example 1" not in text
    assert "Paper reproductions" not in text
    assert "unknown (no meta.json)" in text
    assert not list((out / "figures").glob("fig4*"))
    for rel in _figure_links(text):
        assert (out / rel).is_file()
    assert build_report(out).read_text() == text  # two reports of one table diff cleanly


def test_counterexample_case_needs_stored_arrays(tmp_path: Path) -> None:
    df = fabricate_table()
    out = write_out(tmp_path, df[df["scene"] == "counterexample"], fmt="csv")
    table = read_table(out)  # the CSV fallback
    ctx = rp.ReportContext(out, table, {})
    cells = rce.seed_readings(table)
    msg = rce._counterexample_case(ctx, cells)
    assert re.search(r"cannot be plotted: no array file `arrays/counterexample-n100-s\d+-greedy-cg\.npz` "
                     r"\(keys p, p_ref, ubar, w\)", msg)
    assert not ctx.figures
    # p and p_ref only: ubar and w are rebuilt from the problem (no solve)
    path = write_counterexample_arrays(out, full=False)
    assert rce.find_counterexample_arrays(out) == {("n100-s1", "greedy-cg"): path}
    case = rce.load_counterexample_case(path, "n100-s1", "greedy-cg")
    from contactbench.problems.instances import counterexample

    inst = counterexample(100, 1)
    np.testing.assert_allclose(case.ubar, inst.qp.ubar)
    np.testing.assert_allclose(case.w, inst.qp.H.matvec(case.p) - inst.qp.ubar)
    np.savez(out / "arrays" / "counterexample-n100-s2-greedy-cg.npz", p=case.p)
    with pytest.raises(rp.ReportInputError, match="p_ref"):
        rce.load_counterexample_case(out / "arrays" / "counterexample-n100-s2-greedy-cg.npz", "n100-s2", "greedy-cg")


def test_csv_and_parquet_read_alike(tmp_path: Path) -> None:
    df = fabricate_table()
    a = read_table(write_out(tmp_path / "pq", df))
    b = read_table(write_out(tmp_path / "csv", df, fmt="csv"))
    for col in ("status", "solver", "instance", "params", "trace", "skip_reason"):
        assert list(a[col]) == list(b[col]), col
    for col in ("solve_time_s", "kkt_error", "n", "dim_load"):
        np.testing.assert_allclose(a[col].to_numpy(), b[col].to_numpy(), rtol=1e-12, equal_nan=True)
    assert list(a["warm_start"]) == list(b["warm_start"])
    assert repr(rp.agg.summarize(a)) == repr(rp.agg.summarize(b))


def test_bad_tables_give_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(rp.ReportInputError, match="no results table"):
        build_report(tmp_path)
    df = fabricate_table().drop(columns=["kkt_error"])
    write_out(tmp_path, df)
    with pytest.raises(rp.ReportInputError, match="kkt_error"):
        build_report(tmp_path)
    df = fabricate_table()
    df.loc[0, "status"] = "great"
    write_out(tmp_path, df)
    with pytest.raises(rp.ReportInputError, match="great"):
        build_report(tmp_path)


def test_a_corrupted_csv_is_named_not_read_as_rows(tmp_path: Path) -> None:
    """A results.csv cut off in a row, with text in a number column, a negative time or bytes
    that are not text: one error naming the file (and row), no report from half a row."""
    df = fabricate_table()
    whole = tmp_path / "whole"
    write_out(whole, df, fmt="csv")
    text = (whole / "results.csv").read_text()
    cases = {
        "cut": (text[: len(text) * 2 // 3], "ends in the middle of its row"),
        "word": (None, "not a number"),
        "negative": (None, "negative duration"),
        "binary": (b"\xff\xfe\x00\x01garbage\n", "cannot be read as a results table"),
    }
    for name, (content, match) in cases.items():
        out = tmp_path / name
        if name == "word":
            bad = df.astype({"step": "object"})
            bad.loc[3, "step"] = "x"
            write_out(out, bad, fmt="csv")
        elif name == "negative":
            bad = df.copy()
            bad.loc[2, "solve_time_s"] = -1.0
            write_out(out, bad, fmt="csv")
        else:
            write_out(out, df, fmt="csv")
            f = out / "results.csv"
            f.write_bytes(content) if isinstance(content, bytes) else f.write_text(content)
        with pytest.raises(rp.ReportInputError, match=match) as err:
            build_report(out, html=False)
        assert f"{name}" in str(err.value), name  # the folder or its results.csv
        assert not (out / "report.md").exists() and not list(out.glob("figures/*.png")), name
    no_newline = tmp_path / "no-newline"
    write_out(no_newline, df, fmt="csv")
    (no_newline / "results.csv").write_text(text.rstrip("\n"))  # a whole last row without its newline: read
    assert load_table(no_newline).shape[0] == len(df)


def test_a_registered_section_is_rendered_for_its_scene(tmp_path: Path) -> None:
    df = fabricate_table()
    new = df[(df["scene"] == "hertz") & (df["solver"] == "nnls")].assign(scene="test-new-scene")
    out = write_out(tmp_path, new)

    @rp.register_section("test-new-scene", title="New", group="paper", order=60)
    def new_section(ctx: rp.ReportContext, rows: pd.DataFrame) -> rp.Section:
        return rp.Section("Fig. 99: a new scene", f"New section with {len(rows)} rows.\n")

    try:
        text = build_report(out).read_text()
    finally:
        rp.unregister_section("test-new-scene")
    assert "### Fig. 99: a new scene" in text and f"New section with {len(new)} rows." in text
    assert "test-new-scene" not in rp.registered_sections()
    with pytest.raises(ValueError, match="already registered"):
        rp.register_section("hertz", title="x")(lambda ctx, rows: None)


def test_roles_are_found_by_base_solver_and_params_not_by_label() -> None:
    curves = pd.DataFrame({
        "solver": ["greedy-chol", "my-cg", "nnls", "nnls-gp[K=50]", "gp100", "pk", "pk (warm)", "cmr+pk", "polonsky"],
        "base_solver": ["greedy-chol", "greedy-cg", "nnls", "nnls-gp", "nnls-gp", "pk", "pk", "cmr+pk", "fast-ccg"],
        "params": ["{}", "{}", "{}", '{"K": 50}', '{"K": 100}', "{}", "{}", "{}", "{}"],
        "warm": [False, False, False, False, False, False, True, False, False],
    })
    assert rpp.resolve_role(curves, "nnls-gp") == "gp100"  # the paper's K, whatever the label
    assert rpp.resolve_role(curves[curves["solver"] != "gp100"], "nnls-gp") == "nnls-gp[K=50]"  # another K
    assert rpp.resolve_role(curves, "pk") == "pk"  # cold first
    assert rpp.resolve_role(curves, "pk-warm") == "pk (warm)"
    assert rpp.resolve_role(curves[curves["solver"] != "pk"], "pk") == "pk (warm)"  # warm when no cold run
    assert rpp.resolve_role(curves[curves["solver"] != "pk (warm)"], "pk-warm") is None
    assert rpp.resolve_role(curves, "greedy-cg") == "my-cg"
    assert rpp.resolve_role(curves, "admm") is None
    assert rpp.resolve_role(curves.drop(columns="warm"), "pk") == "pk"


def test_claim_agreement_words() -> None:
    claim = rpp.ledger_claim("fig4-pk-cold-over-nnlsgp")
    assert claim.text == "~26x"
    assert rpp.agreement(26.0, claim).startswith("agrees with the paper")
    assert rpp.agreement(50.0, claim).startswith("is close to")
    assert "smaller" in rpp.agreement(3.0, claim)
    assert rpp.agreement(0.5, claim).startswith("points the opposite way")
    assert "row `fig4-pk-cold-over-nnlsgp`, condition `dense`" in rpp.agreement(0.5, claim)
    assert rpp.agreement(float("nan"), claim).startswith("cannot")


# ---------------------------------------------------------------------------
# The table contract (harness/table/schema.py) and the plug-in registry (contactbench/plugins.py)
# ---------------------------------------------------------------------------


def test_the_schema_types_every_column_and_load_table_applies_it(tmp_path: Path) -> None:
    from contactbench.harness.table import schema

    assert list(schema.COLUMNS) == list(ALL_COLUMNS) and ALL_COLUMNS[:len(REQUIRED_COLUMNS)] == REQUIRED_COLUMNS
    assert all(c.dtype in schema.DTYPES and c.doc for c in schema.COLUMNS.values())
    assert schema.COLUMNS["verdict"].dtype == "string" and set(schema.VERDICTS) == {"pass", "wrong", "unconverged"}
    df = fabricate_table().drop(columns=["verdict", "history"])  # a table written before these columns
    for source in (write_out(tmp_path / "pq", df), write_out(tmp_path / "csv", df, fmt="csv"),
                   tmp_path / "csv" / "results.csv"):
        t = load_table(source)
        assert list(t.columns) == list(ALL_COLUMNS)
        assert {c: str(t[c].dtype) for c in ALL_COLUMNS} == \
            {c.name: ("string" if c.dtype == "string" else c.dtype) for c in schema.COLUMNS.values()}
        assert set(t["verdict"]) == {""} and t["warm_start"].dtype == "boolean"
        assert list(t["n"]) == list(df["n"].astype("Int64"))


def test_load_table_reads_a_journal_newer_than_the_table_without_writing(tmp_path: Path) -> None:
    import os

    from contactbench.harness.table.schema import MissingTableError, TableError

    from contactbench.harness.table.store import ResultStore

    rows = fabricate_table().head(3).assign(cell_id=["a", "b", "c"], verdict=["pass", "wrong", "unconverged"])
    store = ResultStore(tmp_path)
    for r in rows.to_dict("records")[:2]:
        store.append(r)
    store.finalize()
    store.append(rows.to_dict("records")[2])
    pq = tmp_path / "results.parquet"
    os.utime(pq, (1, 1))  # the journal is newer: the table is stale
    before = pq.read_bytes()
    t = load_table(tmp_path).sort_values("cell_id")
    assert list(t["cell_id"]) == ["a", "b", "c"] and list(t["verdict"]) == ["pass", "wrong", "unconverged"]
    assert pq.read_bytes() == before and pq.stat().st_mtime == 1  # reading never writes
    with pytest.raises(MissingTableError, match="no results table"):
        load_table(tmp_path / "nowhere")
    bad = fabricate_table().head(2).assign(verdict=["pass", "fine"])
    with pytest.raises(TableError, match="verdict.*fine"):
        load_table(write_out(tmp_path / "bad", bad))


def _write_plugin_package(root: Path, name: str) -> None:
    pkg = root / name
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    reg = ("from contactbench.plugins import PluginRegistry\n"
           f"WIDGETS = PluginRegistry('widget', package={name!r}, include=lambda short: short != 'registry')\n")
    (pkg / "registry.py").write_text(reg)
    (pkg / "alpha.py").write_text(f"from {name}.registry import WIDGETS\nWIDGETS.add('alpha', 1)\n")
    (pkg / "beta.py").write_text(f"from {name}.registry import WIDGETS\nWIDGETS.add('beta', 2)\n")
    (pkg / "broken.py").write_text("raise RuntimeError('this plug-in is broken')\n")
    (pkg / "_helper.py").write_text("raise AssertionError('helpers are not plug-ins')\n")


def test_plugin_registry_discovers_once_keeps_import_errors_and_names_the_known(tmp_path: Path,
                                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib

    from contactbench.plugins import UnknownPluginError

    _write_plugin_package(tmp_path, "cb_test_widgets")
    monkeypatch.syspath_prepend(str(tmp_path))
    reg = importlib.import_module("cb_test_widgets.registry").WIDGETS
    assert reg.all() == {"alpha": 1, "beta": 2}
    errors = reg.import_errors()
    assert list(errors) == ["cb_test_widgets.broken"] and "this plug-in is broken" in errors["cb_test_widgets.broken"]
    with pytest.raises(UnknownPluginError, match=r"unknown widget 'gamma'; known widgets: alpha, beta") as e:
        reg.get("gamma")
    assert isinstance(e.value, KeyError)
    with pytest.raises(ValueError, match="already registered"):
        reg.add("alpha", 3)
    reg.add("alpha", 3, replace=True)
    reg.remove("beta")
    assert reg.all() == {"alpha": 3}  # discovery ran once: beta is not imported again


def test_solvers_scenes_and_sections_share_the_plugin_registry() -> None:
    from contactbench.plugins import PluginRegistry
    from contactbench.problems import scenes
    from contactbench.problems.scenes import base as scene_base
    from contactbench.solvers import registry

    assert isinstance(registry._SOLVERS, PluginRegistry) and isinstance(scene_base._SCENES, PluginRegistry)
    assert isinstance(rp._SECTIONS, PluginRegistry)
    with pytest.raises(registry.UnknownSolverError, match="unknown solver 'no-such'; known solvers: "):
        registry.get_solver("no-such")
    with pytest.raises(KeyError, match="unknown scene 'no-such'; known scenes: .*paper-sweep"):
        scenes.get_scene("no-such")
    sections = rp.registered_sections()
    assert {"paper-sweep", "counterexample", "cmr", "population", "work-precision", "scene-tables"} <= set(sections)
    assert not rp.section_import_errors()


def test_a_summary_section_is_rendered_for_every_table(tmp_path: Path) -> None:
    df = fabricate_table()
    out = write_out(tmp_path, df[df["scene"] == "hertz"])

    @rp.register_section("test-summary", title="x", group="summary", order=25)
    def summary(ctx: rp.ReportContext, table: pd.DataFrame) -> rp.Section:
        return rp.Section("A summary", f"{table['scene'].nunique()} scene(s), {len(table)} rows.\n")

    try:
        text = build_report(out).read_text()
    finally:
        rp.unregister_section("test-summary")
    assert f"## A summary\n\n1 scene(s), {int((df['scene'] == 'hertz').sum())} rows." in text
    assert text.index("## Aggregates across instances") < text.index("## A summary") < \
        text.index("## Skips and failures")


@pytest.mark.slow
def test_stress_rows_get_the_verdict_counts_per_solver(tmp_path: Path) -> None:
    df = fabricate_table()
    stress = df[(df["scene"] == "hertz") & df["solver"].isin(["nnls", "pk"])].assign(scene="stress-edge")
    stress["verdict"] = ["pass", "wrong", "pass", "unconverged", "pass", "", "pass", "pass"]
    text = build_report(write_out(tmp_path, pd.concat([df[df["scene"] == "hertz"], stress]))).read_text()
    section = text.split("## Stress battery")[1].split("\n## ")[0]
    assert "| solver | rows | pass | wrong | unconverged | not judged |" in section
    counts = stress.groupby("solver")["verdict"].apply(list).to_dict()
    for s, v in counts.items():
        row = f"| {s} | {len(v)} | {v.count('pass')} | {v.count('wrong')} | {v.count('unconverged')} | {v.count('')} |"
        assert row in section
    wrong = sorted(stress.loc[stress["verdict"] == "wrong", "solver"].unique())
    assert f"Wrong answers claimed as converged: {', '.join(f'`{s}`' for s in wrong)}." in section
    assert "## Stress battery" not in build_report(write_out(tmp_path / "plain", df[df["scene"] == "hertz"])) \
        .read_text()


@pytest.mark.slow
def test_at_33_solvers_no_panel_draws_more_than_ten_and_no_family_vanishes(tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """33 solvers in six families (one registered from outside with family "other"): every
    panel of every figure draws at most 10 solvers, Fig. 4 draws the outside solver, and
    the reading names the accuracy beside every "fastest"."""
    from contactbench.harness.report.style import MAX_SERIES

    rng = np.random.default_rng(5)
    fams = ["paper"] * 10 + ["fast"] * 6 + ["qp"] * 11 + ["wrapper"] * 4 + ["reference", "other"]
    solvers = {f"{f}-s{i}": f for i, f in enumerate(fams)}
    rows = []
    for k in range(4):
        for s, f in solvers.items():
            t = 1e-3 * (k + 1) * (1 + 10 * rng.random())
            rows.append(report_row(scene="paper-sweep", instance="i0", step=k, n=100 * (k + 1), N=64, solver=s, family=f,
                             profile="high", solve_time_s=t, dim_load=1e-4 * (k + 1), trace=trace_json(t),
                             kkt_error=10 ** rng.uniform(-12, -9), warm_start=False))
    out = write_out(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    seen: dict[str, list[int]] = {}
    real_save = rp.ReportContext.save_figure

    def spy(self: rp.ReportContext, fig: Any, name: str) -> str:
        counts = []
        for ax in fig.axes:
            _, labels = ax.get_legend_handles_labels()
            counts.append(len({lab.removesuffix(" (warm)") for lab in labels} & set(solvers)))
        seen[name] = counts
        return real_save(self, fig, name)

    monkeypatch.setattr(rp.ReportContext, "save_figure", spy)
    text = build_report(out, html=False).read_text()
    assert {"fig4-paper-sweep", "wp-paper-sweep", "pp-paper-sweep"} <= set(seen)
    for name, counts in seen.items():
        assert max(counts, default=0) <= MAX_SERIES, (name, counts)
    for name in ("fig4-paper-sweep", "wp-paper-sweep", "pp-paper-sweep"):
        assert sum(seen[name]) >= len(solvers), name  # every solver drawn in colour somewhere
    fig4 = text.split("### Fig. 4")[1].split("**Reading.**")[0]
    assert "other (1)" in fig4 and "light grey" in fig4
    reading = text.split("### Fig. 4")[1].split("**Reading.**")[1].split("\n")[0]
    assert re.search(r"fastest solver over the whole sweep here is `[^`]+` with [0-9.]+ s at worst kkt \d\.\de-\d+",
                     reading)


def test_a_report_failing_part_way_keeps_the_last_figures(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The figures of the last report stay, byte for byte, until a new report is written, and
    a report that fails part-way leaves no figure of its own; then a PNG the last report
    wrote and the new one does not (stale) goes, and a PNG no report wrote (the user's) stays."""
    table = fabricate_table()
    table = table[table["scene"].isin(["hertz", "paper-sweep", "counterexample"])]  # three sections: enough
    out = write_out(tmp_path, table)
    build_report(out)
    before = {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")}
    assert len(before) > 5

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("a section failed part-way")

    with monkeypatch.context() as m:
        m.setattr(rce, "violation_counts", broken)
        with pytest.raises(RuntimeError, match="part-way"):
            build_report(out)
    assert {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")} == before
    assert sorted(p.name for p in (out / "figures").iterdir() if p.is_dir()) == []  # nothing staged is left
    (out / "figures" / "mine.png").write_bytes(b"the user's own figure")
    gone = "wp-hertz.png"
    assert gone in before
    write_out(out, table[table["scene"] != "hertz"])
    build_report(out)
    after = {p.name for p in (out / "figures").glob("*.png")}
    assert gone not in after and "mine.png" in after
    assert (out / "figures" / "mine.png").read_bytes() == b"the user's own figure"
    assert set(before) - after == {n for n in before if "hertz" in n}


def test_a_second_report_in_a_folder_is_refused_and_the_first_one_s_figures_stay(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """While a report writes in a folder (its lock on OUT/figures/ held), another report of
    that folder is refused in one line, exit 2, before it stages anything: the first one's
    staged figures and the published ones stay as they were."""
    from contactbench.harness.cli import main
    from contactbench.harness.report.figure_files import staging_dir
    from contactbench.problems.atomic_files import folder_lock

    table = fabricate_table()
    out = write_out(tmp_path, table[table["scene"] == "hertz"])
    build_report(out)
    before = {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")}
    staged = staging_dir(out)
    staged.mkdir()
    (staged / "wp-hertz.png").write_bytes(b"the first report's staged figure")
    capsys.readouterr()
    with folder_lock(out / "figures"):  # the first report, part-way
        assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another report is writing" in err[0] and str(out) in err[0]
    assert (staged / "wp-hertz.png").read_bytes() == b"the first report's staged figure"
    assert {p.name: p.read_bytes() for p in (out / "figures").glob("*.png")} == before
    assert main(["report", str(out)]) == 0  # the lock released: the next one runs
    assert not staged.exists()


def test_a_claims_csv_that_is_not_a_ledger_is_left_alone(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Outside a claims run, a user's own claims.csv (few of the ledger's columns) is not read
    as a ledger: the report is written, the file stays byte for byte, no claims.md is
    written, and a warning names the file."""
    from contactbench.harness.cli import main

    table = fabricate_table()
    out = write_out(tmp_path, table[table["scene"] == "hertz"])
    mine = b"claim,owner,verdict\nthe mesh converges,me,maybe\n"
    (out / "claims.csv").write_bytes(mine)
    assert main(["report", str(out)]) == 0
    assert (out / "claims.csv").read_bytes() == mine
    assert not (out / "claims.md").exists()
    assert "ledger" not in (out / "report.md").read_text().split("##")[1]  # no ledger section leads it
    assert "claims.csv: not a claims ledger" in caplog.text


def test_a_run_without_a_reference_draws_no_empty_error_panel(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run with ``--reference none`` has no error in p: its work-precision figure is the KKT
    panel alone (no empty box beside it), the caption says why, and with one profile each
    solver's points take its own marker, so the first solvers of two families -- whose dark
    shades come close -- differ in shape as well as hue."""
    from contactbench.harness.report.panels import blank_panels

    solvers = {"fast-a": "fast", "fast-b": "fast", "peer-a": "peer", "paper-a": "paper"}
    rows = [report_row(scene="paper-sweep", instance="i0", step=k, n=100, N=64, solver=s, family=f, profile="default",
                       solve_time_s=1e-3 * (k + 1 + i), trace=trace_json(1e-3), kkt_error=1e-9, p_rel_error=np.nan,
                       warm_start=False)
            for k in range(3) for i, (s, f) in enumerate(solvers.items())]
    out = write_out(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)),
                    {**META, "config": {"run": {"reference": "none"}}})
    figures: dict[str, Any] = {}
    real_save = rp.ReportContext.save_figure

    def spy(self: rp.ReportContext, fig: Any, name: str) -> str:
        figures[name] = (fig, {s: self.marker(s) for s in solvers})
        return real_save(self, fig, name)

    monkeypatch.setattr(rp.ReportContext, "save_figure", spy)
    text = build_report(out, html=False).read_text()
    fig, markers = figures["wp-paper-sweep"]
    visible = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    assert [ax.get_title() for ax in visible] == ["paper-sweep: KKT error"]
    assert blank_panels(fig) == []
    assert "no reference solution (`--reference none`)" in text
    # a run that asked for a reference none of whose candidates served says that, not "none"
    none_served = pd.DataFrame(rows, columns=list(ALL_COLUMNS)).assign(reference_solver="")
    write_out(out, none_served, {**META, "config": {"run": {"reference": "auto"}}})
    text = build_report(out, html=False).read_text()
    assert "`--reference none`" not in text and "the run asked for one, but no candidate served" in text
    # a reference that served, with no answer measured against it, is named, not denied
    served = pd.DataFrame(rows, columns=list(ALL_COLUMNS)).assign(reference_solver="scipy-nnls")
    write_out(out, served, {**META, "config": {"run": {"reference": "auto"}}})
    text = build_report(out, html=False).read_text()
    assert "no candidate served" not in text and "(`scipy-nnls`) served, but no answer here" in text
    assert markers["fast-a"] != markers["peer-a"] and markers["fast-a"] != markers["paper-a"]
    _, labels = visible[0].get_legend_handles_labels()
    assert not any(lab.startswith("profile ") for lab in labels)  # one profile: nothing to key


def test_a_trace_of_one_point_is_named_not_drawn(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A solver that reports only its final residual (a one-point trace) gets no panel of
    its own in the trace figure -- a row with a single dot -- but is named in the caption."""
    solvers = {"fast-a": "fast", "fast-b": "fast", "peer-a": "peer"}
    rows = [report_row(scene="paper-sweep", instance="i0", step=0, n=100, N=64, solver=s, family=f, profile="default",
                       solve_time_s=1e-2, trace=trace_json(1e-2, iters=1 if f == "peer" else 12), kkt_error=1e-9,
                       warm_start=False)
            for s, f in solvers.items()]
    out = write_out(tmp_path, pd.DataFrame(rows, columns=list(ALL_COLUMNS)))
    figures: dict[str, Any] = {}
    real_save = rp.ReportContext.save_figure

    def spy(self: rp.ReportContext, fig: Any, name: str) -> str:
        figures[name] = fig
        return real_save(self, fig, name)

    monkeypatch.setattr(rp.ReportContext, "save_figure", spy)
    text = build_report(out, html=False).read_text()
    titles = [ax.get_title() for ax in figures["traces-paper-sweep"].axes]
    assert titles and all("fast" in t for t in titles)
    assert "single point (their final residual only: `peer-a`)" in text


def test_the_header_names_the_commit_of_every_command_that_wrote_to_the_folder(tmp_path: Path) -> None:
    """meta.json's own ``git`` is the last command's: a resume at another commit (which may
    add no row) must not hide the commit of the run that made the rows, so the header
    lists every command's commit, first first, each once."""
    first = {"date": "d0", "command": ["run", "a"], "git": {"commit": "aaaa111", "dirty": False}, "config": {}}
    again = {**first, "date": "d1", "git": {"commit": "bbbb222", "dirty": True}}
    for record in (first, again, first):
        write_meta(tmp_path, record)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["git"]["commit"] == "aaaa111"
    assert rp._git_text(meta) == "aaaa111; bbbb222 (with uncommitted changes)"
    assert rp._git_text({"git": {"commit": "cccc333"}}) == "cccc333"  # a meta.json written before invocations
