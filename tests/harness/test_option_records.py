"""The scene options' one table (problems/scenes/options.py) and the refusals derived from it.

Every rule of every record gets an input that triggers it and one that passes; the API
(``run_benchmark``) raises ``ProblemInputError`` with the same line the command line
prints with exit 2, and neither writes anything.  Then the probes of the options'
paths: a load-sweep's ``--steps`` and ``--loads``, ``--nu``'s rule, plausibility and its
override, a plan whose every cell the solvers' models reject, and ``export --out``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from contactbench.harness.cli import main
from contactbench.harness.run.plan import PlanError, RunConfig, option_problems, plan_run
from contactbench.harness.run.runner import run_benchmark
from contactbench.harness.table.store import load_table
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes import SceneConfig, get_scene
from contactbench.problems.scenes.options import (ALLOW_IMPLAUSIBLE, BY_NAME, CONFIG_FIELDS, OPTIONS, OptionRecord,
                                                  Range)

pytestmark = pytest.mark.usefixtures("in_tmp")

#: A value of each option that passes every rule of its record.
GOOD: dict[str, Any] = {
    "size": 16, "steps": 2, "seeds": (0, 3), "surface_path": "s.npy", "length": 1e-4, "E": 1e9, "kernel": "bcc",
    "periodic": True, "operator": "fft", "channel": "0", "height_unit": "um", "allow_steep": True,
    "family": "saupe", "detrend": "none", "nan": "error", "crop": "square", "thickness": 1e-5, "nu": 0.45,
    "interface": "frictionless", "control": "load", "loads": (0.001, 0.002), "hardness": 3e8,
    "allow_any_E": True, ALLOW_IMPLAUSIBLE: True}
#: What an option needs beside it to pass (its records' ``requires``).
CONTEXT: dict[str, dict[str, Any]] = {
    **{k: {"surface_path": "s.npy"} for k in ("channel", "height_unit", "allow_steep", "detrend", "nan", "crop")},
    "nu": {"thickness": 1e-5}, "interface": {"thickness": 1e-5}, "control": {"loads": (0.001, 0.002)},
    "loads": {"control": "load"}}


def config(options: dict[str, Any]) -> SceneConfig:
    """The API's SceneConfig of ``options`` (record names)."""
    return SceneConfig(**{k: v for k, v in options.items() if k in CONFIG_FIELDS},
                       extra={k: v for k, v in options.items() if k not in CONFIG_FIELDS})


