"""1×1 rib: knit and purl columns alternating (docs/model.md §11).

One knit stitch as a free periodic yarn whose odd columns are its mirror images through
the fabric plane (glide reflections: z -> -z plus one course period). The row's yarn
runs from the knit stitch into the purl one beside it, so the cell closes through the
glide (``geometry``); joint 0, where it does, is pinned at the origin on the mirror
plane. a_x and a_y are the per-stitch course and wale spacings, as stockinette's (the
fabric repeats every 2 a_x along the course).

* ``geometry``: state -> control points with their exact Jacobian (numba);
* the state, bounds and weights are the free yarn's (``stockinette_free.layout``); the
  starts (``data/``) are the authors' Init files made rib stitches
  (``start.rib_start``).
"""

from __future__ import annotations

from ..stockinette_free import free_yarn_stitch

STITCH = free_yarn_stitch(
    "rib",
    "1x1 rib: knit and purl columns alternating (odd columns mirrored)",
    __name__,
    mirror_parity=(1, 0),
    stage_dL_mm=2.0,
)
"""The 1×1 rib stitch: one knit stitch, its odd columns mirrored."""
