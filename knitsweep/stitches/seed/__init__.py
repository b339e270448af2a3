"""Seed (moss) stitch: knit and purl alternating along the course and along the wale
(docs/model.md §11).

One knit stitch as a free periodic yarn whose images (m, n) with m + n odd are its
mirror images through the fabric plane (glide reflections). As in 1×1 rib the row's
yarn runs from the knit stitch into the purl one beside it, so the cell closes through
the glide with rib's geometry (``rib.geometry``, used unchanged); joint 0, where it
does, is pinned at the origin on the mirror plane. a_x and a_y are the per-stitch
course and wale spacings (the fabric repeats every 2 a_x and 2 a_y).

* the geometry is rib's (``knitsweep.stitches.rib.geometry``);
* the state, bounds and weights are the free yarn's (``stockinette_free.layout``); the
  starts (``data/``) are the authors' Init files made seed stitches (``start``).
"""

from __future__ import annotations

from ..stockinette_free import free_yarn_stitch

STITCH = free_yarn_stitch(
    "seed",
    "seed: knit and purl alternating in both directions (images with m + n odd mirrored)",
    __name__,
    mirror_parity=(1, 1),
    geometry_module="knitsweep.stitches.rib.geometry",
    stage_dL_mm=1.0,
)
"""The seed stitch: one knit stitch, its images with m + n odd mirrored."""
