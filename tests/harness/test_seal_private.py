"""The seal reaches everything an operator holds (docs/verdicts.md): a write into a private
cache is the writer's ``failed``/``wrong`` and the judge computes with the cache rebuilt, while
the products themselves -- of every kind, in both precisions -- leave the seal whole; and a
thread a solver leaves running ends its worker, so no solver after it in a run is blamed
for what that thread writes."""

from __future__ import annotations

import concurrent.futures.thread
import gc
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterator

import numpy as np
import pytest

from contactbench.harness import get_profile
from contactbench.harness.judging import ProblemSeal, judge
from contactbench.harness.run import worker
from contactbench.harness.run.worker import running_threads, threads_left
from contactbench.problems.instances import QP, counterexample
from contactbench.problems.kkt import kkt_check
from contactbench.problems.kernels import kernel_table
from contactbench.problems.lcp import exact_solution
from contactbench.problems.operator_state import seal_rule
from contactbench.problems.operators import FFTOperator, KernelTransform
from contactbench.problems.operators_gpu import ArrayKernelTransform
from tests.fake_device import SPACE
from contactbench.solvers import Capabilities, Outcome, SolveContext, Solver

HERE = __name__
TOL = get_profile("mid").check_tol


def fft_problem(periodic: bool, n: int) -> QP:
    """A QP on ``n`` points of a 48 x 48 grid (FFT operator; a small set switches to a dense block)."""
    N = 48
    transform = KernelTransform(kernel_table("bcc", (N, N), 1e-6, 1e9, periodic), (N, N))
    idx = np.sort(np.random.default_rng(1).choice(N * N, n, replace=False))
    H = FFTOperator(transform, idx)
    return QP(H, H.matvec(np.random.default_rng(2).random(n)))


def every_kind_of_product(qp: QP) -> None:
    """What solvers run on an FFT operator: products (enough for the dense switch), the
    float32 twin, a restriction, gathers, partial products, unit sums and floors."""
    H, x = qp.H, np.linspace(0.5, 1.5, qp.n)
    for _ in range(6):
        H.matvec(x)
    H.with_precision(np.float32).matvec(x)
    H.restrict(np.arange(0, H.n, 2)).matvec(x[::2])
    H.displacement_field(x)
    H.diagonal(), H.entry_floor(), H.submatrix(np.arange(4)), H.blocks(np.array([[0, 1], [2, -1]]))
    H.partial_product(np.arange(5), np.arange(5, 20), x[5:20])
    H.unit_sums([(np.arange(5), np.arange(5, 20))])
    H.transform.transposed_spectrum(np.float64), H.transform.transposed_spectrum(np.float32)


def held_arrays(obj: Any, path: str = "H") -> Iterator[tuple[str, np.ndarray, Any, str]]:
    """(path, array, owner object, path relative to it) of every array ``obj`` holds,
    through objects, dicts, lists and tuples."""
    seen: set[int] = set()

    def walk(value: Any, where: str, owner: Any, rel: str) -> Iterator[tuple[str, np.ndarray, Any, str]]:
        if isinstance(value, np.ndarray):
            yield where, value, owner, rel
        elif isinstance(value, (list, tuple)):
            for i, item in enumerate(value):
                yield from walk(item, f"{where}[{i}]", owner, f"{rel}[{i}]")
        elif isinstance(value, dict):
            for key, item in value.items():
                yield from walk(item, f"{where}[{key!r}]", owner, f"{rel}[{key!r}]")
        elif hasattr(value, "__dict__") and not callable(value) and id(value) not in seen:
            seen.add(id(value))
            for name, item in vars(value).items():
                yield from walk(item, f"{where}.{name}", value, name)

    yield from walk(obj, path, None, "")


def is_work_buffer(owner: Any, rel: str) -> bool:
    rule = seal_rule(type(owner))
    return any(rel == w or (w.replace("[*]", "[0]") == rel) or (w.endswith("[*]") and rel.startswith(w[:-3]))
               or (w == "_row_buffers[*][1]" and rel.startswith("_row_buffers[") and rel.endswith("][1]"))
               for w in rule.work)


