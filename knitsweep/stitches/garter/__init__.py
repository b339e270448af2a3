"""Garter: knit and purl rows alternating (docs/model.md §11).

One knit stitch as a free periodic yarn; the odd rows are its mirror images through the
fabric plane (glide reflections: z -> -z plus one wale period), so the fabric is the cell
at m t_c + n t_w, mirrored when n is odd. a_x and a_y are the per-stitch course and wale
spacings, as stockinette's.

* ``layout``: the 88 entries (the free yarn's shape, z0, the periods), bounds, starts;
* ``geometry``: state -> control points with their exact Jacobian (numba).
"""

from __future__ import annotations

from ..base import MIRROR_CLASSES
from ..stockinette_free import free_yarn_stitch
from . import layout

__all__ = ["MIRROR_CLASSES", "STITCH"]

STITCH = free_yarn_stitch(
    "garter",
    "garter: knit and purl rows alternating (odd rows mirrored)",
    __name__,
    mirror_parity=(0, 1),
    state=layout,
)
"""The garter stitch: one knit stitch, its odd rows mirrored."""
