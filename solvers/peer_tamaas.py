"""Tamaas (Frérot, Anciaux & Molinari, ``pip install contactbench[peers]``) as registered
solvers, judged raw by our KKT check.

What Tamaas can pose exactly (solvers/_peers.py: the QP on the full grid, E* = E, nu = 0):

* periodic ``spectral`` -- its periodic Westergaard operator is 2/(E*|q|) (our spectral
  kernel); the rigid offset is its free mean mode, so displacement control is the target
  mean gap -mean(U);
* non-periodic ``love`` -- ``ModelFactory.registerNonPeriodic`` is Love's uniformly
  loaded square, identical to our ``love`` table (to 6e-15; it freezes E when called, so
  it is registered after E is set).  That operator serves only load control
  (PolonskyKeerRey pressure/pressure; gap control returns p = 0), so the load is searched
  for (``load_for_offset``): regula falsi on the total load P until Tamaas' implied rigid
  offset c(P) = mean over the contact of (u - U) is zero within tol x max(ubar); each
  step is one cold Tamaas solve, all counted in the solve time.

It has no BCC kernel, no periodic real-space (``bcc``, ``love``) kernel and no elastic
layer of finite thickness: ``skip`` says so for those.  Rectangular pixels (two
spacings) it poses: its model takes the system size [L0, L1] (``GridProblem.sizes``),
and a pressure is turned into an element's force by the element's area d0 d1.

tamaas-pkr
    ``tamaas.PolonskyKeerRey`` -- Polonsky & Keer, Wear 231 (1999) 206, with Rey, Anciaux
    & Molinari, Comput. Mech. 60 (2017) 69 (the dual/primal functional variants).
    Periodic: displacement control, primal variable ``params["primal"]`` (gap or
    pressure).  Non-periodic Love: pressure/pressure under the load search.
tamaas-kato
    ``tamaas.Kato`` -- Kato's projected-gradient method on the pressure (Kato, "Tamaas"
    frictional module; Coulomb friction with mu = 0 here), load control.
tamaas-beck-teboulle
    ``tamaas.BeckTeboulle`` -- FISTA (Beck & Teboulle, SIAM J. Imaging Sci. 2 (2009)
    183) on the pressure, mu = 0, load control.
tamaas-condat
    ``tamaas.Condat`` -- Condat's primal-dual splitting (J. Optim. Theory Appl. 158
    (2013) 460), mu = 0, load control.

Load control (``problems.constraints``): tamaas-pkr poses it natively (periodic:
PolonskyKeerRey pressure/pressure at the mean pressure P / A; non-periodic Love: the
same, without the load search), and so do the three frictional solvers below, at the
QP's own load.  Hardness: ``tamaas.KatoSaturated`` (``tamaas-kato-saturated``; Kato's
projected gradient with the pressure capped at pmax = the bound / delta^2), periodic
spectral under load control only; on a flat field, where KatoSaturated does not return,
the adapter answers without it (``flat_field_outcome``).  The approach Delta is fitted
from the answer.  The
four first-order solvers run in reduced units (``reduced_units``: E* = 1, L0 = 1); PKR in SI.

The three load-controlled solvers (periodic spectral only, Tamaas' ``surface_2d`` model)
on a displacement-controlled QP get the load P that Tamaas' own PolonskyKeerRey finds
under displacement control on the same problem (time counted); a load-controlled exact answer at that P is the
displacement-controlled answer.  Their claim is Tamaas' own figure (``_cost``: its
``computeError``, else the returned error, else ``computeCost``) <= tol.  Tamaas reports
no iteration count (``ITERATIONS_NOT_REPORTED``).  None supports a warm start (warm_start
"none").
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from contactbench.problems.errors import ProblemInputError

from ._peers import GridProblem, PeerSolver, grid_problem, package_availability
from .base import Capabilities, Outcome, Param, ProblemTraits, SolveContext, Status
from .registry import register


def tamaas_serves(kernel: str, periodic: bool, layer: bool = False) -> str | None:
    """None when Tamaas has exactly this kernel, else the reason it cannot pose it (its
    surface operators are the half-space's: an elastic layer of finite thickness is not
    among them)."""
    if layer:
        return ("Tamaas cannot pose an elastic layer of finite thickness (its surface operators are the "
                "half-space's: periodic 2/(E*|q|), non-periodic Love)")
    if periodic and kernel == "spectral" or (not periodic and kernel == "love"):
        return None
    if kernel == "bcc":
        return "Tamaas has no BCC kernel (only its periodic Westergaard 2/(E*|q|) and non-periodic Love operators)"
    return (f"Tamaas cannot pose the {'periodic' if periodic else 'non-periodic'} {kernel!r} kernel exactly "
            "(its operators: periodic 2/(E*|q|), non-periodic Love)")


def _model(gp: GridProblem, kind: str = "basic_2d", reduced: bool = False) -> Any:
    """Tamaas' model of ``gp``: in SI units, or ``reduced`` (``reduced_units``)."""
    import tamaas as tm

    tm.set_log_level(tm.LogLevel.error)
    L0, E = reduced_units(gp) if reduced else (1.0, 1.0)
    model = tm.ModelFactory.createModel(getattr(tm.model_type, kind), [x / L0 for x in gp.sizes], list(gp.shape))
    model.E, model.nu = gp.E / E, 0.0  # E* = E / (1 - nu^2) = E
    return model


