"""External programs and the constrained families: a manifest that declares
``load_control`` / ``bounds`` is handed format 2 (``upper.f64``, ``"load"``) and its
``"multiplier"`` is read back; one that declares neither is skipped with the reason.
The programs are tiny Python scripts written into tmp_path: an honest one (the certified
reference ``problems.mixed_lcp.constrained_exact_solution`` on what it reads) judged
``pass`` on a 16^2 hardness case and a 16^2 load-controlled case, and one that ignores
the bounds (and the load), judged ``wrong``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from contactbench.harness.judging import judge
from contactbench.harness.run.skips import capability_decision
from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import InstanceBuilder, paper_max_displacement
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.surfaces import fourier_synthesis
from contactbench.solvers.base import ProblemTraits, SolverSettings
from contactbench.solvers.external import ExternalSolver, load_manifest

E = 1e9
CHECK_TOL = 1e-8
P_TOL = 1e-6

PROGRAM = '''
import json, sys
from pathlib import Path
import numpy as np
from contactbench.problems.constraints import Constraints
from contactbench.problems.lcp import exact_solution
from contactbench.problems.mixed_lcp import constrained_exact_solution
from contactbench.problems.qpfile import read_problem_dir

problem, solution, mode = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
pf = read_problem_dir(problem)
doc = json.loads((problem / "problem.json").read_text())
report = {"status": "converged", "iterations": 1, "format": doc["format"], "load": doc.get("load"),
          "has_upper": pf.upper is not None}
if mode == "honest":
    sol = constrained_exact_solution(pf.H, pf.ubar, pf.constraints())
    p = sol.p
    if pf.load is not None:
        report["multiplier"] = sol.multiplier
else:  # ignores the bounds and the load: the plain displacement-controlled answer
    p = exact_solution(pf.H, pf.ubar).p
np.asarray(p, dtype="<f8").tofile(solution / "p.f64")
protocol = ("iterations", "status", "time_s", "multiplier")  # (what solution.json may hold)
(solution / "solution.json").write_text(json.dumps({k: v for k, v in report.items() if k in protocol}))
(Path(sys.argv[4]) / "seen.json").write_text(json.dumps(report))
'''


def write_program(tmp_path: Path) -> Path:
    path = tmp_path / "constrained_program.py"
    path.write_text(PROGRAM)
    return path


def manifest_solver(tmp_path: Path, name: str, mode: str, **flags: bool) -> ExternalSolver:
    prog = write_program(tmp_path)
    lines = ["[[solver]]", f'name = "{name}"',
             f'command = "{sys.executable} {prog} {{problem}} {{solution}} {mode} {tmp_path}"', 'inputs = "dense"']
    lines += [f"{k} = {'true' if v else 'false'}" for k, v in flags.items()]
    m = tmp_path / f"{name}.toml"
    m.write_text("\n".join(lines) + "\n")
    (spec,) = load_manifest(m)
    return ExternalSolver(spec)


@pytest.fixture(scope="module")
def cases() -> dict[str, object]:
    """16^2 BCC: a hardness case (0.05 E*: a share of the contact plastic) under
    displacement control, and a load-controlled case at the load of the top step."""
    b = InstanceBuilder(fourier_synthesis(16, 0.8, 0.1, length=1e-4, seed=3), E, operator="dense")
    top = paper_max_displacement(b.surface)
    hard = b.build(top, hardness=0.05 * E)
    plain = b.build(top)
    load = b.build_load(float(np.sum(exact_solution(plain.qp.H.to_dense(), plain.qp.ubar).p)))
    return {"hardness": hard, "load": load}


def reference_p(inst) -> np.ndarray:
    return constrained_exact_solution(inst.qp.H.to_dense(), np.asarray(inst.qp.ubar), inst.qp.constraints).p


def traits_of(inst) -> ProblemTraits:
    c = inst.qp.constraints
    return ProblemTraits(n=inst.n, operator="dense", kernel=inst.kernel, load_control=c.load_control,
                         bounded=c.bounded)


@pytest.mark.parametrize("case", ["hardness", "load"])
def test_a_declaring_program_gets_the_fields_and_passes(tmp_path: Path, cases, case: str) -> None:
    inst = cases[case]
    solver = manifest_solver(tmp_path, "ext-constrained", "honest", load_control=True, bounds=True)
    assert solver.capabilities.load_control and solver.capabilities.bounds
    assert capability_decision(solver, traits_of(inst), 1e12).operator == "dense"
    r = solver.solve(inst.qp, SolverSettings(tol=1e-10, time_limit=120.0))
    seen = json.loads((tmp_path / "seen.json").read_text())
    assert seen["format"] == "contactbench-qp/2"
    if case == "hardness":
        assert seen["has_upper"] and seen["load"] is None
        assert np.any(inst.plastic_mask(r.p, CHECK_TOL))
    else:
        assert not seen["has_upper"] and seen["load"] == pytest.approx(inst.qp.constraints.load, rel=1e-15)
        assert r.multiplier == pytest.approx(seen["multiplier"], rel=1e-15)  # read back, not fitted
    v = judge(inst, r.p, r.converged, CHECK_TOL, p_ref=reference_p(inst), p_tol=P_TOL)
    assert v.reading == "pass", v.problems


@pytest.mark.parametrize("case", ["hardness", "load"])
def test_a_program_that_ignores_the_constraints_is_judged_wrong(tmp_path: Path, cases, case: str) -> None:
    """It declares both, is handed both, answers the plain problem and claims convergence."""
    inst = cases[case]
    solver = manifest_solver(tmp_path, "ext-liar", "ignore", load_control=True, bounds=True)
    r = solver.solve(inst.qp, SolverSettings(tol=1e-10, time_limit=120.0))
    assert r.converged
    v = judge(inst, r.p, r.converged, CHECK_TOL, p_ref=reference_p(inst), p_tol=P_TOL)
    assert v.reading == "wrong" and v.status == "inaccurate", (v.status, v.problems)


@pytest.mark.parametrize("case,flags,words", [
    ("hardness", {}, "cannot pose bounded pressures"),
    ("load", {}, "cannot pose load control"),
    ("load", {"bounds": True}, "cannot pose load control"),
    ("hardness", {"load_control": True}, "cannot pose bounded pressures"),
])
def test_a_program_that_does_not_declare_them_is_skipped_with_the_reason(tmp_path: Path, cases, case: str,
                                                                           flags: dict[str, bool], words: str) -> None:
    inst = cases[case]
    solver = manifest_solver(tmp_path, "ext-plain", "honest", **flags)
    d = capability_decision(solver, traits_of(inst), 1e12)
    assert d.skip and words in d.reason and "ext-plain" in d.reason
    with pytest.raises(ProblemInputError, match=words):
        solver.solve(inst.qp, SolverSettings(tol=1e-10, time_limit=120.0))
    assert not (tmp_path / "seen.json").exists()  # the program never ran


def test_the_new_keys_must_be_true_or_false(tmp_path: Path) -> None:
    m = tmp_path / "bad.toml"
    m.write_text('[[solver]]\nname = "x"\ncommand = "prog {problem} {solution}"\nload_control = "yes"\n')
    with pytest.raises(ProblemInputError, match="'load_control' must be true or false"):
        load_manifest(m)
