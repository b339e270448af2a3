"""Garter state -> the 8 segments' control points with the exact Jacobian (docs/model.md
§11): the free yarn's kernel on the shape entries and periods, lifted by z0.

``x`` (88,) as in ``layout``; ``cp`` (8, 6, 3) mm; ``jac`` (8, 6, 3, 88).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from ..stockinette_free.geometry import state_to_control_points as free_control_points
from .layout import IDX_Z0, N_FREE_SHAPE


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 88) from the garter state ``x``."""
    nf = N_FREE_SHAPE
    xf = np.empty(nf + 2)
    xf[:nf] = x[:nf]
    xf[nf] = x[nf + 1]
    xf[nf + 1] = x[nf + 2]
    jf = np.empty((cp.shape[0], 6, 3, nf + 2))
    free_control_points(xf, cp, jf)
    for s in range(cp.shape[0]):
        for i in range(6):
            cp[s, i, 2] += x[IDX_Z0]
            for c in range(3):
                for k in range(nf):
                    jac[s, i, c, k] = jf[s, i, c, k]
                jac[s, i, c, IDX_Z0] = 1.0 if c == 2 else 0.0
                jac[s, i, c, nf + 1] = jf[s, i, c, nf]
                jac[s, i, c, nf + 2] = jf[s, i, c, nf + 1]
