"""The outside check: our exported QPs judged by qpbenchmark itself.

    .venv/bin/pip install -e .[qpbenchmark]
    .venv/bin/python benchmarks/bench_export_qpbenchmark.py [--out results/export] [--sizes 32,64]

1. ``contactbench export`` a small paper-sweep and the counterexample as a qpbenchmark
   test set (P = H, q = -ubar, lb = 0; problems named ``<instance>-step<k>``).
2. Run qpbenchmark's own runner (``qpbenchmark.run.run``) on it with a few of its
   solvers at its "mid_accuracy" settings (eps_abs = 1e-6, eps_rel = 0; verdict: found
   and primal, dual residuals and duality gap <= 1e-6).  qpbenchmark does not store
   objective values, so each solver is called once more through
   ``qpsolvers.solve_problem`` with the same settings for the objective 1/2 x'Px + q'x.
3. Run our harness on the same scenes with the same backends (``qp-<backend>``,
   profile ``mid``) and read its rows.
4. Write ``comparison.csv`` (one row per problem x backend) and ``comparison.md``
   (agreement counts and every disagreement) under --out.

Not part of the timed test suite (minutes of CPU).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from contactbench.problems.export import qpbenchmark_test_set

SOLVERS = ("clarabel", "osqp", "proxqp")
SETTINGS = "mid_accuracy"
PROFILE = "mid"


def scene_runs(sizes: list[int], steps: int) -> list[tuple[str, str, list[str]]]:
    """(label, scene, its scene options) of every part of the check."""
    runs = [(f"paper-sweep-N{n}", "paper-sweep", ["--size", str(n), "--steps", str(steps)]) for n in sizes]
    return runs + [("counterexample-n100", "counterexample", ["--size", "10", "--seeds", "0-4"])]


def export(out: Path, sizes: list[int], steps: int) -> dict[str, Path]:
    """The test sets (Parquet files) of the check, exported by the CLI."""
    paths = {}
    for label, scene, opts in scene_runs(sizes, steps):
        d = out / "testset" / label
        subprocess.run([sys.executable, "-m", "contactbench.harness.cli", "export", scene, *opts,
                        "--format", "qpbenchmark", "--out", str(d)], check=True)
        paths[label] = d / f"{scene}.parquet"
    return paths


def contact_test_set(parquet_paths: list[Path], out: Path):  # -> a qpbenchmark TestSet
    """One qpbenchmark test set over every exported Parquet file (concatenated: same layout)."""
    merged = out / "testset" / "all.parquet"
    pd.concat([pd.read_parquet(p, engine="pyarrow") for p in parquet_paths], ignore_index=True).to_parquet(
        merged, engine="pyarrow", index=False)
    return qpbenchmark_test_set(merged, description="contactbench export: paper-sweep and counterexample")


def run_qpbenchmark(test_set, out: Path) -> pd.DataFrame:
    from qpbenchmark.results import Results
    from qpbenchmark.run import run

    csv = out / "qpbenchmark_results.csv"
    if csv.exists():
        csv.unlink()
    results = Results(str(csv), test_set)
    for solver in SOLVERS:
        run(test_set, results, only_settings=SETTINGS, only_solver=solver)
    results.write()
    df = pd.read_csv(csv)
    tol = test_set.tolerances[SETTINGS]
    ok = (df["found"].astype(bool) & (df["primal_residual"] <= tol.primal) & (df["dual_residual"] <= tol.dual)
          & (df["duality_gap"] <= tol.gap) & (df["runtime"] <= tol.runtime))
    return df.assign(qpb_success=ok)


def qpbenchmark_objectives(test_set) -> pd.DataFrame:
    import qpsolvers

    from contactbench.problems.kkt import scaled_kkt_error

    rows = []
    settings = test_set.solver_settings[SETTINGS]
    for pb in test_set:
        for solver in SOLVERS:
            sol = qpsolvers.solve_problem(pb, solver=solver, **settings[solver])
            x = sol.x
            obj = float(0.5 * x @ pb.P @ x + pb.q @ x) if x is not None else np.nan
            kkt = (scaled_kkt_error(x, pb.P @ x + pb.q, -pb.q, float(np.max(np.diag(pb.P))))
                   if x is not None else np.nan)
            rows.append({"problem": pb.name, "solver": solver, "qpb_objective": obj, "qpb_x_our_kkt": kkt})
    return pd.DataFrame(rows)


def run_harness(out: Path, sizes: list[int], steps: int) -> pd.DataFrame:
    from contactbench.harness import load_table

    solvers = ",".join(f"qp-{s}" for s in SOLVERS)
    tables = []
    for label, scene, extra in scene_runs(sizes, steps):
        run_dir = out / f"harness-{label}"
        cmd = [sys.executable, "-m", "contactbench.harness.cli", "run", scene, *extra, "--solvers", solvers,
               "--profile", PROFILE, "--reference", "none", "--no-progress", "--no-warmup", "--cold",
               "--out", str(run_dir)]
        subprocess.run(cmd, check=True)
        tables.append(load_table(run_dir))
    t = pd.concat(tables, ignore_index=True)
    from contactbench.problems.export import problem_name

    return pd.DataFrame({
        "problem": [problem_name(i, int(k)) for i, k in zip(t["instance"], t["step"])],
        "solver": [str(s).removeprefix("qp-") for s in t["solver"]],
        "n": t["n"], "ours_status": t["status"], "ours_kkt_error": t["kkt_error"], "ours_objective": t["objective"],
    })


def compare(qpb: pd.DataFrame, obj: pd.DataFrame, ours: pd.DataFrame) -> pd.DataFrame:
    q = qpb[["problem", "solver", "found", "qpb_success", "primal_residual", "dual_residual", "duality_gap"]]
    df = ours.merge(q, on=["problem", "solver"], how="outer").merge(obj, on=["problem", "solver"], how="left")
    df["ours_success"] = df["ours_status"] == "solved"
    df["agree"] = df["ours_success"] == df["qpb_success"]
    df["qpb_x_passes_our_check"] = df["qpb_x_our_kkt"] <= 1e-6
    scale = np.maximum(np.abs(df["ours_objective"]), 1e-300)
    df["objective_rel_diff"] = np.abs(df["qpb_objective"] - df["ours_objective"]) / scale
    return df


def write_markdown(df: pd.DataFrame, path: Path) -> None:
    lines = ["# qpbenchmark vs contactbench on the exported QPs", "",
             f"qpbenchmark settings `{SETTINGS}` (eps_abs 1e-6; success = found and residuals, gap <= 1e-6); "
             f"contactbench profile `{PROFILE}` (scaled KKT <= 1e-6), cold starts.", "",
             "| solver | problems | both succeed | both fail | only qpbenchmark | only contactbench | "
             "median objective rel. diff | qpbenchmark's x passes our KKT check (<= 1e-6) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for solver, g in df.groupby("solver"):
        lines.append(f"| {solver} | {len(g)} | {int((g.ours_success & g.qpb_success).sum())} | "
                     f"{int((~g.ours_success & ~g.qpb_success).sum())} | {int((g.qpb_success & ~g.ours_success).sum())} | "
                     f"{int((g.ours_success & ~g.qpb_success).sum())} | {g.objective_rel_diff.median():.2e} | "
                     f"{int(g.qpb_x_passes_our_check.sum())} / {len(g)} |")
    dis = df[~df["agree"]]
    lines += ["", f"## Disagreements ({len(dis)})", "",
              "| problem | solver | n | ours (status, kkt) | qpbenchmark (found, primal, dual, gap) |",
              "| --- | --- | --- | --- | --- |"]
    for r in dis.itertuples():
        lines.append(f"| {r.problem} | {r.solver} | {r.n} | {r.ours_status}, {r.ours_kkt_error:.1e} | "
                     f"{r.found}, {r.primal_residual:.1e}, {r.dual_residual:.1e}, {r.duality_gap:.1e} |")
    path.write_text("\n".join(lines) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/export")
    ap.add_argument("--sizes", default="32,64", help="paper-sweep grid sizes (comma list)")
    ap.add_argument("--steps", type=int, default=3)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sizes = [int(x) for x in args.sizes.split(",")]
    paths = export(out, sizes, args.steps)
    test_set = contact_test_set(list(paths.values()), out)
    qpb = run_qpbenchmark(test_set, out)
    obj = qpbenchmark_objectives(test_set)
    ours = run_harness(out, sizes, args.steps)
    df = compare(qpb, obj, ours)
    df.to_csv(out / "comparison.csv", index=False)
    write_markdown(df, out / "comparison.md")
    print((out / "comparison.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
