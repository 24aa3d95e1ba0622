"""Where one cold top-step solve spends its time: ``cProfile`` of ``fast-dual-pccg`` (or
--solver) on the paper-sweep scene's top step at --size, by --operator, the functions with
the largest own time first.  On a GPU a function's own time includes the device work it
waits for: the first host read after a kernel (a scalar, a transfer) carries it.

Usage:
  python benchmarks/profile_solve.py [--size 2048] [--operator fft|gpu] [--solver fast-dual-pccg]
      [--params '{}'] [--top 30] [--callers 0] [--chains REGEX] [--depth 5]

--chains prints, for each function whose name matches REGEX, the chains of its callers
up to --depth frames, each with its calls and cumulative seconds (who, through a
library's own functions, reaches a call).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import re
import time

from bench_cost_law import top_step
from csv_rows import host_name, refuse_bad_grid_sizes, refuse_missing_device
from device_warmup import warm_up_device


def caller_chains(stats: pstats.Stats, pattern: str, depth: int) -> list[str]:
    """Lines naming each function matching ``pattern`` and the chains of its callers, a
    caller indented under its callee, ``depth`` frames at most."""
    table = stats.stats  # type: ignore[attr-defined]
    lines: list[str] = []

    def name(func: tuple) -> str:
        return f"{func[0].split('/')[-1]}:{func[1]}({func[2]})"

    def walk(func: tuple, level: int, seen: frozenset) -> None:
        for caller, (cc, nc, tt, ct) in sorted(table[func][4].items(), key=lambda kv: -kv[1][3]):
            lines.append(f"{'  ' * level}<- {nc:6d} calls {ct:8.3f} s  {name(caller)}")
            if level < depth and caller in table and caller not in seen:
                walk(caller, level + 1, seen | {caller})

    for func in sorted(table, key=lambda f: -table[f][3]):
        if re.search(pattern, name(func)):
            lines.append(f"{name(func)}: {table[func][1]} calls, {table[func][3]:.3f} s cumulative")
            walk(func, 1, frozenset({func}))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=2048)
    ap.add_argument("--operator", default="fft", choices=("fft", "gpu"))
    ap.add_argument("--solver", default="fast-dual-pccg")
    ap.add_argument("--params", default="{}", help="solver params as JSON")
    ap.add_argument("--top", type=int, default=30, help="functions listed")
    ap.add_argument("--callers", type=int, default=0, help="... and the callers of this many of them")
    ap.add_argument("--chains", default=None, help="regex on 'file:line(function)': those functions' caller chains")
    ap.add_argument("--depth", type=int, default=5, help="frames of a --chains chain")
    args = ap.parse_args()
    params = json.loads(args.params)
    if not isinstance(params, dict):
        ap.error("--params must be a JSON object")
    refuse_bad_grid_sizes(ap, "--size", [args.size])
    refuse_missing_device(ap, args.operator)
    from contactbench.solvers.base import SolverSettings
    from contactbench.solvers.registry import get_solver

    warm_up_device(args.solver, params, args.operator, lambda: top_step(args.size, 10, args.operator)[0].qp)
    t0 = time.perf_counter()
    inst, recipe = top_step(args.size, 10, args.operator)
    setup = time.perf_counter() - t0
    solver = get_solver(args.solver)
    settings = SolverSettings(tol=1e-9, params=params)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    res = solver.solve(inst.qp, settings)
    prof.disable()
    seconds = time.perf_counter() - t0
    print(f"{recipe} n={inst.n} {args.solver} {args.operator} on {host_name()}: {res.status}, "
          f"{res.iterations} iterations, {res.matvecs} matvecs, {seconds:.2f} s (setup {setup:.1f} s); "
          f"info: { {k: v for k, v in res.info.items() if not hasattr(v, '__len__') or isinstance(v, str)} }")
    stats = pstats.Stats(prof).sort_stats("tottime")
    stats.print_stats(args.top)
    if args.callers > 0:
        stats.print_callers(args.callers)
    if args.chains:
        print("\n".join(caller_chains(stats, args.chains, args.depth)))


if __name__ == "__main__":
    main()
