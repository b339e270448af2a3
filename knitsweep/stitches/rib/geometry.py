"""Rib state -> the 8 segments' control points with the exact Jacobian
(docs/model.md §11): the free yarn's kernel, its course closing through a glide.

In 1×1 rib (and in seed) the yarn runs from the cell's knit stitch into the purl stitch
beside it, the cell's mirror image (z -> -z) one course period on. So the cell's last
segment ends where that image's yarn begins, at joint 0 mirrored and shifted by
t_c = (a_x, 0, 0), with joint 0's tangent and curvature vector mirrored: G2 into the
mirrored continuation by construction, for any joint-0 frame (the junction need not be
level; it must lie in the mirror plane, which pinning joint 0 at the origin does).

``x`` (87,) as ``stockinette_free.layout``; ``cp`` (8, 6, 3) mm; ``jac`` (8, 6, 3, 87).
"""

from __future__ import annotations

from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from ..stockinette_free.geometry import closed_control_points


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 87) from the state ``x`` (87,):
    segment 7 ends at M joint 0 + t_c with joint 0's frame mirrored, M = diag(1, 1, -1)."""
    closed_control_points(x, cp, jac, True)
