"""The tidy table: one row per solve.  Column names here are a public contract
(reports, scripts and users depend on them) -- add columns, never rename.

Definitions
-----------
delta            far-field displacement Delta of the step, in the instance's length unit
                 (metres by default); NaN for scenes without one (counterexample).
n                trial-set size.
load             total force P = sum p_ij (N when E is in Pa and lengths in m).
contact_fraction elements with p_i > 1e-9 max(p), divided by all N^2 elements (A/A0).
kkt_error        the scaled figure from harness/kkt.py.
p_rel_error      ||p - p_ref||_inf / ||p_ref||_inf against the scene's reference.
load_rel_error   |P - P_ref| / |P_ref| against the reference solve (or the analytic
                 load where the scene has one and no reference solve ran).
status           the harness's verdict, one of STATUSES (never the solver's own claim,
                 which is in solver_status / solver_converged).
"""

from __future__ import annotations

from typing import Final

STATUSES: Final = ("solved", "inaccurate", "failed", "timeout", "crashed", "skipped")

#: The columns the issue fixes, in this order.
REQUIRED_COLUMNS: Final = (
    "scene",
    "instance",
    "step",
    "delta",
    "n",
    "solver",
    "profile",
    "repeat",
    "warm_start",
    "status",
    "skip_reason",
    "build_time_s",
    "solve_time_s",
    "iterations",
    "primal_residual",
    "dual_residual",
    "complementarity",
    "kkt_error",
    "load",
    "load_rel_error",
    "p_rel_error",
    "contact_fraction",
    "peak_mem_mb",
)

#: Further columns every row carries (NaN / "" where not applicable).
EXTRA_COLUMNS: Final = (
    "cell_id",  # stable hash of (scene, instance, step, solver, profile, repeat, params)
    "base_solver",  # registry name (``solver`` may be a labelled variant, e.g. "nnls-gp[K=50]")
    "params",  # JSON of the variant's solver parameters
    "family",  # solver family: paper, qp, fast, wrapper, reference
    "solver_status",  # the solver's own status string
    "solver_converged",  # the solver's own claim (bool)
    "solver_message",
    "correct_claim",  # solver_converged == (status == "solved")
    "check_tol",  # the profile's KKT tolerance used for the verdict
    "solve_time_min_s",  # min over repeats of this cell's group (filled at the end)
    "solve_time_median_s",
    "solver_internal_time_s",
    "setup_time_s",
    "matvecs",
    "complementarity_sum",
    "objective",
    "dim_load",  # P / (E A)
    "E",
    "nominal_area",
    "N",  # grid points per side
    "kernel",
    "periodic",
    "operator",  # "fft" or "dense": what the solver was given
    "reference_solver",
    "analytic_load",
    "analytic_load_rel_error",
    "time_limit_s",
    "error",  # exception text for failed / crashed rows
    "trace",  # JSON list of [iteration, elapsed_s, residual], possibly thinned
    "host",
    "timestamp",
    "history",  # "warm": the run warm-starts along load histories (default); "cold": --cold
)

ALL_COLUMNS: Final = REQUIRED_COLUMNS + EXTRA_COLUMNS
