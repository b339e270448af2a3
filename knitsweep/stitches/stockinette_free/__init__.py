"""The free periodic yarn of one stockinette cell (docs/model.md §11).

Every control point of the cell's 8 quintic segments is free, subject only to G2 at
every joint (continuity by construction) and the yarn length; it contains the paper's
ansatz exactly (``ansatz.to_free``) and measures how much that ansatz restricts.

* ``layout``: the 87 entries, bounds, bending weights (all 1), starts;
* ``geometry``: state -> control points with their exact Jacobian (numba);
* ``ansatz``: a stockinette state's control points -> the free state.
"""

from __future__ import annotations

from ..base import TRANSLATION_CLASSES, Stitch
from . import layout

STITCH = Stitch(
    name="stockinette_free",
    description="stockinette as a free periodic yarn (every control point free, G2 joints)",
    state_names=layout.STATE_NAMES,
    n_segments=layout.N_SEGMENTS,
    segment_weights=layout.SEGMENT_WEIGHTS,
    bounds=layout.state_bounds,
    twist_index=None,
    starts=layout.STARTS,
    data_package=f"{__name__}.data",
    geometry_module=f"{__name__}.geometry",
    images="translations",
    contact_classes=TRANSLATION_CLASSES,
    path_order=tuple(range(layout.N_SEGMENTS)),
    closing_shift=(1, 0),
)
"""The free stockinette yarn: stockinette's path and images, no crossover ansatz."""
