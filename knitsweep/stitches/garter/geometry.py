"""Garter state -> the 8 segments' control points with the exact Jacobian (docs/model.md
§11): the free yarn's kernel on the shape entries and periods, lifted by z0
(``stockinette_free.geometry.lifted_control_points``).

``x`` (88,) as in ``layout``; ``cp`` (8, 6, 3) mm; ``jac`` (8, 6, 3, 88).
"""

from __future__ import annotations

from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from ..stockinette_free.geometry import lifted_control_points


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 88) from the garter state ``x``."""
    lifted_control_points(x, cp, jac, 1.0)
