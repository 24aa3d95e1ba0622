"""pytest plugin ``contactbench`` (entry point pytest11), loaded in every pytest session
of an environment where the package is installed -- so it imports nothing heavy at
module level.

Fixtures
--------
``contact_instance``  factory: ``contact_instance("rmd", N=32, step=-1)`` or
                      ``contact_instance("counterexample", n=100, seed=1)`` -> ContactInstance.
``contactbench_conformance``  assert_conforms(solver): the conformance battery in a test.
``contactbench_settle``  ``settle(verdict, what, solver_message)``: a pytest outcome from
                      the judge's verdict, the rule pytest-benchmark runs use (below).
``run_harness``       factory: run the harness into a temporary directory and return the
                      tidy table (pandas DataFrame), e.g.
                      ``run_harness(["paper-sweep"], solvers=["nnls"], size=16, steps=2)``;
                      a measured surface's ``height_unit`` / ``allow_steep`` go in
                      ``extra={"height_unit": "um"}``.  The options are checked by the
                      plan, as on the command line (``problems.scenes.options``): a
                      refused one raises ``ProblemInputError`` with the CLI's message.
"""

from __future__ import annotations

from typing import Any, Callable

import pytest


def settle(verdict: Any, what: str, solver_message: str = "") -> None:
    """The pytest outcome of a judged answer (``harness.judging.Verdict``), as in
    ``contactbench validate``: reading "wrong" (a failing answer claimed as converged,
    no answer claimed as one, or a solver that wrote into its problem) fails the test;
    "unconverged" (the solver said it did not converge) is an xfail; "pass" returns."""
    figures = ", ".join(f"{k} {float(verdict.figures[k]):.3e}" for k in
                        ("kkt_error", "primal_residual", "dual_residual", "complementarity", "p_rel_error",
                         "load_rel_error") if k in verdict.figures) or f"kkt_error {verdict.kkt_error:.3e}"
    if verdict.reading == "wrong":
        who = "the solver claims convergence but" if verdict.claimed else "the solver wrote into its problem:"
        pytest.fail(f"{what}: {who} the judge reads the answer as wrong: {verdict.message()}; KKT figures: {figures}",
                    pytrace=False)
    if verdict.reading == "unconverged":
        pytest.xfail(f"{what}: not converged, as the solver says ({solver_message or 'no message'}): "
                     f"{'; '.join(verdict.problems)}; KKT figures: {figures}")


@pytest.fixture
def contactbench_settle() -> Callable[..., None]:
    """``settle(verdict, what, solver_message)`` (module function ``settle``)."""
    return settle


@pytest.fixture
def contact_instance() -> Callable[..., Any]:
    def make(kind: str = "rmd", **kw: Any) -> Any:
        if kind == "counterexample":
            from contactbench.problems.instances import counterexample

            return counterexample(int(kw.get("n", 100)), int(kw.get("seed", 0)), operator=kw.get("operator", "dense"))
        if kind == "rmd":
            from contactbench.problems.scenes import SceneConfig, get_scene

            scene = get_scene("paper-sweep")
            cfg = scene.config(SceneConfig(size=int(kw.get("N", 32)), steps=int(kw.get("steps", 3)),
                                           seeds=(int(kw.get("seed", 0)),), operator=kw.get("operator")))
            seq = scene.build(scene.instances(cfg)[0])
            return seq.at(int(kw.get("step", -1)) % len(seq))
        raise ValueError(f"unknown instance kind {kind!r}: use 'rmd' or 'counterexample'")

    return make


@pytest.fixture
def run_harness(tmp_path: Any) -> Callable[..., Any]:
    def run(scenes: list[str], solvers: Any = None, out: Any = None, **options: Any) -> Any:
        from contactbench.harness.run.plan import RunConfig
        from contactbench.harness.run.runner import run_benchmark
        from contactbench.harness.table.store import RunLock, load_table
        from contactbench.problems.scenes import SceneConfig
        from contactbench.problems.scenes.options import CONFIG_FIELDS

        scene_keys = CONFIG_FIELDS | {"extra"}  # the rest is the RunConfig's; run_benchmark's plan checks both
        cfg = SceneConfig(**{k: v for k, v in options.items() if k in scene_keys})
        run_cfg = RunConfig(progress=False, **{k: v for k, v in options.items() if k not in scene_keys})
        out_dir = out or tmp_path / "run"
        with RunLock(out_dir):  # one writer per results folder, as `contactbench run`
            run_benchmark(scenes, cfg, solvers, run_cfg, out_dir, command=["pytest"])
        return load_table(out_dir)

    return run


@pytest.fixture
def contactbench_conformance() -> Callable[..., Any]:
    """``contactbench_conformance(solver)`` runs the conformance battery (fast subset) on a
    solver (instance, registry name or ``module:NAME``) and fails the test on a wrong
    answer claimed as converged.  See docs/adding-a-solver.md."""
    from contactbench.harness.conformance.battery import assert_conforms

    return assert_conforms
