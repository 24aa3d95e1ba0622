"""ContactMechanics (the contact.engineering group's code, ``pip install contactbench[peers]``)
as registered solvers, judged raw by our KKT check.

cm-dual-ccg
    ContactMechanics' "dual" constrained CG: ``NonSmoothContactSystem.dual_minimize_proxy``
    (NuMPI's ``CCGWithoutRestart``), the algorithm of Bugnicourt, Sainsot, Dureisseix,
    Gauthier & Lubrecht, Tribol. Lett. 66 (2018) 29, on the pixel forces (gradient = gap).
    ``params={"variant": "with-restart"}`` runs NuMPI's ``CCGWithRestart`` instead.
    Stops on its own test max|projected gap| <= gtol, with gtol = tol * max(ubar) (our
    scaled dual residual).  Warm start: primal (``init_force``).
cm-pk-ccg
    ContactMechanics' Polonsky-Keer constrained CG (Polonsky & Keer, Wear 231 (1999) 206):
    ``ContactMechanics.Optimization.constrained_conjugate_gradients`` at a fixed offset.
    Its own test: rms and max penetration and max change of u below pentol =
    tol * max(ubar), tensile force below forcetol = tol * max(ubar) / max diag H, relative
    change of the total force below thermotol = tol.  Warm start: primal
    (``initial_forces``).

Kernels (``params={"green": ...}``):

* ``"auto"`` (default) -- ContactMechanics' own Green's function where it has the
  scene's kernel: ``FreeFFTElasticHalfSpace`` (Love's uniformly loaded square, Johnson
  eq. 3.25) for a non-periodic ``love`` scene, ``PeriodicFFTElasticHalfSpace`` with
  ``stiffness_q0=0`` (2/(E*|q|), mean mode removed) for a periodic ``spectral`` scene;
  everywhere else (``bcc``, periodic ``love``/``bcc``) our influence coefficients;
* ``"ours"`` -- always our influence coefficients (the operator's circulant table), put
  into ContactMechanics through its Green's-function hook ``_compute_greens_function``.

An elastic layer of finite thickness (``problems.layers``) is posed with our table,
which carries it ("auto" picks "ours" then).  Rectangular pixels (two spacings) are posed
as they are: ContactMechanics' half-spaces take ``physical_sizes`` (L0, L1) with the grid
(``GridProblem.sizes``), and its Love kernel is the uniformly loaded d0 x d1 rectangle.

Load control and hardness: cm-pk-ccg poses both natively (``native_control``): its
``external_force`` is the load P (its returned ``offset`` is the approach Delta, reported
as the multiplier), its ``hardness`` the per-pixel force bound -- except load control on
the periodic domain, which it skips (``PERIODIC_LOAD_SKIP``), and a load within one
element of every element plastic, which it cannot pose (``SATURATED_LOAD_SKIP``).  cm-dual-ccg poses
neither (its ``dual_minimize_proxy`` takes an offset only) and is skipped on them.

Either way ContactMechanics solves exactly our problem (solvers/_peers.py: the QP posed on
the full grid); its force field on the trial set is judged as it comes.  At ``max_iter`` 0
neither is called (the lifecycle answers it: ``base.ZERO_LIMIT_NOTE``; ContactMechanics
fails on a zero limit: its PK CG reads a value it never set, its dual CCG returns no
result).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from contactbench.problems.constraints import Constraints
from contactbench.problems.kkt import constrained_scales

from ._peers import GridProblem, PeerSolver, captured, full_field, grid_problem, package_availability
from .base import Capabilities, Outcome, Param, ProblemTraits, SolveContext, Status
from .registry import register

GREEN_CHOICES = ("auto", "ours")
#: Why cm-pk-ccg does not pose periodic load control.  Our periodic kernel is mean-free
#: (ContactMechanics' ``stiffness_q0=0``); its force-controlled PK then returns its uniform
#: first iterate after one iteration, claiming convergence (the uniform pressure displaces
#: nothing, so no offset is found: offset 0 on a 32^2 periodic RMD surface, judged wrong at a
#: scaled KKT error of 0.48), while with a q = 0 stiffness it converges in 25 -- on another
#: problem than ours.
PERIODIC_LOAD_SKIP = ("cm-pk-ccg does not pose periodic load control on our mean-free kernel: ContactMechanics' "
                      "force-controlled PK with stiffness_q0 = 0 stops after one iteration at its uniform start "
                      "(a q = 0 stiffness would pose another problem)")

#: Why cm-pk-ccg does not pose a load above (n - 1) elements at a uniform bound h.  Where its
#: CG area vanishes it relaxes the contact area, finding the offset by bisection on
#: #(g < offset) h - P between max(g) and min(g): at most (n - 1) h - P at max(g), so for
#: P > (n - 1) h no sign change -- scipy's ``bisect`` raises ValueError (plastic-sweep under
#: load control, 8^2 and 16^2: it raises at P = (n - 0.99) h, not at (n - 1.01) h).
SATURATED_LOAD_SKIP = ("cm-pk-ccg does not pose a load above what all elements but one carry at their bound: "
                       "ContactMechanics' plastic-area bisection for the offset has no sign change there "
                       "(scipy bisect raises)")


#: Why cm-pk-ccg is not run on a periodic real-space kernel.  On our mean-free periodic
#: 'love' and 'bcc' tables its first iterate is p = 0 and it runs to its iteration limit
#: ("Reached maxiter", scaled KKT error 0.31 at 16^2 and 32^2; a 16^2 step timed out at 30 s),
#: where cm-dual-ccg and the periodic 'spectral' kernel converge.
PERIODIC_REAL_SPACE_SKIP = ("cm-pk-ccg does not converge on a periodic real-space kernel ('love', 'bcc') as we pose "
                            "it (mean-free): it stays at p = 0 until its iteration limit; it is run on the periodic "
                            "'spectral' kernel and on non-periodic grids")


def native_green(kernel: str, periodic: bool, layer: bool = False) -> bool:
    """Whether ContactMechanics has this kernel as its own Green's function (on a
    half-space: with an elastic layer our table, which carries it, is used instead)."""
    return not layer and ((kernel == "love" and not periodic) or (kernel == "spectral" and periodic))


def _counting(cls: type, gp: GridProblem) -> type:
    """``cls`` with its products counted (``evaluate_disp`` and ``evaluate_force``) and,
    non-periodic, the 2N1 x 2N2 computational grid that FreeFFTElasticHalfSpace sets only
    for itself (not for a subclass)."""

    class Counting(cls):  # type: ignore[misc, valid-type]
        products = 0

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            if not gp.periodic:
                self._comp_nb_grid_pts = (2 * gp.shape[0], 2 * gp.shape[1])
            super().__init__(*args, **kwargs)

        def evaluate_disp(self, forces: Any) -> Any:
            type(self).products += 1
            return super().evaluate_disp(forces)

        def evaluate_force(self, disp: Any) -> Any:
            type(self).products += 1
            return super().evaluate_force(disp)

    return Counting


def cm_substrate(gp: GridProblem, table: np.ndarray | None) -> Any:
    """A ContactMechanics half-space for ``gp``: its own (``table`` None) or with our
    influence coefficients ``table`` (m per N, the operator's circulant layout)."""
    from ContactMechanics import FreeFFTElasticHalfSpace, PeriodicFFTElasticHalfSpace

    base = PeriodicFFTElasticHalfSpace if gp.periodic else FreeFFTElasticHalfSpace
    counting = _counting(base, gp)
    if table is None:
        if gp.periodic:
            return counting(gp.shape, gp.E, physical_sizes=gp.sizes, stiffness_q0=0.0)
        return counting(gp.shape, gp.E, physical_sizes=gp.sizes)

    class OurGreen(counting):  # type: ignore[misc, valid-type]
        """ContactMechanics' half-space with our influence coefficients as Green's function
        (evaluate_disp divides by the pixel area: the force kernel times the area)."""

        def __init__(self) -> None:
            kwargs = {"stiffness_q0": 0.0} if gp.periodic else {}
            super().__init__(gp.shape, gp.E, physical_sizes=gp.sizes, **kwargs)

        def _compute_greens_function(self) -> np.ndarray:
            self.real_buffer.p[...] = table * self.area_per_pt
            self.fftengine.fft(self.real_buffer, self.fourier_buffer)
            return self.fourier_buffer.p.copy()

    return OurGreen()


class _CMSolver(PeerSolver):
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="primal", needs_geometry=False)

    def availability(self) -> tuple[bool, str]:
        ok, why = package_availability("ContactMechanics", "ContactMechanics")
        if ok:
            ok2, why2 = package_availability("SurfaceTopography", "SurfaceTopography")
            return (ok2, why if ok2 else why2)
        return ok, why

    def time_estimate(self, n: int, operator_kind: str) -> float | None:
        return None

    def posed(self, ctx: SolveContext) -> tuple[GridProblem, Any, str]:
        gp = grid_problem(ctx.qp)
        ours = ctx.params["green"] == "ours" or not native_green(gp.kernel, gp.periodic, gp.layer is not None)
        sub = cm_substrate(gp, gp.table(ctx.qp) if ours else None)
        return gp, sub, ("ours" if ours else "contactmechanics")

    def tolerance(self, ctx: SolveContext, gp: GridProblem) -> float:
        """The peer's absolute gap tolerance: tol x max(ubar) (our scaled dual residual);
        under load control, where ubar <= 0, tol x u_s with the judge's own displacement
        scale (``kkt.constrained_scales``: at least the indentation by the mean force), which
        stays above 0 on a flat surface (ubar = 0), where a tolerance of 0 would keep
        ContactMechanics' PK iterating to its limit."""
        if ctx.constraints.load_control:
            u_s, _ = constrained_scales(ctx.qp.ubar, ctx.diag_max, ctx.constraints, ctx.ubar_scale())
            return float(ctx.tol) * u_s
        return float(ctx.tol) * float(np.max(gp.ubar))


