"""Accuracy profiles: the harness's study design for "how accurate must an answer be".

A profile is a pair of numbers.  ``tol`` is what the harness hands a solver
(``SolverSettings.tol``; None lets each solver use its own ``default_tol``), and
``check_tol`` is the scaled KKT error (``contactbench.problems.kkt``) at or under which
the harness's judge counts an answer as solved.  Both go to the solver
(``Profile.solver_settings``): a solver that leaves its stopping test to a backend's
defaults (the QP adapters) derives the backend's tolerances from the check when no
``tol`` is asked, and claims only what meets it.  Solvers never see a profile's name.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from contactbench.solvers.base import Solver, SolverSettings


@dataclass(frozen=True)
class Profile:
    """A named accuracy target (see module doc)."""

    name: str
    tol: float | None
    check_tol: float
    #: whether a solver whose declared floor is above the check is skipped (``floor_skip``);
    #: False where every method runs as printed and the judge records what it reached
    skips_floors: bool = True

    def solver_settings(self, time_limit: float | None = None, params: dict[str, Any] | None = None,
                        max_iter: int | None = None) -> SolverSettings:
        """The settings a solve under this profile is handed: its ``tol`` and its
        ``check_tol`` (module doc), with the given limits and parameters."""
        return SolverSettings(tol=self.tol, max_iter=max_iter, time_limit=time_limit, params=dict(params or {}),
                              check_tol=self.check_tol)

    def floor_skip(self, solver: Solver) -> str | None:
        """Why ``solver`` is not run under this profile: its declared accuracy floor
        (``Capabilities.promise``, a scaled KKT error it cannot go below) is above this
        profile's check.  None: the check is within its reach."""
        floor = solver.capabilities.accuracy_floor
        if not self.skips_floors or floor is None or self.check_tol >= floor:
            return None
        return (f"{solver.name} declares an accuracy floor of {floor:g} (scaled KKT error); the {self.name} "
                f"profile checks {self.check_tol:g}, tighter than it can reach")


PROFILES: dict[str, Profile] = {
    "default": Profile("default", None, 1e-6),
    "low": Profile("low", 1e-3, 1e-3),
    "mid": Profile("mid", 1e-6, 1e-6),
    "high": Profile("high", 1e-9, 1e-8),
    # the paper's eps = 1e-8 handed to every solver (sec. 4), judged as ``default`` is; the
    # paper's methods run as printed whatever floor they declare (pk-printed's stop is not a
    # KKT test: its answers are timed and judged, inaccurate where the judge says so)
    "paper": Profile("paper", 1e-8, 1e-6, skips_floors=False),
}


class UnknownProfileError(ValueError):
    """A profile name that is not in ``PROFILES``."""


def get_profile(name: str) -> Profile:
    """The profile called ``name``, or an error listing the known ones."""
    try:
        return PROFILES[name]
    except KeyError:
        raise UnknownProfileError(f"unknown profile {name!r}; choose one of {', '.join(PROFILES)}") from None


#: The claims study's paper condition (harness/run/studies.py ``claims_parts``; the ledger,
#: harness/report/claim_tables.py, reads its rows by it): the dense H, the paper's
#: tolerance (profile "paper": eps = 1e-8), the paper's algorithms with their paper parameters (the registry defaults: NNLS+GP K =
#: 100, ADMM alpha 1.5; ADMM's rho = 1 as given, ``CLAIMS_ADMM_PAPER``, beside the registry's
#: relative rho).  P&K runs warm along the load history (paper-sweep) and cold ("P&K1999":
#: pk-printed, the printed Algorithm 2, and pk, Polonsky & Keer's own) on the same surface
#: and steps as independent solves (greedy-linear-solvers with the paper-sweep seed and 10
#: steps: the same instances).
CLAIMS_DENSE_PROFILE = "paper"
#: Our condition: FFT operators, each solver's own tolerance, the fast solvers beside the paper's.
CLAIMS_FFT_PROFILE = "default"
