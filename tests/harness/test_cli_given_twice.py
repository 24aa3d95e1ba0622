"""An option that takes one value, given twice, is refused in one line with exit 2 before
anything runs (argparse alone would keep the last silently: ``--size 8 --size 16`` ran 16),
by either spelling; a repeatable option (``validate --group``) is not; a scene named twice
is refused by the plan (``harness.arguments.given_twice``, ``plan.plan_run``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness import cli
from contactbench.harness.arguments import Parser, given_twice
from contactbench.harness.run.plan import PlanError, plan_run

RUN = ["run", "paper-sweep", "--steps", "2", "--solvers", "pk", "--reference", "none", "--no-progress"]


@pytest.mark.parametrize("twice", [["--size", "8", "--size", "16"], ["--size=8", "--size", "16"],
                                   ["--solvers", "nnls"], ["--timeout", "5", "--timeout=9"],
                                   ["--size", "8", "--siz", "17"], ["--size=8", "--siz=16"]])
def test_a_one_value_option_given_twice_is_one_line_exit_2_and_writes_nothing(
        twice: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as ended:
        cli.main([*RUN, *twice, "--out", str(out)])
    err = capsys.readouterr().err
    assert ended.value.code == 2 and err.count("\n") == 1 and "given twice" in err, err
    assert twice[0].split("=")[0] in err and not out.exists()


def test_repeatable_options_and_values_that_look_alike_are_not_refused() -> None:
    ap = Parser(prog="t")
    ap.add_argument("--group", action="append")
    ap.add_argument("--size", type=int)
    ap.add_argument("-v", action="count", default=0)
    assert given_twice(ap, ["--group", "a", "--group", "b", "-v", "-v", "--size", "1"]) is None
    assert given_twice(ap, ["--size", "1", "--", "--size", "2"]) is None  # (after "--": values)
    assert given_twice(ap, ["--size", "1", "--size=2"]) == "--size"
    assert given_twice(ap, ["--size", "1", "--siz=2"]) == "--siz (as --size)"  # (a prefix argparse takes)
    assert given_twice(ap, ["--s", "1", "--size", "2"]) == "--size (as --s)"
    ap.add_argument("--seed", type=int)
    assert given_twice(ap, ["--s", "1", "--size", "2"]) is None  # (now ambiguous: argparse's own error)
    ns = ap.parse_args(["--group", "a", "--group", "b", "-vv"])
    assert ns.group == ["a", "b"] and ns.v == 2


def test_a_scene_named_twice_is_refused_by_the_plan() -> None:
    with pytest.raises(PlanError, match="scene 'hertz' named twice"):
        plan_run(["hertz", "hertz"])