def reduced_units(gp: GridProblem) -> tuple[float, float]:
    """(length, pressure) units of the reduced posing: the side L0 along axis 0 and E*, so
    that the model has E* = 1 and L0 = 1 (heights / L0, pressures / E*; small-slope
    elasticity is unchanged by the scaling).  Tamaas' Kato, BeckTeboulle and Condat take
    steps that are not scale-free: in SI units Condat diverges
    (``test_tamaas_condat_posed_in_si_units_diverges``)."""
    return float(gp.sizes[0]), float(gp.E)


def reduced_surface(gp: GridProblem) -> np.ndarray:
    """The heights U in the reduced posing's length unit (``reduced_units``)."""
    return np.ascontiguousarray(gp.U / reduced_units(gp)[0])


def _normal_traction(model: Any, gp: GridProblem) -> np.ndarray:
    t = np.asarray(model.traction, dtype=np.float64)
    if t.ndim == 3:  # surface_2d: (N1, N2, 3), the normal component last
        t = t[..., -1]
    return t.reshape(gp.shape) * gp.area  # pressure -> force per element


def _cost(solver: Any, returned: Any) -> float:
    """Tamaas' own error figure of a finished solve: its ``computeError`` where the solver
    has one (the PolonskyKeerRey family, KatoSaturated among them, whose solve returns 0.0
    whether it converged or was stopped at max_iter), else the value its solve returned
    (BeckTeboulle's error), else its ``computeCost`` (Kato and Condat return nothing)."""
    if hasattr(solver, "computeError"):
        return float(solver.computeError())
    if returned is not None:
        return float(returned)
    try:
        return float(solver.computeCost(False))
    except TypeError:
        return float(solver.computeCost())


def pkr_displacement_control(gp: GridProblem, tol: float, max_iter: int, primal: str) -> tuple[np.ndarray, float]:
    """Periodic PolonskyKeerRey at the rigid offset of U: (force field, Tamaas' error)."""
    import tamaas as tm

    model = _model(gp)
    kind = getattr(tm.PolonskyKeerRey, primal)
    solver = tm.PolonskyKeerRey(model, np.ascontiguousarray(gp.U), tol, kind, tm.PolonskyKeerRey.gap)
    solver.max_iter = max_iter
    err = solver.solve(-float(np.mean(gp.U)))  # zero-mean H: mean gap = -mean(U) at offset 0
    return _normal_traction(model, gp), float(err)


def pkr_periodic_load(gp: GridProblem, tol: float, max_iter: int, load: float) -> tuple[np.ndarray, float]:
    """Periodic PolonskyKeerRey (pressure/pressure) at total load ``load``: (force field, error)."""
    import tamaas as tm

    model = _model(gp)
    solver = tm.PolonskyKeerRey(model, np.ascontiguousarray(gp.U), tol, tm.PolonskyKeerRey.pressure,
                                tm.PolonskyKeerRey.pressure)
    solver.max_iter = max_iter
    err = solver.solve(load / (gp.sizes[0] * gp.sizes[1]))
    return _normal_traction(model, gp), float(err)