@register
class CMDualCCG(_CMSolver):
    """ContactMechanics' dual CCG (Bugnicourt et al., Tribol. Lett. 2018) on the pixel
    forces through ``NonSmoothContactSystem.dual_minimize_proxy``; our kernel through its
    Green's-function hook or its own Love / periodic kernel (module doc).  Warm start:
    primal."""

    name = "cm-dual-ccg"
    description = "ContactMechanics: dual CCG of Bugnicourt et al. 2018 (NuMPI) on the pixel forces [peers extra]"
    params = (Param("green", str, "auto", "auto: CM's own kernel where it has the scene's, else ours; ours: always ours",
                    choices=GREEN_CHOICES),
              Param("variant", str, "without-restart", "NuMPI's CCG without or with restart",
                    choices=("without-restart", "with-restart")))

    def iterate(self, ctx: SolveContext) -> Outcome:
        from ContactMechanics.Systems import NonSmoothContactSystem
        from SurfaceTopography import Topography

        gp, sub, green = self.posed(ctx)
        topo = Topography(gp.U, physical_sizes=gp.sizes, periodic=gp.periodic)
        system = NonSmoothContactSystem(sub, topo)
        init = full_field(gp, ctx.p0)
        gtol = self.tolerance(ctx, gp)
        ctx.mark_setup_done()
        with captured() as said:
            res = system.dual_minimize_proxy(0.0, init_force=init, solver=f"ccg-{ctx.params['variant']}",
                                             gtol=gtol, maxiter=int(ctx.max_iter))
        ctx.add_matvecs(type(sub).products)
        force = np.asarray(res.x).reshape(gp.shape)
        return peer_outcome(gp, force, bool(res.success), int(res.nit), str(res.message),
                            {"green": green, "gtol": gtol, "peer_printed": said.tail()})


