"""A scene whose section colours its solvers itself (``style.register_scene_colors``: Fig. 6's
K variants, dark to light along K) is drawn in those colours in every figure of the scene --
Fig. 6, the run time against error and the performance profile PNGs -- and on the page."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from contactbench.harness.report import build_report
from contactbench.harness.report.core import ReportContext
from contactbench.harness.report.style import scene_colors
from tests.helpers import fabricate_table, write_out

SCENE = "gp-k-sweep"


def test_every_figure_of_the_k_sweep_asks_for_the_scenes_own_colours(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    df = fabricate_table()
    k_variants = set(df.loc[df["scene"] == SCENE, "solver"])
    asked: list[tuple[str, str]] = []
    plain = ReportContext.color

    def recording(self: ReportContext, solver: str, scene: str = "") -> object:
        asked.append((solver, scene))
        return plain(self, solver, scene)

    monkeypatch.setattr(ReportContext, "color", recording)
    out = write_out(tmp_path, df)
    build_report(out)
    own = scene_colors(df, SCENE)
    assert set(own) == k_variants and len(set(own.values())) == len(own)
    # the K variants run in this scene only: every colour asked for one of them is the scene's
    asked_for_k = [(s, scene) for s, scene in asked if s in k_variants]
    assert asked_for_k and all(scene == SCENE for _, scene in asked_for_k), sorted(set(asked_for_k))
    html = (out / "report.html").read_text()
    data = re.search(r'<script id="report-data" type="application/json">(.*?)</script>', html, re.S)
    assert data is not None
    (chart,) = [c for c in json.loads(data.group(1))["rowcharts"] if c["scene"] == SCENE]
    assert dict(map(tuple, chart["colors"])) == own  # the page draws the scene in the same colours
