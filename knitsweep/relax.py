"""Constrained relaxation at fixed yarn length, and continuation in parameters.

docs/model.md §7: minimise E = E_b + E_c subject to length(x) = L and cos(tw) >= c_tw,
either with every entry free (the zero-force state) or with one cell period
fixed (a strain step). SciPy's SLSQP is given the exact gradients of the energy
and of both constraints. Every result says truthfully how it ended: a
non-finite, unconverged or core-overlapping state is never called converged.

A relaxation runs its BLAS/LAPACK calls (inside SLSQP, and the least squares for
the multipliers) on one thread: with more, OpenBLAS sums in another order and the
same relaxation ends ~1e-13 elsewhere, depending on what the process did before.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import ThreadpoolController

from .config import (
    CONVERGED,
    NOT_CONVERGED,
    NOT_KNITTABLE,
    Direction,
    Fidelity,
    SolverSettings,
    StitchParams,
)
from .kernels.contact import CORE_EPS
from .model import CellModel
from .state import IDX_AX, IDX_AY, IDX_TW, N_STATE, PERIOD_INDEX, state_bounds

_BLAS: list[ThreadpoolController] = []  # made on first use: inspecting the libraries costs ~1 ms
_TWIST_ACTIVE_TOL = 1e-8
_KKT_RTOL = 1e-6  # relative stationarity that counts as converged after a stalled line search


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
        return float(self.x[IDX_AX])

    @property
    def a_y(self) -> float:
        return float(self.x[IDX_AY])


class _Problem:
    """Energy and constraints over the free entries, evaluated once per point."""

    def __init__(self, model: CellModel, x_full: np.ndarray, free: np.ndarray) -> None:
        self.model = model
        self.x = np.array(x_full, dtype=float)
        # a Verlet list of the contact candidates: the same sums, ~15 % faster here
        self.neighbours = model.neighbour_list(self.x)
        self.free = free
        self.L = model.ip.L
        self.bound = model.ip.twist_bound
        self.evaluations = 0
        self._z: np.ndarray | None = None

    def full(self, z: np.ndarray) -> np.ndarray:
        x = self.x.copy()
        x[self.free] = z
        return x

    def _eval(self, z: np.ndarray) -> None:
        if self._z is not None and np.array_equal(z, self._z):
            return
        e, ge, gl = self.model.energy_and_gradients(self.full(z), self.neighbours)
        self._z = z.copy()
        self.e, self.ge, self.gl = e, ge, gl
        self.evaluations += 1

    def energy(self, z):
        self._eval(z)
        return self.e.total_energy

    def energy_grad(self, z):
        self._eval(z)
        return self.ge[self.free]

    def length(self, z):
        self._eval(z)
        return self.e.length - self.L

    def length_grad(self, z):
        self._eval(z)
        return self.gl[self.free]

    def twist(self, z):
        return math.cos(self.full(z)[IDX_TW]) - self.bound

    def twist_grad(self, z):
        g = np.zeros(N_STATE)
        g[IDX_TW] = -math.sin(self.full(z)[IDX_TW])
        return g[self.free]


def relax(
    model: CellModel,
    x0: np.ndarray,
    fixed: Direction | None = None,
    settings: SolverSettings | None = None,
) -> Relaxation:
    """Minimise the energy at fixed yarn length ``model.params.L_mm`` from ``x0``.

    ``fixed=None`` frees both periods (zero-force state); ``'x'``/``'y'`` keeps
    a_x/a_y at its value in ``x0`` (a strain step, docs/model.md §8).
    """
    settings = settings or SolverSettings()
    t0 = time.perf_counter()
    x0 = np.asarray(x0, dtype=float)
    free = np.array([i for i in range(N_STATE) if fixed is None or i != PERIOD_INDEX[fixed]])
    prob = _Problem(model, x0, free)
    all_bounds = state_bounds(model.ip.L, model.ip.r)
    bounds = [_widen(all_bounds[i], x0[i]) for i in free]
    constraints = [
        {"type": "eq", "fun": prob.length, "jac": prob.length_grad},
        {"type": "ineq", "fun": prob.twist, "jac": prob.twist_grad},
    ]
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    with _BLAS[0].limit(limits=1):
        try:
            with np.errstate(all="ignore"):
                res = minimize(
                    prob.energy,
                    x0[free],
                    jac=prob.energy_grad,
                    method="SLSQP",
                    bounds=bounds,
                    constraints=constraints,
                    options={"ftol": settings.ftol, "maxiter": settings.maxiter},
                )
            x, success, message = prob.full(res.x), bool(res.success), str(res.message)
            nit = res.nit
        except (ValueError, FloatingPointError, ZeroDivisionError) as e:
            x, success, message, nit = x0.copy(), False, f"minimiser failed: {e}", 0
        return _assess(model, x0, x, free, success, message, nit, prob.evaluations, settings, t0)


def _finite_state(model: CellModel, x: np.ndarray) -> bool:
    if not (np.all(np.isfinite(x)) and x[IDX_AX] > 0 and x[IDX_AY] > 0):
        return False
    e = model.energies(x)
    return all(map(math.isfinite, (e.bending_energy, e.contact_energy, e.length)))


def _widen(bound, value):
    """A bound never excludes the starting value itself."""
    lo, hi = bound
    lo = None if lo is None else min(lo, value)
    hi = None if hi is None else max(hi, value)
    return lo, hi


def _assess(model, x0, x, free, success, message, nit, nev, settings, t0) -> Relaxation:
    """Measure the result and give it a truthful status."""
    if not _finite_state(model, x):
        # never report a non-finite state: keep the (finite) start, say what happened
        x = np.array(x0, dtype=float)
        success, message = False, f"the minimiser left the finite states ({message}); start kept"
    e, ge, gl = model.energy_and_gradients(x)
    twist_margin = math.cos(x[IDX_TW]) - model.ip.twist_bound
    twist_active = twist_margin <= _TWIST_ACTIVE_TOL
    # Lagrange multipliers by least squares on the free entries: grad E = lam grad l (+ mu grad g)
    cols = [gl[free]]
    if twist_active:
        g = np.zeros(N_STATE)
        g[IDX_TW] = -math.sin(x[IDX_TW])
        cols.append(g[free])
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, ge[free], rcond=None)
    kkt = float(np.max(np.abs(ge[free] - a @ coef)))
    lam = float(coef[0])
    # envelope theorem: dE*/da = dE/da - lam dl/da (the twist constraint does not involve a)
    forces = (float(ge[IDX_AX] - lam * gl[IDX_AX]), float(ge[IDX_AY] - lam * gl[IDX_AY]))
    residual = e.length - model.ip.L
    zeta = model.min_zeta(x)
    finite = all(map(math.isfinite, (e.bending_energy, e.contact_energy, e.length, kkt)))
    scale = max(float(np.max(np.abs(ge[free]))), 1e-300)
    stationary = kkt <= _KKT_RTOL * scale
    if not finite:
        status, why = NOT_CONVERGED, f"non-finite energy: {message}"
    elif abs(residual) > settings.length_tol_mm:
        status, why = NOT_CONVERGED, f"length constraint missed by {residual:.3g} mm: {message}"
    elif twist_margin < -_TWIST_ACTIVE_TOL:
        status, why = NOT_CONVERGED, f"twist bound violated by {-twist_margin:.3g}: {message}"
    elif success or stationary:
        status, why = CONVERGED, message
        if zeta < CORE_EPS:
            status = NOT_KNITTABLE
            why = f"hard cores overlap at the minimum (smallest zeta = {zeta:.3g} < {CORE_EPS:g})"
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
        evaluations=int(nev) + 1,
        length_residual=float(residual),
        twist_margin=float(twist_margin),
        twist_active=bool(twist_active),
        min_zeta=float(zeta),
        kkt_residual=kkt,
        length_multiplier=lam,
        period_forces=forces,
        seconds=time.perf_counter() - t0,
    )


def continuation_path(
    start: StitchParams, target: StitchParams, settings: SolverSettings
) -> list[StitchParams]:
    """Parameter stages from ``start`` to ``target`` (the last one is ``target``).

    L, r, r_core, p and the regularisation move linearly, k and B geometrically,
    each by at most the step allowed in ``settings``.
    """
    f = math.log(settings.continuation_factor)
    n = max(
        1,
        math.ceil(abs(target.L_mm - start.L_mm) / settings.continuation_dL_mm - 1e-9),
        math.ceil(abs(math.log(target.k_mN_per_mm2 / start.k_mN_per_mm2)) / f - 1e-9),
        math.ceil(abs(math.log(target.B_mN_mm2 / start.B_mN_mm2)) / f - 1e-9),
        math.ceil(abs(target.r_mm - start.r_mm) / settings.continuation_dr_mm - 1e-9),
        math.ceil(abs(target.r_core_mm - start.r_core_mm) / settings.continuation_dr_mm - 1e-9),
        math.ceil(abs(target.p - start.p) / settings.continuation_dp - 1e-9),
    )
    stages = []
    for i in range(1, n):
        t = i / n

        def lin(a: float, b: float, t: float = t) -> float:
            return a + t * (b - a)

        def geo(a: float, b: float, t: float = t) -> float:
            return a * (b / a) ** t

        stages.append(
            target.model_copy(
                update={
                    "L_mm": lin(start.L_mm, target.L_mm),
                    "k_mN_per_mm2": geo(start.k_mN_per_mm2, target.k_mN_per_mm2),
                    "B_mN_mm2": geo(start.B_mN_mm2, target.B_mN_mm2),
                    "r_mm": lin(start.r_mm, target.r_mm),
                    "r_core_mm": lin(start.r_core_mm, target.r_core_mm),
                    "p": lin(start.p, target.p),
                    "regularization_mN_mm4": lin(
                        start.regularization_mN_mm4, target.regularization_mN_mm4
                    ),
                }
            )
        )
    stages.append(target)
    return stages


def relax_with_continuation(
    target: StitchParams,
    fidelity: Fidelity,
    x_start: np.ndarray,
    start: StitchParams,
    settings: SolverSettings | None = None,
) -> tuple[Relaxation, int]:
    """Zero-force relaxation at ``target``, walking there from a state relaxed at
    ``start`` in small parameter stages (docs/model.md §7). Returns the final
    relaxation and the number of stages used.

    Intermediate stages use a looser tolerance; a stage that ends non-finite or
    with overlapping cores stops the walk, and the last stage's status is kept.
    """
    settings = settings or SolverSettings()
    stages = continuation_path(start, target, settings)
    loose = settings.model_copy(update={"ftol": max(settings.ftol, 1e-7)})
    x = np.asarray(x_start, dtype=float)
    result = None
    for i, params in enumerate(stages):
        last = i == len(stages) - 1
        result = relax(CellModel(params, fidelity), x, None, settings if last else loose)
        if not np.all(np.isfinite(result.x)) or (not last and result.status == NOT_KNITTABLE):
            where = f"at continuation stage {i + 1}/{len(stages)} (L = {params.L_mm:.4g} mm)"
            status = result.status if result.status == NOT_KNITTABLE else NOT_CONVERGED
            return _with_status(result, status, f"{result.message} {where}"), i + 1
        x = result.x
    assert result is not None
    return result, len(stages)


def _with_status(r: Relaxation, status: str, message: str) -> Relaxation:
    return replace(r, status=status, message=message)