@register
class CMPolonskyKeer(_CMSolver):
    """ContactMechanics' Polonsky-Keer constrained CG (Wear 1999) at a fixed rigid offset,
    ``ContactMechanics.Optimization.constrained_conjugate_gradients``; kernels as for
    cm-dual-ccg (module doc).  Warm start: primal (``initial_forces``)."""

    name = "cm-pk-ccg"
    description = ("ContactMechanics: Polonsky-Keer constrained CG at fixed offset, or at a fixed external force; "
                   "hardness by its own bound [peers extra]")
    capabilities = Capabilities(operators=frozenset({"fft", "dense"}), warm_start="primal", load_control=True,
                                bounds=True)
    params = (Param("green", str, "auto", "auto: CM's own kernel where it has the scene's, else ours; ours: always ours",
                    choices=GREEN_CHOICES),)

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)
        if why:
            return why
        if traits.periodic and traits.load_control:
            return PERIODIC_LOAD_SKIP
        if traits.load_control and traits.bounded and traits.n > 1 and traits.capacity_share * traits.n > traits.n - 1:
            return SATURATED_LOAD_SKIP
        if traits.periodic and traits.kernel in ("love", "bcc"):
            return PERIODIC_REAL_SPACE_SKIP
        return None

    def iterate(self, ctx: SolveContext) -> Outcome:
        from ContactMechanics.Optimization import constrained_conjugate_gradients
        from SurfaceTopography import Topography

        gp, sub, green = self.posed(ctx)
        topo = Topography(gp.U, physical_sizes=gp.sizes, periodic=gp.periodic)
        pentol = self.tolerance(ctx, gp)
        forcetol = pentol / float(np.max(ctx.qp.H.diagonal()))
        init = None
        if ctx.p0 is not None:
            init = np.zeros(sub.nb_subdomain_grid_pts)
            init[: gp.shape[0], : gp.shape[1]] = -full_field(gp, ctx.p0)  # CM: compressive force < 0
        control = native_control(gp, ctx.constraints)
        ctx.mark_setup_done()
        with captured() as said:
            res = constrained_conjugate_gradients(sub, topo, initial_forces=init, pentol=pentol,
                                                  forcetol=forcetol, thermotol=float(ctx.tol),
                                                  maxiter=int(ctx.max_iter), **control)
        ctx.add_matvecs(type(sub).products)
        force = np.asarray(res.jac).reshape(gp.shape)
        out = peer_outcome(gp, force, bool(res.success), int(res.nit), str(res.message),
                           {"green": green, "pentol": pentol, "forcetol": forcetol, "peer_printed": said.tail(),
                            "control": "load" if "external_force" in control else "displacement"})
        if ctx.constraints.load_control:
            out.multiplier = float(res.offset)  # CM's rigid offset at the given force: the approach Delta
        return out


