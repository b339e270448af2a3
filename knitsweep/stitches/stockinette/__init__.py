"""Stockinette (jersey): the paper's stitch (docs/model.md §2–5).

One cell holds one stitch: two crossovers C1, C2 (C2 the mirror image of C1 through
the cell's centre plane x = 0), each made of two quintic curves A and B, and four
connectors; 8 segments in all, the state's 28 shape parameters plus the two periods.
The fabric is the cell translated by the course and wale periods.

* ``layout``: the state's entries, bounds, bending weights, contact classes, starts;
* ``crossover``: one crossover's frame, end conditions and control points (numba);
* ``geometry``: state -> the 8 segments' control points with their exact Jacobian.
"""

from __future__ import annotations

from ..base import TRANSLATION_CLASSES, Stitch
from . import layout

STITCH = Stitch(
    name="stockinette",
    description="stockinette (jersey): knit stitches only, the paper's stitch",
    state_names=layout.STATE_NAMES,
    n_segments=layout.N_SEGMENTS,
    segment_weights=layout.SEGMENT_WEIGHTS,
    bounds=layout.state_bounds,
    twist_index=layout.IDX_TW,
    starts=layout.STARTS,
    data_package=f"{__name__}.data",
    geometry_module=f"{__name__}.geometry",
    images="translations",
    contact_classes=TRANSLATION_CLASSES,
    path_order=tuple(range(layout.N_SEGMENTS)),
    closing_shift=(1, 0),
)
"""The stockinette stitch: its segments in path order close after one course period."""
