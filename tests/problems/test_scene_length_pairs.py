"""A generated surface is square: every scene that generates one reads its ``--length``
through ``scenes.core.square_length``, so a pair L0,L1 (for a surface file) is refused in
one line, exit 2, at planning, for ``run`` and ``export``, and nothing is written."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.scenes.core import square_length
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")

PAIR = "1e-4,2e-4"
REFUSAL = "a generated surface is square: give one length"


def one_line(err: str) -> str:
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("scene", ["hertz", "flat-punch", "cmr-cutoff", "paper-sweep", "population"])
def test_run_refuses_a_length_pair_on_a_generated_surface(scene: str, in_tmp: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = in_tmp / "out"
    rc, _, err = run_cli(["run", scene, "--size", "16", "--steps", "1", "--solvers", "pk", "--length", PAIR,
                          "--reference", "none", "--no-progress", "--out", str(out)], capsys)
    assert rc == 2 and REFUSAL in one_line(err) and scene in err
    assert not out.exists()


@pytest.mark.parametrize("scene", ["cmr-cutoff", "hertz", "flat-punch"])
def test_export_refuses_a_length_pair_on_a_generated_surface(scene: str, in_tmp: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = in_tmp / "x"
    rc, _, err = run_cli(["export", scene, "--size", "16", "--length", PAIR, "--format", "problem-dir",
                          "--out", str(out)], capsys)
    assert rc == 2 and REFUSAL in one_line(err)
    assert not out.exists()


def test_square_length_takes_one_length_and_refuses_a_pair() -> None:
    assert square_length(2e-3) == 2e-3
    for pair in ((1e-4, 2e-4), [1e-4, 2e-4]):
        with pytest.raises(ProblemInputError, match=REFUSAL):
            square_length(pair)
