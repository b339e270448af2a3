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

from ..base import Stitch
from ..garter import MIRROR_CLASSES
from ..stockinette_free import layout

STITCH = Stitch(
    name="rib",
    description="1x1 rib: knit and purl columns alternating (odd columns mirrored)",
    state_names=layout.STATE_NAMES,
    n_segments=layout.N_SEGMENTS,
    segment_weights=layout.SEGMENT_WEIGHTS,
    bounds=layout.state_bounds,
    twist_index=None,
    starts=layout.STARTS,
    data_package=f"{__name__}.data",
    geometry_module=f"{__name__}.geometry",
    images="glides",
    contact_classes=MIRROR_CLASSES,
    path_order=tuple(range(layout.N_SEGMENTS)),
    closing_shift=(1, 0),
    mirror_parity=(1, 0),
    rough=True,
    stage_dL_mm=2.0,
)
"""The 1×1 rib stitch: one knit stitch, its odd columns mirrored."""
