"""pytest plugin ``contactbench`` (entry point pytest11), loaded in every pytest session
of an environment where the package is installed -- so it imports nothing heavy at
module level.

Fixtures
--------
``contact_instance``  factory: ``contact_instance("rmd", N=32, step=-1)`` or
                      ``contact_instance("counterexample", n=100, seed=1)`` -> ContactInstance
                      whose ubar (and upper bounds, trial set and dense H) are read-only
                      arrays that cannot be made writeable again (``surfaces.read_only``):
                      a solver that writes into them raises.  Its operator's attributes
                      and methods are not frozen (a solver handed ``inst.qp`` can replace
                      ``H.matvec``); the problem is sealed (``ProblemSeal``) when made and
                      ``contactbench_settle`` checks the seal.  Refused, each with one
                      ``ProblemInputError`` line naming the keyword and the value: an
                      unknown kind or keyword, an integer keyword that is not an int
                      (a float, a str or a bool: never rounded), a step outside the
                      sequence, and an instance whose memory estimate
                      (``scenes.base.check_instance_memory``, as the plan's) is over the
                      memory budget, before anything is built.
``contactbench_solve``  ``solve(solver, inst, settings=None)``: the harness's own solve of
                      a test -- the solver handed a copy of ``inst``'s problem, sealed
                      (``harness.judging.ProblemSeal``), its answer judged by the judge
                      (``harness.judging.judge``) against ``inst`` and settled (``settle``):
                      one call that a solver cannot fool by writing into its problem or
                      by its own claim; under a hard time limit (``settings.time_limit``,
                      else ``SOLVE_TIME_LIMIT``), the processes it starts ended and the
                      working folder, environment and NumPy error state put back after
                      it.  Use it rather than calling ``solver.solve`` and ``judge`` by
                      hand.
``contactbench_conformance``  assert_conforms(solver): the conformance battery in a test.
``case_conforms``     (a function) one case of the battery in a test, for a test
                      parametrized over ``conformance_cases()`` (``ids=str``); a case may
                      be given by its name.
``contactbench_settle``  ``settle(verdict, what, solver_message)``: a pytest outcome from
                      the judge's verdict, the rule pytest-benchmark runs use (below),
                      after checking that each problem ``contact_instance`` made in the
                      test is as sealed when made (``check_made``): a hand judge after a
                      plain ``benchmark(solver.solve, inst.qp, ...)`` whose solver wrote
                      into ``inst`` or replaced its operator's products fails the test.
``contactbench_benchmark``  pytest-benchmark's ``benchmark`` judged
                      (``harness.judged_benchmark.JudgedBenchmark``): ``run(solver, inst,
                      settings)`` -- each round a problem no earlier solve saw, every
                      solve judged outside the clock, the row kept only when all passed;
                      judged at ``settings.check_tol`` and stopped past ``kill_limit`` of
                      ``settings.time_limit`` (or the ``check_tol=`` / ``time_limit=``
                      keywords; one that differs from the settings' is refused).

Hooks: a test using ``benchmark`` that does not pass has its row left out of
pytest-benchmark's table and JSON (``pytest_runtest_makereport``,
``pytest_benchmark_group_stats``: ``harness.judged_benchmark``).
``run_harness``       factory: run the harness into a temporary directory and return the
                      tidy table (pandas DataFrame), e.g.
                      ``run_harness(["paper-sweep"], solvers=["nnls"], size=16, steps=2)``;
                      a measured surface's ``height_unit`` / ``allow_steep`` go in
                      ``extra={"height_unit": "um"}``.  The options are checked by the
                      plan, as on the command line (``problems.scenes.options``): a
                      refused one raises ``ProblemInputError`` with the CLI's message.
                      A keyword that is neither a ``SceneConfig`` nor a ``RunConfig``
                      field, and an ``extra`` key that is neither a scene option
                      (``OPTIONS``) nor declared by the named scenes (``extra_keys``), is
                      a ``ProblemInputError`` naming it and the valid ones: a typo never
                      silently runs the default.
"""