def argv(options: dict[str, Any]) -> list[str]:
    """The command line's flags of ``options``."""
    out: list[str] = []
    for name, value in options.items():
        rec = BY_NAME[name]
        if rec.kind == "switch":
            out += [rec.flag] if value else []
        elif isinstance(value, (tuple, list)):
            out += [rec.flag, ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)]
        else:
            out += [rec.flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return out


@dataclass(frozen=True)
class Case:
    """One rule of one record: ``bad`` triggers it, ``good`` passes; ``same_line``: the
    command line prints the API's line (else argparse refuses the text itself)."""

    rule: str
    bad: dict[str, Any]
    good: dict[str, Any]
    scene: str = "paper-sweep"
    good_scene: str = ""
    needle: str = ""
    same_line: bool = True


def outside(r: Range) -> float:
    """A number just outside range ``r`` (below it)."""
    return r.lo if r.lo_open else r.lo - 1.0


def value_cases(rec: OptionRecord) -> list[Case]:
    """The cases of a record's value rules: type, choices, hard range, order, plausibility."""
    ctx, good = CONTEXT.get(rec.name, {}), {rec.name: GOOD[rec.name], **CONTEXT.get(rec.name, {})}
    many = rec.kind == "floats"
    cases = []
    if rec.kind in ("int", "float", "floats", "length"):
        cases.append(Case(f"{rec.name}:type", {rec.name: "abc", **ctx}, good, needle=rec.flag, same_line=False))
    if rec.kind == "choice":
        cases.append(Case(f"{rec.name}:choice", {rec.name: "nonesuch", **ctx}, good, needle="nonesuch",
                          same_line=False))
    if rec.kind == "seeds":
        cases.append(Case(f"{rec.name}:type", {rec.name: (-1,), **ctx}, good, needle=rec.flag, same_line=False))
    if rec.valid is not None:
        x = outside(rec.valid)
        cases.append(Case(f"{rec.name}:valid", {rec.name: (x,) if many else x, **ctx}, good, needle=rec.valid.text()))
        if not np.isinf(rec.valid.hi):
            y = rec.valid.hi + 0.2
            cases.append(Case(f"{rec.name}:valid-hi", {rec.name: y, **ctx}, good, needle=rec.valid.text()))
    if rec.increasing:
        cases.append(Case(f"{rec.name}:increasing", {rec.name: (0.002, 0.001), **ctx}, good, needle="increasing"))
    if rec.plausible is not None:
        lo, hi = rec.plausible.lo / 10, rec.plausible.hi * 10
        for side, x in (("lo", lo), ("hi", hi)):
            bad = {rec.name: (x,) if many else x, **ctx}
            allowed = {**bad, ALLOW_IMPLAUSIBLE: True}  # the override passes it
            cases.append(Case(f"{rec.name}:plausible-{side}", bad, allowed, needle="plausible range"))
        if rec.allowed_by:
            bad = {rec.name: lo, **ctx}
            cases.append(Case(f"{rec.name}:{rec.allowed_by}", bad, {**bad, rec.allowed_by: True},
                              needle=BY_NAME[rec.allowed_by].flag))
    return cases


def scene_cases(rec: OptionRecord) -> list[Case]:
    """The cases of a record's rules against scenes: read, generated-only, requires, excludes."""
    good = {rec.name: GOOD[rec.name], **CONTEXT.get(rec.name, {})}
    cases = []
    if not rec.universal:
        cases.append(Case(f"{rec.name}:read", {rec.name: GOOD[rec.name]}, good, scene="stress-edge",
                          good_scene="paper-sweep",
                          needle="does not take"))
    if rec.generated_only:
        cases.append(Case(f"{rec.name}:generated-only", {**good, "surface_path": "s.npy"}, good,
                          needle="does not apply with --surface"))
    for req in rec.requires:
        bad = {rec.name: GOOD[rec.name]} if req.when is None else {rec.name: req.when}
        cases.append(Case(f"{rec.name}:requires-{req.keys[0]}", bad, good, needle=req.why))
    for other in rec.excludes:
        both = {**good, other: GOOD[other], **CONTEXT.get(other, {})}
        cases.append(Case(f"{rec.name}:excludes-{other}", both, {k: v for k, v in both.items() if k != rec.name},
                          needle="exclude each other"))
    return cases


CASES = [c for rec in OPTIONS for c in value_cases(rec) + scene_cases(rec)]


def test_every_record_has_each_of_its_rules_cased() -> None:
    rules = {c.rule.split(":", 1)[0] for c in CASES}
    assert rules == {r.name for r in OPTIONS} - {"allow_any_E", ALLOW_IMPLAUSIBLE} | {"E"}
    for rec in OPTIONS:
        mine = {c.rule for c in CASES if c.rule.startswith(rec.name + ":")}
        assert (rec.valid is None) or f"{rec.name}:valid" in mine
        assert (rec.plausible is None) or {f"{rec.name}:plausible-lo", f"{rec.name}:plausible-hi"} <= mine
        assert len([r for r in mine if ":requires-" in r]) == len(rec.requires)
        assert rec.universal or f"{rec.name}:read" in mine


def cli_line(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        rc = main(args)
    except SystemExit as exc:
        rc = int(exc.code or 0)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return rc, lines[0]


@pytest.mark.parametrize("case", CASES, ids=[c.rule for c in CASES])
def test_the_api_and_the_command_line_refuse_each_rule_alike(case: Case, in_tmp: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ProblemInputError) as caught:
        run_benchmark([case.scene], config(case.bad), ["pk"], RunConfig(progress=False), in_tmp / "api")
    message = str(caught.value)
    assert "\n" not in message and case.needle in message, message
    rc, line = cli_line(["run", case.scene, *argv(case.bad), "--solvers", "pk", "--out", "cli"], capsys)
    assert rc == 2
    if case.same_line:
        assert line == f"contactbench: error: {message}"
    else:
        assert BY_NAME[case.rule.split(":")[0]].flag in line or case.needle in line, line
    assert sorted(p.name for p in in_tmp.iterdir()) == []  # neither wrote anything
    assert option_problems([case.good_scene or case.scene], config(case.good)) == []


def test_the_pytest_plugin_and_a_dask_run_refuse_as_the_command_line(run_harness: Any, in_tmp: Path) -> None:
    from contactbench.harness.run.distributed import run_benchmark_on_dask

    bad = SceneConfig(size=16, extra={"thickness": 1e-5, "nu": 0.7})
    with pytest.raises(ProblemInputError, match=r"^--nu must be in \(-1, 0.5\] \(Poisson's ratio\), got 0.7$"):
        run_harness(["paper-sweep"], solvers=["pk"], size=16, extra=dict(bad.extra))
    with pytest.raises(ProblemInputError, match=r"^--nu must be in \(-1, 0.5\]"):  # before any scheduler is asked
        run_benchmark_on_dask(["paper-sweep"], bad, ["pk"], RunConfig(progress=False), in_tmp / "dask",
                              scheduler="tcp://127.0.0.1:9")
    assert not (in_tmp / "dask").exists()


# ---------------------------------------------------------------------------
# The probes of the options' paths
# ---------------------------------------------------------------------------


def test_a_load_sweep_runs_the_steps_it_is_given_and_records_them(in_tmp: Path) -> None:
    cfg = SceneConfig(size=16, steps=3)
    run_benchmark(["load-sweep"], cfg, ["bvls"], RunConfig(progress=False, reference="none"), in_tmp / "o")
    table = load_table(in_tmp / "o")
    assert sorted(set(table["step"])) == [0, 1, 2]
    meta = json.loads((in_tmp / "o" / "meta.json").read_text())
    assert meta["config"]["scene_config"]["steps"] == 3
    jobs = plan_run(["load-sweep"], cfg, ["bvls"]).jobs
    assert jobs[0].spec.params["loads"] == pytest.approx([4e-3 / 3, 8e-3 / 3, 4e-3], rel=1e-11)
    default = plan_run(["load-sweep"], SceneConfig(size=16), ["bvls"]).jobs[0].spec.params["loads"]
    assert default == pytest.approx([4e-4 * k for k in range(1, 11)], rel=1e-12)


def test_a_load_sweep_takes_loads_without_control_and_refuses_them_with_steps(capsys: pytest.CaptureFixture[str]) -> None:
    jobs = plan_run(["load-sweep"], SceneConfig(size=16, extra={"loads": (0.001, 0.002)}), ["bvls"]).jobs
    assert jobs[0].steps_hint == 2 and jobs[0].spec.params["loads"] == (0.001, 0.002)
    rc, line = cli_line(["run", "load-sweep", "--steps", "3", "--loads", "0.001", "--out", "o"], capsys)
    assert rc == 2 and "--steps and --loads exclude each other" in line


@pytest.mark.parametrize("over", [1.0 - 1e-6, 1.0 + 1e-6])
def test_a_load_beyond_what_the_hardness_carries_is_refused_before_anything_runs(
        over: float, in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The plan refuses a load P/(E* A) over H_A/E* from the options, exactly where the
    step's own build (``Constraints.check``) would refuse it mid-run."""
    hardness, E = 5e6, 1e9
    loads = (0.001, over * hardness / E)
    cfg = SceneConfig(size=17, E=E, extra={"control": "load", "loads": loads, "hardness": hardness})
    args = ["run", "paper-sweep", "--size", "17", "--E", f"{E:g}", "--control", "load", "--loads",
            ",".join(f"{x!r}" for x in loads), "--hardness", f"{hardness:g}", "--solvers", "bvls", "--out", "o"]
    if over < 1.0:
        (job,) = plan_run(["paper-sweep"], cfg, ["bvls"]).jobs
        assert job.spec.build().at(1).qp.constraints.load > 0.0
        return
    with pytest.raises(ProblemInputError, match="exceeds what --hardness 5e\\+06 Pa can carry"):
        plan_run(["paper-sweep"], cfg, ["bvls"])
    (spec,) = get_scene("paper-sweep").instances(get_scene("paper-sweep").config(cfg))
    with pytest.raises(ProblemInputError, match="exceeds what the bounds can carry"):
        spec.build().at(1)
    rc, line = cli_line(args, capsys)
    assert rc == 2 and "--loads: the load P/(E* A)" in line and "\n" not in line
    assert not (in_tmp / "o").exists()


def test_nu_states_its_rule(capsys: pytest.CaptureFixture[str]) -> None:
    rc, line = cli_line(["run", "paper-sweep", "--thickness", "1e-5", "--nu", "0.7", "--out", "o"], capsys)
    assert rc == 2 and "--nu must be in (-1, 0.5]" in line and "got 0.7" in line


@pytest.mark.parametrize(("args", "options"), [
    (["--control", "load", "--loads", "0.001,1e6"], {"control": "load", "loads": (0.001, 1e6)}),
    (["--hardness", "1e-30"], {"hardness": 1e-30})], ids=["loads", "hardness"])
def test_absurd_values_are_refused_unless_allowed(args: list[str], options: dict[str, Any],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    rc, line = cli_line(["run", "paper-sweep", *args, "--out", "o"], capsys)
    assert rc == 2 and "plausible range" in line and "--allow-implausible" in line
    assert option_problems(["paper-sweep"], config(options)) == [line.removeprefix("contactbench: error: ")]
    assert option_problems(["paper-sweep"], config({**options, ALLOW_IMPLAUSIBLE: True})) == []


def test_a_plan_whose_every_cell_the_models_reject_is_refused(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = RunConfig(progress=False, timeout=1e-6)
    with pytest.raises(PlanError, match="every cell would be skipped: pk: predicted solve time"):
        plan_run(["paper-sweep"], SceneConfig(size=16, steps=2), ["pk"], run)
    rc, line = cli_line(["run", "paper-sweep", "--size", "16", "--steps", "2", "--solvers", "pk", "--timeout", "1e-6",
                         "--out", "o"], capsys)
    assert rc == 2 and "every cell would be skipped" in line
    assert not (in_tmp / "o").exists()
    assert plan_run(["paper-sweep"], SceneConfig(size=16, steps=2), ["pk"]).jobs  # at the default limit it runs


def test_export_refuses_a_foreign_folder_as_run_does(in_tmp: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (in_tmp / "mine").mkdir()
    (in_tmp / "mine" / "notes.txt").write_text("keep")
    args = ["export", "counterexample", "--size", "5", "--seeds", "0", "--format", "problem-dir", "--out"]
    for command in (["run", "counterexample", "--size", "5", "--seeds", "0", "--solvers", "pk", "--out"], args):
        rc, line = cli_line([*command, "mine"], capsys)
        assert rc == 2 and "is not empty and is not a contactbench" in line, line
    assert [p.name for p in (in_tmp / "mine").iterdir()] == ["notes.txt"]
    assert main([*args, "fresh"]) == 0 and main([*args, "fresh"]) == 0  # its own folder is written over
    capsys.readouterr()


def test_list_options_prints_the_table_with_the_scenes_that_read_each(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "options"]) == 0
    out = capsys.readouterr().out.splitlines()
    flags = [line.split()[0] for line in out[::2]]
    assert flags == [r.flag for r in OPTIONS]
    readers = dict(zip(flags, (line.split("read by: ")[1].split(", ") for line in out[1::2])))
    assert "paper-sweep" in readers["--thickness"] and "layer-sweep" not in readers["--thickness"]
    assert "layer-sweep" in readers["--nu"] and "cmr" not in readers["--hardness"]
    assert readers["--allow-implausible"] == ["every scene"]


def test_a_lazy_seed_range_is_checked_without_expanding_it() -> None:
    huge = range(10**12)  # (a list of it would not fit in memory)
    assert option_problems(["paper-sweep"], SceneConfig(seeds=huge)) == []  # type: ignore[arg-type]
    assert option_problems(["paper-sweep"], SceneConfig(seeds=range(0)))  # type: ignore[arg-type]
    with pytest.raises(PlanError, match="--max-cells"):
        plan_run(["paper-sweep"], SceneConfig(size=16, seeds=huge), ["pk"])  # type: ignore[arg-type]


@pytest.mark.parametrize("seeds", [(2**63,), range(2**63, 2**63 + 1), range(0, 10**20), (0, 10**20)])
def test_a_seed_the_table_cannot_store_is_refused_before_anything_runs(seeds: object) -> None:
    """Seeds are stored in the table's Int64 column: one above 2^63 - 1 is refused in one
    line before anything runs (else every cell is solved and the table cannot be written,
    nor the folder read again); a range longer than a machine integer is sized without len()."""
    problems = option_problems(["paper-sweep"], SceneConfig(seeds=seeds))  # type: ignore[arg-type]
    assert len(problems) == 1 and "--seeds takes integers from 0 to 9223372036854775807" in problems[0]
    assert option_problems(["paper-sweep"], SceneConfig(seeds=(2**63 - 1,))) == []  # type: ignore[arg-type]
