"""pytest plugin ``contactbench`` (entry point pytest11), loaded in every pytest session
of an environment where the package is installed -- so it imports nothing heavy at
module level.

Fixtures
--------
``contact_instance``  factory: ``contact_instance("rmd", N=32, step=-1)`` or
                      ``contact_instance("counterexample", n=100, seed=1)`` -> ContactInstance;
                      an unknown keyword or a step outside the sequence is refused.
``contactbench_conformance``  assert_conforms(solver): the conformance battery in a test.
``case_conforms``     (a function) one case of the battery in a test, for a test
                      parametrized over ``conformance_cases()`` (``ids=str``).
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

import operator
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


#: The keywords ``contact_instance`` takes for each kind, with their defaults.
INSTANCE_KEYWORDS: dict[str, dict[str, Any]] = {
    "rmd": {"N": 32, "steps": 3, "seed": 0, "step": -1, "operator": None},
    "counterexample": {"n": 100, "seed": 0, "operator": "dense"},
}


def instance_options(kind: str, kw: dict[str, Any]) -> dict[str, Any]:
    """The keywords of ``contact_instance(kind, **kw)`` with the defaults filled in;
    ``ValueError`` for an unknown kind, ``ProblemInputError`` naming any keyword the kind
    does not take (a typo never silently runs the default)."""
    from contactbench.problems.errors import ProblemInputError

    if kind not in INSTANCE_KEYWORDS:
        raise ValueError(f"unknown instance kind {kind!r}: use 'rmd' or 'counterexample'")
    known = INSTANCE_KEYWORDS[kind]
    unknown = sorted(set(kw) - set(known))
    if unknown:
        raise ProblemInputError(f"contact_instance({kind!r}): unknown keyword(s) {', '.join(unknown)}; "
                                f"it takes {', '.join(known)}")
    return {**known, **kw}


def step_index(step: Any, steps: int) -> int:
    """Load step ``step`` of a sequence of ``steps`` as an index in [0, steps): an integer
    in [-steps, steps), negative ones counted from the end; ``ProblemInputError`` else."""
    from contactbench.problems.errors import ProblemInputError

    try:
        k = operator.index(step)
    except TypeError:
        raise ProblemInputError(f"contact_instance: step {step!r} is not an integer") from None
    if not -steps <= k < steps:
        raise ProblemInputError(f"contact_instance: step {k} is outside the {steps} load step(s) of the instance "
                                f"(0 to {steps - 1}, or -{steps} to -1 counted from the end)")
    return k % steps


@pytest.fixture
def contact_instance() -> Callable[..., Any]:
    """``make(kind="rmd", **kw)`` -> a ContactInstance: "rmd" (a paper-sweep instance;
    keywords N, steps, seed, step, operator) or "counterexample" (keywords n, seed,
    operator); ``INSTANCE_KEYWORDS`` gives the defaults.  An unknown keyword or a step
    outside the sequence raises ``ProblemInputError`` naming it."""

    def make(kind: str = "rmd", **kw: Any) -> Any:
        o = instance_options(kind, kw)
        if kind == "counterexample":
            from contactbench.problems.instances import counterexample

            return counterexample(int(o["n"]), int(o["seed"]), operator=o["operator"])
        from contactbench.problems.scenes import SceneConfig, get_scene

        scene = get_scene("paper-sweep")
        cfg = scene.config(SceneConfig(size=int(o["N"]), steps=int(o["steps"]), seeds=(int(o["seed"]),),
                                       operator=o["operator"]))
        seq = scene.build(scene.instances(cfg)[0])
        return seq.at(step_index(o["step"], len(seq)))

    return make


@pytest.fixture
def run_harness(tmp_path: Any) -> Callable[..., Any]:
    """``run(scenes, solvers=None, out=None, **options)`` -> the tidy table of
    ``run_benchmark`` into ``out`` (default: a temporary folder); the options are split
    between ``SceneConfig`` and ``RunConfig``.  ``run_benchmark`` checks the folder, then
    holds its lock while it writes: a folder it refuses is left as it is."""

    def run(scenes: list[str], solvers: Any = None, out: Any = None, **options: Any) -> Any:
        from contactbench.harness.run.plan import RunConfig
        from contactbench.harness.run.runner import run_benchmark
        from contactbench.harness.table.store import load_table
        from contactbench.problems.scenes import SceneConfig
        from contactbench.problems.scenes.options import CONFIG_FIELDS

        scene_keys = CONFIG_FIELDS | {"extra"}  # the rest is the RunConfig's; run_benchmark's plan checks both
        cfg = SceneConfig(**{k: v for k, v in options.items() if k in scene_keys})
        run_cfg = RunConfig(progress=False, **{k: v for k, v in options.items() if k not in scene_keys})
        out_dir = out or tmp_path / "run"
        run_benchmark(scenes, cfg, solvers, run_cfg, out_dir, command=["pytest"])
        return load_table(out_dir)

    return run


@pytest.fixture
def contactbench_conformance() -> Callable[..., Any]:
    """``contactbench_conformance(solver)`` runs the conformance battery (fast subset) on a
    solver (instance, registry name or ``module:NAME``) and fails the test unless it
    conforms (``battery.assert_conforms``: a wrong answer claimed as converged, a case
    left unsolved, or nothing judged).  See docs/adding-a-solver.md."""
    from contactbench.harness.conformance.battery import assert_conforms

    return assert_conforms


def case_conforms(solver: Any, case: Any, *, strict: bool = False, **kw: Any) -> Any:
    """One conformance case (``battery.ConformanceCase``) of ``solver`` (instance, registry
    name or ``module:NAME``) as a pytest outcome: a failure, its verdict line first, on a
    wrong answer claimed as converged or a case left unsolved (``strict``: also a crash, a
    timeout or a flagged row); a skip with the reason where the solver is not available or
    is not handed the case (a declared capability, its own skip, the lifecycle's answer:
    the battery's coverage rule is ``assert_conforms``'s); else the verdict table."""
    from contactbench.harness.conformance.battery import validate

    table = validate(solver, [case], **kw)
    if not table.available:
        pytest.skip(table.note)
    outcome = table.outcome(strict)
    if outcome == "untested":
        why = "; ".join(dict.fromkeys(r.message for r in table.rows if r.step >= 0)) or "no answer judged"
        pytest.skip(f"{case}: not handed to {table.solver}: {why}")
    if outcome != "conforms":
        pytest.fail(f"{table.solver} on {case}: {table.headline(strict)}\n{table.format(strict)}", pytrace=False)
    return table