from __future__ import annotations

import operator
from typing import Any, Callable, NamedTuple

import pytest

from .outcomes import settle


@pytest.fixture
def contactbench_made() -> list[tuple[Any, Any]]:
    """The problems ``contact_instance`` made in this test, each with its ``ProblemSeal``
    taken when made (what ``contactbench_settle`` checks)."""
    return []


def check_made(made: list[tuple[Any, Any]], what: str) -> None:
    """Fail the test (``pytest.fail``, one line naming ``what``) where a problem of ``made``
    is not as sealed when made: an array written, ubar or H replaced, a method of its
    operator replaced or hidden (``ProblemSeal.broken``), so a verdict judged on it is not
    the harness's; what can be is put back first (``ProblemSeal.mend``)."""
    broken = []
    for qp, seal in made:
        found = seal.broken(qp)
        if found:
            seal.mend(qp)
            broken.append(found)
    if broken:
        pytest.fail(f"{what}: the judge reads the answer as wrong: {'; '.join(broken)} -- a problem contact_instance "
                    "made in this test, so no verdict judged on it counts", pytrace=False)


@pytest.fixture
def contactbench_settle(contactbench_made: list[tuple[Any, Any]]) -> Callable[..., None]:
    """``settle(verdict, what, solver_message="")`` (module function ``settle``), after
    checking that every problem ``contact_instance`` made in this test is as it was made
    (``check_made``: a solver handed ``inst.qp`` that wrote into it or replaced its
    operator's products fails the test, whatever the verdict)."""

    def settle_checked(verdict: Any, what: str, solver_message: str = "") -> None:
        check_made(contactbench_made, what)
        settle(verdict, what, solver_message)

    return settle_checked


#: The keywords ``contact_instance`` takes for each kind, with their defaults.
INSTANCE_KEYWORDS: dict[str, dict[str, Any]] = {
    "rmd": {"N": 32, "steps": 3, "seed": 0, "step": -1, "operator": None},
    "counterexample": {"n": 100, "seed": 0, "operator": "dense"},
}
#: The keywords of ``INSTANCE_KEYWORDS`` that are integers (an int or a NumPy integer).
INTEGER_KEYWORDS: frozenset[str] = frozenset({"N", "n", "steps", "seed", "step"})


def whole(what: str, name: str, value: Any) -> int:
    """``value`` as an int where it is one (``operator.index``: an int or a NumPy integer,
    never a bool, a str or a float, which would be rounded or parsed), else a one-line
    ``ProblemInputError`` naming ``what``'s keyword ``name`` and the value."""
    import numpy as np

    from contactbench.problems.errors import ProblemInputError

    if not isinstance(value, (bool, np.bool_, str, bytes)):
        try:
            return operator.index(value)
        except TypeError:
            pass
    raise ProblemInputError(f"{what}: {name} must be an integer, got {value!r} ({type(value).__name__})")


def instance_options(kind: str, kw: dict[str, Any]) -> dict[str, Any]:
    """The keywords of ``contact_instance(kind, **kw)`` with the defaults filled in, the
    integer ones (``INTEGER_KEYWORDS``) as ints; a one-line ``ProblemInputError`` for an
    unknown kind, a keyword the kind does not take (a typo never silently runs the
    default) or an integer keyword that is not an integer (``whole``)."""
    from contactbench.problems.errors import ProblemInputError

    if not isinstance(kind, str) or kind not in INSTANCE_KEYWORDS:
        raise ProblemInputError(f"contact_instance: unknown instance kind {kind!r}; use 'rmd' or 'counterexample'")
    known = INSTANCE_KEYWORDS[kind]
    unknown = sorted(set(kw) - set(known))
    if unknown:
        raise ProblemInputError(f"contact_instance({kind!r}): unknown keyword(s) {', '.join(unknown)}; "
                                f"it takes {', '.join(known)}")
    what = f"contact_instance({kind!r})"
    return {k: whole(what, k, v) if k in INTEGER_KEYWORDS else v for k, v in {**known, **kw}.items()}


