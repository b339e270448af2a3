"""Seed (moss) stitch: knit and purl alternating along both the course and the wale, a
checkerboard (docs/model.md §11).

One knit stitch as a free periodic yarn; the image at m t_c + n t_w is its mirror image
(z -> -z) when m + n is odd. As in rib the row's yarn runs from the knit stitch into
the purl one beside it, so the cell closes through the glide (``rib.geometry``, shared);
the rows above and below are mirrored too.
"""

from __future__ import annotations

from ..base import Stitch
from ..garter import MIRROR_CLASSES
from ..stockinette_free import layout

STITCH = Stitch(
    name="seed",
    description="seed: knit and purl alternating in both directions (a checkerboard)",
    state_names=layout.STATE_NAMES,
    n_segments=layout.N_SEGMENTS,
    segment_weights=layout.SEGMENT_WEIGHTS,
    bounds=layout.state_bounds,
    twist_index=None,
    starts=layout.STARTS,
    data_package=f"{__name__}.data",
    geometry_module="knitsweep.stitches.rib.geometry",
    images="glides",
    contact_classes=MIRROR_CLASSES,
    path_order=tuple(range(layout.N_SEGMENTS)),
    closing_shift=(1, 0),
    mirror_parity=(1, 1),
)
"""The seed stitch: one knit stitch, the images with m + n odd mirrored."""