def native_control(gp: GridProblem, c: Constraints) -> dict[str, Any]:
    """ContactMechanics' own keywords for our constraints: ``external_force`` = P under
    load control (else ``offset`` = 0: U is ubar at the QP's approach), ``hardness`` = the
    per-pixel force bound (a scalar when uniform, else a field, inf off the trial set)."""
    kw: dict[str, Any] = {"external_force": float(c.load)} if c.load is not None else {"offset": 0.0}
    if c.bounded:
        u = c.upper_or_inf(gp.indices.size)
        if np.all(u == u[0]):
            kw["hardness"] = float(u[0])
        else:
            field = np.full(gp.shape[0] * gp.shape[1], np.inf)
            field[gp.indices] = u
            kw["hardness"] = field.reshape(gp.shape)
    return kw


def peer_outcome(gp: GridProblem, force: np.ndarray, success: bool, nit: int, message: str,
                 info: dict[str, Any]) -> Outcome:
    """The peer's raw force field on the trial set, its own claim, count and message."""
    p = gp.on_set(force)
    off = gp.force_off_set(force)
    status = None if success else (Status.FAILED if not np.all(np.isfinite(p)) else Status.MAX_ITER)
    note = f"{message}" + (f"; force off the trial set {off:.1e} of max" if off > 0 else "")
    return Outcome(p, nit, success, note, status=status,
                   info={**info, "peer_status": message, "peer_iterations": nit, "force_off_set": off})
