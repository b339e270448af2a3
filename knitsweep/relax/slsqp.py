"""SciPy's SLSQP on the exact gradients of the energy and both constraints (docs/model.md §7).

The minimiser the authors use (they give it finite differences); the ``paper`` preset
keeps it, since with SciPy's default tolerance it retraces their relaxation, and the
Newton solver falls back to it where it cannot finish.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from ..config import SolverSettings
from .problem import Minimum, Problem


def slsqp_minimise(
    prob: Problem, z0: np.ndarray, bounds: list, settings: SolverSettings
) -> Minimum:
    """Minimise from z0 within ``bounds`` (SciPy's format). Raises what SLSQP raises on
    non-finite trial points."""
    constraints = [
        {"type": "eq", "fun": prob.length, "jac": prob.length_grad},
        {"type": "ineq", "fun": prob.twist, "jac": prob.twist_grad},
    ]
    with np.errstate(all="ignore"):
        res = minimize(
            prob.energy,
            z0,
            jac=prob.energy_grad,
            method="SLSQP",
            bounds=bounds,
            constraints=constraints,
            options={"ftol": settings.energy_change_goal_mJ, "maxiter": settings.maxiter},
        )
    return Minimum(np.asarray(res.x, dtype=float), bool(res.success), str(res.message),
                   int(res.nit))  # fmt: skip