def step_index(step: Any, steps: int) -> int:
    """Load step ``step`` of a sequence of ``steps`` as an index in [0, steps): an integer
    in [-steps, steps), negative ones counted from the end; ``ProblemInputError`` else."""
    from contactbench.problems.errors import ProblemInputError

    k = whole("contact_instance", "step", step)
    if not -steps <= k < steps:
        raise ProblemInputError(f"contact_instance: step {k} is outside the {steps} load step(s) of the instance "
                                f"(0 to {steps - 1}, or -{steps} to -1 counted from the end)")
    return k % steps


def check_instance_budget(kind: str, o: dict[str, Any], budget: float) -> tuple[Any, Any]:
    """Before anything is built: the scene and merged config of ``contact_instance(kind,
    **o)`` ("rmd": paper-sweep's; "counterexample": its scene's where n is a square, else
    (None, None): ``counterexample`` refuses it), refused in one ``ProblemInputError``
    line where its instance's memory bound (``scenes.base.check_instance_memory``, the
    plan's) is over ``budget`` bytes."""
    import math

    from contactbench.problems.scenes import SceneConfig, get_scene
    from contactbench.problems.scenes.base import check_instance_memory

    if kind == "counterexample":
        N = math.isqrt(o["n"]) if o["n"] >= 4 else 0
        if N * N != o["n"]:
            return None, None
        scene = get_scene("counterexample")
        cfg = scene.config(SceneConfig(size=N, seeds=(o["seed"],), operator=o["operator"]))
    else:
        scene = get_scene("paper-sweep")
        cfg = scene.config(SceneConfig(size=o["N"], steps=o["steps"], seeds=(o["seed"],), operator=o["operator"]))
    check_instance_memory(scene.instances(cfg), budget, "CONTACTBENCH_MEMORY_BUDGET_GB", f"contact_instance({kind!r})")
    return scene, cfg


def sealed_instance(inst: Any) -> Any:
    """``inst`` with its problem's arrays read-only for good (``surfaces.read_only``, a copy
    of each: ubar, the upper bounds and a dense operator's H; the trial set is already): a
    solver that writes into them raises instead of changing what it is judged on."""
    from dataclasses import replace

    from contactbench.problems.instances import QP
    from contactbench.problems.operators import DenseOperator
    from contactbench.problems.surfaces import read_only

    qp = inst.qp
    cons = qp.constraints
    if cons.upper is not None:
        cons = replace(cons, upper=read_only(cons.upper, None))
    if type(qp.H) is DenseOperator:  # (the fixture's own operator: no one else holds it)
        qp.H.H = read_only(qp.H.H, None)
    return replace(inst, qp=QP(qp.H, read_only(qp.ubar, None), qp.geometry, cons))


def make_instance(kind: str = "rmd", **kw: Any) -> Any:
    """``contact_instance``'s factory (its doc): refused before anything is built where a
    keyword or the memory estimate is bad; a ``MemoryBudgetError`` of the build is a
    ``ProblemInputError`` naming the budget."""
    from contactbench.problems.errors import MemoryBudgetError, ProblemInputError
    from contactbench.problems.operators import memory_budget

    o = instance_options(kind, kw)
    scene, cfg = check_instance_budget(kind, o, memory_budget())
    try:
        if kind == "counterexample":
            from contactbench.problems.instances import counterexample

            return sealed_instance(counterexample(o["n"], o["seed"], operator=o["operator"]))
        seq = scene.build(scene.instances(cfg)[0])
        return sealed_instance(seq.at(step_index(o["step"], len(seq))))
    except MemoryBudgetError as exc:
        raise ProblemInputError(f"contact_instance({kind!r}): {exc} (contact_instance's budget, "
                                "CONTACTBENCH_MEMORY_BUDGET_GB)") from None


