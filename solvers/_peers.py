"""What the field's codes (solvers/peer_cm.py, solvers/peer_tamaas.py) share: the
optional-import check, their base class (``PeerSolver``: family "peer", the grid skip),
and posing one of our QPs as the full-grid problem a peer code takes (a height field, a
grid, a modulus, a kernel).

Posing (no cleaning).  A peer code works on the whole N1 x N2 grid; our QP lives on the
trial set I (``QP.geometry.indices``).  The peer is handed the field U with U_I = ubar
and, off I, the rigid-body interpenetration Delta - xi_max + xi of the instance's own
surface (negative there; without a surface: -max|ubar|).  For the positive non-periodic
kernels the exact full-grid answer is then zero off I, so both problems have the same
answer; periodic scenes are posed on the whole grid (I is every point) and need no fill.
The peer's answer on I is judged raw; any force it leaves off I is reported as
``info["force_off_set"]`` (relative to its largest force), never hidden.
"""

from __future__ import annotations

import contextlib
import importlib
import io
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from contactbench.problems.errors import ProblemInputError
from contactbench.problems.instances import QP
from contactbench.problems.kernels import kernel_table
from contactbench.problems.layers import Layer

from .base import ProblemTraits, Solver

#: The install hint every peer solver prints when its package is missing.
INSTALL_HINT = "pip install contactbench[peers]  (contactmechanics>=1.4, tamaas>=2.8)"


def package_availability(module: str, label: str) -> tuple[bool, str]:
    """(True, "available (label version)") when ``module`` imports, else (False, the
    install hint)."""
    try:
        mod = importlib.import_module(module)
    except ImportError as e:  # the optional extra "peers" is not installed
        return False, f"not installed: {INSTALL_HINT} ({label}: {e})"
    except Exception as e:  # noqa: BLE001 -- a broken install (ABI mismatch, missing shared library)
        return False, f"{label} does not import ({type(e).__name__}: {e}); reinstall with {INSTALL_HINT}"
    return True, f"available ({label} {getattr(mod, '__version__', '?')})"


class PeerSolver(Solver):
    """A peer code: it poses the QP on a grid, so it skips a problem without one."""

    family = "peer"

    def skip(self, traits: ProblemTraits) -> str | None:
        why = super().skip(traits)  # the constraints it cannot pose
        if why:
            return why
        if not traits.has_geometry or not traits.kernel:
            return f"{self.name} poses the problem on a grid: it needs the QP's grid geometry and kernel"
        return None


@dataclass(frozen=True)
class GridProblem:
    """One QP posed on the full grid (module doc)."""

    shape: tuple[int, int]
    delta: float  # grid spacing (m)
    E: float  # composite modulus E*
    kernel: str
    periodic: bool
    indices: np.ndarray  # the QP's unknowns: flat grid indices
    U: np.ndarray  # N1 x N2 field, U.flat[indices] == ubar
    delta1: float | None = None  # spacing along axis 1 (None: square pixels, delta)
    layer: Layer | None = None  # the elastic layer (None: half-space)

    @property
    def spacing(self) -> tuple[float, float]:
        return (self.delta, self.delta if self.delta1 is None else self.delta1)

    @property
    def sizes(self) -> tuple[float, float]:
        return (self.spacing[0] * self.shape[0], self.spacing[1] * self.shape[1])

    @property
    def area(self) -> float:
        """One element's area d0 d1 (a pressure times it is the element's force)."""
        return self.spacing[0] * self.spacing[1]

    @property
    def ubar(self) -> np.ndarray:
        return self.U.ravel()[self.indices]

    def on_set(self, field: np.ndarray) -> np.ndarray:
        """A peer's N1 x N2 force field read on the QP's unknowns (raw, as float64)."""
        return np.asarray(field, dtype=np.float64).reshape(self.shape).ravel()[self.indices].copy()

    def force_off_set(self, field: np.ndarray) -> float:
        """max |force| off the trial set / max |force| (0 when the set is the whole grid)."""
        f = np.abs(np.asarray(field, dtype=np.float64).ravel())
        top = float(np.max(f, initial=0.0))
        if self.indices.size == f.size or top == 0.0:
            return 0.0
        off = np.ones(f.size, dtype=bool)
        off[self.indices] = False
        return float(np.max(f[off], initial=0.0)) / top

    def table(self, qp: QP) -> np.ndarray:
        """Our influence coefficients (m/N) as the circulant table of the FFT operator:
        the operator's own table when H is one, else rebuilt from the geometry."""
        transform = getattr(qp.H, "transform", None)
        if transform is not None and tuple(transform.grid_shape) == self.shape:
            return np.asarray(transform.table)
        return kernel_table(self.kernel, self.shape, self.spacing, self.E, periodic=self.periodic, layer=self.layer)


def grid_problem(qp: QP) -> GridProblem:
    """The full-grid posing of ``qp`` (module doc); ``ProblemInputError`` when the QP has
    no grid geometry with a modulus and kernel (a bare dense or random LCP)."""
    g = qp.geometry
    if g is None or g.E is None or g.kernel is None or g.periodic is None:
        raise ProblemInputError("a peer code needs the QP's grid geometry with E, kernel and periodicity; "
                                "this QP has none (a bare matrix problem)")
    shape = (int(g.grid_shape[0]), int(g.grid_shape[1]))
    idx = np.asarray(g.indices, dtype=np.int64)
    ubar = np.asarray(qp.ubar, dtype=np.float64)
    U = np.full(shape[0] * shape[1], -float(np.max(np.abs(ubar), initial=1.0)))
    surf = g.surface
    if surf is not None and g.far_field is not None and tuple(surf.shape) == shape:
        h = np.asarray(surf.heights, dtype=np.float64).ravel()
        U = np.minimum(float(g.far_field) - float(h.max()) + h, 0.0) if idx.size < U.size else U
    U[idx] = ubar
    return GridProblem(shape, float(g.delta), float(g.E), str(g.kernel), bool(g.periodic), idx, U.reshape(shape),
                       None if g.delta1 is None else float(g.delta1), g.layer)


def full_field(gp: GridProblem, p: np.ndarray | None) -> np.ndarray:
    """A force vector on the QP's unknowns placed on the N1 x N2 grid (zeros: None)."""
    out = np.zeros(gp.shape[0] * gp.shape[1])
    if p is not None:
        out[gp.indices] = p
    return out.reshape(gp.shape)


class PeerOutput(io.StringIO):
    """What a peer printed during a solve (NuMPI prints warnings to stdout)."""

    def tail(self, chars: int = 300) -> str:
        return self.getvalue()[-chars:].strip()


@contextlib.contextmanager
def captured() -> Iterator[PeerOutput]:
    """Capture the peer's Python-level stdout (kept in the result's info, not lost in a
    worker's pipe)."""
    buf = PeerOutput()
    with contextlib.redirect_stdout(buf):
        yield buf
