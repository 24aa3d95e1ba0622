"""What a device partial product costs beside a device matvec: the break-even of
``partial_product_pays`` on a GPU.  On the paper-sweep scene's cold top step at --size
(``--operator gpu``), times, synchronised and each the median of --repeats, one matvec in
float32 and in float64 and the partial products H[rows, cols] x of a third of the unknowns
(sorted, as the gap's rows are) against --cols raised points, by the fused kernel and by
the chunked array operations (``operators_gpu.FUSED_GATHER``); prints one line per case
and writes them to --out as CSV: the entries per P log2 P (P: the padded grid's points),
the form ``partial_product_pays`` compares with ``operators.PARTIAL_PRODUCT_FACTOR``.

Usage: python benchmarks/bench_device_partial.py [--size 4096] [--cols 16 256 4096 65536]
       [--repeats 5] [--out results/perf/gpu/device-partial.csv]
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path
from statistics import median
from typing import Any, Callable

import numpy as np

from bench_cost_law import top_step
from csv_rows import host_name, refuse_bad_grid_sizes, refuse_missing_device


def device_seconds(run: Callable[[], Any], sync: Callable[[], None], repeats: int) -> float:
    """Median seconds of ``run`` (after one untimed call), the device synchronised around each."""
    run()
    sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        sync()
        times.append(time.perf_counter() - t0)
    return median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=4096)
    ap.add_argument("--cols", type=int, nargs="+", default=[16, 256, 4096, 65536])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=Path("results/perf/gpu/device-partial.csv"))
    args = ap.parse_args()
    refuse_bad_grid_sizes(ap, "--size", [args.size])
    if args.repeats < 1 or min(args.cols) < 1:
        ap.error("--repeats and every --cols must be >= 1")
    refuse_missing_device(ap, "gpu")
    from contactbench.problems import operators_gpu

    inst, recipe = top_step(args.size, 10, "gpu")
    H = inst.qp.H
    space = H.space
    sync = space.xp.cuda.Device().synchronize
    rng = np.random.default_rng(0)
    x_dev = space.put(rng.random(H.n))
    P = int(np.prod(H.transform.padded_shape))
    plogp = P * np.log2(P)
    mv = {name: device_seconds(lambda op=H.with_precision(dt): op.matvec(x_dev.astype(dt)), sync, args.repeats)
          for name, dt in (("float32", np.float32), ("float64", np.float64))}
    rows = space.put(np.sort(rng.choice(H.n, H.n // 3, replace=False)))
    out_rows = []
    for ncols in args.cols:
        cols = space.put(rng.choice(H.n, min(ncols, H.n), replace=False))
        amounts = space.put(rng.random(min(ncols, H.n)))
        row: dict[str, Any] = {"N": args.size, "n": H.n, "rows": H.n // 3, "cols": min(ncols, H.n),
                               "entries_per_plogp": H.n // 3 * min(ncols, H.n) / plogp,
                               "matvec32_s": mv["float32"], "matvec64_s": mv["float64"]}
        for fused in (True, False):
            operators_gpu.FUSED_GATHER = fused
            row["fused_s" if fused else "chunks_s"] = device_seconds(
                lambda: H.partial_product(rows, cols, amounts), sync, args.repeats)
        operators_gpu.FUSED_GATHER = True
        row["host"] = host_name()
        out_rows.append(row)
        print(f"{recipe} rows {row['rows']} cols {row['cols']}: entries/PlogP {row['entries_per_plogp']:.4f} "
              f"fused {row['fused_s'] * 1e3:.2f} ms chunks {row['chunks_s'] * 1e3:.2f} ms; matvec f32 "
              f"{mv['float32'] * 1e3:.2f} ms f64 {mv['float64'] * 1e3:.2f} ms", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(out_rows[0]))
        w.writeheader()
        w.writerows(out_rows)


if __name__ == "__main__":
    main()