def pkr_nonperiodic_load(gp: GridProblem, tol: float, max_iter: int, load: float) -> tuple[np.ndarray, float]:
    """Non-periodic (Love) PolonskyKeerRey at total load ``load``: (force field, error)."""
    import tamaas as tm

    model = _model(gp)
    tm.ModelFactory.registerNonPeriodic(model, "contactbench-love")  # after E is set: it freezes E
    solver = tm.PolonskyKeerRey(model, np.ascontiguousarray(gp.U), tol, tm.PolonskyKeerRey.pressure,
                                tm.PolonskyKeerRey.pressure)
    solver.setIntegralOperator("contactbench-love")
    solver.max_iter = max_iter
    err = solver.solve(load / (gp.sizes[0] * gp.sizes[1]))
    return _normal_traction(model, gp), float(err)


def implied_offset(gp: GridProblem, table_apply: Callable[[np.ndarray], np.ndarray], force: np.ndarray) -> float:
    """Tamaas' rigid offset of a load-controlled answer: mean of (Hp - U) over its contact."""
    contact = force > 0.0
    if not np.any(contact):
        return -float(np.max(gp.U))
    return float(np.mean((table_apply(force) - gp.U)[contact]))


def load_for_offset(offset_at: Callable[[float], float], guess: float, tol: float,
                    max_solves: int = 60) -> tuple[float, int]:
    """The load P with offset_at(P) = 0 within ``tol`` (offset_at increases with P):
    bracket by doubling/halving from ``guess``, then Illinois regula falsi.  Returns
    (P, solves)."""
    solves = 0

    def f(P: float) -> float:
        nonlocal solves
        solves += 1
        return offset_at(P)

    a, fa = guess, f(guess)
    if abs(fa) <= tol:
        return a, solves
    b, fb = a, fa
    while fa * fb > 0 and solves < max_solves:
        b = b * 2.0 if fb < 0 else b / 2.0
        fb = f(b)
    side = 0
    while solves < max_solves and abs(fb) > tol and abs(b - a) > 1e-15 * abs(b):
        c = b - fb * (b - a) / (fb - fa)
        fc = f(c)
        if fc * fb < 0:
            a, fa = b, fb
            side = 0
        else:
            fa = fa / 2.0 if side == 1 else fa
            side = 1
        b, fb = c, fc
    return b, solves


class _TamaasSolver(PeerSolver):
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none")

    def availability(self) -> tuple[bool, str]:
        return package_availability("tamaas", "Tamaas")

    def skip(self, traits: ProblemTraits) -> str | None:
        return super().skip(traits) or tamaas_serves(traits.kernel, traits.periodic, traits.layer)

    def posed(self, ctx: SolveContext) -> GridProblem:
        gp = grid_problem(ctx.qp)
        why = tamaas_serves(gp.kernel, gp.periodic, gp.layer is not None)
        if why is not None:
            raise ProblemInputError(why)
        return gp


#: What a Tamaas outcome says of its iterations: Tamaas' solver objects expose no count
#: (their solve returns an error figure or nothing), and the table they print -- every
#: ``dump_freq`` iterations, only at its info log level, from its C++ side -- is no count
#: either.  The outcome's ``iterations`` is then 0 (the field is a whole number) and
#: ``info["peer_iterations"]`` is None: unknown, not zero.
ITERATIONS_NOT_REPORTED = "Tamaas reports no iteration count"


def tamaas_outcome(gp: GridProblem, force: np.ndarray, cost: float, tol: float, info: dict[str, Any]) -> Outcome:
    """Tamaas' raw answer on the trial set and its own claim (cost <= tol); its iteration
    count unknown (``ITERATIONS_NOT_REPORTED``)."""
    p = gp.on_set(force)
    off = gp.force_off_set(force)
    claimed = bool(np.isfinite(cost) and cost <= tol)
    status = Status.FAILED if not np.all(np.isfinite(p)) else (None if claimed else Status.MAX_ITER)
    note = (f"Tamaas error {cost:.2e} {'<=' if claimed else '>'} tol {tol:.0e}; {ITERATIONS_NOT_REPORTED}"
            + (f"; force off the trial set {off:.1e} of max" if off > 0 else ""))
    return Outcome(p, 0, claimed, note, status=status,
                   info={**info, "peer_error": cost, "peer_iterations": None, "force_off_set": off})