@pytest.fixture
def contact_instance(contactbench_made: list[tuple[Any, Any]]) -> Callable[..., Any]:
    """``make(kind="rmd", **kw)`` -> a ContactInstance: "rmd" (a paper-sweep instance;
    keywords N, steps, seed, step, operator) or "counterexample" (keywords n, seed,
    operator); ``INSTANCE_KEYWORDS`` gives the defaults.  Its problem's arrays are
    read-only (``sealed_instance``); its problem is sealed (``ProblemSeal``) when made, for
    ``contactbench_settle`` to check.  Bad input raises one ``ProblemInputError`` line
    naming it (module doc)."""

    def make(kind: str = "rmd", **kw: Any) -> Any:
        from contactbench.harness.judging import ProblemSeal

        inst = make_instance(kind, **kw)
        contactbench_made.append((inst.qp, ProblemSeal.of(inst.qp)))
        return inst

    return make


class JudgedSolve(NamedTuple):
    """What ``judged_solve`` returns: the solver's ``SolveResult`` and the judge's
    ``Verdict`` (its reading "pass", or "unconverged" under ``settle=False``)."""

    result: Any
    verdict: Any


#: ``contactbench_solve``'s time limit (seconds) where neither ``settings`` nor the call
#: names one: ``contactbench run``'s default ``--timeout`` (``RunConfig.timeout``).
SOLVE_TIME_LIMIT = 60.0


def judged_solve(solver: Any, inst: Any, settings: Any = None, *, warm: Any = None, check_tol: float | None = None,
                 what: str | None = None, settle_it: bool = True) -> JudgedSolve:
    """Solve ``inst`` with ``solver`` (an instance, a registry name or ``module:NAME``) as the
    harness does: the solver is handed a copy of the problem that shares nothing with it
    (``judged_benchmark.handed_copy``), sealed with ``inst``'s beside it (``ProblemSeal``); what it changed, or the
    threads it left running, makes the answer "wrong"; the answer is judged by ``judge``
    against ``inst`` at ``check_tol`` (default: ``settings.check_tol``, else the "default"
    profile's; the solver is told it) and, with ``settle_it``, settled (``settle``: a
    wrong answer fails the test, an unconverged one xfails it).  ``settings``: a
    ``SolverSettings`` or None; ``warm``: a ``WarmStart`` or None.  The solve runs under
    ``settings.time_limit`` (None: ``SOLVE_TIME_LIMIT``; the solver is told it): one still
    running past ``kill_limit`` of it is stopped (``judged_benchmark.Watchdog``, as in
    ``contactbench_benchmark``) and fails the test as a timeout.  The processes the solve
    starts end with it, and the working folder, the environment and NumPy's error
    handling are put back after it (``ends_what_it_starts``, ``process_state_kept``).
    What the solver raises propagates.  Bad input (``inst`` not a ContactInstance,
    ``settings`` not a SolverSettings, a ``check_tol`` that is not finite and > 0) is a
    one-line ``ProblemInputError``."""
    from dataclasses import replace

    from contactbench.harness.judged_benchmark import SolveTimeout, Watchdog, handed_copy, kill_time
    from contactbench.harness.judging import ProblemSeal, judge
    from contactbench.harness.profiles import get_profile
    from contactbench.harness.run.worker import process_state_kept, running_threads, threads_left
    from contactbench.problems.errors import ProblemInputError, check_positive
    from contactbench.problems.instances import ContactInstance
    from contactbench.solvers._processes import ends_what_it_starts
    from contactbench.solvers.base import SolverSettings
    from contactbench.solvers.registry import load_solver

    if not isinstance(inst, ContactInstance):
        raise ProblemInputError(f"contactbench_solve: inst must be a ContactInstance (contact_instance(...)), got "
                                f"{type(inst).__name__}")
    if settings is not None and not isinstance(settings, SolverSettings):
        raise ProblemInputError(f"contactbench_solve: settings must be a SolverSettings or None, got "
                                f"{type(settings).__name__}")
    s = load_solver(solver)
    what = what or f"{s.name} on n = {inst.n}"
    settings = settings or SolverSettings()
    tol = check_tol if check_tol is not None else settings.check_tol
    tol = get_profile("default").check_tol if tol is None else check_positive("contactbench_solve: check_tol", tol)
    limit = SOLVE_TIME_LIMIT if settings.time_limit is None else settings.time_limit
    settings = replace(settings, params=dict(settings.params), check_tol=tol, time_limit=limit)
    qp = inst.qp
    handed = handed_copy(qp)  # (the benchmarks' copy: nothing shared with the judge's problem)
    seal, threads = ProblemSeal.of(handed, [qp]), running_threads()
    watchdog, stopped = Watchdog(kill_time(limit)), ""
    try:
        with watchdog.installed(), ends_what_it_starts(), process_state_kept():
            watchdog.arm()
            try:
                res = s.solve(handed, settings, warm)
            except SolveTimeout as exc:
                stopped = str(exc)
            finally:
                watchdog.disarm()
    finally:
        tampered = seal.broken(handed)
        seal.mend(handed)  # (the judge's products run the sealed code)
    tampered = tampered or threads_left(threads)
    if stopped:
        pytest.fail(f"{what}: timeout: {stopped} (the time limit {limit:g} s plus the grace); the solve was stopped"
                    + (f"; {tampered}" if tampered else ""), pytrace=False)
    verdict = judge(inst, res.p, bool(res.converged), tol, tampered=tampered, multiplier=res.multiplier)
    if settle_it:
        settle(verdict, what, str(res.message))
    return JudgedSolve(res, verdict)


