"""A registered solver (an in-package module's, an entry point's) whose ``availability()``
raises is a defect of that solver (``harness.run.skips.checked_availability``): its rows fail
naming it, the other solvers' rows are all there, ``list solvers`` says so on its line, and
``validate`` refuses it in one line -- never a traceback from the plan or the listing."""

from __future__ import annotations

from pathlib import Path

import pytest

from contactbench.harness import cli
from contactbench.harness.table.store import load_table
from contactbench.solvers import register, unregister
from contactbench.solvers.registry import get_solver

PK = type(get_solver("pk"))


class BrokenAvailability(PK):  # type: ignore[misc, valid-type]
    name = "test-broken-availability"

    def availability(self) -> tuple[bool, str]:
        raise RuntimeError("a bug in availability")


@pytest.fixture
def broken() -> object:
    register(BrokenAvailability, replace=True)
    yield
    unregister(BrokenAvailability.name)


@pytest.mark.usefixtures("broken")
def test_run_fails_the_rows_of_a_solver_whose_availability_raises(tmp_path: Path) -> None:
    out = tmp_path / "o"
    code = cli.main(["run", "paper-sweep", "--size", "8", "--steps", "2", "--solvers", f"{BrokenAvailability.name},pk",
                     "--out", str(out)])
    df = load_table(out)
    assert code == 0 and set(df[df.solver == "pk"]["status"]) == {"solved"}
    broken_rows = df[df.solver == BrokenAvailability.name]
    assert len(broken_rows) == 2 and set(broken_rows["status"]) == {"failed"}
    assert broken_rows["error"].str.contains("its availability() failed: RuntimeError: a bug in availability",
                                              regex=False).all()


@pytest.mark.usefixtures("broken")
def test_list_and_validate_name_an_availability_that_raises(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["list", "solvers"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith(BrokenAvailability.name))
    assert "no (its availability() failed: RuntimeError: a bug in availability)" in line
    assert cli.main(["validate", BrokenAvailability.name, "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "its availability() failed: RuntimeError: a bug in availability" in err[0]
