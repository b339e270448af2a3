"""SciPy's SLSQP on the exact gradients of the energy and both constraints (docs/model.md §7).

The minimiser the authors use (they give it finite differences); the ``paper`` preset
keeps it, since with SciPy's default tolerance it retraces their relaxation, and the
Newton solver falls back to it where it cannot finish.

A long descent (more than ``OVERLAP_CHECK`` iterations, as the rough stitches' are,
``continuation.ROUGH_SLSQP_MAXITER``) looks at its iterate every ``OVERLAP_CHECK``
iterations and gives up where the hard cores still overlap: measured on seed at
L = 8.5 mm (too tight to knit), SLSQP from the last knittable stage jumped to 3·10⁸ mJ in
its first step, sat above 1000 mJ from its 200th iteration on and ended at its limit,
7904 iterations (7 s), at 1065 mJ with the cores overlapping, as every descent there
does; the relaxation's verdict (``not_knittable``) is the same after 2000.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from ..config import SolverSettings
from ..kernels.contact import CORE_EPS
from .problem import Minimum, Problem

OVERLAP_CHECK = 2000
"""Iterations between two looks at a long descent's cores (``SolverSettings.maxiter``'s
default: a descent within the default limit is never looked at)."""


class _CoresOverlap(Exception):
    """Raised from SLSQP's callback to stop a long descent whose cores still overlap."""

    def __init__(self, z: np.ndarray, nit: int) -> None:
        super().__init__()
        self.z, self.nit = z, nit


def slsqp_minimise(
    prob: Problem, z0: np.ndarray, bounds: list, settings: SolverSettings
) -> Minimum:
    """Minimise from z0 within ``bounds`` (SciPy's format). Raises what SLSQP raises on
    non-finite trial points. A descent longer than ``OVERLAP_CHECK`` iterations stops
    where its cores still overlap at a multiple of it (module docstring)."""
    nit = 0

    def look(zk: np.ndarray) -> None:
        nonlocal nit
        nit += 1
        if nit % OVERLAP_CHECK == 0 and nit < settings.maxiter:
            if prob.model.min_zeta(prob.full(zk)) < CORE_EPS:
                raise _CoresOverlap(np.array(zk, dtype=float), nit)

    constraints = [
        {"type": "eq", "fun": prob.length, "jac": prob.length_grad},
        {"type": "ineq", "fun": prob.twist, "jac": prob.twist_grad},
    ]
    with np.errstate(all="ignore"):
        try:
            res = minimize(
                prob.energy,
                z0,
                jac=prob.energy_grad,
                method="SLSQP",
                bounds=bounds,
                constraints=constraints,
                options={"ftol": settings.energy_change_goal_mJ, "maxiter": settings.maxiter},
                callback=look if settings.maxiter > OVERLAP_CHECK else None,
            )
        except _CoresOverlap as stop:
            return Minimum(stop.z, False, f"hard cores still overlap after {stop.nit} "
                           "iterations: gave up", stop.nit)  # fmt: skip
    return Minimum(np.asarray(res.x, dtype=float), bool(res.success), str(res.message),
                   int(res.nit))  # fmt: skip
