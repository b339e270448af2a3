"""A chart's state -> its row's control points with the exact Jacobian (docs/model.md
§12): the free yarn's chain of S = 8 n segments through the row's n stitches, closing by
the row's width n a_x, lifted by z0 when the state has it (rows mirrored).

``x`` as ``stitches.chart`` lays it out; ``cp`` (S, 6, 3) mm; ``jac`` (S, 6, 3, len(x)).
"""

from __future__ import annotations

from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from ..stockinette_free.geometry import chain_control_points, lifted_control_points
from ..stockinette_free.layout import JOINT0, PER_JOINT, PER_SEGMENT


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` and ``jac`` from the chart state ``x`` (stitches: S / 8)."""
    n_seg = cp.shape[0]
    cx = float(n_seg // 8)
    if x.shape[0] == JOINT0 + PER_JOINT * (n_seg - 1) + PER_SEGMENT * n_seg + 2:
        chain_control_points(x, cp, jac, False, cx)
    else:  # z0 before the periods
        lifted_control_points(x, cp, jac, cx)
