"""The solver registry and the shared solver records."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from contactbench.problems.instances import QP
from contactbench.problems.operators import DenseOperator
from contactbench.harness.profiles import PROFILES, get_profile
from contactbench.solvers.base import Capabilities, SolverSettings
from contactbench.solvers.registry import all_solvers, get_solver, load_solver, register, unregister
from tests.helpers import DummySolver


def test_register_and_lookup_roundtrip() -> None:
    register(DummySolver)
    try:
        assert "test-dummy" in all_solvers()
        s = get_solver("test-dummy")
        qp = QP(DenseOperator(np.eye(3)), np.array([1.0, -1.0, 2.0]))
        r = s.solve(qp, SolverSettings())
        np.testing.assert_array_equal(r.p, [1.0, 0.0, 2.0])
    finally:
        unregister("test-dummy")
    assert "test-dummy" not in all_solvers()


def test_unknown_solver_message_lists_known() -> None:
    with pytest.raises(KeyError) as e:
        get_solver("no-such-solver")
    assert "no-such-solver" in str(e.value)


def test_load_solver_by_import_path() -> None:
    s = load_solver("tests.helpers:DummySolver")
    assert isinstance(s, DummySolver)


def test_duplicate_name_of_other_class_is_refused() -> None:
    class Other(DummySolver):
        pass

    register(DummySolver)
    try:
        with pytest.raises(ValueError, match="already registered"):
            register(Other)
    finally:
        unregister("test-dummy")


def test_profiles_and_settings_tolerance() -> None:
    assert get_profile("high").tol == 1e-9 and get_profile("high").check_tol == 1e-8
    with pytest.raises(ValueError, match="unknown profile"):
        get_profile("ultra")
    assert set(PROFILES) == {"default", "low", "mid", "high", "paper"}


def test_every_registered_solver_is_well_formed() -> None:
    for name, s in all_solvers().items():
        assert s.name == name
        assert isinstance(s.capabilities, Capabilities)
        ok, why = s.availability()
        assert isinstance(ok, bool) and why


# ---------------------------------------------------------------------------
# Specs on the command line: lists, name[k=v], modules in the current folder
# ---------------------------------------------------------------------------


def test_split_solver_list_keeps_commas_inside_brackets() -> None:
    from contactbench.solvers.registry import SolverSpecError, split_solver_list

    assert split_solver_list("a, b[k=1,j=2] ,c,,") == ["a", "b[k=1,j=2]", "c"]
    assert split_solver_list("") == [] and split_solver_list(" , ") == []
    for bad in ("a[k=1", "a]k", "a[k=[1]]x]"):
        with pytest.raises(SolverSpecError):
            split_solver_list(bad)


def test_param_from_text_reads_the_declared_type_and_checks_it() -> None:
    from contactbench.solvers.base import Param, ParamError
    from contactbench.solvers.registry import param_from_text

    flag = Param("flag", bool, False)
    assert [param_from_text(flag, t) for t in ("true", "Yes", "on", "1", "false", "NO", "0")] == [
        True, True, True, True, False, False, False]
    k = Param("K", int, 10, low=1, high=100)
    assert param_from_text(k, "50") == 50
    x = Param("x", float, 1.0, low=0.0)
    assert param_from_text(x, "1e-3") == 1e-3
    for p, text in ((flag, "maybe"), (k, "1.5"), (k, "0"), (k, "101"), (x, "inf"), (x, "nan"), (x, "-1"),
                    (Param("m", str, "a", choices=("a", "b")), "c")):
        with pytest.raises(ParamError, match=repr(p.name)):
            param_from_text(p, text)


def test_parse_solver_spec_checks_params_against_the_solver() -> None:
    from contactbench.solvers.base import ParamError
    from contactbench.solvers.registry import SolverSpec, SolverSpecError, parse_solver_spec

    spec, solver = parse_solver_spec("nnls-gp[K=5]")
    assert spec == SolverSpec("nnls-gp", {"K": 5}) and solver.name == "nnls-gp"
    assert spec.label == "nnls-gp[K=5]"
    assert SolverSpec("s", {"b": 1, "a": True}).label == "s[a=True,b=1]"  # keys sorted: one label per variant
    assert SolverSpec("s").label == "s"
    with pytest.raises(ParamError, match="has no parameter 'k'"):
        parse_solver_spec("nnls-gp[k=5]")
    for bad in ("nnls-gp[K]", "nnls-gp[]", "nnls-gp[K=1,K=2]", "[K=1]", "nnls-gp[K=1]x"):
        with pytest.raises(SolverSpecError):
            parse_solver_spec(bad)


def test_a_module_in_the_current_folder_loads(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    (tmp_path / "cwd_only_solver.py").write_text(
        "from tests.helpers import DummySolver\n\nclass Here(DummySolver):\n    name = 'test-here'\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    monkeypatch.delitem(sys.modules, "cwd_only_solver", raising=False)
    assert load_solver("cwd_only_solver:Here").name == "test-here"
    with pytest.raises(ModuleNotFoundError):
        load_solver("no_such_module_anywhere:Here")


def test_did_you_mean_names_only_close_ones() -> None:
    from contactbench.plugins import did_you_mean

    assert did_you_mean("scipy-nnsl", ["scipy-nnls", "pk"]) == " (did you mean 'scipy-nnls'?)"
    assert did_you_mean("zzz", ["scipy-nnls", "pk"]) == ""
    with pytest.raises(KeyError, match=r"unknown solver 'greedy-gc' \(did you mean .*'greedy-cg'"):
        get_solver("greedy-gc")


# ---------------------------------------------------------------------------
# External solvers: the manifest is read when they are resolved, not on import
# ---------------------------------------------------------------------------

#: Run in a folder whose ./contactbench-solvers.toml is broken, with a good manifest named
#: by the environment that is written only after the import and a built-in lookup: an
#: external name then resolves from it (so nothing was read before), and a name the
#: broken manifest should have declared is refused with that manifest's error.
LAZY_MANIFEST_SCRIPT = """
import sys
from pathlib import Path

import contactbench.solvers.registry as registry

assert registry.get_solver("scipy-nnls").name == "scipy-nnls"
Path(sys.argv[1]).write_text('[[solver]]\\nname = "ext-late"\\ncommand = "prog {problem} {solution}"\\n')
assert registry.get_solver("ext-late").family == "external"
try:
    registry.get_solver("ext-broken")
except registry.UnknownSolverError as exc:
    print("REFUSED", exc)
else:
    raise SystemExit("ext-broken resolved from a broken manifest")
print("ERRORS", *registry.import_errors())
print("LISTED", "ext-late" in registry.all_solvers())
"""


def test_a_broken_local_manifest_breaks_no_import_and_is_reported_on_resolution(in_tmp: Path) -> None:
    broken = in_tmp / "contactbench-solvers.toml"
    broken.write_text('[[solver]]\nname = "ext-broken"\ncommand = \n')  # a TOML syntax error
    late = in_tmp / "late.toml"
    env = {**os.environ, "CONTACTBENCH_EXTERNAL_SOLVERS": str(late)}
    proc = subprocess.run([sys.executable, "-c", LAZY_MANIFEST_SCRIPT, str(late)], cwd=in_tmp, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    refused = next(line for line in proc.stdout.splitlines() if line.startswith("REFUSED"))
    assert "unknown solver 'ext-broken'" in refused and str(broken) in refused and "unreadable" in refused
    assert "Traceback" not in refused  # one line: the manifest's own error, not a traceback
    assert "ERRORS contactbench.solvers.external_manifests" in proc.stdout  # what `list solvers` prints
    assert "LISTED True" in proc.stdout
