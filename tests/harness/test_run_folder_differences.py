"""A refused resume names what differs, not whole settings: two solver lists that differ by
one solver are named by that solver (a folder of 54 solvers against a run of 43 printed a
2,000-character line)."""

from __future__ import annotations

from contactbench.harness.table.store import differences


def test_two_lists_are_named_by_what_only_one_holds() -> None:
    many = [f"solver-{k:02d}" for k in range(50)]
    (line,) = differences({"solvers": many}, {"solvers": [*many[:-1], "mine"]})
    assert line == 'solvers: only in the folder "solver-49"; only in this run "mine"'
    (fewer,) = differences({"solvers": many}, {"solvers": many[:40]})
    assert fewer.startswith('solvers: only in the folder "solver-40", ') and "this run" not in fewer


def test_a_value_is_named_on_both_sides() -> None:
    assert differences({"run": {"timeout": 60.0}}, {"run": {"timeout": 5.0}}) == [
        "run.timeout: 60.0 in the folder, 5.0 in this run"]
    assert differences({}, {"solvers": ["a"]}) == ['solvers: "(unset)" in the folder, ["a"] in this run']
