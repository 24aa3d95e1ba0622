"""A scene added from outside the repository: one module declares the scene, its study,
its report section and the section's page chart, and is named by an entry point of
group ``contactbench.scenes``.  A run and a report in fresh processes find it with no
edit to any file of the project (docs/architecture.md, "Add a scene")."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from contactbench.harness.report.charts import Chart, Series

PLUGIN = textwrap.dedent('''
    """A scene shipped by another package: scene, study, section and chart in one place."""
    from contactbench.harness.report.charts import Chart, Series
    from contactbench.harness.report.core import Section, register_section
    from contactbench.harness.run.studies import Study, register_study
    from contactbench.problems.scenes import register_scene
    from contactbench.problems.scenes.core import Counterexample

    NAME = "plugin-demo"


    @register_scene
    class PluginDemo(Counterexample):
        name = NAME
        description = "a scene from outside the repository (the greedy counterexample's recipe)"


    register_study(Study(NAME, solvers=("scipy-nnls",)))


    @register_section(NAME, title="Plugin demo", group="scenes")
    def plugin_section(ctx, rows):
        chart = Chart("plugin-demo-load", "Plugin demo chart: load per seed", "seed", "load",
                      series=(Series("scipy-nnls", tuple(float(s) for s in rows["seed"]),
                                     tuple(float(v) for v in rows["load"]), mode="markers"),))
        return Section("Plugin demo section", f"{len(rows)} rows of the plugin scene.\\n", charts=[chart])
''')


def install_plugin(site: Path) -> None:
    """The module and a dist-info folder naming it in group ``contactbench.scenes``: what
    ``pip install`` of a package with that entry point leaves on sys.path."""
    site.mkdir(parents=True)
    (site / "cb_plugin_demo.py").write_text(PLUGIN)
    info = site / "cb_plugin_demo-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cb-plugin-demo\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[contactbench.scenes]\nplugin-demo = cb_plugin_demo\n")


def contactbench(args: list[str], site: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "contactbench.harness.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_a_scene_from_outside_the_repository_reaches_report_md_and_report_html(tmp_path: Path) -> None:
    repo = Path(__file__).resolve().parents[2]
    assert repo not in tmp_path.parents
    site, out = tmp_path / "site", tmp_path / "out"
    install_plugin(site)
    run = contactbench(["run", "plugin-demo", "--size", "3", "--seeds", "0,1", "--reference", "none",
                        "--out", str(out)], site, tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    rep = contactbench(["report", str(out)], site, tmp_path)
    assert rep.returncode == 0, rep.stderr[-3000:]
    md = (out / "report.md").read_text()
    assert "### Plugin demo section" in md and "2 rows of the plugin scene." in md
    assert "figures/chart-plugin-demo-load.png" in md and (out / "figures" / "chart-plugin-demo-load.png").is_file()
    page = (out / "report.html").read_text()
    data = json.loads(re.search(r'<script id="report-data" type="application/json">(.*?)</script>', page,
                                re.S).group(1))
    charts = [c for c in data["charts"] if c["scene"] == "plugin-demo"]
    assert [c["layout"]["title"]["text"] for c in charts] == ["Plugin demo chart: load per seed"]
    assert sorted(charts[0]["data"][0]["x"]) == [0.0, 1.0]
    # the scene is unknown without its entry point: nothing of it was added to the project
    bare = subprocess.run([sys.executable, "-m", "contactbench.harness.cli", "list", "scenes"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert bare.returncode == 0 and "counterexample" in bare.stdout and "plugin-demo" not in bare.stdout


def test_a_chart_is_drawn_by_both_backends_from_the_same_data() -> None:
    chart = Chart("c", "t", "x", "y", series=(Series("a", (1.0, 10.0, 100.0), (1.0, float("nan"), 3.0)),),
                  x_log=True)
    spec = chart.to_plotly()
    assert spec["layout"]["xaxis"]["type"] == "log" and spec["layout"]["yaxis"]["type"] == "linear"
    assert spec["data"][0]["y"] == [1.0, None, 3.0]  # NaN is left out, not drawn as 0
    json.dumps(spec, allow_nan=False)
    ax = chart.to_figure().axes[0]
    assert ax.get_xscale() == "log" and ax.get_title() == "t" and len(ax.lines) == 1


def test_a_series_with_unequal_lengths_or_an_unknown_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="2 x values but 1 y values"):
        Series("a", (1.0, 2.0), (1.0,))
    with pytest.raises(ValueError, match="mode"):
        Series("a", (1.0,), (1.0,), mode="bars")
