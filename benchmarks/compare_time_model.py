"""Each row of a run's table (results.csv) beside the static model's prediction for it (the skip
policy's problem_time_estimate on the row's own grid).  Run: .venv/bin/python benchmarks/compare_time_model.py RESULTS.csv ..."""
from __future__ import annotations
import sys
import pandas as pd
from contactbench.harness.run.skips import problem_time_estimate
from contactbench.solvers.base import ProblemTraits
from contactbench.solvers.registry import load_solver

for path in sys.argv[1:]:
    df = pd.read_csv(path)
    print(path)
    print(f"{'solver':<16} {'st':>2} {'n':>6} {'N':>5} {'status':<10} {'op':<5} {'sec':>8} {'pred':>9} {'pred/sec':>8} {'mv':>6} {'it':>6} {'ms/mv':>7}")
    for _, r in df.sort_values(["solver", "step"]).iterrows():
        op = r["operator"] if isinstance(r["operator"], str) else "fft"
        s = load_solver(r["base_solver"])
        caps = s.capabilities
        opk = "dense" if (caps.needs_dense or "fft" not in caps.operators) else "fft"
        tr = ProblemTraits(n=int(r["n"]), operator="fft", has_surface=True, surface_side=int(r["N"]),
                           periodic=bool(r["periodic"]))
        pred = problem_time_estimate(s, tr, opk)
        sec = r["solve_time_s"]
        ratio = pred / sec if pred is not None and sec and sec == sec else float("nan")
        mv = r["matvecs"]
        print(f"{r['solver']:<16} {r['step']:>2} {int(r['n']):>6} {int(r['N']):>5} {r['status']:<10} {opk:<5} "
              f"{sec:>8.3g} {pred if pred is not None else float('nan'):>9.3g} {ratio:>8.2f} {mv:>6.0f} {r['iterations']:>6.0f} "
              f"{1e3 * sec / mv if mv and mv == mv and sec == sec else float('nan'):>7.3f}"
              + ("  " + str(r["skip_reason"])[:90] if r["status"] == "skipped" else ""))
