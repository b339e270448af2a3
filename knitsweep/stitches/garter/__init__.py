"""Garter: knit and purl rows alternating (docs/model.md §11).

One knit stitch as a free periodic yarn; the odd rows are its mirror images through the
fabric plane (glide reflections: z -> -z plus one wale period), so the fabric is the cell
at m t_c + n t_w, mirrored when n is odd. a_x and a_y are the per-stitch course and wale
spacings, as stockinette's.

* ``layout``: the 88 entries (the free yarn's shape, z0, the periods), bounds, starts;
* ``geometry``: state -> control points with their exact Jacobian (numba).
"""

from __future__ import annotations

from ..base import Stitch
from ..stockinette_free import layout as _free
from . import layout

MIRROR_CLASSES = ("self", "same_row", "same_column", "mirrored", "other")
"""As ``kernels.mirrored.MIRROR_CLASSES`` (garter's mirrored class: the rows above and
below)."""

STITCH = Stitch(
    name="garter",
    description="garter: knit and purl rows alternating (odd rows mirrored)",
    state_names=layout.STATE_NAMES,
    n_segments=layout.N_SEGMENTS,
    segment_weights=_free.SEGMENT_WEIGHTS,
    bounds=layout.state_bounds,
    twist_index=None,
    starts=layout.STARTS,
    data_package=f"{__name__}.data",
    geometry_module=f"{__name__}.geometry",
    images="glides",
    contact_classes=MIRROR_CLASSES,
    path_order=tuple(range(layout.N_SEGMENTS)),
    closing_shift=(1, 0),
    mirror_parity=(0, 1),
    rough=True,
)
"""The garter stitch: one knit stitch, its odd rows mirrored."""