@register
class TamaasPKR(_TamaasSolver):
    """Tamaas' PolonskyKeerRey (Polonsky & Keer 1999; Rey et al. 2017): periodic spectral
    under displacement control, non-periodic Love under the load search (module doc).
    Warm start: none."""

    name = "tamaas-pkr"
    description = "Tamaas: PolonskyKeerRey CG (periodic 2/(E*|q|); non-periodic Love by load search) [peers extra]"
    params = (Param("primal", str, "gap", "periodic: the primal variable of the functional",
                    choices=("gap", "pressure")),)
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none", load_control=True)

    def iterate(self, ctx: SolveContext) -> Outcome:
        gp = self.posed(ctx)
        tol, max_iter = float(ctx.tol), int(ctx.max_iter)
        if ctx.constraints.load_control:
            load = float(ctx.constraints.load)  # type: ignore[arg-type]
            force, err = (pkr_periodic_load(gp, tol, max_iter, load) if gp.periodic
                          else pkr_nonperiodic_load(gp, tol, max_iter, load))
            return tamaas_outcome(gp, force, err, tol, {"posing": "load control (native)", "load": load})
        if gp.periodic:
            force, err = pkr_displacement_control(gp, tol, max_iter, ctx.params["primal"])
            return tamaas_outcome(gp, force, err, tol, {"posing": "displacement control"})
        H = ctx.qp.H
        table = gp.table(ctx.qp)
        from contactbench.problems.operators import KernelTransform

        transform = KernelTransform(table, gp.shape)

        def apply(force: np.ndarray) -> np.ndarray:
            ctx.add_matvecs(1)
            return transform.convolve_physical(np.array(force, copy=True))

        last: dict[str, Any] = {}

        def offset_at(P: float) -> float:
            force, err = pkr_nonperiodic_load(gp, tol, max_iter, P)
            last.update(force=force, err=err, load=P)
            return implied_offset(gp, apply, force)

        guess = float(np.max(gp.ubar)) / float(np.max(H.diagonal()))
        P, solves = load_for_offset(offset_at, guess, tol * float(np.max(gp.ubar)))
        if last.get("load") != P:
            offset_at(P)
        return tamaas_outcome(gp, last["force"], last["err"], tol,
                              {"posing": "load control, load searched", "load_solves": solves, "load": P})


class _TamaasLoadControlled(_TamaasSolver):
    """A Tamaas frictional solver at mu = 0 under load control (module doc)."""

    tamaas_class: str = ""
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none", load_control=True)

    def default_max_iter(self, n: int) -> int | None:
        return None  # Tamaas' own limit (its default max_iter)

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why is None and not traits.periodic:
            return f"Tamaas' {self.tamaas_class} runs on its periodic surface model only"
        return why

    def make(self, tm: Any, model: Any, gp: GridProblem, tol: float, ctx: SolveContext) -> Any:
        """The Tamaas solver object (mu = 0), in reduced units."""
        return getattr(tm, self.tamaas_class)(model, reduced_surface(gp), tol, 0.0)

    def run(self, solver: Any, mean_pressure: float) -> Any:
        return solver.solve([0.0, 0.0, mean_pressure])

    def without_tamaas(self, gp: GridProblem, ctx: SolveContext) -> Outcome | None:
        """The answer to a problem Tamaas' solver cannot be called on, given by the adapter
        (None: call it)."""
        return None

    def iterate(self, ctx: SolveContext) -> Outcome:
        import tamaas as tm

        gp = self.posed(ctx)
        if not gp.periodic:
            raise ProblemInputError(f"Tamaas' {self.tamaas_class} runs on its periodic surface model only")
        answered = self.without_tamaas(gp, ctx)
        if answered is not None:
            return answered
        tol = float(ctx.tol)
        if ctx.constraints.load_control:
            load, calib_err = float(ctx.constraints.load), None  # type: ignore[arg-type]
        else:
            calib, calib_err = pkr_displacement_control(gp, tol, 100_000, "gap")
            load = float(np.sum(calib))
        ctx.mark_setup_done()
        E = reduced_units(gp)[1]
        model = _model(gp, "surface_2d", reduced=True)
        solver = self.make(tm, model, gp, tol, ctx)
        if ctx.max_iter is not None:
            solver.max_iter = int(ctx.max_iter)
        returned = self.run(solver, load / (gp.sizes[0] * gp.sizes[1]) / E)
        force = _normal_traction(model, gp) * E
        return tamaas_outcome(gp, force, _cost(solver, returned), tol,
                              {"posing": "load control at the load of Tamaas' PKR, in reduced units (E* = L0 = 1)",
                               "load": load, "calibration_error": calib_err})