@pytest.fixture
def contactbench_solve() -> Callable[..., JudgedSolve]:
    """``solve(solver, inst, settings=None, *, warm=None, check_tol=None, what=None)``
    -> ``JudgedSolve`` (module function ``judged_solve``): solved sealed, judged by the
    harness and settled as a pytest outcome."""
    return judged_solve


#: ``SceneConfig.extra`` keys scenes read without a default in ``Scene.defaults.extra``:
#: the Hurst exponent of a generated rough surface and a stress scene's largest n.
UNDEFAULTED_EXTRA: frozenset[str] = frozenset({"hurst", "max_n"})


def extra_keys(scenes: list[str]) -> set[str]:
    """The ``SceneConfig.extra`` keys the named scenes (or composites' parts) declare besides
    the scene options (``OPTIONS``): their defaults' extra keys, a composite part's own,
    their studies' sweep parameters (``Sweep.param``, ``fixed``, ``options``) and
    ``UNDEFAULTED_EXTRA``.  An unknown name declares none (the plan refuses it)."""
    from contactbench.harness.run.studies import expand
    from contactbench.problems.scenes import get_scene

    keys = set(UNDEFAULTED_EXTRA)
    for name in scenes:
        try:
            parts = expand(name, None)
        except KeyError:
            continue
        for study, cfg in parts:
            keys |= set(get_scene(study.scene).defaults.extra) | set(cfg.extra)
            for w in study.sweeps:
                keys |= {w.param, *w.fixed, *w.options}
    return keys


