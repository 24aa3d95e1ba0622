"""``validate`` keeps what an outside program said when it failed: a crashed row's one-line
message carries the program's stderr tail, as ``run``'s error column does (it kept only the
"exited with code 3" line)."""

from __future__ import annotations

from contactbench.harness.conformance import battery as cf
from contactbench.solvers.external import command_solver
from tests.solvers.test_external import script_command


def test_a_crashed_program_s_stderr_is_in_its_row() -> None:
    table = cf.validate(command_solver(script_command("--variant", "fail")),
                        cf.conformance_cases("fast", ["edge"], "edge/plateau*"))
    (row,) = table.rows
    assert row.status == "crashed" and "exited with code 3" in row.message, row.message
    assert "giving up on purpose" in row.message and "\n" not in row.message, row.message