@register
class TamaasKato(_TamaasLoadControlled):
    """Tamaas' Kato projected-gradient solver (mu = 0), load control at the load of
    Tamaas' PolonskyKeerRey (module doc).  Warm start: none."""

    name = "tamaas-kato"
    description = "Tamaas: Kato projected gradient on the pressure, mu = 0, load control [peers extra]"
    tamaas_class = "Kato"


@register
class TamaasBeckTeboulle(_TamaasLoadControlled):
    """Tamaas' BeckTeboulle solver (FISTA, Beck & Teboulle 2009; mu = 0), load control at
    the load of Tamaas' PolonskyKeerRey (module doc).  Warm start: none."""

    name = "tamaas-beck-teboulle"
    description = "Tamaas: Beck-Teboulle (FISTA) on the pressure, mu = 0, load control [peers extra]"
    tamaas_class = "BeckTeboulle"


@register
class TamaasCondat(_TamaasLoadControlled):
    """Tamaas' Condat primal-dual solver (Condat 2013; mu = 0), load control at the load of
    Tamaas' PolonskyKeerRey (module doc).  Warm start: none."""

    name = "tamaas-condat"
    description = "Tamaas: Condat primal-dual splitting, mu = 0, load control [peers extra]"
    tamaas_class = "Condat"


@register
class TamaasKatoSaturated(_TamaasLoadControlled):
    """Tamaas' KatoSaturated: Kato's projected gradient with the pressure capped at a
    hardness pmax (the bound / delta^2), periodic spectral under load control only
    (module doc).  Warm start: none."""

    name = "tamaas-kato-saturated"
    description = "Tamaas: KatoSaturated, Kato with pressures capped by a hardness, load control [peers extra]"
    tamaas_class = "KatoSaturated"
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="none", load_control=True,
                                bounds=True)

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why is None and not traits.load_control:
            return "Tamaas' KatoSaturated poses load control only"
        return why

    def without_tamaas(self, gp: GridProblem, ctx: SolveContext) -> Outcome | None:
        """A load-controlled flat field U (every height equal), where KatoSaturated's solve
        never returns whatever its ``max_iter``, answered by the adapter
        (``flat_field_outcome``); else None."""
        if ctx.constraints.load_control and float(np.ptp(gp.U)) == 0.0:
            return flat_field_outcome(gp, ctx)
        return None

    def make(self, tm: Any, model: Any, gp: GridProblem, tol: float, ctx: SolveContext) -> Any:
        c = ctx.constraints
        if not c.load_control:
            raise ProblemInputError("Tamaas' KatoSaturated poses load control only")
        u = c.upper_or_inf(ctx.n)
        if not np.all(u == u[0]):
            raise ProblemInputError("Tamaas' KatoSaturated takes one hardness for every element")
        pmax = float(u[0]) / gp.area / reduced_units(gp)[1] if np.isfinite(u[0]) else float(np.finfo(float).max)
        return tm.KatoSaturated(model, reduced_surface(gp), tol, pmax)


#: Why ``tamaas-kato-saturated`` does not call Tamaas on a flat field (``flat_field_outcome``).
FLAT_FIELD_NOTE = ("flat field (every height equal): Tamaas' KatoSaturated does not return on it whatever its "
                   "max_iter, so it was not called")


def flat_field_outcome(gp: GridProblem, ctx: SolveContext) -> Outcome:
    """The answer to a load-controlled periodic QP on a flat field without Tamaas: on the
    whole grid the kernel is mean-free (H 1 = 0), so the uniform force P / n with Delta
    = -ubar is exact (0 <= P / n <= the uniform bound: the load fits, ``Constraints.check``);
    on a proper subset of the grid no answer is claimed (FAILED, p = NaN).  Zero
    iterations; ``info["answered_by_adapter"]`` says who answered."""
    info = {"posing": FLAT_FIELD_NOTE, "answered_by_adapter": True}
    if gp.indices.size != gp.U.size:
        return Outcome(np.full(ctx.n, np.nan), 0, False, f"{FLAT_FIELD_NOTE}; on a proper subset of the grid the "
                       "uniform force is not the answer", status=Status.FAILED, info=info)
    load = float(ctx.constraints.load)  # type: ignore[arg-type]
    p = np.full(ctx.n, load / ctx.n)
    return Outcome(p, 0, True, f"{FLAT_FIELD_NOTE}; the uniform force P / n is exact on the mean-free periodic kernel",
                   multiplier=-float(gp.ubar[0]), info={**info, "load": load})