def harness_options(scenes: Any, options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``run_harness``'s options split into ``SceneConfig`` and ``RunConfig`` keywords; a
    one-line ``ProblemInputError`` naming a keyword that is neither, and an ``extra`` key
    that is neither a scene option nor one the named scenes declare (``extra_keys``), with
    the valid ones."""
    from dataclasses import fields

    from contactbench.harness.run.plan import RunConfig
    from contactbench.problems.errors import ProblemInputError
    from contactbench.problems.scenes.options import CONFIG_FIELDS, OPTIONS

    scene_keys = CONFIG_FIELDS | {"extra"}
    run_keys = {f.name for f in fields(RunConfig)}
    option_names = {r.name for r in OPTIONS}
    unknown = sorted(set(options) - scene_keys - run_keys)
    if unknown:
        hint = [k for k in unknown if k in option_names]
        tip = f" ({', '.join(hint)}: a scene option, given in extra={{...}})" if hint else ""
        raise ProblemInputError(f"run_harness: unknown keyword(s) {', '.join(unknown)}{tip}; it takes scenes, "
                                f"solvers, out, {', '.join(sorted(scene_keys))} and {', '.join(sorted(run_keys))}")
    extra = options.get("extra", {})
    if not isinstance(extra, dict):
        raise ProblemInputError(f"run_harness: extra must be a dict of scene options, got {type(extra).__name__}")
    names = [scenes] if isinstance(scenes, str) else list(scenes)
    declared = extra_keys(names) | (option_names - CONFIG_FIELDS)
    bad = sorted(k for k in extra if k not in declared)
    if bad:
        raise ProblemInputError(f"run_harness: extra key(s) {', '.join(map(repr, bad))} neither a scene option nor "
                                f"read by {', '.join(map(repr, names))}; the valid ones: "
                                f"{', '.join(sorted(declared, key=str))}")
    return ({k: v for k, v in options.items() if k in scene_keys},
            {"progress": False, **{k: v for k, v in options.items() if k in run_keys}})


@pytest.fixture
def run_harness(tmp_path: Any) -> Callable[..., Any]:
    """``run(scenes, solvers=None, out=None, **options)`` -> the tidy table of
    ``run_benchmark`` into ``out`` (default: a temporary folder); the options are split
    between ``SceneConfig`` and ``RunConfig`` (``harness_options``: an unknown keyword or
    ``extra`` key is refused).  ``run_benchmark`` checks the folder, then holds its lock
    while it writes: a folder it refuses is left as it is."""

    def run(scenes: list[str], solvers: Any = None, out: Any = None, **options: Any) -> Any:
        from contactbench.harness.run.plan import RunConfig
        from contactbench.harness.run.runner import run_benchmark
        from contactbench.harness.table.store import load_table
        from contactbench.problems.scenes import SceneConfig

        from contactbench.problems.errors import ProblemInputError

        scene_kw, run_kw = harness_options(scenes, options)
        cfg = SceneConfig(**scene_kw)
        try:
            run_cfg = RunConfig(**run_kw)
        except ProblemInputError:
            raise
        except ValueError as exc:  # (RunConfig's one line, naming the option and its flag)
            raise ProblemInputError(f"run_harness: {exc}") from None
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


@pytest.fixture
def contactbench_benchmark(benchmark: Any) -> Any:
    """pytest-benchmark's ``benchmark`` as a ``harness.judged_benchmark.JudgedBenchmark``:
    ``contactbench_benchmark.run(solver, inst, settings)`` times rounds of problems no
    earlier solve saw, judges every solve outside the clock and counts the row only when
    every one passed (a solver that carries work across solves fails).  Needs
    pytest-benchmark."""
    from contactbench.harness.judged_benchmark import JudgedBenchmark

    return JudgedBenchmark(benchmark)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: Any, call: Any) -> Any:
    """A test with pytest-benchmark's ``benchmark`` that does not pass (a failure -- a
    ``contactbench_settle`` of a wrong answer --, an xfail, a skip after its call, a
    teardown error) has its row left out of the table and the JSON
    (``judged_benchmark.exclude_unpassed``): a user's own benchmark never records a timing
    its test failed."""
    report = yield
    if "benchmark" in getattr(item, "fixturenames", ()):
        from contactbench.harness.judged_benchmark import exclude_unpassed

        exclude_unpassed(item, report)
    return report


@pytest.hookimpl(wrapper=True, optionalhook=True)
def pytest_benchmark_group_stats(config: Any, benchmarks: Any, group_by: Any) -> Any:
    """pytest-benchmark's table groups less the rows that do not count
    (``judged_benchmark.keep_judged``); called only where pytest-benchmark is installed."""
    from contactbench.harness.judged_benchmark import keep_judged

    return keep_judged((yield))
