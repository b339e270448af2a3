"""The outcome of one relaxation and its truthful status (docs/model.md §7).

Whatever minimiser ran, ``assess`` measures the end state itself: energies finite,
length within ``length_tol_mm``, twist bound met, and either the minimiser's own
success or stationarity (max |∇E − λ∇ℓ − μ∇g| over the free entries at most 1e-6 of
max |∇E|, multipliers by least squares, μ only where the twist bound is active);
``not_knittable`` where the hard cores overlap at such a minimum. It also gives the
length multiplier λ and the period forces dE*/da = ∂E/∂a − λ ∂ℓ/∂a (envelope theorem;
the twist constraint does not involve a).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..config import CONVERGED, NOT_CONVERGED, NOT_KNITTABLE, SolverSettings
from ..kernels.contact import CORE_EPS
from ..model import CORES_OVERLAP, CellModel
from .problem import twist_gradient, twist_margin

TWIST_ACTIVE_TOL = 1e-8
KKT_RTOL = 1e-6  # relative stationarity that counts as converged after a stalled line search


@dataclass(frozen=True)
class Relaxation:
    """Outcome of one constrained minimisation (energies mJ, lengths mm, forces N)."""

    x: np.ndarray
    bending_energy: float
    contact_energy: float
    length: float
    status: str
    message: str
    iterations: int
    evaluations: int
    length_residual: float
    twist_margin: float
    twist_active: bool
    min_zeta: float
    kkt_residual: float
    length_multiplier: float
    period_forces: tuple[float, float]
    seconds: float

    @property
    def total_energy(self) -> float:
        return self.bending_energy + self.contact_energy

    @property
    def converged(self) -> bool:
        return self.status == CONVERGED

    @property
    def a_x(self) -> float:
        """The course period (mm): a state's next-to-last entry."""
        return float(self.x[-2])

    @property
    def a_y(self) -> float:
        """The wale period (mm): a state's last entry."""
        return float(self.x[-1])


def with_status(r: Relaxation, status: str, message: str) -> Relaxation:
    return replace(r, status=status, message=message)


def _finite_state(model: CellModel, x: np.ndarray) -> bool:
    if not (np.all(np.isfinite(x)) and x[-2] > 0 and x[-1] > 0):
        return False
    e = model.energies(x)
    return all(map(math.isfinite, (e.bending_energy, e.contact_energy, e.length)))


def assess(model: CellModel, x0: np.ndarray, x: np.ndarray, free: np.ndarray, success: bool,
           message: str, nit: int, nev: int, settings: SolverSettings, seconds: float,
           evaluated: tuple | None = None) -> Relaxation:  # fmt: skip
    """Measure the end state ``x`` and give it a truthful status.

    ``evaluated``: (Energies, ∇E (n,), ∇ℓ (n,)) already computed at ``x`` (by the
    minimiser's last call), saving one evaluation; ``nev`` counts the minimiser's.
    """
    if evaluated is None or not math.isfinite(evaluated[0].total_energy):
        if not _finite_state(model, x):
            # never report a non-finite state: keep the (finite) start, say what happened
            x = np.array(x0, dtype=float)
            success = False
            message = f"the minimiser left the finite states ({message}); start kept"
        evaluated = model.energy_and_gradients(x)
        nev += 1
    e, ge, gl = evaluated
    margin = twist_margin(x, model.ip.twist_bound, model.stitch)
    twist_active = margin <= TWIST_ACTIVE_TOL
    # Lagrange multipliers by least squares on the free entries: grad E = lam grad l (+ mu grad g)
    cols = [gl[free]]
    if twist_active:
        cols.append(twist_gradient(x, model.stitch)[free])
    a = np.column_stack(cols)
    coef = np.linalg.solve(a.T @ a, a.T @ ge[free])  # the normal equations: 1 or 2 columns
    kkt = float(np.max(np.abs(ge[free] - a @ coef)))
    lam = float(coef[0])
    forces = (float(ge[-2] - lam * gl[-2]), float(ge[-1] - lam * gl[-1]))  # on a_x, a_y
    residual = e.length - model.ip.L
    zeta = model.min_zeta(x)
    finite = all(map(math.isfinite, (e.bending_energy, e.contact_energy, e.length, kkt)))
    scale = max(float(np.max(np.abs(ge[free]))), 1e-300)
    stationary = kkt <= KKT_RTOL * scale
    if not finite:
        status, why = NOT_CONVERGED, f"non-finite energy: {message}"
    elif zeta < CORE_EPS and not (success or stationary):
        # the minimiser stopped with the cores overlapping, where the hard core's energy
        # (10^2 mJ a pair at CORE_EPS, §6) dwarfs any fabric's: it could not get them apart
        # at this yarn length (seed below 9.1 mm, every descent, docs/model.md §11)
        status = NOT_KNITTABLE
        why = (f"{CORES_OVERLAP} where the minimiser stopped (smallest zeta = {zeta:.3g} < "
               f"{CORE_EPS:g}; not converged: {message})")  # fmt: skip
    elif abs(residual) > settings.length_tol_mm:
        status, why = NOT_CONVERGED, f"length constraint missed by {residual:.3g} mm: {message}"
    elif margin < -TWIST_ACTIVE_TOL:
        status, why = NOT_CONVERGED, f"twist bound violated by {-margin:.3g}: {message}"
    elif success or stationary:
        status, why = CONVERGED, message
        if zeta < CORE_EPS:
            status = NOT_KNITTABLE
            why = f"{CORES_OVERLAP} at the minimum (smallest zeta = {zeta:.3g} < {CORE_EPS:g})"
        elif changed := model.topology_change(x):  # patterns only (docs/model.md §11)
            status, why = NOT_CONVERGED, changed
        elif coarse := model.resolution_change(x, e.contact_energy):  # patterns only
            status = NOT_KNITTABLE if coarse.startswith(CORES_OVERLAP) else NOT_CONVERGED
            why = coarse
    else:
        status, why = NOT_CONVERGED, message
    return Relaxation(
        x=x,
        bending_energy=e.bending_energy,
        contact_energy=e.contact_energy,
        length=e.length,
        status=status,
        message=why,
        iterations=int(nit),
        evaluations=int(nev),
        length_residual=float(residual),
        twist_margin=float(margin),
        twist_active=bool(twist_active),
        min_zeta=float(zeta),
        kkt_residual=kkt,
        length_multiplier=lam,
        period_forces=forces,
        seconds=seconds,
    )
