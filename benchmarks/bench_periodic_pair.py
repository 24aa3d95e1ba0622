"""The periodic product as one 2-D transform pair (``fft_transform.WHOLE_PERIODIC_PAIR``) against
the row blocks and column pass, interleaved in one process; and the whole-grid convolution
(``fft_threads.periodic_convolve``, the wave-number preconditioner's) with its float32 rows in
``row_batch`` calls against one 2-D call each way.

The operator is the paper-sweep scene's periodic top step (spectral kernel, the whole grid)
restricted to random sets of a few fractions of the grid; for each set the two paths take
turns in float32 (float64 always runs the row blocks), ``--rounds`` rounds of ``--reps`` products each, and the median and least
milliseconds per product of each are printed as a Markdown table (host, date, commit) and
written to ``--out`` when given.  Where the rule keeps long rows in the row blocks (rows of
``FLOAT32_LONG_ROW`` points or more) both columns of the first table are the row blocks.

Usage: python benchmarks/bench_periodic_pair.py [--size 512] [--fractions 1,0.12,0.02]
       [--rounds 30] [--reps 10] [--threads 1] [--out results/perf/periodic-pair/pair.md]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np
from csv_rows import host_name, refuse_bad_grid_sizes
from bench_surface_population import code_commit


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--fractions", default="1,0.12,0.02")
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    refuse_bad_grid_sizes(ap, "--size", [args.size])
    try:
        fractions = [float(f) for f in args.fractions.split(",")]
    except ValueError:
        ap.error(f"--fractions {args.fractions!r}: expected a comma list of numbers in (0, 1]")
    if not all(0.0 < f <= 1.0 for f in fractions) or args.rounds < 1 or args.reps < 1 or args.threads < 1:
        ap.error("--fractions must lie in (0, 1], --rounds, --reps and --threads be >= 1")
    os.environ["CONTACTBENCH_FFT_WORKERS"] = str(args.threads)
    from contactbench.harness.run.sequence import instances_of
    from contactbench.problems import fft_transform
    from contactbench.problems.scenes import SceneConfig, get_scene

    scene = get_scene("paper-sweep")
    (spec,) = scene.instances(scene.config(SceneConfig(size=args.size, steps=1, periodic=True, kernel="spectral")))
    H = next(iter(instances_of(scene.build(spec)))).qp.H
    rng = np.random.default_rng(0)
    default = fft_transform.WHOLE_PERIODIC_PAIR
    lines = [f"# One 2-D pair against the row blocks, periodic {args.size}^2 (benchmarks/bench_periodic_pair.py)", "",
             f"Host {host_name()}, {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, commit {code_commit()}, "
             f"{args.threads} FFT thread(s), {args.rounds} rounds of {args.reps} products, paths taking turns.", "",
             "| set / grid | points | precision | 2-D pair ms median (least) | row blocks ms median (least) | pair / blocks |",
             "|---:|---:|---|---:|---:|---:|"]
    for fraction in fractions:
        idx = np.sort(rng.choice(H.n, int(fraction * H.n), replace=False))
        op = H.restrict(idx).with_precision(np.float32)
        x = rng.random(idx.size)

        def use_pair(on: bool) -> None:
            fft_transform.WHOLE_PERIODIC_PAIR = on

        times = taking_turns(use_pair, lambda: op.matvec(x), args.rounds, args.reps)
        lines.append(f"| {fraction:g} | {idx.size} | float32 | {compared(times)} |")
    fft_transform.WHOLE_PERIODIC_PAIR = default
    lines += convolution_lines(args.size, args.rounds)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)


def convolution_lines(size: int, rounds: int) -> list[str]:
    """The float32 whole-grid convolution of a ``size``^2 grid with its rows in ``row_batch``
    calls (as the rule has it for long rows) and in one 2-D call each way (the row limit
    lifted), taking turns: a Markdown table."""
    from contactbench.problems import fft_threads

    rng = np.random.default_rng(1)
    f0 = rng.standard_normal((size, size)).astype(np.float32)
    m = rng.random((size, size // 2 + 1)).astype(np.float32)
    spec = np.empty(m.shape, np.complex64)
    f = f0.copy()
    limit = fft_threads.FLOAT32_LONG_ROW

    def batch_rows(on: bool) -> None:  # and a fresh input: the convolution overwrites it
        fft_threads.FLOAT32_LONG_ROW = 1 if on else 1 << 62
        np.copyto(f, f0)

    times = taking_turns(batch_rows, lambda: fft_threads.periodic_convolve(f, spec, m, fft_threads.fft_workers()),
                         rounds, 1)
    fft_threads.FLOAT32_LONG_ROW = limit
    return ["", f"The whole-grid float32 convolution (`periodic_convolve`), {size}^2, {rounds} rounds:", "",
            "| rows in batches of 8, ms median (least) | one 2-D call each way, ms median (least) | batched / 2-D |",
            "|---:|---:|---:|", f"| {compared(times)} |"]


def taking_turns(switch: Callable[[bool], None], run: Callable[[], object], rounds: int,
                 reps: int) -> dict[bool, list[float]]:
    """Milliseconds per ``run``, after ``switch(True)`` and ``switch(False)`` in turn: ``rounds``
    rounds of ``reps`` runs on each side (``switch`` is outside the clock)."""
    times: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(rounds):
        for on in (True, False):
            switch(on)
            t = time.perf_counter()
            for _ in range(reps):
                run()
            times[on].append((time.perf_counter() - t) / reps * 1e3)
    return times


def compared(times: dict[bool, list[float]]) -> str:
    """The table cells "on: median (least) | off: median (least) | on / off" of ``taking_turns``."""
    on, off = statistics.median(times[True]), statistics.median(times[False])
    return f"{on:.3f} ({min(times[True]):.3f}) | {off:.3f} ({min(times[False]):.3f}) | {on / off:.2f}"


if __name__ == "__main__":
    sys.exit(main())