@pytest.mark.parametrize("periodic, n", [(False, 30), (True, 30), (False, 900)])
def test_every_array_an_operator_holds_is_sealed_and_its_products_leave_it_whole(periodic: bool, n: int) -> None:
    """Products of every kind leave the seal whole (work buffers and the last plan change,
    caches are built, counters count), while a write into any array the operator or the
    objects it holds keep -- private ones included, work buffers aside -- breaks it."""
    qp = fft_problem(periodic, n)
    seal = ProblemSeal.of(qp)
    every_kind_of_product(qp)
    assert seal.broken(qp) == ""
    seal.mend(qp)
    checked = []
    for path, arr, owner, rel in list(held_arrays(qp.H)):
        if arr.size == 0 or (owner is not None and is_work_buffer(owner, rel)) or "._last" in path:
            continue
        seal = ProblemSeal.of(qp)
        flat = arr.reshape(-1)
        old = flat[0].copy()
        flat[0] = old + 1 if arr.dtype.kind in "iu" else old * 2 + 1
        try:
            assert seal.broken(qp) != "", path
        finally:
            flat[0] = old  # (as sealed again: no mend, which would drop a cache written into)
        checked.append(path)
    assert {"H._pi", "H.transform.table"} <= set(checked) and any("_row_buffers" in p for p in checked), checked


def judge_row(p: np.ndarray, tampered: str) -> tuple[str, str]:
    v = judge(counterexample(16, 0), p, True, TOL, tampered=tampered)  # (the seal's finding decides)
    return v.status, v.reading


def test_a_cache_a_solver_writes_into_is_caught_dropped_and_built_again_for_the_judge() -> None:
    """A solver that doubles the FFT operator's dense block -- built before its solve, or by
    its own products -- and answers the doubled problem is ``failed``/``wrong``; ``mend``
    drops the block, so the judge's products rebuild it and the right answer passes.  A
    block built by an honest solve is kept."""
    qp = fft_problem(False, 30)
    H = qp.H
    p = exact_solution(H.to_dense(), qp.ubar).p
    for built_before in (True, False):
        H._dense = None
        if built_before:
            for _ in range(6):
                H.matvec(p)
        seal = ProblemSeal.of(qp)
        for _ in range(6):
            H.matvec(p)
        assert H.uses_dense
        H._dense *= 2.0
        tampered = seal.broken(qp)
        assert "H._dense" in tampered
        assert judge_row(p / 2.0, tampered) == ("failed", "wrong")
        seal.mend(qp)
        assert not H.uses_dense
        assert not kkt_check(qp, p / 2.0).passes(TOL) and kkt_check(qp, p).passes(TOL)  # (the judge's figures)
        assert H.uses_dense and ProblemSeal.of(qp).broken(qp) == ""
    seal = ProblemSeal.of(qp)
    H._dense = None
    for _ in range(6):
        H.matvec(p)
    assert seal.broken(qp) == ""
    seal.mend(qp)
    assert H.uses_dense


class DoublesTheDenseBlock(Solver):
    """Runs products until the FFT operator switches to its dense block, doubles the block
    and answers the doubled problem, claimed: an answer the tampered block would pass."""

    name = "test-doubles-the-dense-block"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"fft"}))

    def iterate(self, ctx: SolveContext) -> Outcome:
        H = ctx.qp.H
        p = exact_solution(H.to_dense(), np.asarray(ctx.qp.ubar)).p
        for _ in range(8):
            H.matvec(p)
        if getattr(H, "_dense", None) is not None:
            H._dense *= 2.0
            return Outcome(p / 2.0, 1, True)
        return Outcome(p, 1, True)


@pytest.mark.parametrize("warmup", [False, True])
def test_a_write_into_a_private_cache_is_the_solver_s_and_no_other_solver_s(run_harness, warmup: bool) -> None:
    """The writer's rows are ``failed``/``wrong`` where its products used the dense block;
    pk after it in the same worker is judged on the problem as built (its error in p small)."""
    table = run_harness(["paper-sweep"], solvers=[f"{HERE}:DoublesTheDenseBlock", "pk"], size=32, steps=2,
                        profiles=("mid",), reference="nnls", warmup=warmup, timeout=60.0)
    writer = table[table["solver"] == DoublesTheDenseBlock.name]
    assert ("failed", "wrong") in set(zip(writer["status"], writer["verdict"])), writer["error"].tolist()
    assert not (writer["status"] == "solved").all()
    assert writer[writer["status"] == "failed"]["error"].str.contains(r"wrote into the problem .*H\._dense").all()
    pk = table[table["solver"] == "pk"]
    assert (pk["status"] == "solved").all() and (pk["p_rel_error"].astype(float) < 1e-3).all()  # (0.5 on 2H)


# ---------------------------------------------------------------------------
# Threads a solver leaves running
# ---------------------------------------------------------------------------

