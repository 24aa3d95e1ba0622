"""The constrained sweeps' section says what it shows: its title names every solver (not
"the field's codes"), its caption says what the KKT error counts on that scene (the load
equality on load-sweep, the bound on plastic-sweep), and a solver skipped on every cell is
named with its reason rather than dropped from the table."""

from __future__ import annotations

from pathlib import Path

from contactbench.harness.report.build import write_report
from contactbench.harness.run.plan import RunConfig
from contactbench.harness.run.runner import run_benchmark
from contactbench.problems.scenes import SceneConfig


def section_text(out: Path, scene: str) -> str:
    text = (out / "report.md").read_text()
    start = text.index(f"### Every solver on {scene}")
    return text[start:text.index("\n## ", start)]


def test_load_sweep_names_its_solvers_its_figures_and_what_did_not_run(tmp_path: Path) -> None:
    out = tmp_path / "load"
    run_benchmark(["load-sweep"], SceneConfig(size=16, steps=2), ["pk", "nnls"],
                  RunConfig(reference="none", warmup=False, progress=False), out)
    write_report(out, html=False)
    text = section_text(out, "load-sweep")
    assert "The field's codes" not in (out / "report.md").read_text()
    assert "load equality's residual" in text and "both bounds" not in text
    assert "Not run: `nnls` (" in text and "load control" in text
