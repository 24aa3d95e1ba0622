"""The CMR scenes' PSD check is advice: on a grid too small to fit a power law
(``coarsen.power_law_check``: fewer than 3 bins, or no range between twice the fundamental
and half the Nyquist wave number) the run warns and solves, and the refusal of the check
itself names the range the right way round."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from contactbench.problems.coarsen import power_law_check
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.surfaces import rmd_surface_n
from tests.helpers import run_cli

pytestmark = pytest.mark.usefixtures("in_tmp")


@pytest.mark.parametrize(("scene", "size"), [("cmr-h-sweep", 4), ("cmr-h-sweep", 16), ("cmr-cutoff", 16),
                                             ("cmr", 16)])
def test_a_small_grid_warns_and_solves(scene: str, size: int, in_tmp: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = in_tmp / "out"
    rc, _, err = run_cli(["run", scene, "--size", str(size), "--seeds", "0", "--steps", "1", "--solvers", "pk",
                          "--reference", "none", "--no-progress", "--out", str(out)], capsys)
    assert rc == 0 and "Traceback" not in err, err
    assert (out / "results.csv").exists()
    warned = json.loads((out / "meta.json").read_text())["warnings"]
    assert any("too small for a power-law check" in w for w in warned), warned


def test_the_check_names_an_empty_range_as_such() -> None:
    with pytest.raises(ProblemInputError, match="no range") as caught:
        power_law_check(rmd_surface_n(4, 0.7, length=1e-4, seed=0))
    lo, hi = (float(w.split(" rad/m")[0]) for w in str(caught.value).split("(")[1:3])
    assert lo > hi  # as the message says: no range between them