_GO = threading.Event()  # set by the solver after the one that left the thread, where that thread lives
_WRITTEN = threading.Event()
_LEFT: list[threading.Thread] = []  # the thread, in the process that runs it


class LeavesAWriterThread(Solver):
    """Answers right, claimed, leaving a thread that doubles the dense H it was handed
    once ``_GO`` is set."""

    name = "test-leaves-a-writer-thread"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        H = ctx.qp.H.to_dense()  # (DenseOperator: the operator's own matrix)
        p = exact_solution(H, np.asarray(ctx.qp.ubar)).p

        def write_later() -> None:
            _GO.wait()
            H[...] *= 2.0
            _WRITTEN.set()

        thread = threading.Thread(target=write_later, name="left-behind", daemon=True)
        _LEFT.append(thread)
        thread.start()
        return Outcome(p, 1, True)


class StartsTheLeftThread(Solver):
    """Where a thread of the solver before it lives on in this process, lets it write into
    the problem during this solve; then answers the problem it was handed, claimed."""

    name = "test-starts-the-left-thread"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense"}), needs_dense=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        if any(t.is_alive() for t in _LEFT):
            _GO.set()
            _WRITTEN.wait()
        return Outcome(exact_solution(ctx.qp.H.to_dense(), np.asarray(ctx.qp.ubar)).p, 1, True)


@pytest.mark.parametrize("warmup", [False, True])
def test_a_thread_left_running_is_its_solver_s_and_ends_its_worker(run_harness, monkeypatch: pytest.MonkeyPatch,
                                                                   warmup: bool) -> None:
    """The solver that leaves a thread is ``failed``/``wrong`` (named so), its worker is not
    reused, and the solver after it is judged on a problem no thread of another writes into."""
    monkeypatch.setattr(worker, "THREAD_GRACE_S", 0.05)  # (the workers are forked: they read this)
    table = run_harness(["counterexample"], solvers=[f"{HERE}:LeavesAWriterThread", f"{HERE}:StartsTheLeftThread"],
                        size=10, seeds=(0,), profiles=("mid",), reference="nnls", warmup=warmup, timeout=60.0)
    leaver = table[table["solver"] == LeavesAWriterThread.name]
    assert set(zip(leaver["status"], leaver["verdict"])) == {("failed", "wrong")}, leaver["error"].tolist()
    assert leaver["error"].str.contains("left 1 thread running after its solve \\('left-behind'\\)").all()
    after = table[table["solver"] == StartsTheLeftThread.name]
    assert set(zip(after["status"], after["verdict"])) == {("solved", "pass")}, after["error"].tolist()


def test_idle_pool_workers_and_threads_that_end_are_not_left_running() -> None:
    """``threads_left`` names a thread still running after the solve, and neither the idle
    workers of a pool (the FFT threads', a solver's) nor a thread that ends in the grace."""
    before = running_threads()
    pool = ThreadPoolExecutor(2)
    assert pool.submit(lambda: 1).result() == 1
    done = threading.Thread(target=lambda: None)
    done.start()
    stop = threading.Event()
    waiting = threading.Thread(target=stop.wait, name="still-waiting", daemon=True)
    try:
        assert threads_left(before, grace=0.5) == ""
        waiting.start()
        assert "'still-waiting'" in threads_left(before, grace=0.0)
    finally:
        stop.set()
        waiting.join()
        pool.shutdown()


def ducc_works(qp: QP) -> list[Any]:
    return list(qp.H.transform._works.values())


def test_a_solve_s_own_plan_of_its_last_product_is_kept_and_a_forged_one_dropped() -> None:
    """The plan an honest solve's products leave (``_DuccWork._last``) is its rebuild: the
    seal keeps it, so a timed solve after its warm-up does not plan its products again
    inside its clock; a plan that is not what its key gives is put back to None."""
    qp = fft_problem(periodic=False, n=1200)
    seal = ProblemSeal.of(qp)
    sub = qp.H.restrict(np.arange(0, qp.n, 3))
    sub.matvec(np.ones(sub.n))
    kept = [(w, w._last) for w in ducc_works(qp) if w._last is not None]
    assert kept and seal.broken(qp) == ""
    seal.mend(qp)
    assert all(w._last is plan for w, plan in kept)
    seal = ProblemSeal.of(qp)
    work, plan = kept[0]
    plan.seg[1:] = plan.seg[:-1]  # a forged plan: what its key gives no more
    assert seal.broken(qp) == ""  # (the solver's own products would be wrong, not the problem)
    seal.mend(qp)
    assert work._last is None


def device_problem() -> QP:
    """A QP on the fake device (tests/fake_device.py): its transform keeps a ``_DeviceState``."""
    N = 24
    host = KernelTransform(kernel_table("bcc", (N, N), 1e-6, 1e9, False), (N, N))
    H = FFTOperator(ArrayKernelTransform.from_host(host, SPACE), np.arange(0, N * N, 2))
    return QP(H, np.linspace(-1e-7, 1e-7, H.n))


def test_device_state_a_solve_uploads_is_kept_and_one_written_into_is_the_solver_s() -> None:
    """What an honest solve puts on the device (the spectrum, the indices) is kept, so a
    timed solve after its warm-up does not upload it again inside its clock; device
    memory written into in place is found at the next check (copied back, compared),
    dropped and named as a write."""
    qp = device_problem()
    seal = ProblemSeal.of(qp)
    qp.H.matvec(np.ones(qp.n))
    state = qp.H.transform._device
    assert state is not None and seal.broken(qp) == ""
    seal.mend(qp)
    assert qp.H.transform._device is state
    seal = ProblemSeal.of(qp)
    state._stored.a[0, 0] += 1.0  # a write into the device's copy of the spectrum, in place
    assert "_device" in seal.broken(qp)
    seal.mend(qp)
    assert qp.H.transform._device is None
    qp.H.matvec(np.ones(qp.n))  # built again, as the operator builds it
    assert ProblemSeal.of(qp).broken(qp) == ""


class ZeroesTheJudgesProblem(Solver):
    """Finds every other problem of its process (``gc``): their ubar set to -1 (so p = 0 is
    right there) and, under load control, their load to 0 -- then answers p = 0, claimed."""

    name = "test-zeroes-the-judges-problem"
    family = "test"
    capabilities = Capabilities(operators=frozenset({"dense", "fft"}))

    def iterate(self, ctx: SolveContext) -> Outcome:
        for other in gc.get_objects():
            if isinstance(other, QP) and other is not ctx.qp and isinstance(other.ubar, np.ndarray):
                other.ubar[...] = -1.0
                object.__setattr__(other.constraints, "load", 0.0)
        return Outcome(np.zeros(ctx.n), 1, True)


@pytest.mark.parametrize("warmup", [False, True])
def test_a_write_into_the_judge_s_own_problem_is_the_solver_s_and_no_other_solver_s(run_harness,
                                                                                  warmup: bool) -> None:
    """The judge's copy of the problem (and every step the worker holds) is sealed with the
    solver's: a solver that reaches it through ``gc`` is ``failed``/``wrong``, and pk after
    it in the same worker is judged on the problem as built."""
    table = run_harness(["counterexample"], solvers=[f"{HERE}:ZeroesTheJudgesProblem", "pk"], size=10, seeds=(0,),
                        reference="none", warmup=warmup)
    writer = table[table["solver"] == ZeroesTheJudgesProblem.name]
    assert set(zip(writer["status"], writer["verdict"])) == {("failed", "wrong")}, writer["error"].tolist()
    assert writer["error"].str.contains(r"held\[0\]\.ubar").all()
    pk = table[table["solver"] == "pk"]
    assert (pk["status"] == "solved").all() and (pk["verdict"] == "pass").all() and (pk["kkt_error"] < 1e-6).all()


def test_a_thread_that_only_looks_like_an_idle_pool_worker_counts() -> None:
    """A thread counts as an idle pool worker only when it runs the library's own worker
    code on a queue of its own type: one compiled under that file and name, waiting on a
    queue that says it is empty, is a thread left running."""
    fake = "def _worker(work_queue, held):\n    held.acquire(timeout=30)\n"  # (blocked in C: its frame innermost)
    namespace: dict[str, Any] = {}
    exec(compile(fake, concurrent.futures.thread.__file__, "exec"), namespace)
    before, held = running_threads(), threading.Lock()
    held.acquire()
    queue = type("Q", (), {"empty": lambda self: True})()
    thread = threading.Thread(target=namespace["_worker"], args=(queue, held), daemon=True)
    thread.start()
    try:
        assert threads_left(before, grace=0.05)
    finally:
        held.release()
        thread.join()
    with ThreadPoolExecutor(1) as pool:
        pool.submit(int).result()
        assert threads_left(before, grace=0.5) == ""  # a real idle worker does not count
